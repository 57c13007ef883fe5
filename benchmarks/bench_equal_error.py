"""Equal-error comparison with Mitsuba 3: time to reach the same RMS error on a Stokes image.

``python benchmarks/bench_equal_error.py [--write]`` (``--write``: docs/equal-error.md).

Method
------
* Scenes both renderers model identically: a smooth-shaded sphere (radius 0.5 m) and the
  3U CubeSat mesh without its whip antenna (flat faces; the antenna's specular line is
  narrower than the reference's sub-pixels, so the reference would not be converged), the
  CubeSat turned to a generic attitude (``ATTITUDE``; the mesh itself is rotated, so both
  renderers see the same vertices; at the identity it is seen end-on, one face filling
  most covered pixels with its edges on pixel boundaries), one ``roughconductor``
  material (Beckmann, alpha 0.2, aluminium's eta at 1064 nm, Smith masking with Walter's
  G1, single bounce: pprender's ``shadowing="smith", smith_g1="walter",
  terms=["single"]``), monostatic, unpolarized transmitter, orthographic view of the
  bounding square at 128 x 128 pixels.
* The truth: pprender's exact f64 reference (``quality="reference"``, core BRDF, exact ray
  casting) at 8 x 8 sub-pixels per pixel, summed: the area-integrated pixel values, which
  is what Mitsuba's box pixel filter converges to (and what a pixel of a real camera is).
* Error of an image: ``sqrt(mean((S0 - S0_ref)^2)) / mean(S0_ref)`` over the pixels covered
  in either (S0 in m^2 per pixel; Mitsuba's radiance times ``4 pi delta^2``).
* pprender: the settings in ``SETTINGS`` (quality preset, visibility samples per pixel,
  supersampling, and the arithmetic: the f32 device kernel on lavapipe, or its f64 CPU
  twin, ``arithmetic="f64"``, native with rayon on the same CPU) at 128 x 128; time per realization in a batch of 32 attitudes (best of
  ``repeats``) and for one attitude per call.
* Mitsuba (``llvm_ad_mono_polarized``, ``stokes`` integrator over ``path`` with
  ``max_depth`` 2, directional emitter, ``independent`` sampler): its error measured at
  ``MITSUBA_SPP`` (mean over two seeds) and its time there (best of ``repeats``). The spp
  that reaches an error ``e`` is interpolated log-log between the measured points; below
  the error at the largest measured spp it is extrapolated as Monte Carlo noise,
  ``spp = spp_max (err_max / e)^2``, and its time linearly in spp from the measured
  times (marked "extrapolated"). A bias floor in Mitsuba's result would make it slower
  than extrapolated, so extrapolated ratios are lower bounds. Mitsuba's kernel
  compilation is excluded (it is cached between runs of a scene).
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

import pprender

#: The repository's docs/ (the pages ``--write`` writes).
DOCS = Path(__file__).resolve().parents[1] / "docs"

RES = 128
SS_REF = 8
# (label, quality preset, visibility samples per pixel (None: the preset's), supersampling,
# arithmetic: "f32" the device kernel, "f64" its CPU twin on the same tables)
SETTINGS = [
    ("fast", "fast", None, 1, "f32"),
    ("fast, ss 2", "fast", None, 2, "f32"),
    ("fast, 4 samples", "fast", 4, 1, "f32"),
    ("balanced", "balanced", None, 1, "f32"),
    ("accurate", "accurate", None, 1, "f32"),
    ("accurate, ss 2", "accurate", None, 2, "f32"),
    ("accurate, ss 4", "accurate", None, 4, "f32"),
    ("fast, f64 CPU twin", "fast", None, 1, "f64"),
    ("accurate, ss 2, f64 CPU twin", "accurate", None, 2, "f64"),
    ("accurate, ss 4, f64 CPU twin", "accurate", None, 4, "f64"),
]
MITSUBA_SPP = (4, 16, 64, 256, 1024)
# the CubeSat's attitude: a rotation by 0.7 rad about (1, 2, 0.5) (generic: no face
# edge-on, no edge along the pixel grid)
ATTITUDE_AXIS = (1.0, 2.0, 0.5)
ATTITUDE_ANGLE = 0.7
ALUMINIUM_1064 = 1.3763 + 10.2449j
ALPHA = 0.2


def _material() -> pprender.Material:
    return pprender.Material("beckmann", alpha=ALPHA, eta=ALUMINIUM_1064, shadowing="smith",
                             correlation="none", smith_g1="walter", terms=("single",))


def _scenes() -> list[tuple[str, Any, bool]]:
    from pprender import models

    import trimesh

    cubesat = models.cubesat("3U", antenna=False).copy()
    cubesat.apply_transform(trimesh.transformations.rotation_matrix(ATTITUDE_ANGLE, ATTITUDE_AXIS))
    return [("sphere", models.sphere(radius=0.5, subdivisions=5), True),
            ("3U CubeSat, no antenna, generic attitude", cubesat, False)]


def rms_error(img: np.ndarray, ref: np.ndarray) -> float:
    """``sqrt(mean((img - ref)^2)) / mean(ref)`` over pixels covered in either image."""
    cov = (img > 0) | (ref > 0)
    return float(np.sqrt(np.mean((img[cov] - ref[cov]) ** 2)) / np.mean(ref[cov]))


def _best(f: Any, repeats: int) -> float:
    from bench_render import best_time

    return best_time(f, repeats)[0]


def _mitsuba_scene(mesh: Any, ext: float, smooth: bool, d: str) -> Any:
    from bench import MitsubaBench

    MitsubaBench._prepare_llvm()
    import mitsuba as mi

    mi.set_variant("llvm_ad_mono_polarized")
    path = os.path.join(d, "mesh.ply")
    mesh.export(path)
    from bench_render import mitsuba_monostatic_scene

    return mi, mitsuba_monostatic_scene(mi, path, ext, RES, {
        "type": "roughconductor", "distribution": "beckmann", "alpha": ALPHA,
        "eta": ALUMINIUM_1064.real, "k": ALUMINIUM_1064.imag}, smooth=smooth)


def measure(repeats: int = 3, batch: int = 32, device: str = "auto") -> list[dict[str, Any]]:
    out = []
    mat = _material()
    q1 = np.eye(3)[None]
    for name, mesh, smooth in _scenes():
        scene = pprender.Scene(mesh, mat, smooth=smooth)
        ext = scene.radius
        pix = 2 * ext / RES
        t0 = time.perf_counter()
        ref = pprender.render(scene, pprender.Lidar(quality="reference", resolution=RES, supersampling=SS_REF),
                              q1, outputs=("mueller",))
        t_ref = time.perf_counter() - t0
        assert ref.mueller is not None
        s0_ref = ref.mueller[0, ..., 0, 0].astype(np.float64)
        rows: list[dict[str, Any]] = []
        qb = np.repeat(q1, batch, axis=0)
        for label, quality, samples, ss, arithmetic in SETTINGS:
            sensor = pprender.Lidar(quality=quality, resolution=RES, supersampling=ss, polarization=[1, 0, 0, 0],
                                    pixel_samples=samples, arithmetic=arithmetic)
            r = pprender.render(scene, sensor, q1, outputs=("stokes",), device=device)
            assert r.stokes is not None
            err = rms_error(r.stokes[0, ..., 0].astype(np.float64), s0_ref)
            t_batch = _best(lambda: pprender.render(scene, sensor, qb, outputs=("stokes",), device=device),
                            repeats) / batch
            t_one = _best(lambda: pprender.render(scene, sensor, q1, outputs=("stokes",), device=device), repeats)
            rows.append({"setting": label, "samples": sensor.effective_pixel_samples() * ss * ss, "err": err,
                         "t_batch": t_batch, "t_one": t_one})
        with tempfile.TemporaryDirectory() as d:
            mi, msc = _mitsuba_scene(mesh, ext, smooth, d)

            def s0(spp: int, seed: int) -> np.ndarray:
                img = np.asarray(mi.render(msc, spp=spp, seed=seed))  # type: ignore[arg-type]
                return img[..., 1].astype(np.float64) * 4 * math.pi * pix * pix

            s0(4, 0)  # compile
            timed: dict[int, float] = {}
            errs: dict[int, float] = {}
            for spp in MITSUBA_SPP:
                s0(spp, 1)  # this spp's kernel
                timed[spp] = _best(lambda: s0(spp, 2), repeats)
                errs[spp] = float(np.mean([rms_error(s0(spp, 10 + k), s0_ref) for k in range(2)]))
            spps = np.array(MITSUBA_SPP, dtype=float)
            per_spp, fixed = np.polyfit(spps, [timed[k] for k in MITSUBA_SPP], 1)

            def mitsuba_time(e: float) -> tuple[float, float, bool]:
                """(spp, seconds, extrapolated) for Mitsuba to reach error e."""
                ev = np.array([errs[k] for k in MITSUBA_SPP])
                if e >= ev[0]:
                    return float(MITSUBA_SPP[0]), timed[MITSUBA_SPP[0]], False
                if e < ev[-1]:
                    spp = spps[-1] * (ev[-1] / e) ** 2
                    return spp, fixed + per_spp * spp, True
                # log-log between the bracketing measurements (errors fall with spp, but
                # not always monotonically: take the first bracket)
                k = int(np.argmax(ev <= e))
                t = math.log(e / ev[k - 1]) / math.log(ev[k] / ev[k - 1])
                spp = math.exp(math.log(spps[k - 1]) + t * math.log(spps[k] / spps[k - 1]))
                sec = math.exp(math.log(timed[MITSUBA_SPP[k - 1]]) + t * math.log(timed[MITSUBA_SPP[k]] / timed[MITSUBA_SPP[k - 1]]))
                return spp, sec, False

            targets = sorted({0.01} | {float(r["err"]) for r in rows}, reverse=True)
            mt = {e: mitsuba_time(e) for e in targets}
        out.append({"scene": name, "rows": rows, "ref_seconds": t_ref, "mitsuba_errs": errs,
                    "mitsuba": mt, "timed": timed})
    return out


def report(results: list[dict[str, Any]], batch: int) -> str:
    info = pprender.device_info()
    L = ["# Equal-error comparison with Mitsuba 3", "",
         "Generated by `python benchmarks/bench_equal_error.py --write` (method in the module "
         f"docstring). pprender on {info['name']}; Mitsuba 3 llvm_ad_mono_polarized on the same CPU, "
         "same run. Error: RMS of S0 over covered pixels relative to the mean S0, against the "
         f"exact f64 reference at {SS_REF}x{SS_REF} sub-pixels per pixel.", ""]
    for res in results:
        ladder = ", ".join(f"{res['mitsuba_errs'][k]:.2e} at {k} spp ({1e3 * res['timed'][k]:,.0f} ms)"
                           for k in MITSUBA_SPP)
        L += [f"## {res['scene']}", "",
              f"Mitsuba, measured: {ladder}. Reference render {res['ref_seconds']:.1f} s.", "",
              "| pprender setting | visibility samples per pixel (K ss^2) | RMS error | ms / image (batch of %d) | ms (one per call) | Mitsuba spp for that error | Mitsuba ms | ratio (batch) | ratio (one per call) |" % batch,
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in res["rows"]:
            spp, tm, extrap = res["mitsuba"][r["err"]]
            mark = " (extrapolated)" if extrap else ""
            L.append(f"| {r['setting']} | {r['samples']} | {r['err']:.2e} | {1e3 * r['t_batch']:.2f} | "
                     f"{1e3 * r['t_one']:.1f} | {spp:,.0f}{mark} | {1e3 * tm:,.0f} | {tm / r['t_batch']:,.0f}x | "
                     f"{tm / r['t_one']:,.0f}x |")
        # the 1% level: the fastest pprender setting within 1%
        ok = [r for r in res["rows"] if r["err"] <= 0.01]
        spp, tm, extrap = res["mitsuba"][0.01]
        if ok:
            best = min(ok, key=lambda r: r["t_batch"])
            L += ["", f"At 1% RMS: Mitsuba needs {spp:,.0f} spp, {1e3 * tm:,.0f} ms"
                  f"{' (extrapolated)' if extrap else ''}; the fastest pprender setting within 1% is "
                  f"{best['setting']} ({100 * best['err']:.2f}%): {1e3 * best['t_batch']:.2f} ms "
                  f"per image in a batch, {1e3 * best['t_one']:.1f} ms alone: **{tm / best['t_batch']:,.0f}x** "
                  f"(batch), {tm / best['t_one']:,.0f}x (one per call)."]
        else:
            L += ["", "At 1% RMS: no pprender setting here reaches 1% (see the rows)."]
        L.append("")
    return "\n".join(L) + "\n"


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(prog="python benchmarks/bench_equal_error.py")
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--device", default="auto")
    a = ap.parse_args(argv)
    text = report(measure(repeats=a.repeats, batch=a.batch, device=a.device), a.batch)
    print(text)
    if a.write:
        path = DOCS / "equal-error.md"
        path.write_text(text)
        print(f"wrote {path}")
    return text


if __name__ == "__main__":
    main()
