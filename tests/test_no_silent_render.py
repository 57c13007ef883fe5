"""Regression tests for the silent wrong answers of issue 21 on the rendering side: each
failed (wrong number, raw TypeError or abort) before its fix and passes after.

* named materials labelled with the wavelength their constants are for;
* a mesh far from the body origin refused when its pixels cannot see it, warned when
  off-centre;
* CPU (f64) renders refused up front when they would exhaust memory or the bin limit;
* ``help(pprender.Material)`` documents its parameters;
* ``RenderResult.device`` names the CPU path that ran;
* scipy ``Rotation`` objects accepted wherever attitudes go, converted without the
  scalar-first / scalar-last ambiguity.
"""

from __future__ import annotations

import inspect
import warnings

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

import pprender
from pprender import database, materials, so3

BOX = trimesh.creation.box((0.5, 0.4, 0.3))
GREY = pprender.Material("beckmann", alpha=0.3, eta=1.5)


def _box_scene(offset=(0.0, 0.0, 0.0), material=GREY) -> pprender.Scene:
    return pprender.Scene((BOX.vertices + np.asarray(offset), BOX.faces), material)


# ------------------------------------------------------------------ 1. wavelengths


@pytest.mark.parametrize("wl", [532e-9, 1064e-9])
def test_named_material_is_labelled_with_its_wavelength(wl) -> None:
    m = materials.get("aluminium", wavelength=wl)
    assert m.wavelength == wl
    assert m.eta == materials.optical_constants("aluminium", wl)


def test_named_material_at_532_is_refused_by_a_1064_sensor() -> None:
    scene = pprender.Scene((BOX.vertices, BOX.faces), materials.get("aluminium", wavelength=532e-9))
    with pytest.raises(pprender.Error, match="wavelength"):
        pprender.render(scene, pprender.Lidar(resolution=16), [1, 0, 0, 0], outputs=("profile",))


def test_named_materials_render_at_532() -> None:
    """By name in Scene and as materials.get: the same materials, accepted by a 532 nm
    sensor (before: "built for 1.064e-06 m"), and the 532 nm constants are the ones used:
    the cross-section equals that of the explicit Material with the 532 nm index."""
    sensor = pprender.Lidar(wavelength=532e-9, resolution=24)
    by_name = pprender.render(pprender.Scene((BOX.vertices, BOX.faces), "aluminium", wavelength=532e-9),
                              sensor, [1, 0, 0, 0], outputs=("profile",))
    kw = materials.material_kwargs("aluminium", 532e-9)
    explicit = pprender.render(pprender.Scene((BOX.vertices, BOX.faces), pprender.Material(**kw)),
                               sensor, [1, 0, 0, 0], outputs=("profile",))
    np.testing.assert_array_equal(by_name.cross_section, explicit.cross_section)
    at_1064 = pprender.render(pprender.Scene((BOX.vertices, BOX.faces), "aluminium"),
                              pprender.Lidar(resolution=24), [1, 0, 0, 0], outputs=("profile",))
    # aluminium's R0 is 0.917 at 532 nm and 0.950 at 1064 nm: the renders must differ
    assert not np.allclose(by_name.cross_section, at_1064.cross_section, rtol=1e-3)


def test_database_with_material_names_at_532(tmp_path) -> None:
    # a face toward the sensor (the identity) and a random attitude: the aluminium (alpha
    # 0.1, orders from the path banks) returns light only near a face's normal, where
    # the seed's depolarizing multiple term lit the box at any attitude
    attitudes = np.vstack([[1.0, 0.0, 0.0, 0.0], so3.grid(2)[:1]])
    ds = database.build_database(tmp_path / "db.zarr", {"box": (BOX.vertices, BOX.faces)}, {"al": "aluminium"},
                                 attitudes, pprender.Lidar(wavelength=532e-9, resolution=16),
                                 progress=False)
    m00 = np.asarray(ds["profile"])[..., 0, 0]  # (the 16 elements of a face-on glint sum to 0)
    assert float(m00.sum()) > 0


# ------------------------------------------------------------------ 3. far from origin


def test_mesh_far_from_the_origin_is_refused_not_zero() -> None:
    """1e4 m from the body origin with bin_width=1 gave a cross-section of 0.0: the image
    spans the 2e4 m sphere about the origin and the 0.7 m box falls between samples."""
    scene = _box_scene((1e4, 0.0, 0.0))
    for arithmetic in ("f32", "f64"):
        with pytest.warns(pprender.OffCentreWarning, match="from the body origin"):
            with pytest.raises(pprender.Error, match=r"resolution.*pixel"):
                pprender.render(scene, pprender.Lidar(bin_width=1.0, arithmetic=arithmetic), [1, 0, 0, 0],
                                outputs=("profile",))


def test_off_centre_mesh_warns_and_resolved_one_renders_right() -> None:
    """3 m off-centre and resolved (about 40 pixels across the box): a warning, and the
    same cross-section as the centred box within the pixel sampling error (1%; the
    measured difference is ~0.3%)."""
    centred = pprender.render(_box_scene(), pprender.Lidar(resolution=128), [1, 0, 0, 0], outputs=("profile",))
    with pytest.warns(pprender.OffCentreWarning):
        off = pprender.render(_box_scene((3.0, 0.0, 0.0)), pprender.Lidar(resolution=512), [1, 0, 0, 0],
                              outputs=("profile",))
    np.testing.assert_allclose(off.cross_section[0, 0, 0], centred.cross_section[0, 0, 0], rtol=1e-2)


def test_centred_mesh_does_not_warn() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pprender.render(_box_scene((0.1, 0.0, 0.0)), pprender.Lidar(resolution=16), [1, 0, 0, 0],
                        outputs=("profile",))


