"""Co- and cross-polarized inter-reflections of a rough-aluminium dihedral against Mitsuba 3.

``python scripts/corner_co_cross.py`` prints a markdown page; with ``--write`` it also
writes it to ``docs/corner-co-cross.md`` (the page is exactly what the script prints).
``--quick`` runs a small version (writes nothing unless asked).

Mitsuba's emitters are unpolarized: its ``stokes`` renders see only the first column of the
Mueller matrix. The polarizer-sheet set-up (``mitsuba_corners.mitsuba_polarized_totals``)
puts an ideal linear polarizer across the beam between the orthographic camera's origin and
its near-clip plane, with the ``volpath`` integrator: the camera rays start beyond the
sheet, the next-event rays toward the ``directional`` emitter cross it, so the sheet
polarizes the illumination only and the received Stokes vector is ``M s_t``. Sections:

1. The set-up: Malus's law on a face-on plate (the next-event rays cross the sheet), and
   the camera rays made to cross it too (``sheet_analyzes``), which turns it into an
   analyzer (so in the set-up they do not).
2. Transmit conventions on a flat plate (one bounce, where pprender's Mueller matrix was
   already validated): the sheet angles that are pprender's H ``[1, 1, 0, 0]``, V
   ``[1, -1, 0, 0]``, +45 ``[1, 0, 1, 0]`` and -45 (transmit basis ``(X, -Y)``), full Stokes.
3. The 90 deg dihedral (0.3 m, ``mc.dihedral()``), Beckmann alpha 0.3 and 0.1 (single
   term, Walter's G1: Mitsuba's ``roughconductor``), seen along its symmetry axis
   (``theta`` 0) and 20 deg across its opening, rolled about the line of sight so that the
   edge is at ``psi`` = 0, 22.5 and 45 deg from the image's ``Y`` axis
   (``R = Rz(psi) dihedral_rotation(theta)``); H transmit; co ``(S0 + S1)/2`` and cross
   ``(S0 - S1)/2`` in the receiver basis ``(X, Y)``, per bounce order 1-3 (Mitsuba:
   ``max_depth`` 2, then k + 1 minus k, same seed).
4. +45 transmit: the full Stokes vector per bounce order at one view.

Noise: standard deviation of the mean of two seeds (Mitsuba 1 and 2, pprender 0 and 1),
from the per-pixel seed differences, ``sqrt(sum_pix (a - b)^2) / 2`` (pixels are
independent in both renderers), per channel.

Run time of the full version: about 100 s on a 2-core machine (``--quick``: 5 s).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import mitsuba_corners as mc  # noqa: E402

import pprender  # noqa: E402

ALUMINIUM = complex(1.3763, 10.2449)
PAGE = ROOT / "docs" / "corner-co-cross.md"
ALPHAS = (0.3, 0.1)
THETAS = (0.0, 20.0)
PSIS = (0.0, 22.5, 45.0)
PLUS45_VIEW = (0.3, 20.0, 22.5)  # alpha, theta, psi
# sheet angle (deg), flipped, pprender's transmitted Stokes vector (transmit basis), name
TRANSMITS = [(0.0, False, (1.0, 1.0, 0.0, 0.0), "H"), (90.0, False, (1.0, -1.0, 0.0, 0.0), "V"),
             (45.0, False, (1.0, 0.0, 1.0, 0.0), "+45"), (45.0, True, (1.0, 0.0, -1.0, 0.0), "-45")]


def aluminium(alpha: float) -> pprender.Material:
    """The single-term Beckmann conductor that Mitsuba's ``roughconductor`` evaluates."""
    return pprender.Material("beckmann", alpha=alpha, eta=ALUMINIUM, shadowing="smith", correlation="none",
                             smith_g1="walter", terms=("single",))


def rz(deg: float) -> np.ndarray:
    """Rotation by ``deg`` about the telescope ``Z`` (the line of sight)."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def ry(deg: float) -> np.ndarray:
    """Rotation by ``deg`` about ``Y``."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def plate(side: float = 0.2) -> trimesh.Trimesh:
    """A square plate in the body ``z = 0`` plane, front face ``+z``."""
    h = side / 2
    return trimesh.Trimesh(np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]]),
                           np.array([[0, 1, 2], [0, 2, 3]]), process=False)


def with_co_cross(s: np.ndarray) -> np.ndarray:
    """Append co ``(S0 + S1)/2`` and cross ``(S0 - S1)/2`` (H transmit, receiver basis
    ``(X, Y)``) to the last axis of Stokes values (..., 4): (..., 6)."""
    s = np.asarray(s, dtype=np.float64)
    return np.concatenate([s, 0.5 * (s[..., :1] + s[..., 1:2]), 0.5 * (s[..., :1] - s[..., 1:2])], axis=-1)


