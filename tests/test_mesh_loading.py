"""Loading meshes into pprender.Scene (pprender.mesh): trimesh.Scene CAD exports with
part -> material mappings (geometry, node and material names, instances, node
transforms), units and axes warnings, and bad mesh input (issue 21).

The GLB is built here with trimesh, exported and loaded back, as a user's CAD export
would be: a box "bus" (material "gold_foil") and one geometry "panel" (material "cells")
instanced by two nodes with different transforms. Every check compares with something
pprender's loader did not produce: where each face lies (which body it came from), the
original meshes moved by hand with trimesh, and a render of a hand-assembled
(vertices, faces) pair with explicit face_material.
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

import pprender
from pprender import models
from pprender.mesh import SkippedGeometryWarning, UnitsWarning, flatten

ROT_X60 = trimesh.transformations.rotation_matrix(np.pi / 3, [1, 0, 0])
# node transforms of the two panel instances: left flat at y = +1, right tilted by 60 deg
# about x at y = -1.25 (so the two have different projected areas, 0.5 and 0.125 m^2)
T_LEFT = trimesh.transformations.translation_matrix([0.0, 1.0, 0.0])
T_RIGHT = trimesh.transformations.translation_matrix([0.0, -1.25, 0.0]) @ ROT_X60


def lambertian(rho: float) -> pprender.Material:
    # eta = 1: no specular layer, so the BRDF is rho / pi (as tests/test_render.py)
    return pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0j, terms=["diffuse"], diffuse_albedo=rho)


A, B, C = lambertian(0.1), lambertian(0.5), lambertian(0.9)


def _pbr(name: str) -> trimesh.visual.TextureVisuals:
    return trimesh.visual.TextureVisuals(
        material=trimesh.visual.material.PBRMaterial(name=name, baseColorFactor=[200, 200, 200, 255])
    )


def _originals() -> tuple[trimesh.Trimesh, trimesh.Trimesh]:
    bus = trimesh.creation.box(extents=[1.0, 1.0, 2.0])
    panel = trimesh.creation.box(extents=[1.0, 0.5, 0.02])
    return bus, panel


def build_glb(path: Path) -> trimesh.Scene:
    bus, panel = _originals()
    bus.visual = _pbr("gold_foil")
    panel.visual = _pbr("cells")
    s = trimesh.Scene()
    s.add_geometry(bus, geom_name="bus", node_name="bus")
    s.add_geometry(panel, geom_name="panel", node_name="panel_left", transform=T_LEFT)
    # a second instance of the same geometry (not a copy)
    s.graph.update(frame_to="panel_right", frame_from="world", geometry="panel", matrix=T_RIGHT)
    path.write_bytes(s.export(file_type="glb"))
    loaded = trimesh.load(path)
    assert isinstance(loaded, trimesh.Scene)
    assert sorted(loaded.geometry) == ["bus", "panel"]  # the instance survived the round trip
    assert sorted(loaded.graph.nodes_geometry) == ["bus", "panel_left", "panel_right"]
    return loaded


@pytest.fixture
def glb(tmp_path: Path) -> trimesh.Scene:
    return build_glb(tmp_path / "sat.glb")


def _body_of_faces(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Which body each face belongs to, from where it lies: "bus" (|y| <= 0.5),
    "panel_left" (y > 0.5), "panel_right" (y < -0.5)."""
    y = vertices[faces].mean(axis=1)[:, 1]
    return np.where(y > 0.6, "panel_left", np.where(y < -0.6, "panel_right", "bus"))


def _face_materials(scene: pprender.Scene) -> list[pprender.Material]:
    return [scene.materials[i] for i in scene.face_material]


