"""The README's Python examples run as written, on a CAD-like GLB made here (a bus box with
the glTF material "gold_foil" under the node "bus", solar panels with the material
"cells", a painted antenna mast with the material "paint")."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parents[1]


def _glb(path: Path) -> None:
    def part(mesh: trimesh.Trimesh, material: str) -> trimesh.Trimesh:
        mesh.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(name=material))
        return mesh

    s = trimesh.Scene()
    s.add_geometry(part(trimesh.creation.box((0.3, 0.3, 0.6)), "gold_foil"), node_name="bus", geom_name="bus_box")
    panel = part(trimesh.creation.box((0.6, 0.01, 0.3)), "cells")
    for name, x in (("wing_left", -0.46), ("wing_right", 0.46)):
        s.add_geometry(panel, node_name=name, geom_name="panel",
                       transform=trimesh.transformations.translation_matrix([x, 0, 0]))
    s.add_geometry(part(trimesh.creation.cylinder(0.01, 0.3), "paint"), node_name="mast", geom_name="mast",
                   transform=trimesh.transformations.translation_matrix([0, 0, 0.45]))
    s.export(str(path))


def test_readme_python_blocks_run(tmp_path, monkeypatch) -> None:
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    assert len(blocks) >= 2
    _glb(tmp_path / "sat.glb")
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    for code in blocks:
        exec(compile(code, "README.md", "exec"), ns)
    res = ns["res"]
    assert res.profile.shape[0] == 8 and res.mueller.shape[-2:] == (4, 4)
    np.testing.assert_allclose(res.profile.sum(axis=1), res.cross_section, rtol=1e-6, atol=1e-12)
    assert {m.key for m in ns["scene"].matched.values()} == {"bus", "cells", "paint"}
