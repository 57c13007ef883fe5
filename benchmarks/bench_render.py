"""Renderer benchmark: realizations per second, memory against batch size, and Mitsuba.

``python benchmarks/bench_render.py [--write] [--device auto|cpu|gpu]`` prints a markdown
report (``--write``: also to ``docs/render-benchmark.md``, or ``--write PATH``).

Scene: the default 3U CubeSat of :func:`pprender.models.cubesat` (bus, deployed wings,
antenna; about 12k triangles) with an aluminium bus (Beckmann alpha 0.15, single + double +
multiple), glass-covered cells (alpha 0.05), white-painted panel backs and an aluminium
antenna, monostatic at 1064 nm, 100 ps pulse, 128x128 pixels, one visibility sample per pixel
(``pixel_samples=1``, the ``"fast"`` sampling; two rows show 4 and 8, the ``"balanced"``
default; two more the kernel's f64 CPU twin, ``arithmetic="f64"``, which runs natively with
rayon instead of on the device; three ``brdf="shader"``, the single, multiple and diffuse
terms evaluated per pixel in the kernel instead of looked up) (and the same pulse as samples every
5 ps, whose profile takes the sampled-pulse path: accumulated on the host in f64). A realization is one
attitude. Rates are batch size / best wall time of ``--repeats`` calls of a batch of random
attitudes; the one-off costs (device creation, shader compilation, material tables) are
excluded from the rates and listed separately.

Memory: peak resident set size of a fresh process that renders one profile-only batch of
N attitudes (on lavapipe the device memory is host memory, so it is included).

Mitsuba: the same mesh and view (orthographic, a directional emitter along the view, the
``stokes`` integrator around ``path`` with ``max_depth=2``: single bounce), every part a
``roughconductor`` (Beckmann, aluminium's eta at 1064 nm, alpha 0.15), variant
``llvm_ad_mono_polarized``. Its pixel noise is measured from two renders with different
seeds (rms of the difference / sqrt 2 over covered pixels, relative to the mean S0 there);
the spp for 1% rms noise follows from noise ~ 1/sqrt(spp), and that render is timed (best
of ``--repeats``, after a warm-up render that compiles the kernels). pprender renders the
Stokes image of the same scene (its own materials, single bounce only for the
comparison) in the same run.

Inter-reflections (``bounces`` 2 and 3, :func:`interreflection_rows`): the same CubeSat at the
``"balanced"`` sampling (8 visibility samples per pixel), 128x128, Stokes profile only, a
batch of 8 random attitudes, on the device and on the f64 twin: realizations per second at
``path_samples`` 4 and 16, the cost against ``bounces=1`` on the same backend (same run),
and the noise, defined once (docs/interreflections.md): the RMS relative error of the
profile's bins above 1% of its peak, mean over the attitudes and over path seeds 0, 1 and
2, against the same settings with 1024 paths per pixel (64x and 256x the samples) and
another seed (7: with the same seed the reference would hold the measured render's paths).
The paths are traced on the CPU for every backend, so their noise is the same on each.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np

import pprender
from pprender import materials, models
from bench import cpu_model, emit_report, load_average, threads_available

RES = 128
# a 100 ps FWHM Gaussian sampled every 5 ps over +-150 ps (the sampled-pulse path)
SAMPLED_PULSE = np.exp(-0.5 * (np.arange(-30, 31) * 5e-12 / (100e-12 / (2 * math.sqrt(2 * math.log(2))))) ** 2)


def cubesat_scene(terms: tuple[str, ...] = ("single", "double", "multiple"),
                  orders: str | None = None) -> pprender.Scene:
    """The benchmark's CubeSat; ``orders`` (None: ``pprender.materials``' default, the
    path banks' ``"surface"`` for the Beckmann materials) for every material."""
    mesh = models.cubesat("3U")
    kw = {} if orders is None else {"orders": orders}
    mats = {
        "bus": materials.get("aluminium", alpha=0.15, terms=terms, **kw),
        "solar_cells": materials.get("fused_silica", alpha=0.05, **kw),
        "panel_back": materials.get("white_paint", **kw),
        "antenna": materials.get("aluminium", alpha=0.3, terms=terms, **kw),
    }
    return pprender.Scene(mesh, {p: mats[p] for p in mesh.metadata["pprender_parts"]})


