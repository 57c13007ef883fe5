"""A thin wire's total cross-section against the analytic sum over its facets.

A 16-sided aluminium wire (alpha 0.3), 0.6 m long, of diameter 3 mm (and 1 mm), seen
side-on with its axis at 0 to 90 deg (5 deg steps) to the image rows, rendered at the
``"balanced"`` preset (161 pixels across, 8 samples per pixel, pixel ~3.7 mm). The facet
sum is ``4 pi f(wo, wo) cos^2(theta) A`` over the facets turned toward the sensor (all
fully visible on a convex prism). Prints one line per angle: the relative error of
``balanced``, of 16 samples per pixel, of ``coverage="analytic"`` (also with the wire in
an open mesh, beside a triangle edge-on to the sensor: the wire's back faces stay out of
the clipping since its own component is closed) and of one sample per pixel (``"fast"``'s
sampling); then the render benchmark's CubeSat's cost at 1, 8 and 16
samples per pixel (:func:`cubesat_cost`); ``--write`` also writes both to
docs/thin-parts.md.

    python scripts/thin_wire.py [--write]

Every pixel has the same sample pattern, so a part narrower than a pixel and aligned with
the pixel grid (or its diagonal) meets the same samples all along, and its coverage error
does not average out (a wire between two rows of samples is not seen at all). With more
than one sample per pixel (the pixels shaded on the CPU, render::cpu::add_thin_pixels), and
with analytic coverage (in the kernel), the pixels a thin face overlaps take its area
exactly (src/render/thin.rs); one sample per pixel is left as it was, and its column shows
what that costs in accuracy.
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numpy as np
import trimesh

import pprender
from pprender import materials


def attitude(phi: float) -> np.ndarray:
    """Body x toward the sensor, the wire's axis (body z) at ``phi`` to the image's X."""
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[0.0, s, c], [0.0, -c, s], [1.0, 0.0, 0.0]])


def facet_sum(mesh: trimesh.Trimesh, mat: pprender.Material, rot: np.ndarray) -> float:
    """Sum over the faces turned toward the sensor of ``4 pi f(wo, wo) cos^2 A`` (m^2)."""
    wo = np.array([0.0, 0.0, 1.0])
    total = 0.0
    for n_body, area in zip(mesh.face_normals, mesh.area_faces):
        n = rot @ n_body
        c = float(n @ wo)
        if c <= 1e-12:
            continue
        t1 = np.cross([0.0, 1.0, 0.0] if abs(n[1]) < 0.9 else [1.0, 0.0, 0.0], n)
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(n, t1)
        w = np.array([wo @ t1, wo @ t2, wo @ n])
        total += 4 * math.pi * pprender.brdf(mat, w, w)[0, 0] * c * c * area
    return total


def errors(radius: float, lidar: pprender.Lidar, degrees: np.ndarray, open_mesh: bool = False) -> np.ndarray:
    """Relative error of the total cross-section at each angle. ``open_mesh``: the wire with
    a small open triangle beside it, edge-on to the sensor at every attitude (it adds
    nothing and hides nothing), so that the mesh is not closed while the wire is."""
    mesh = trimesh.creation.cylinder(radius=radius, height=0.6, sections=16)
    if open_mesh:
        sheet = trimesh.Trimesh([[0.0, 0.02, 0.0], [0.01, 0.02, 0.0], [0.0, 0.02, 0.01]], [[0, 1, 2]])
        mesh = trimesh.util.concatenate([mesh, sheet])
    mat = materials.get("aluminium", alpha=0.3)
    scene = pprender.Scene(mesh, mat)
    rots = np.stack([attitude(math.radians(d)) for d in degrees])
    got = pprender.render(scene, lidar, rots, outputs=("profile",)).cross_section[:, 0, 0]
    want = np.array([facet_sum(mesh, mat, r) for r in rots])
    return got / want - 1


def cubesat_cost(repeats: int = 3) -> list[str]:
    """Milliseconds per attitude of the render benchmark's 3U CubeSat (128x128, Stokes
    profile only, lavapipe, 16 random attitudes, best of ``repeats``) at 1, 8 and 16
    samples per pixel, in one run: what the thin-part pixels cost where a mesh has them."""
    import time

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_render import cubesat_scene

    rng = np.random.default_rng(7)
    q = rng.normal(size=(16, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    scene = cubesat_scene()
    rows = ["| samples per pixel | ms per attitude | relative to 1 |", "|---|---|---|"]
    base = None
    for k in (1, 8, 16):
        lidar = pprender.Lidar(resolution=128, pixel_samples=k, polarization=[1, 1, 0, 0])
        pprender.render(scene, lidar, q[:2], outputs=("profile",), device="cpu")
        best = math.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            pprender.render(scene, lidar, q, outputs=("profile",), device="cpu")
            best = min(best, time.perf_counter() - t0)
        ms = 1e3 * best / len(q)
        base = base or ms
        rows.append(f"| {k} | {ms:.1f} | {ms / base:.1f}x |")
    return rows


def main(argv: list[str]) -> None:
    degrees = np.arange(0, 91, 5)
    cols = {"3 mm balanced": errors(0.0015, pprender.Lidar(), degrees),
            "1 mm balanced": errors(0.0005, pprender.Lidar(), degrees),
            "3 mm, 16 samples": errors(0.0015, pprender.Lidar(pixel_samples=16), degrees),
            "3 mm analytic": errors(0.0015, pprender.Lidar(coverage="analytic"), degrees),
            "3 mm analytic, open mesh": errors(0.0015, pprender.Lidar(coverage="analytic"), degrees,
                                               open_mesh=True),
            "3 mm, 1 sample": errors(0.0015, pprender.Lidar(pixel_samples=1), degrees)}
    lines = ["# Thin parts: a wire against the sum over its facets", "",
             "Written by `python scripts/thin_wire.py --write` (its docstring: the scene, and how thin "
             "parts are rendered). Relative error of the total cross-section, by the angle of the wire's "
             "axis to the image rows:", "",
             "| deg | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for i, d in enumerate(degrees):
        lines.append(f"| {d} | " + " | ".join(f"{c[i]:+.1e}" for c in cols.values()) + " |")
    lines.append("| worst | " + " | ".join(f"{np.abs(c).max():.1e}" for c in cols.values()) + " |")
    lines += ["", "Cost on the render benchmark's 3U CubeSat (`benchmarks/bench_render.py`'s scene: panel "
              "rims and the whip antenna are thin at 128x128), 128x128, Stokes profile only, on lavapipe "
              f"({os.cpu_count()} CPU threads), one run:", ""]
    lines += cubesat_cost()
    lines += ["", f"pprender {pprender.__version__}.", ""]
    text = "\n".join(lines)
    print(text)
    if "--write" in argv:
        (Path(__file__).resolve().parents[1] / "docs/thin-parts.md").write_text(text)


if __name__ == "__main__":
    main(sys.argv[1:])