def noise_of_mean(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Standard deviation of ``(A + B) / 2`` for two independent renders' images ``a``,
    ``b`` (..., H, W, C) whose totals are pixel sums: ``sqrt(sum_pix (a - b)^2) / 2``."""
    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    return np.sqrt((d**2).sum(axis=(-3, -2))) / 2.0


def mitsuba_orders(mesh: trimesh.Trimesh, alpha: float, rots: np.ndarray, orders: int, polarizer_deg: float,
                   spp: int, res: int, seeds: Sequence[int] = (1, 2)) -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba cross-sections per bounce order, (N, orders, 6): S0..S3, co, cross
    (:func:`with_co_cross`), the mean over ``seeds`` (two), and their noise; order 1 is
    ``max_depth`` 2, order k the step k + 1 minus k (same seed)."""
    delta = 2.0 * mc.extent(mesh) / res
    scale = 4.0 * math.pi * delta**2
    imgs = []
    for seed in seeds:
        by_depth = [mc.mitsuba_polarized_totals(mesh, mc.roughconductor(alpha), rots, depth, spp, res, seed,
                                                polarizer_deg=polarizer_deg, return_images=True)[1]
                    for depth in range(2, orders + 2)]
        im = np.stack(by_depth, axis=1).astype(np.float64)  # (N, D, H, W, 4)
        im[:, 1:] = np.diff(im, axis=1)
        imgs.append(with_co_cross(scale * im))
    mean = 0.5 * (imgs[0] + imgs[1]).sum(axis=(-3, -2))
    return mean, noise_of_mean(imgs[0], imgs[1])


def pprender_orders(mesh: trimesh.Trimesh, alpha: float, rots: np.ndarray, orders: int, transmit: Sequence[float],
                    res: int, paths: int, seeds: Sequence[int] = (0, 1)) -> tuple[np.ndarray, np.ndarray]:
    """pprender's cross-sections per bounce order, (N, orders, 6) as :func:`mitsuba_orders`,
    the mean over two seeds, and their noise (per-pixel seed differences). The f64 twin
    with analytic pixel coverage: the one-bounce part is then exact (sampled coverage at
    64 x 64 is off by up to 0.25% on the dihedral's plates when their edges run along the
    pixel rows)."""
    sc = pprender.Scene(mesh, aluminium(alpha))
    imgs, tots = [], []
    for seed in seeds:
        lidar = pprender.Lidar(resolution=res, bounces=orders, path_samples=paths, path_seed=seed,
                               polarization=list(transmit), arithmetic="f64", coverage="analytic")
        by = pprender.render(sc, lidar, rots, outputs=("stokes",)).by_bounce
        assert by is not None  # bounces >= 2
        tots.append(with_co_cross(by["cross_section"]))
        imgs.append(with_co_cross(by["stokes"]))
    return 0.5 * (tots[0] + tots[1]), noise_of_mean(imgs[0], imgs[1])


def f(x: float) -> str:
    return f"{x:.4g}"


def vec(x: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:+.4f}" for v in x) + ")"


