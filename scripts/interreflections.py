"""Inter-reflections (``bounces`` 2 and 3) against Mitsuba 3, and what they cost.

``python scripts/interreflections.py`` prints markdown tables and writes them to
``docs/interreflections.md`` (``--quick`` runs a small version and writes nothing; the
tests run it; ``--section 3`` runs section 3 alone and replaces it in the committed page).
The Mitsuba numbers are read from the committed references
(``benchmarks/mitsuba_corners.py --write docs/data/mitsuba-corners.json``, and for the
CubeSat ``benchmarks/mitsuba_cubesat.py --write docs/data/mitsuba-cubesat.json`` where it
exists), so this script needs no Mitsuba. Sections:

1. Corners: a 0.3 m dihedral of rough aluminium (Beckmann alpha 0.1 and 0.3, single term,
   Smith masking with Walter's G1: what Mitsuba's ``roughconductor`` evaluates) swept
   across its opening and tilted out of it, and a square trihedral (alpha 0.05) off its
   axis: each bounce order's S0 against Mitsuba's (``max_depth`` 2, 3, 4 differences), and
   the second bounce's S1/S0. pprender: 128 x 128, 64 paths per pixel, mean of two seeds;
   its noise is half their difference (a rough estimate, as Mitsuba's).
2. The 3U CubeSat against Mitsuba (matched stand-in materials, 50 attitudes; pprender the mean
   of two path seeds, and each seed alone where an order is furthest from Mitsuba), if its
   reference file exists.
3. Noise and cost on the 3U CubeSat with the demo materials (``bench_render.cubesat_scene``,
   128 x 128, monostatic, H-polarized transmitter, profile only, ``arithmetic="f64"``: the
   CPU twin): seconds per attitude for ``bounces`` 1, 2, 3 at several ``path_samples``, and
   the noise, defined once: the RMS relative error of the profile's bins above 1% of its
   peak, and separately of the S0 image's pixels above 1% of its maximum, against a render
   with 64 times the paths (16 times for the largest count).
4. What each bounce adds on the CubeSat over 50 attitudes (``numpy.random.default_rng(2024)``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import mitsuba_corners as mc  # noqa: E402  (the corners' meshes and attitudes)
from bench_render import cubesat_scene  # noqa: E402

import pprender  # noqa: E402

ALUMINIUM = complex(1.3763, 10.2449)


def aluminium(alpha: float) -> pprender.Material:
    return pprender.Material("beckmann", alpha=alpha, eta=ALUMINIUM, shadowing="smith", correlation="none",
                             smith_g1="walter", terms=("single",))


def attitudes(n: int) -> np.ndarray:
    q = np.random.default_rng(2024).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def fmt(x: float) -> str:
    return f"{x:.4g}"


def corners(quick: bool) -> list[str]:
    data = json.loads((ROOT / "docs/data/mitsuba-corners.json").read_text())
    res, paths = (48, 16) if quick else (128, 64)
    out = ["## 1. Corners against Mitsuba", "",
           f"pprender {res} x {res}, {paths} paths per pixel, mean of seeds 0 and 1 (+- half their difference); "
           f"Mitsuba {data['mitsuba']['version']} ({data['mitsuba']['variant']}) {data['entries'][0]['spp']} spp, "
           f"{data['entries'][0]['resolution']} x {data['entries'][0]['resolution']}, seeds "
           f"{data['entries'][0]['seeds']} (+- its noise estimate). S0 in m^2 per bounce order (Mitsuba's "
           "`max_depth` k + 1 minus k); orders below 1e-3 of the total are left out; ratio = pprender / Mitsuba.", "",
           "| corner | alpha | view | bounces | Mitsuba S0 | pprender S0 | ratio | S1/S0 Mitsuba | S1/S0 pprender |",
           "|---|---|---|---|---|---|---|---|---|"]
    worst = {1: 0.0, 2: 0.0}
    for s in data["summary"]:
        if quick and not (s["mesh"] == "trihedral" and s["off_axis_deg"] == 0.0 or
                          s["mesh"] == "dihedral" and s["alpha"] == 0.3 and s["theta_deg"] == 20.0):
            continue
        mesh = mc.dihedral() if s["mesh"] == "dihedral" else mc.trihedral()
        entry = next(e for e in data["entries"] if e["mesh"] == s["mesh"] and e["bsdf"]["alpha"] == s["alpha"]
                     and e["view"] == {k: s[k] for k in e["view"]})
        rot = np.asarray(entry["rotation"])[None]
        sc = pprender.Scene(mesh, aluminium(s["alpha"]))
        runs = []
        for seed in (0, 1):
            lidar = pprender.Lidar(resolution=res, bounces=3, path_samples=paths, path_seed=seed,
                                   polarization=[1, 0, 0, 0], arithmetic="f64")
            by = pprender.render(sc, lidar, rot, outputs=("profile",)).by_bounce
            assert by is not None
            runs.append(by["cross_section"][0])
        ours, noise = 0.5 * (runs[0] + runs[1]), 0.5 * np.abs(runs[0] - runs[1])
        theirs = [s["single_S0"], s["double_S0"], s["triple_S0"]]
        their_noise = [0.0, s["double_S0_noise"], s["triple_S0_noise"]]
        total = sum(theirs)
        view = (f"{s['theta_deg']:g} deg, tilt {s['tilt_deg']:g}" if s["mesh"] == "dihedral"
                else f"{s['off_axis_deg']:g} deg off axis")
        for k in range(3):
            if theirs[k] <= 1e-3 * total:
                continue
            ratio = ours[k, 0] / theirs[k]
            if theirs[k] > 0.01 * total and k > 0:
                worst[k] = max(worst[k], abs(ratio - 1))
            pol = ("", "")
            if k == 1:
                pol = (fmt(s["double_stokes"][1] / s["double_stokes"][0]), fmt(ours[1, 1] / ours[1, 0]))
            out.append(f"| {s['mesh']} | {s['alpha']:g} | {view} | {k + 1} | {fmt(theirs[k])} +- {their_noise[k]:.2g} | "
                       f"{fmt(ours[k, 0])} +- {noise[k, 0]:.2g} | {ratio:.4f} | {pol[0]} | {pol[1]} |")
    out += ["", f"Largest |ratio - 1| where the order carries more than 1% of the total: second bounce "
                f"{worst[1]:.4f}, third bounce {worst[2]:.4f} (compare each with the two noise estimates "
                "beside it: the rare-event views, such as the alpha 0.1 dihedral tilted 20 deg out of its "
                "cross-section, are noisy in both renderers).", ""]
    return out


def cubesat_vs_mitsuba(quick: bool) -> list[str]:
    path = ROOT / "docs/data/mitsuba-cubesat.json"
    if not path.exists():
        return ["## 2. The 3U CubeSat against Mitsuba", "",
                "No reference file (docs/data/mitsuba-cubesat.json): not compared.", ""]
    import mitsuba_cubesat  # noqa: PLC0415  (benchmarks/, on the path above)

    data = json.loads(path.read_text())
    scene, _ = mitsuba_cubesat.matched_scene()
    entries = data["entries"][: 4 if quick else None]
    res = 64 if quick else int(data["render"]["resolution"])
    paths = 16 if quick else 64
    rots = np.asarray([e["rotation"] for e in entries])
    # the one-bounce part at 16 samples and 4 x 4 sub-pixels: the panels' 2 mm painted rims
    # are a third of a pixel wide (benchmarks/mitsuba_cubesat.py)
    seeds = (0, 1)
    per_seed = []
    for seed in seeds:
        lidar = pprender.Lidar(resolution=res, supersampling=1 if quick else 4, pixel_samples=16, bounces=3,
                               path_samples=paths, path_seed=seed, polarization=[1, 0, 0, 0], arithmetic="f64")
        r = pprender.render(scene, lidar, rots, outputs=("profile",))
        assert r.by_bounce is not None
        per_seed.append(r.by_bounce["cross_section"][..., 0])
    ours = np.mean(per_seed, axis=0)
    t = {d: np.array([e["by_depth"][str(d)]["totals"][0] for e in entries]) for d in (2, 3, 4, 8)}
    theirs = np.stack([t[2], t[3] - t[2], t[4] - t[3]], axis=1)

    def q(v: np.ndarray) -> str:
        if len(v) == 0:
            return "-"
        return f"{np.median(v):+.4f} / {np.quantile(np.abs(v), 0.9):.4f} / {v[np.argmax(np.abs(v))]:+.4f} ({len(v)})"

    rows = ["## 2. The 3U CubeSat against Mitsuba", "",
            f"{len(entries)} attitudes (`numpy.random.default_rng(2024)`), matched stand-in materials "
            "(benchmarks/mitsuba_cubesat.py: single-term Beckmann aluminium and glass, Lambertian paint), Mitsuba "
            f"{data['render']['spp']} spp from the committed file; pprender {res} x {res}, 16 visibility samples "
            f"{'' if quick else 'and 4 x 4 sub-pixels '}per pixel, {paths} paths per pixel, the mean of path seeds "
            f"{seeds[0]} and {seeds[1]}, f64. Relative error of "
            "S0 (pprender / Mitsuba - 1): median / 90th percentile of its magnitude / largest in magnitude "
            "(attitudes counted), each bounce order where it carries more than 1% of Mitsuba's total:", "",
            "| compared | relative error |", "|---|---|"]
    worst = []
    for k, name in enumerate(("1 bounce vs max_depth 2", "2nd bounce vs max_depth 3 - 2",
                              "3rd bounce vs max_depth 4 - 3")):
        m = theirs[:, k] > 0.01 * t[8]
        rows.append(f"| {name} | {q(ours[m, k] / theirs[m, k] - 1)} |")
        if k > 0 and m.any():
            i = np.flatnonzero(m)[np.argmax(np.abs(ours[m, k] / theirs[m, k] - 1))]
            each = ", ".join(f"{s_[i, k] / theirs[i, k] - 1:+.3f}" for s_ in per_seed)
            worst.append(f"order {k + 1}: attitude {i} ({theirs[i, k] / t[8][i]:.3f} of S0), seeds {each}")
    rows.append(f"| bounces=3 vs max_depth 4 | {q(ours.sum(1) / t[4] - 1)} |")
    rows.append(f"| bounces=3 vs max_depth 8 | {q(ours.sum(1) / t[8] - 1)} |")
    rows += ["", "Where each order is furthest from Mitsuba, the error of each seed alone (their spread is the "
                 "noise of the paths there): " + "; ".join(worst) + "."]
    multi, third, beyond = (t[8] - t[2]) / t[8], (t[4] - t[3]) / t[8], (t[8] - t[4]) / t[8]
    rows += ["", "Mitsuba's light by number of bounces, fraction of S0 at max_depth 8 (median / 90th percentile / "
                 "largest):", "",
             "| bounces | fraction of S0 |", "|---|---|"]
    for name, v in (("2 or more", multi), ("3", third), ("4 or more", beyond)):
        rows.append(f"| {name} | {np.median(v):.4f} / {np.quantile(v, 0.9):.4f} / {v.max():.4f} |")
    rows += ["", "Beyond 3 bounces Mitsuba finds at most the fraction above: `bounces=3` is within 2% of "
                 "`max_depth` 8 wherever the three orders are right.", ""]
    return rows


def noise_and_cost(quick: bool) -> list[str]:
    sc = cubesat_scene()
    n = 2 if quick else 6
    rots = attitudes(50)[[3, 7, 11, 19, 23, 31][:n]]
    res = 48 if quick else 128
    counts = (4,) if quick else (4, 16, 64)

    def run(bounces: int, paths: int, seed: int = 0, repeats: int = 3):
        lidar = pprender.Lidar(resolution=res, bounces=bounces, path_samples=paths, path_seed=seed,
                               polarization=[1, 1, 0, 0], arithmetic="f64")
        pprender.render(sc, lidar, rots[:1], outputs=("profile",))  # tables, warm-up
        best = math.inf
        for _ in range(repeats):
            t = time.perf_counter()
            r = pprender.render(sc, lidar, rots, outputs=("profile",))
            best = min(best, (time.perf_counter() - t) / len(rots))
        return r, best

    def with_images(bounces: int, paths: int, seed: int = 1):
        lidar = pprender.Lidar(resolution=res, bounces=bounces, path_samples=paths, path_seed=seed,
                               polarization=[1, 1, 0, 0], arithmetic="f64")
        return pprender.render(sc, lidar, rots, outputs=("profile", "stokes"))

    def rms(x: np.ndarray, ref: np.ndarray) -> float:
        m = ref > 0.01 * ref.max()
        return float(np.sqrt(np.mean(((x[m] - ref[m]) / ref[m]) ** 2)))

    _, t1 = run(1, 1)
    out = ["## 3. Noise and cost on the 3U CubeSat", "",
           f"{len(rots)} attitudes of the 50 (indices 3, 7, 11, 19, 23, 31: several with corners), {res} x {res}, "
           "profile only, CPU twin (`arithmetic=\"f64\"`, 2 threads here), times the best of 3. Noise: RMS "
           "relative error of the profile bins above 1% of the peak (mean over the attitudes and over path seeds "
           "0, 1 and 2), and of the S0 image's pixels above 1% "
           "of its maximum (seed 1), against the same settings with 64x the paths (16x for 64 paths; seed 7). "
           "Paths per pixel: "
           "`path_samples`, the mean over the pixels the mesh may cover (they are drawn in the pixels of "
           "surfaces facing other parts, `src/render/paths/allocate.rs`).", "",
           f"`bounces=1`: {t1 * 1e3:.1f} ms per attitude.", "",
           "| bounces | paths per pixel | ms per attitude | cost vs bounces=1 | profile noise | pixel noise |",
           "|---|---|---|---|---|---|"]
    refs: dict[tuple[int, int], pprender.RenderResult] = {}
    per_attitude: list[float] = []
    per_seed: list[float] = []
    for bounces in (2, 3):
        for paths in counts:
            ref_paths = min(paths * 64, 1024)
            key = (bounces, ref_paths)
            if key not in refs:
                refs[key] = with_images(bounces, ref_paths, seed=7)
            ref = refs[key]
            r, t = run(bounces, paths)
            img = with_images(bounces, paths)
            assert r.profile is not None and ref.profile is not None
            assert img.stokes is not None and ref.stokes is not None
            seeds = [r] + [run(bounces, paths, seed, repeats=1)[0] for seed in (1, 2)]
            pns = [float(np.mean([rms(s.profile[a, :, 0], ref.profile[a, :, 0]) for s in seeds
                                  if s.profile is not None])) for a in range(len(rots))]
            pn = np.mean(pns)
            if (bounces, paths) == (2, counts[min(1, len(counts) - 1)]):
                per_attitude, per_paths = pns, paths
                per_seed = [float(np.mean([rms(s.profile[a, :, 0], ref.profile[a, :, 0])
                                           for a in range(len(rots))])) for s in seeds if s.profile is not None]
            xn = np.mean([rms(img.stokes[a, ..., 0], ref.stokes[a, ..., 0]) for a in range(len(rots))])
            out.append(f"| {bounces} | {paths} | {t * 1e3:.1f} | {t / t1:.1f}x | {pn:.4f} | {xn:.4f} |")
    idx = [3, 7, 11, 19, 23, 31][:n]
    out += ["", f"Profile noise per attitude, `bounces=2`, {per_paths} paths per pixel: "
            + ", ".join(f"{i}: {v:.4f}" for i, v in zip(idx, per_attitude))
            + "; the mean over the attitudes by seed: " + ", ".join(f"{v:.4f}" for v in per_seed) + "."
            + ("" if quick else
               " Pixels of parts thinner than a pixel get 8x the paths (src/render/paths/allocate.rs): at "
               "attitudes 23 and 31 the 3 mm whip antenna against the bus (a glossy cylinder against a glossy "
               "face, whose normal sweeps around within a pixel) held most of the variance (maps of the "
               "per-pixel variance), 3.7% and 2.0% of profile noise at 16 paths before."), ""]
    return out


def what_bounces_add(quick: bool) -> list[str]:
    sc = cubesat_scene()
    rots = attitudes(8 if quick else 50)
    lidar = pprender.Lidar(resolution=48 if quick else 128, bounces=3, path_samples=16 if quick else 64,
                           polarization=[1, 1, 0, 0], arithmetic="f64")
    r = pprender.render(sc, lidar, rots, outputs=("profile",))
    assert r.by_bounce is not None
    cs = r.by_bounce["cross_section"][..., 0]
    frac = cs / cs.sum(1, keepdims=True)
    dop = np.hypot(r.cross_section[:, 1], r.cross_section[:, 2]) / r.cross_section[:, 0]
    dop1 = np.hypot(r.by_bounce["cross_section"][:, 0, 1], r.by_bounce["cross_section"][:, 0, 2]) / cs[:, 0]
    rows = ["## 4. What each bounce adds on the 3U CubeSat", "",
            f"{len(rots)} attitudes, demo materials, H-polarized transmitter, bounces=3. Share of the returned S0 "
            "by number of bounces, and the linear degree of polarization of the total with and without "
            "the inter-reflections:", "",
            "| quantity | median | 90th percentile | largest |", "|---|---|---|---|"]
    for name, v in (("1 bounce", frac[:, 0]), ("2 bounces", frac[:, 1]), ("3 bounces", frac[:, 2]),
                    ("2 + 3 bounces", frac[:, 1] + frac[:, 2]),
                    ("DoP, 1 bounce only", dop1), ("DoP, bounces=3", dop)):
        rows.append(f"| {name} | {np.median(v):.3f} | {np.quantile(v, 0.9):.3f} | {v.max():.3f} |")
    rows += ["", f"Attitudes where 2 + 3 bounces carry more than 10% of S0: "
                 f"{int(np.sum(frac[:, 1] + frac[:, 2] > 0.1))} of {len(rots)}.", ""]
    return rows


SECTIONS = {1: corners, 2: cubesat_vs_mitsuba, 3: noise_and_cost, 4: what_bounces_add}


def replace_sections(text: str, new: dict[int, list[str]]) -> str:
    """``text`` (the docs page) with each section ``k`` of ``new`` in place of its own: from
    its ``## k.`` heading to the next ``## `` heading or the closing ``pprender`` line."""
    lines = text.split("\n")
    for k, body in sorted(new.items()):
        start = next(i for i, line in enumerate(lines) if line.startswith(f"## {k}."))
        end = next((i for i in range(start + 1, len(lines))
                    if lines[i].startswith("## ") or lines[i].startswith("pprender ")), len(lines))
        lines[start:end] = body
    return "\n".join(lines)