def _hand_assembled() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The same satellite from the original meshes, moved with trimesh by hand; face
    material 0 bus, 1 left panel, 2 right panel."""
    bus, panel = _originals()
    left = panel.copy().apply_transform(T_LEFT)
    right = panel.copy().apply_transform(T_RIGHT)
    verts, faces, fm, off = [], [], [], 0
    for i, m in enumerate((bus, left, right)):
        verts.append(m.vertices)
        faces.append(m.faces + off)
        fm.append(np.full(len(m.faces), i))
        off += len(m.vertices)
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(fm)


def _xs(scene: pprender.Scene) -> float:
    r = pprender.render(scene, pprender.Lidar(resolution=32), [1.0, 0, 0, 0], outputs=("profile",))
    return float(r.cross_section[0, 0, 0])  # M00 (unpolarized cross-section)


# ---------------------------------------------------------------------- trimesh.Scene + mapping


def test_mapping_by_node_names_lands_on_the_right_faces(glb: trimesh.Scene) -> None:
    scene = pprender.Scene(glb, {"bus": A, "panel_left": B, "panel_right": C})
    body = _body_of_faces(scene.vertices, scene.faces)
    fmat = _face_materials(scene)
    want = {"bus": A, "panel_left": B, "panel_right": C}
    for f, b in enumerate(body):
        assert fmat[f] is want[b], (f, b)
    assert sorted(scene.parts) == ["bus", "panel_left", "panel_right"]
    assert {n: m.key for n, m in scene.matched.items()} == {
        "bus": "bus", "panel_left": "panel_left", "panel_right": "panel_right"}
    assert scene.matched["panel_right"].material is C
    assert scene.matched["panel_right"].by == "node"
    # the per-face part index names the node each face came from
    assert [scene.parts[i] for i in scene.face_part] == list(body)
    text = repr(scene)
    assert "panel_right" in text and "bus" in text


def test_mapping_by_material_and_geometry_names(glb: trimesh.Scene) -> None:
    by_mat = pprender.Scene(glb, {"gold_foil": A, "cells": B})
    body = _body_of_faces(by_mat.vertices, by_mat.faces)
    fmat = _face_materials(by_mat)
    for f, b in enumerate(body):
        assert fmat[f] is (A if b == "bus" else B)
    assert by_mat.matched["panel_left"].by == "material"
    assert by_mat.matched["panel_left"].key == "cells"

    by_geom = pprender.Scene(glb, {"bus": A, "panel": C})
    fmat = _face_materials(by_geom)
    for f, b in enumerate(_body_of_faces(by_geom.vertices, by_geom.faces)):
        assert fmat[f] is (A if b == "bus" else C)
    assert by_geom.matched["panel_right"].by == "geometry"


def test_precedence_node_over_geometry_over_material(glb: trimesh.Scene) -> None:
    # "cells" (material) covers both panels, "panel" (geometry) overrides it, and the
    # node name "panel_right" overrides both for its instance
    scene = pprender.Scene(glb, {"gold_foil": A, "cells": C, "panel": B, "panel_right": C})
    fmat = _face_materials(scene)
    want = {"bus": A, "panel_left": B, "panel_right": C}
    for f, b in enumerate(_body_of_faces(scene.vertices, scene.faces)):
        assert fmat[f] is want[b]
    assert scene.matched["panel_left"].key == "panel"
    assert scene.matched["panel_right"].key == "panel_right"
    assert scene.matched["bus"].key == "gold_foil"


def test_node_transforms_and_instances_are_applied(glb: trimesh.Scene) -> None:
    flat = flatten(glb)
    bus, panel = _originals()
    assert sorted(flat.parts) == ["bus", "panel_left", "panel_right"]
    want = {"bus": bus, "panel_left": panel.copy().apply_transform(T_LEFT),
            "panel_right": panel.copy().apply_transform(T_RIGHT)}
    for i, name in enumerate(flat.parts):
        node = flat.nodes[i]
        assert node.name == name
        sel = flat.faces[flat.face_part == i]
        got = flat.vertices[sel]  # (n, 3, 3) corner positions of this node's faces
        ref = want[name].vertices[want[name].faces]
        # same triangles (the GLB keeps the order of faces and corners), moved by the node
        np.testing.assert_allclose(got, ref, atol=1e-6)
        assert node.geometry == ("bus" if name == "bus" else "panel")
    # flattened normals are the transformed geometry's vertex normals
    right = flat.parts.index("panel_right")
    vsel = np.unique(flat.faces[flat.face_part == right])
    tilted = flat.vertices[vsel]
    assert np.ptp(tilted[:, 2]) > 0.4  # the tilt is there (0.5 sin 60 deg)


def test_render_matches_hand_assembled_mesh(glb: trimesh.Scene) -> None:
    v, f, fm = _hand_assembled()
    ref = _xs(pprender.Scene((v, f), [A, B, C], face_material=fm))
    got = _xs(pprender.Scene(glb, {"bus": A, "panel_left": B, "panel_right": C}))
    np.testing.assert_allclose(got, ref, rtol=1e-5)
    # swapping the panels' materials changes the answer (the check can tell them apart)
    swapped = _xs(pprender.Scene((v, f), [A, C, B], face_material=fm))
    assert abs(swapped - ref) > 0.05 * ref
    # the list + face_material route in pprender's flattened order
    flat = flatten(glb)
    per_part = {"bus": A, "panel_left": B, "panel_right": C}
    listed = _xs(pprender.Scene(glb, [per_part[p] for p in flat.parts], face_material=flat.face_part))
    np.testing.assert_allclose(listed, ref, rtol=1e-5)
    # and the same list without face_material: the per-face part index is the default
    listed2 = _xs(pprender.Scene(glb, [per_part[p] for p in flat.parts]))
    np.testing.assert_allclose(listed2, ref, rtol=1e-5)


def test_single_material_for_a_trimesh_scene(glb: trimesh.Scene) -> None:
    v, f, _ = _hand_assembled()
    ref = _xs(pprender.Scene((v, f), B))
    np.testing.assert_allclose(_xs(pprender.Scene(glb, B)), ref, rtol=1e-5)
    s = pprender.Scene(glb, "aluminium")
    assert s.n_faces == len(f)


def test_mapping_errors_name_materials_and_list_names(glb: trimesh.Scene) -> None:
    with pytest.raises(pprender.Error, match="materials") as e:
        pprender.Scene(glb, {"bus": A, "panel": B, "solar_wing": C})
    for name in ("solar_wing", "panel_left", "panel", "gold_foil", "cells"):
        assert name in str(e.value)
    with pytest.raises(pprender.Error, match="materials") as e:
        pprender.Scene(glb, {"panel_left": B, "cells": C})  # nothing for the bus
    assert "bus" in str(e.value) and "gold_foil" in str(e.value)


def test_mirrored_node_keeps_outward_winding() -> None:
    s = trimesh.Scene()
    s.add_geometry(trimesh.creation.box(extents=[1, 1, 1]), geom_name="box", node_name="box",
                   transform=np.diag([-1.0, 1.0, 1.0, 1.0]))
    flat = flatten(s)
    m = trimesh.Trimesh(flat.vertices, flat.faces, process=False)
    assert m.volume > 0.99  # outward normals (a flipped winding gives -1)


def test_non_triangle_geometry_is_skipped_with_a_warning() -> None:
    s = trimesh.Scene()
    s.add_geometry(trimesh.creation.box(extents=[1, 1, 1]), geom_name="box", node_name="box")
    s.add_geometry(trimesh.load_path(np.array([[0, 0, 0], [1.0, 1.0, 1.0]])), geom_name="edge", node_name="edge")
    with pytest.warns(SkippedGeometryWarning, match="edge"):
        scene = pprender.Scene(s, {"box": A})
    assert scene.parts == ["box"]
    only_path = trimesh.Scene()
    only_path.add_geometry(trimesh.load_path(np.array([[0, 0, 0], [1.0, 1.0, 1.0]])), geom_name="edge")
    with pytest.warns(SkippedGeometryWarning), pytest.raises(pprender.Error, match="mesh"):
        pprender.Scene(only_path, A)


def test_model_parts_still_work() -> None:
    mesh = models.cubesat("3U")
    parts = mesh.metadata["pprender_parts"]
    mats = {p: lambertian(0.1 + 0.2 * i) for i, p in enumerate(parts)}
    scene = pprender.Scene(mesh, mats)
    assert scene.parts == parts
    np.testing.assert_array_equal(scene.face_material, mesh.metadata["pprender_material"])
    assert [scene.materials[i] for i in range(len(parts))] == [mats[p] for p in parts]
    with pytest.raises(pprender.Error, match="materials"):
        pprender.Scene(mesh, {"bus": A})


# ---------------------------------------------------------------------- units and axes


def _box_mm() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=[2000.0, 2000.0, 2000.0])  # a 2 m box in millimetres


def test_millimetre_mesh_warns() -> None:
    with pytest.warns(UnitsWarning, match=r"apply_scale\(1e-3\)"):
        pprender.Scene(_box_mm(), A)
    m = _box_mm()
    with pytest.warns(UnitsWarning):
        pprender.Scene((m.vertices, m.faces), A)
    s = trimesh.Scene()
    s.add_geometry(_box_mm(), geom_name="box")
    with pytest.warns(UnitsWarning):
        pprender.Scene(s, A)
    small = trimesh.creation.box(extents=[2.0, 2.0, 2.0])
    small.units = "mm"
    with pytest.warns(UnitsWarning, match="mm"):
        pprender.Scene(small, A)
    assert issubclass(UnitsWarning, UserWarning)


def test_metre_meshes_do_not_warn(glb: trimesh.Scene) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pprender.Scene(trimesh.creation.box(extents=[2.0, 2.0, 2.0]), A)
        pprender.Scene(glb, A)  # glTF: metres by specification
        pprender.Scene(models.cubesat("6U", panels="deployed"), A)


def test_axes_are_taken_as_given() -> None:
    """No axis conversion: a glTF (Y-up) vertex at +y stays at body +y; the user rotates."""
    s = trimesh.Scene()
    s.add_geometry(trimesh.creation.box(extents=[0.1, 2.0, 0.1]), geom_name="mast")
    data = io.BytesIO(s.export(file_type="glb"))
    loaded = trimesh.load(data, file_type="glb")
    flat = flatten(loaded)
    np.testing.assert_allclose(np.ptp(flat.vertices, axis=0), [0.1, 2.0, 0.1], atol=1e-6)
    loaded.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    np.testing.assert_allclose(np.ptp(flatten(loaded).vertices, axis=0), [0.1, 0.1, 2.0], atol=1e-6)


# ---------------------------------------------------------------------- bad input


def test_bad_mesh_input_names_the_parameter() -> None:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2]])
    with pytest.raises(pprender.Error, match="invalid mesh.*empty"):
        pprender.Scene((np.zeros((0, 3)), np.zeros((0, 3), int)), A)
    with pytest.raises(pprender.Error, match="invalid mesh.*empty"):
        pprender.Scene(trimesh.Trimesh(), A)
    with pytest.raises(pprender.Error, match="invalid mesh"):
        pprender.Scene(trimesh.Scene(), A)
    bad = v.copy()
    bad[1, 0] = np.inf
    with pytest.raises(pprender.Error, match="invalid vertices"):
        pprender.Scene((bad, f), A)
    with pytest.raises(pprender.Error, match="invalid faces"):
        pprender.Scene((v, np.array([[0, 1, 3]])), A)
    with pytest.raises(pprender.Error, match="invalid faces"):
        pprender.Scene((v, np.array([[0, -1, 2]])), A)
    with pytest.raises(pprender.Error, match="invalid faces"):
        pprender.Scene((v, f.astype(float)), A)
    with pytest.raises(pprender.Error, match="invalid vertices"):
        pprender.Scene((v[:, :2], f), A)
    with pytest.raises(pprender.Error, match="invalid vertices"):
        pprender.Scene((["a", "b", "c"], f), A)
    with pytest.raises(pprender.Error, match="invalid normals"):
        pprender.Scene((v, f), A, normals=np.ones((2, 3)))
    with pytest.raises(pprender.Error, match="invalid mesh"):
        pprender.Scene("sat.glb", A)


def test_node_name_beats_another_geometry_of_that_name() -> None:
    """Node "a" instances geometry "b" and node "b" geometry "a": each node takes the key
    naming the node itself (node > geometry > material), so no key is ambiguous."""
    s = trimesh.Scene()
    s.add_geometry(trimesh.creation.box(extents=[1, 1, 1]), geom_name="b", node_name="a",
                   transform=trimesh.transformations.translation_matrix([0, 2.0, 0]))
    s.add_geometry(trimesh.creation.box(extents=[1, 1, 1]), geom_name="a", node_name="b")
    scene = pprender.Scene(s, {"a": A, "b": B})
    assert scene.matched["a"] == ("a", "node", A) and scene.matched["b"] == ("b", "node", B)
    fmat = _face_materials(scene)
    y = scene.vertices[scene.faces].mean(axis=1)[:, 1]
    assert all(m is (A if yy > 1 else B) for m, yy in zip(fmat, y))
    # without a key naming node "a", its geometry's name ("b") gives its material
    only_b = pprender.Scene(s, {"b": B})
    assert only_b.matched["a"] == ("b", "geometry", B) and only_b.matched["b"] == ("b", "node", B)


def test_units_of_the_scene_geometries() -> None:
    box = trimesh.creation.box(extents=[2.0, 2.0, 2.0])
    box.units = "millimeters"
    s = trimesh.Scene()
    s.add_geometry(box, geom_name="box")
    s.add_geometry(trimesh.creation.box(extents=[1.0, 1.0, 1.0]), geom_name="other")  # no units
    with pytest.warns(UnitsWarning, match="millimeters"):
        pprender.Scene(s, A)
