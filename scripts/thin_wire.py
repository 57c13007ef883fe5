"""A thin wire's total cross-section against the analytic sum over its facets.

A 16-sided aluminium wire (alpha 0.3), 0.6 m long, of diameter 3 mm (and 1 mm), seen
side-on with its axis at 0 to 90 deg (5 deg steps) to the image rows, rendered at the
``"balanced"`` preset (161 pixels across, 8 samples per pixel, pixel ~3.7 mm). The facet
sum is ``4 pi f(wo, wo) cos^2(theta) A`` over the facets turned toward the sensor (all
fully visible on a convex prism). Prints one line per angle: the relative error of
``balanced``, of 16 samples per pixel, and of ``coverage="analytic"``; ``--write`` also
writes the table to docs/thin-parts.md.

    python scripts/thin_wire.py [--write]

This measures a known defect (issue 23's thin-part item): every pixel uses the same sample
pattern, so a part narrower than a pixel and aligned with the pixel grid (or its
diagonal) is hit by the same samples all along, and its coverage error does not average
out; analytic coverage finds such a part only where a nearby pixel centre sees it.
"""

from __future__ import annotations

import math
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


def errors(radius: float, lidar: pprender.Lidar, degrees: np.ndarray) -> np.ndarray:
    """Relative error of the total cross-section at each angle."""
    mesh = trimesh.creation.cylinder(radius=radius, height=0.6, sections=16)
    mat = materials.get("aluminium", alpha=0.3)
    scene = pprender.Scene(mesh, mat)
    rots = np.stack([attitude(math.radians(d)) for d in degrees])
    got = pprender.render(scene, lidar, rots, outputs=("profile",)).cross_section[:, 0, 0]
    want = np.array([facet_sum(mesh, mat, r) for r in rots])
    return got / want - 1


def main(argv: list[str]) -> None:
    degrees = np.arange(0, 91, 5)
    cols = {"3 mm balanced": errors(0.0015, pprender.Lidar(), degrees),
            "1 mm balanced": errors(0.0005, pprender.Lidar(), degrees),
            "3 mm, 16 samples": errors(0.0015, pprender.Lidar(pixel_samples=16), degrees),
            "3 mm analytic": errors(0.0015, pprender.Lidar(coverage="analytic"), degrees)}
    lines = ["# Thin parts: a wire against the sum over its facets", "",
             "Written by `python scripts/thin_wire.py --write` (its docstring: the scene and the known "
             "defect it measures). Relative error of the total cross-section, by the angle of the wire's "
             "axis to the image rows:", "",
             "| deg | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for i, d in enumerate(degrees):
        lines.append(f"| {d} | " + " | ".join(f"{c[i]:+.4f}" for c in cols.values()) + " |")
    lines.append("| worst | " + " | ".join(f"{np.abs(c).max():.4f}" for c in cols.values()) + " |")
    lines += ["", f"pprender {pprender.__version__}.", ""]
    text = "\n".join(lines)
    print(text)
    if "--write" in argv:
        (Path(__file__).resolve().parents[1] / "docs/thin-parts.md").write_text(text)


if __name__ == "__main__":
    main(sys.argv[1:])