def main(quick: bool = False, sections: tuple[int, ...] = (1, 2, 3, 4)) -> str:
    """Run ``sections`` (all by default) and return their markdown; unless ``quick``, write
    docs/interreflections.md: the whole page, or with some sections only, those sections
    replaced in the committed page (the others, and its closing line, kept)."""
    t = time.perf_counter()
    new = {k: SECTIONS[k](quick) for k in sorted(set(sections))}
    if set(new) != set(SECTIONS):
        text = "\n".join(line for body in new.values() for line in body)
        if not quick:
            page = ROOT / "docs/interreflections.md"
            page.write_text(replace_sections(page.read_text(), new))
        return text
    lines = ["# Inter-reflections: validation, noise and cost", "",
             "Written by `python scripts/interreflections.py` (its docstring says what each section "
             "measures). pprender traces paths of 2 and 3 bounces on the CPU in f64 for every backend "
             "(`Settings(bounces=..., path_samples=..., path_seed=...)`; the module docs of "
             "`src/render/paths/mod.rs` give the estimator). The co- and cross-polarized channels "
             "against Mitsuba are in [corner-co-cross.md](corner-co-cross.md) (`python "
             "scripts/corner_co_cross.py --write`); where the light goes (a cavity's energy balance, "
             "the trihedral's effective area) in [corner-energy.md](corner-energy.md) (`python "
             "scripts/corner_energy.py --write`).", ""]
    for body in new.values():
        lines += body
    lines += [f"pprender {pprender.__version__}, {time.perf_counter() - t:.0f} s.", ""]
    text = "\n".join(lines)
    if not quick:
        (ROOT / "docs/interreflections.md").write_text(text)
    return text


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="a small version; writes nothing")
    parser.add_argument("--section", type=int, action="append", choices=sorted(SECTIONS),
                        help="run only this section (repeatable) and replace it in the committed page")
    args = parser.parse_args()
    print(main(quick=args.quick, sections=tuple(args.section or SECTIONS)))