def _banks_on_disk() -> set[str]:
    """The path banks' files in ``pprender.cache_dir()`` (empty without a disk cache)."""
    d = pprender.cache_dir()
    return set() if d is None or not d.is_dir() else {p.name for p in d.glob("bank-*.ppbank")}


def random_quaternions(n: int, seed: int = 5) -> np.ndarray:
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def best_time(f: Any, repeats: int) -> tuple[float, float]:
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t0)
    return min(ts), float(np.median(ts))


def _peak_rss_mb() -> float:
    """This process's peak resident set (MB): ``VmHWM`` of /proc/self/status where there is
    one. Not ``getrusage``'s ``ru_maxrss``: Linux carries the parent's peak into a child
    spawned by (v)fork + exec, so a fresh process reported the benchmark's own size (541 to
    721 MB where the child itself peaks near 250)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _memory_child(n: int, device: str) -> None:
    scene = cubesat_scene()
    sensor = pprender.Lidar(resolution=RES, pixel_samples=1)
    q = random_quaternions(n)
    pprender.render(scene, sensor, q, outputs=("profile",), device=device)
    print(json.dumps({"n": n, "maxrss_mb": _peak_rss_mb()}))


def memory_vs_n(ns: list[int], device: str) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    for n in ns:
        r = subprocess.run(
            [sys.executable, __file__, "--memory-child", str(n), "--device", device],
            capture_output=True, text=True, check=False,
        )
        try:
            out.append(json.loads(r.stdout.strip().splitlines()[-1]))
        except (IndexError, json.JSONDecodeError):
            out.append({"n": n, "maxrss_mb": float("nan"), "error": r.stderr[-300:]})
    return out


def mitsuba_monostatic_scene(mi: Any, ply_path: str, extent: float, res: int, bsdf: dict[str, Any],
                             smooth: bool | None = None) -> Any:
    """Mitsuba 3 scene of pprender's monostatic view: an orthographic sensor over the
    square [-extent, extent]^2 looking down -z (box pixel filter, res x res), a directional
    emitter of unit irradiance along the view, the ``stokes`` integrator over ``path`` with
    ``max_depth`` 2 (single scattering), the mesh at ``ply_path`` with ``bsdf`` (vertex
    normals when ``smooth``, face normals when False, Mitsuba's default when None). Its pixel radiance times ``4 pi delta^2`` is pprender's
    differential cross-section."""
    shape: dict[str, Any] = {"type": "ply", "filename": ply_path, "bsdf": bsdf}
    if smooth is not None:
        shape["face_normals"] = not smooth
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "stokes", "integrator": {"type": "path", "max_depth": 2}},
        "sensor": {
            "type": "orthographic",
            "to_world": mi.ScalarTransform4f.look_at(origin=[0, 0, 4 * extent], target=[0, 0, 0], up=[0, 1, 0])
            @ mi.ScalarTransform4f.scale([extent, extent, 1.0]),
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent"},
        },
        "emitter": {"type": "directional", "direction": [0, 0, -1], "irradiance": 1.0},
        "shape": shape,
    })


def mitsuba_stokes(scene_mesh: Any, extent: float, repeats: int) -> dict[str, Any]:
    from bench import MitsubaBench  # reuse its LLVM preparation

    MitsubaBench._prepare_llvm()
    import mitsuba as mi

    mi.set_variant("llvm_ad_mono_polarized")
    eta = materials.optical_constants("aluminium", 1064e-9)
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "cubesat.ply")
        scene_mesh.export(path)
        scene = mitsuba_monostatic_scene(mi, path, extent, RES, {
            "type": "roughconductor", "distribution": "beckmann", "alpha": 0.15,
            "eta": float(eta.real), "k": float(eta.imag)})

        def render(spp: int, seed: int) -> np.ndarray:
            img = np.asarray(mi.render(scene, spp=spp, seed=seed))  # type: ignore[arg-type]
            return img[..., 1] if img.shape[-1] > 1 else img[..., 0]  # S0 after Y

        t0 = time.perf_counter()
        render(4, 0)  # compile
        compile_s = time.perf_counter() - t0
        spp0 = 16
        a, b = render(spp0, 1), render(spp0, 2)
        cov = (a + b) > 0
        mean = float(np.mean(0.5 * (a + b)[cov]))
        noise0 = float(np.sqrt(np.mean(((a - b)[cov]) ** 2) / 2.0)) / mean
        spp = max(1, math.ceil(spp0 * (noise0 / 0.01) ** 2))
        render(spp, 3)  # warm (kernel for this spp)
        best, _ = best_time(lambda: render(spp, 4), repeats)
        c, e = render(spp, 5), render(spp, 6)
        noise = float(np.sqrt(np.mean(((c - e)[cov]) ** 2) / 2.0)) / mean
    return {"compile_s": compile_s, "noise_at_16": noise0, "spp": spp, "time": best, "noise": noise}


# the paths' seeds whose noise is averaged, and the reference's (another)
NOISE_SEEDS = (0, 1, 2)
REF_SEED = 7


def profile_noise(profile: np.ndarray, reference: np.ndarray) -> float:
    """The RMS relative error of a profile's bins above 1% of the reference's peak, averaged
    over attitudes: ``profile``, ``reference`` (N, B) (one channel)."""
    errs = []
    for p, r in zip(profile, reference):
        m = r > 0.01 * r.max()
        errs.append(np.sqrt(np.mean(((p[m] - r[m]) / r[m]) ** 2)))
    return float(np.mean(errs))


def interreflection_rows(device: str, repeats: int) -> list[str]:
    """The inter-reflection table (module docstring)."""
    scene = cubesat_scene()
    q = random_quaternions(8, seed=11)

    def lidar(bounces: int, paths: int, arithmetic: str | None, seed: int = 0) -> pprender.Lidar:
        return pprender.Lidar(resolution=RES, pixel_samples=8, polarization=[1, 1, 0, 0], bounces=bounces,
                              path_samples=paths, path_seed=seed, arithmetic=arithmetic)

    refs: dict[int, np.ndarray] = {}
    for b in (2, 3):
        ref = pprender.render(scene, lidar(b, 1024, "f64", REF_SEED), q, outputs=("profile",)).profile
        assert ref is not None
        refs[b] = ref
    out = ["Inter-reflections (module docstring: `balanced` sampling, batch of 8, Stokes profile only):", "",
           "| backend | bounces | paths per pixel | realizations/s (best) | cost vs bounces=1 | profile noise |",
           "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for backend, arith in ((device, None), ("f64 twin", "f64")):
        base = None
        for bounces, paths in ((1, 1), (2, 4), (2, 16), (3, 4), (3, 16)):
            sensor = lidar(bounces, paths, arith)
            pprender.render(scene, sensor, q[:1], outputs=("profile",), device=device)
            best, _ = best_time(lambda: pprender.render(scene, sensor, q, outputs=("profile",), device=device),
                                repeats)
            base = best if base is None else base
            noise = ""
            if bounces > 1:
                # the mean over path seeds 0, 1, 2 (one seed's noise varies by tens of percent)
                each = []
                for seed in NOISE_SEEDS:
                    seeded = lidar(bounces, paths, arith, seed)
                    r = pprender.render(scene, seeded, q, outputs=("profile",), device=device)
                    assert r.profile is not None
                    each.append(profile_noise(r.profile[..., 0], refs[bounces][..., 0]))
                noise = f"{np.mean(each):.4f}"
            shown = "" if bounces == 1 else str(paths)
            out.append(f"| {backend} | {bounces} | {shown} | {len(q) / best:,.1f} | {best / base:.1f}x | {noise} |")
    out.append("")
    return out


def main(repeats: int = 3, device: str = "auto", write: Any = False, quiet: bool = False,
         with_mitsuba: bool = True, batch: int = 64) -> str:
    info = pprender.device_info(device)
    load0 = load_average()
    t_start = time.perf_counter()
    banks_before = _banks_on_disk()
    t0 = time.perf_counter()
    scene = cubesat_scene()
    t_materials = time.perf_counter() - t0
    traced = sorted(_banks_on_disk() - banks_before)
    t_tables = scene.prepare(0.0)
    q = random_quaternions(batch)
    rows = []
    cases = [
        ("full model: profile + Mueller image + range", pprender.Lidar(resolution=RES, pixel_samples=1), ("profile", "mueller", "range")),
        ("profile only (Mueller, 16 channels)", pprender.Lidar(resolution=RES, pixel_samples=1), ("profile",)),
        ("profile only (Stokes, horizontal transmit)", pprender.Lidar(resolution=RES, pixel_samples=1, polarization=[1, 1, 0, 0]), ("profile",)),
        ("profile only (Stokes), 4 visibility samples per pixel", pprender.Lidar(
            resolution=RES, polarization=[1, 1, 0, 0], pixel_samples=4), ("profile",)),
        ("profile only (Stokes), 8 visibility samples per pixel", pprender.Lidar(
            resolution=RES, polarization=[1, 1, 0, 0], pixel_samples=8), ("profile",)),
        ("cross-section only (Stokes)", pprender.Lidar(resolution=RES, pixel_samples=1, polarization=[1, 1, 0, 0]), ()),
        ("profile only (Stokes), sampled pulse: host accumulation", pprender.Lidar(
            resolution=RES, pixel_samples=1, polarization=[1, 1, 0, 0], pulse_samples=SAMPLED_PULSE, pulse_sample_spacing=5e-12,
        ), ("profile",)),
        ("profile only, intensity of an unpolarized transmitter (M00 alone)", pprender.Lidar(
            resolution=RES, pixel_samples=1, polarization=[1, 0, 0, 0], intensity_only=True), ("profile",)),
        ("profile only (Stokes), terms evaluated in the kernel (`brdf=\"shader\"`; double bounce tabulated)",
         pprender.Lidar(resolution=RES, pixel_samples=1, polarization=[1, 1, 0, 0], brdf="shader"), ("profile",)),
        ("full model, terms evaluated in the kernel (`brdf=\"shader\"`)", pprender.Lidar(
            resolution=RES, pixel_samples=1, brdf="shader"), ("profile", "mueller", "range")),
        ("profile only (Stokes), f64 CPU twin (`arithmetic=\"f64\"`, native, no device)", pprender.Lidar(
            resolution=RES, pixel_samples=1, polarization=[1, 1, 0, 0], arithmetic="f64"), ("profile",)),
        ("profile only (Stokes), 8 visibility samples per pixel, f64 CPU twin", pprender.Lidar(
            resolution=RES, pixel_samples=8, polarization=[1, 1, 0, 0], arithmetic="f64"), ("profile",)),
    ]
    # what the model's terms cost: the same request with single-bounce-only materials
    single_only = cubesat_scene(terms=("single",))
    single_only.prepare(0.0)
    # and with the seed's orders >= 2 (the materials' default before issue 24's item 5)
    t0 = time.perf_counter()
    seed_orders = cubesat_scene(orders="seed")
    t_materials_seed = time.perf_counter() - t0
    t_tables_seed = seed_orders.prepare(0.0)
    seed_cases = [("full model, the seed's orders >= 2 (`orders=\"seed\"`)", *cases[0][1:])]
    special = [
        ("profile only (Stokes), single bounce only", pprender.Lidar(resolution=RES, pixel_samples=1, polarization=[1, 1, 0, 0]),
         ("profile",)),
        ("profile only (Stokes), single bounce only, evaluated in the kernel", pprender.Lidar(
            resolution=RES, pixel_samples=1, polarization=[1, 1, 0, 0], brdf="shader"), ("profile",)),
    ]
    t0 = time.perf_counter()
    pprender.render(scene, cases[0][1], q[:1], outputs=cases[0][2], device=device)
    first_call = time.perf_counter() - t0
    for sc, label, sensor, outs in ([(scene, *c) for c in cases] + [(seed_orders, *c) for c in seed_cases]
                                    + [(single_only, *c) for c in special]):
        pprender.render(sc, sensor, q[:2], outputs=outs, device=device)  # pipeline variant
        best, med = best_time(lambda: pprender.render(sc, sensor, q, outputs=outs, device=device), repeats)
        rows.append((label, batch / best, batch / med))
    # single-attitude calls (latency)
    best1, _ = best_time(lambda: pprender.render(scene, cases[1][1], q[:1], outputs=("profile",), device=device), repeats)
    mem: list[dict[str, Any]] = memory_vs_n([1, 100, 1000], device)
    bounce_rows = interreflection_rows(device, repeats)

    mit: dict[str, Any] | None = None
    ours_stokes = float("nan")
    if with_mitsuba:
        single = cubesat_scene(terms=("single",))
        s_sensor = pprender.Lidar(resolution=RES, pixel_samples=1, polarization=[1, 0, 0, 0])
        pprender.render(single, s_sensor, np.array([[1.0, 0, 0, 0]]), outputs=("stokes",), device=device)
        ours_stokes, _ = best_time(
            lambda: pprender.render(single, s_sensor, np.array([[1.0, 0, 0, 0]]), outputs=("stokes",), device=device),
            repeats,
        )
        try:
            mit = mitsuba_stokes(models.cubesat("3U"), single.radius, repeats)
        except Exception as e:  # report, do not hide
            mit = {"error": repr(e)}
    total_s = time.perf_counter() - t_start

    L = ["# Renderer benchmark", "", f"`python benchmarks/bench_render.py` (module docstring: method).", ""]
    L.append(f"- Device: {info['name']} ({info['device_type']}, {info['driver_info']}); CPU: {cpu_model()}, "
             f"{threads_available()} threads; load average at start {load0}, at end {load_average()}.")
    L.append(f"- Scene: 3U CubeSat, {scene.n_faces} triangles, {RES}x{RES} pixels, monostatic, "
             f"batch of {batch} random attitudes; pprender {pprender.__version__}; total run {total_s:.0f} s.")
    L.append(f"- One-off: materials {t_materials:.2f} s, BRDF tables {t_tables:.2f} s, first render call "
             f"(device + shader compilation) {first_call:.2f} s. The materials are `pprender.materials`' "
             f"defaults: orders >= 2 from the path banks (`orders=\"surface\"`) for the aluminium; "
             f"{'path banks traced in this run (not in the disk cache): ' + ', '.join(traced) if traced else 'the path banks read from the disk cache'}. With the "
             f"seed's orders (`orders=\"seed\"`): materials {t_materials_seed:.2f} s, BRDF tables {t_tables_seed:.2f} s.")
    L.append("")
    L.append("| request | realizations/s (best) | realizations/s (median) |")
    L.append("| --- | ---: | ---: |")
    for label, b, m in rows:
        L.append(f"| {label} | {b:,.0f} | {m:,.0f} |")
    L.append(f"| one attitude per call, profile only | {1 / best1:,.0f} | |")
    L.append("")
    L += bounce_rows
    L.append("Peak memory (RSS of a fresh process, profile only):")
    L.append("")
    L.append("| N attitudes | peak RSS (MB) |")
    L.append("| ---: | ---: |")
    for mm in mem:
        L.append(f"| {mm['n']} | {mm['maxrss_mb']:.0f} |")
    L.append("")
    if with_mitsuba and mit is not None:
        if "error" in mit:
            L.append(f"Mitsuba comparison failed: `{mit['error']}`")
        else:
            L.append("Stokes image of one attitude (single bounce), same machine, same run:")
            L.append("")
            L.append("| renderer | time | note |")
            L.append("| --- | ---: | --- |")
            L.append(f"| pprender | {1e3 * ours_stokes:.1f} ms | deterministic (no sampling noise) |")
            L.append(f"| Mitsuba 3 llvm_ad_mono_polarized | {1e3 * mit['time']:.1f} ms | {mit['spp']} spp for 1% rms "
                     f"pixel noise (measured {100 * mit['noise']:.2f}%; {100 * mit['noise_at_16']:.1f}% at 16 spp); "
                     f"kernel compilation {mit['compile_s']:.1f} s excluded |")
            L.append("")
            L.append(f"Ratio Mitsuba / pprender: {mit['time'] / ours_stokes:.1f}x.")
            L.append("")
    report = "\n".join(L) + "\n"
    return emit_report(report, write, "render-benchmark.md" if device != "gpu" else "render-benchmark-gpu.md", quiet)


def _cli(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="python benchmarks/bench_render.py", description=__doc__.splitlines()[0])
    p.add_argument("-r", "--repeats", type=int, default=3)
    p.add_argument("--device", default="auto")
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--write", nargs="?", const=True, default=False, metavar="PATH")
    p.add_argument("--no-mitsuba", action="store_true")
    p.add_argument("--memory-child", type=int, default=None, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.memory_child is not None:
        _memory_child(a.memory_child, a.device)
        return
    main(repeats=a.repeats, device=a.device, write=a.write, with_mitsuba=not a.no_mitsuba, batch=a.batch)


if __name__ == "__main__":
    _cli()