# ------------------------------------------------------------------ 8. CPU memory


def test_f64_render_over_the_bin_limit_is_refused() -> None:
    """100 m off-centre at resolution 8192 asked for 66,898 bins of the f64 twin (the f32
    path refuses above 65,536) and aborted the process allocating them."""
    scene = _box_scene((100.0, 0.0, 0.0))
    with pytest.warns(pprender.OffCentreWarning):
        with pytest.raises(pprender.Error, match=r"bin_width.*65536 bins"):
            pprender.render(scene, pprender.Lidar(resolution=8192, arithmetic="f64"), [1, 0, 0, 0])


@pytest.mark.parametrize("kw", [dict(arithmetic="f64"), dict(quality="reference")])
def test_cpu_render_beyond_memory_is_refused_up_front(kw) -> None:
    """64 Mueller images of 8192^2 pixels need about 550 GB: refused, naming the memory,
    before anything is allocated (the test would abort or swap otherwise)."""
    with pytest.raises(pprender.Error, match=r"needs about [0-9.]+ GiB of memory"):
        pprender.render(_box_scene(), pprender.Lidar(resolution=8192, **kw), np.tile([1.0, 0, 0, 0], (64, 1)),
                        outputs=("mueller",))


# ------------------------------------------------------------------ help, device


def test_material_docstring_documents_every_parameter() -> None:
    doc = inspect.getdoc(pprender.Material) or ""
    assert "_core.pyi" not in doc
    params = inspect.signature(pprender.Material).parameters
    assert len(params) >= 15
    for name in params:
        assert f"{name}:" in doc or f"``{name}``" in doc, name


@pytest.mark.parametrize("kw, expected", [(dict(arithmetic="f64"), "f64 twin (CPU"),
                                          (dict(quality="reference"), "reference (f64 CPU")])
def test_device_names_the_cpu_path(kw, expected) -> None:
    r = pprender.render(_box_scene(), pprender.Lidar(resolution=16, **kw), [1, 0, 0, 0], outputs=("profile",),
                        device="cpu")
    assert r.device.startswith(expected)
    assert "llvmpipe" not in r.device


def test_device_names_lavapipe_for_f32_on_cpu() -> None:
    r = pprender.render(_box_scene(), pprender.Lidar(resolution=16), [1, 0, 0, 0], outputs=("profile",),
                        device="cpu")
    assert "llvmpipe" in r.device


# ------------------------------------------------------------------ scipy Rotation


ROT = Rotation.from_euler("xyz", [[30, -50, 70], [-120, 10, 40]], degrees=True)


def test_render_accepts_a_scipy_rotation() -> None:
    scene = _box_scene()
    sensor = pprender.Lidar(resolution=24)
    wxyz = ROT.as_quat()[:, [3, 0, 1, 2]]
    by_rot = pprender.render(scene, sensor, ROT, outputs=("profile",))
    by_q = pprender.render(scene, sensor, wxyz, outputs=("profile",))
    by_m = pprender.render(scene, sensor, ROT.as_matrix(), outputs=("profile",))
    np.testing.assert_array_equal(by_rot.cross_section, by_q.cross_section)
    np.testing.assert_allclose(by_rot.cross_section, by_m.cross_section, rtol=1e-6, atol=1e-12)
    one = pprender.render(scene, sensor, ROT[0], outputs=("profile",))
    np.testing.assert_array_equal(one.cross_section[0], by_rot.cross_section[0])
    # the pitfall a Rotation avoids: scipy's scalar-last array read as (w, x, y, z) is
    # another attitude
    wrong = pprender.render(scene, sensor, ROT.as_quat(), outputs=("profile",))
    assert not np.allclose(wrong.cross_section, by_rot.cross_section, rtol=1e-3)


def test_so3_and_database_accept_a_scipy_rotation(tmp_path) -> None:
    wxyz = ROT.as_quat()[:, [3, 0, 1, 2]]
    np.testing.assert_allclose(so3.angular_distance(ROT, wxyz), 0.0, atol=1e-7)
    ds = database.build_database(tmp_path / "db.zarr", {"box": (BOX.vertices, BOX.faces)}, {"grey": GREY}, ROT,
                                 pprender.Lidar(resolution=16), progress=False)
    np.testing.assert_allclose(np.asarray(ds["quaternion"]), wxyz, rtol=0, atol=1e-15)


# ------------------------------------------------------------------ wrong types


@pytest.mark.parametrize("kw, name", [
    (dict(bin_width="0.01"), "bin_width"),  # was a raw TypeError
    (dict(bin_width=True), "bin_width"),  # was accepted as 1 m
    (dict(polarization="H"), "polarization"),  # was a raw ValueError
    (dict(polarization=None, intensity_only="yes"), "intensity_only"),
    (dict(wavelength="1064e-9"), "wavelength"),
    (dict(resolution="64"), "resolution"),
    (dict(supersampling=True), "supersampling"),
    (dict(bistatic_angle="0.1"), "bistatic_angle"),
    (dict(pulse_samples=[1.0, 2.0], pulse_sample_spacing="1e-11"), "pulse_sample_spacing"),
])
def test_lidar_wrong_types_name_the_parameter(kw, name) -> None:
    with pytest.raises(pprender.Error, match=rf"\b{name}\b"):
        pprender.Lidar(**kw)


@pytest.mark.parametrize("materials_arg", [None, 3, [None]])
def test_scene_without_usable_materials_names_them(materials_arg) -> None:
    with pytest.raises(pprender.Error, match=r"\bmaterials?\b"):
        pprender.Scene((BOX.vertices, BOX.faces), materials_arg)