def setup_section(spp: int, res: int) -> list[str]:
    """The sheet polarizes the shadow rays (Malus on a face-on plate) and not the camera rays
    (moving the near-clip plane so that they cross it turns the sheet into an analyzer)."""
    mesh = plate()
    bsdf = mc.roughconductor(0.3)
    out = ["## 1. The set-up", "",
           f"A 0.2 m square plate of rough aluminium (alpha 0.3) seen face-on, Mitsuba `max_depth` 2, {spp} spp, "
           f"{res} x {res}, seed 1. A face-on plate returns the illumination's linear polarization (its Mueller "
           "matrix is R diag(1, 1, -1, -1)), so the received S1/S0 and S2/S0 follow the sheet: cos 2 theta and "
           "-sin 2 theta (Malus: I_X / S0 = cos^2 theta), while S0 stays that of unpolarized illumination.", "",
           "| sheet theta | S0 / S0 unpolarized | S1/S0 | cos 2 theta | S2/S0 | -sin 2 theta |",
           "|---|---|---|---|---|---|"]
    unpol = mc.mitsuba_polarized_totals(mesh, bsdf, np.eye(3), 2, spp, res, 1, polarizer_deg=None)[0]
    for theta in (0.0, 30.0, 60.0, 90.0, 135.0):
        m = mc.mitsuba_polarized_totals(mesh, bsdf, np.eye(3), 2, spp, res, 1, polarizer_deg=theta)[0]
        t = math.radians(theta)
        out.append(f"| {theta:g} | {m[0] / unpol[0]:.5f} | {m[1] / m[0]:+.4f} | {math.cos(2 * t):+.4f} "
                   f"| {m[2] / m[0]:+.4f} | {-math.sin(2 * t):+.4f} |")
    d = mc.dihedral()
    views = [(45.0, 0.0), (22.5, 0.0)]
    rots = np.stack([rz(p) @ mc.dihedral_rotation(t) for p, t in views])
    skip = np.asarray(mc.mitsuba_polarized_totals(d, mc.roughconductor(0.1), rots, 3, spp, res, 1, polarizer_deg=0.0))
    cross = np.asarray(mc.mitsuba_polarized_totals(d, mc.roughconductor(0.1), rots, 3, spp, res, 1, polarizer_deg=0.0,
                                                   sheet_analyzes=True))
    out += ["", "Camera rays: the dihedral (alpha 0.1, theta 0; orders 1 and 2, `max_depth` 3), sheet `theta` 0. "
            "With the near-clip plane at 2 ext (the set-up) the camera rays start beyond the sheet; with it at "
            "0.01 (`sheet_analyzes=True`) they cross it, and it analyzes the received light: S0 is then the "
            "co-polarized part (S0 + S1)/2 of the set-up's render (another code path: the polarizer's `sample` "
            "on the camera side).", "",
            "| psi | set-up S0 | set-up S1 | set-up (S0 + S1)/2 | camera rays crossing: S0 | S1 |",
            "|---|---|---|---|---|---|"]
    for v, (psi, _) in enumerate(views):
        out.append(f"| {psi:g} | {f(skip[v, 0])} | {f(skip[v, 1])} | {f(0.5 * (skip[v, 0] + skip[v, 1]))} "
                   f"| {f(cross[v, 0])} | {f(cross[v, 1])} |")
    out.append("")
    return out


def plate_section(spp: int, res: int) -> list[str]:
    mesh = plate()
    views = [("face-on", np.eye(3)), ("30 deg about Y", ry(30.0)),
             ("30 deg about Y, rolled 25 deg", rz(25.0) @ ry(30.0))]
    rots = np.stack([r for _, r in views])
    out = ["## 2. Transmit conventions on a flat plate (one bounce)", "",
           f"The same plate, alpha 0.3. Mitsuba `max_depth` 2, {spp} spp, {res} x {res}, seed 1; pprender "
           f"{res} x {res} (analytic pixel coverage), `bounces=1`, `polarization` = the transmit column. Received "
           "Stokes vector divided by its S0 (receiver basis (X, Y)); `sheet theta` is the polarizer's `theta` (deg), "
           "`flipped` the sheet turned 180 deg about X. The monostatic single bounce comes from facets at normal "
           "incidence, so these rows fix the linear conventions (H/V, the sign of 45 deg); S3's sign is checked by "
           "the dihedral (sections 3-4).",
           "", "| view | sheet theta | pprender transmit | Mitsuba S0 (m^2) | pprender S0 (m^2) | Mitsuba S/S0 | "
           "pprender S/S0 | max abs diff of S/S0 |", "|---|---|---|---|---|---|---|---|"]
    sc = pprender.Scene(mesh, aluminium(0.3))
    worst = 0.0
    for theta, flipped, transmit, name in TRANSMITS:
        m = np.asarray(mc.mitsuba_polarized_totals(mesh, mc.roughconductor(0.3), rots, 2, spp, res, 1,
                                                   polarizer_deg=theta, flip_sheet=flipped))
        p = pprender.render(sc, pprender.Lidar(resolution=res, polarization=list(transmit), arithmetic="f64",
                                               coverage="analytic"), rots, outputs=("profile",)).cross_section
        for v, (label, _) in enumerate(views):
            mn, pn = m[v] / m[v, 0], p[v] / p[v, 0]
            worst = max(worst, float(np.abs(mn - pn).max()))
            out.append(f"| {label} | {theta:g}{' flipped' if flipped else ''} | {name} `{list(transmit)}` "
                       f"| {f(m[v, 0])} | {f(p[v, 0])} | {vec(mn)} | {vec(pn)} | {np.abs(mn - pn).max():.1e} |")
    out += ["", f"Largest difference of a normalized Stokes component: {worst:.1e}. Mapping: sheet `theta` 0 = H "
            "`[1, 1, 0, 0]`, 90 = V `[1, -1, 0, 0]`, 45 = +45 `[1, 0, 1, 0]` in pprender's transmit basis "
            "(X, -Y); in general `theta` = the angle of the transmitted polarization from X in that basis "
            "(`(1, cos 2 theta, sin 2 theta, 0)`); the flipped sheet reverses the sign of `theta`.", ""]
    return out


def dihedral_section(spp: int, res: int,
                     paths: int) -> tuple[list[str], dict[tuple[int, float], dict[str, Any]], tuple[float, str]]:
    mesh = mc.dihedral()
    views = [(t, p) for t in THETAS for p in PSIS]
    rots = np.stack([rz(p) @ mc.dihedral_rotation(t) for t, p in views])
    out = ["## 3. Dihedral, H transmit: co and cross per bounce order", "",
           f"The 0.3 m, 90 deg dihedral (`mc.dihedral()`), attitude `Rz(psi) @ dihedral_rotation(theta)`: theta "
           "across the opening, psi the edge's angle from the image's Y axis. Sheet `theta` 0 (H, `[1, 1, 0, 0]`). "
           f"Mitsuba {spp} spp, {res} x {res}, seeds 1 and 2; pprender {res} x {res}, {paths} paths per pixel, "
           "analytic pixel coverage (the one-bounce part is exact), seeds 0 and 1; each the mean of its two seeds; "
           "noise = the standard deviation of that mean (per-pixel seed differences), Mitsuba's then pprender's. "
           "co = (S0 + S1)/2, cross = (S0 - S1)/2 in m^2; ratio = pprender / Mitsuba; share = the channel's part of "
           "the view's total S0 (orders 1-3, Mitsuba). Order 1 at theta 0 is the edge-on plates' sliver; at alpha "
           "0.1 the third order is negligible.", ""]
    # worst agreement per (order, share threshold): 5% of the view's total, and 1% for order 3
    stats: dict[tuple[int, float], dict[str, Any]] = {key: {"rel": (0.0, ""), "z": (0.0, ""), "n": 0}
                                                      for key in ((1, 0.05), (2, 0.05), (3, 0.05), (3, 0.01))}
    stokes_worst = (0.0, "")
    for alpha in ALPHAS:
        mit, mit_sd = mitsuba_orders(mesh, alpha, rots, 3, 0.0, spp, res)
        ours, our_sd = pprender_orders(mesh, alpha, rots, 3, (1.0, 1.0, 0.0, 0.0), res, paths)
        out += [f"### alpha {alpha}", "",
                "| theta | psi | order | Mitsuba co | pprender co | ratio co | Mitsuba cross | pprender cross "
                "| ratio cross | share co, cross | noise co | noise cross |",
                "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for v, (theta, psi) in enumerate(views):
            total = mit[v, :, 0].sum()
            for k in range(3):
                row = [f"{theta:g}", f"{psi:g}", str(k + 1)]
                shares, noises = [], []
                for c, name in ((4, "co"), (5, "cross")):
                    m, p = mit[v, k, c], ours[v, k, c]
                    r = p / m if m > 0 else float("nan")
                    row += [f(m), f(p), f"{r:.4f}"]
                    shares.append(f"{m / total:.3f}")
                    noises.append(f"{mit_sd[v, k, c]:.1e}, {our_sd[v, k, c]:.1e}")
                    for (order, share), st in stats.items():
                        if order != k + 1 or m <= share * total:
                            continue
                        st["n"] += 1
                        label = f"{name}, alpha {alpha}, theta {theta:g}, psi {psi:g}"
                        if abs(r - 1) > st["rel"][0]:
                            st["rel"] = (abs(r - 1), f"{label}: ratio {r:.4f}")
                        sd = math.hypot(mit_sd[v, k, c], our_sd[v, k, c])
                        z = abs(p - m) / sd if sd > 0 else float("inf")
                        if z > st["z"][0]:
                            st["z"] = (z, f"{label}: {z:.1f} combined standard deviations")
                out.append("| " + " | ".join(row + [", ".join(shares)] + noises) + " |")
            for c in (2, 3):
                d = abs(ours[v, 1, c] - mit[v, 1, c]) / total
                if d > stokes_worst[0]:
                    stokes_worst = (d, f"S{c}, alpha {alpha}, theta {theta:g}, psi {psi:g}: Mitsuba "
                                       f"{mit[v, 1, c]:.4g}, pprender {ours[v, 1, c]:.4g}")
        out += ["", "Second bounce, all four Stokes components (m^2; Mitsuba / pprender):", "",
                "| theta | psi | S0 | S1 | S2 | S3 | co / S0 |", "|---|---|---|---|---|---|---|"]
        for v, (theta, psi) in enumerate(views):
            cells = " | ".join(f"{f(mit[v, 1, c])} / {f(ours[v, 1, c])}" for c in range(4))
            out.append(f"| {theta:g} | {psi:g} | {cells} | {mit[v, 1, 4] / mit[v, 1, 0]:.3f} / "
                       f"{ours[v, 1, 4] / ours[v, 1, 0]:.3f} |")
        out.append("")
    return out, stats, stokes_worst


def plus45_section(spp: int, res: int, paths: int) -> list[str]:
    alpha, theta, psi = PLUS45_VIEW
    mesh = mc.dihedral()
    rot = (rz(psi) @ mc.dihedral_rotation(theta))[None]
    mit, mit_sd = mitsuba_orders(mesh, alpha, rot, 3, 45.0, spp, res)
    ours, our_sd = pprender_orders(mesh, alpha, rot, 3, (1.0, 0.0, 1.0, 0.0), res, paths)
    out = ["## 4. +45 transmit: full Stokes per bounce order", "",
           f"alpha {alpha}, theta {theta:g}, psi {psi:g}; sheet `theta` 45 (pprender `[1, 0, 1, 0]`), renders as in "
           "section 3. m^2 +- the standard deviation of the two-seed mean (0: no noise, as pprender's one bounce).",
           "", "| order | | S0 | S1 | S2 | S3 |", "|---|---|---|---|---|---|"]
    for k in range(3):
        for name, x, sd in (("Mitsuba", mit, mit_sd), ("pprender", ours, our_sd)):
            out.append(f"| {k + 1} | {name} | " + " | ".join(f"{f(x[0, k, c])} +- {sd[0, k, c]:.1g}" for c in range(4))
                       + " |")
        rel = (ours[0, k, :4] - mit[0, k, :4]) / mit[0, k, 0]
        out.append(f"| {k + 1} | (pprender - Mitsuba) / Mitsuba S0 | " + " | ".join(f"{x:+.2%}" for x in rel) + " |")
    out.append("")
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--write", action="store_true", help=f"write {PAGE.relative_to(ROOT)}")
    ap.add_argument("--quick", action="store_true", help="small renders (a smoke run)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    spp, res, paths = (32, 32, 8) if args.quick else (1024, 64, 256)
    mi = mc.mitsuba()
    cmd = "python scripts/corner_co_cross.py" + (" --quick" if args.quick else "") + (" --write" if args.write else "")
    lines = ["# Co- and cross-polarized inter-reflections against Mitsuba 3", "",
             f"Written by `{cmd}` (its docstring and `mitsuba_corners.mitsuba_polarized_totals` give the set-up). "
             "Mitsuba's emitters are unpolarized; an ideal linear polarizer sheet between the orthographic camera "
             "and its near-clip plane (`volpath`) polarizes the illumination only, so Mitsuba renders `M s_t` for a "
             "linear transmitted state `s_t`. Measured: pprender's received Stokes vector per bounce order, "
             "co = (S0 + S1)/2 and cross = (S0 - S1)/2 for H transmit, against Mitsuba's. "
             f"Mitsuba {getattr(mi, '__version__', '?')} ({mc.MITSUBA_VARIANT}), pprender "
             f"{getattr(pprender, '__version__', '?')}; the illumination is tilted by +-"
             f"{mc.POLARIZED_EMITTER_TILT:g} rad from the line of sight and the two renders averaged (at exact "
             "backscatter Mitsuba's polarized `roughconductor` takes a wrong Fresnel frame).", ""]
    lines += setup_section(spp, res)
    lines += plate_section(spp, res)
    dih, stats, stokes_worst = dihedral_section(spp, res, paths)
    lines += dih
    lines += plus45_section(spp, res, paths)
    lines += ["## Summary", "", "Over the co and cross values of section 3 that carry more than the given share of "
              "their view's total S0 (order 1: pprender's one bounce has no noise, so there the standard deviation "
              "is Mitsuba's alone):", ""]
    for (k, share), st in stats.items():
        if st["n"]:
            lines.append(f"* Order {k}, share > {share:.0%} ({st['n']} values): largest relative error "
                         f"{st['rel'][0]:.2%} ({st['rel'][1]}); largest difference {st['z'][1]}.")
        else:
            lines.append(f"* Order {k}, share > {share:.0%}: no value.")
    lines += [f"* Second bounce S2 and S3: largest difference {stokes_worst[0]:.2%} of the view's total "
              f"S0 ({stokes_worst[1]}).",
              f"* Run time: {time.perf_counter() - t0:.0f} s ({os.cpu_count()} CPU cores).", ""]
    page = "\n".join(lines)
    print(page)
    if args.write:
        PAGE.write_text(page + "\n")
        print(f"wrote {PAGE.relative_to(ROOT)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
