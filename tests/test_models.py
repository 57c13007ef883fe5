"""Procedural meshes of ``pprender.models`` against independent expectations: the stated
bus dimensions, analytic areas and volumes, closedness and outward winding of every body,
the material arrays, the stated triangle counts, and ray casts at known heights."""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np
import pytest
import trimesh
import trimesh.ray.ray_triangle

from pprender import Error, models

DIMS = {"1U": (0.1, 0.1, 0.1135), "3U": (0.1, 0.1, 0.3405), "6U": (0.2263, 0.1, 0.366)}
T = 0.002  # panel thickness
M = 0.005  # body-mounted panel margin
R_ANT, L_ANT, N_ANT = 0.0015, 0.2, 16


def part(mesh: trimesh.Trimesh, name: str) -> trimesh.Trimesh:
    """The faces of one material part as their own mesh."""
    idx = mesh.metadata["pprender_parts"].index(name)
    faces = np.flatnonzero(mesh.metadata["pprender_material"] == idx)
    sub = mesh.submesh([faces], append=True)
    assert isinstance(sub, trimesh.Trimesh)
    return sub


def part_area(mesh: trimesh.Trimesh, name: str) -> float:
    idx = mesh.metadata["pprender_parts"].index(name)
    return float(mesh.area_faces[mesh.metadata["pprender_material"] == idx].sum())


def check_common(mesh: trimesh.Trimesh, n_bodies: int, convex: bool = True) -> None:
    """Material metadata, finite vertices, no zero-area faces, and every connected
    component (= body) closed with outward winding."""
    parts = mesh.metadata["pprender_parts"]
    mat = mesh.metadata["pprender_material"]
    assert isinstance(parts, list) and all(isinstance(p, str) for p in parts)
    assert len(set(parts)) == len(parts)
    assert isinstance(mat, np.ndarray) and mat.dtype == np.int32 and mat.shape == (len(mesh.faces),)
    assert mat.min() >= 0 and mat.max() < len(parts)
    assert set(np.unique(mat)) == set(range(len(parts)))  # every listed part has faces
    assert np.all(np.isfinite(mesh.vertices))
    assert mesh.area_faces.min() > 1e-9 * mesh.area
    bodies = mesh.split(only_watertight=False)
    assert len(bodies) == n_bodies
    for body in bodies:
        assert body.is_watertight and body.is_winding_consistent
        assert body.volume > 0  # outward normals
        if convex:
            # independent of the volume sign: every face normal points away from the
            # body's centroid (true for the convex boxes, cylinders, cones, spheres)
            out = np.einsum("ij,ij->i", body.face_normals, body.triangles_center - body.centroid)
            assert out.min() > 0


@pytest.mark.parametrize("units", ["1U", "3U", "6U"])
@pytest.mark.parametrize("detail", [0, 2, 4])
def test_bus_dimensions(units: str, detail: int) -> None:
    X, Y, Z = DIMS[units]
    mesh = models.cubesat(units=units, panels=None, antenna=False, detail=detail)
    check_common(mesh, 1)
    assert mesh.metadata["pprender_parts"] == ["bus"]
    assert len(mesh.faces) == 12 * 4**detail
    np.testing.assert_allclose(mesh.bounds, [[-X / 2, -Y / 2, -Z / 2], [X / 2, Y / 2, Z / 2]], atol=1e-12)
    assert mesh.area == pytest.approx(2 * (X * Y + Y * Z + Z * X), rel=1e-12)
    assert mesh.volume == pytest.approx(X * Y * Z, rel=1e-12)
    np.testing.assert_allclose(mesh.center_mass, 0.0, atol=1e-12)  # origin = bus centroid


@pytest.mark.parametrize("units", ["1U", "3U", "6U"])
def test_deployed_panels_and_antenna(units: str) -> None:
    X, Y, Z = DIMS[units]
    mesh = models.cubesat(units=units)
    check_common(mesh, 4)  # bus, two wings, antenna
    assert mesh.metadata["pprender_parts"] == ["bus", "solar_cells", "panel_back", "antenna"]
    np.testing.assert_allclose(
        mesh.bounds, [[-1.5 * X, -Y / 2, -Z / 2 - L_ANT], [1.5 * X, Y / 2, Z / 2]], atol=1e-12
    )
    # parts closed on their own: the bus and the antenna
    for name in ("bus", "antenna"):
        sub = part(mesh, name)
        assert sub.is_watertight and sub.volume > 0
    # cells: both wings' +y sides, flush with the bus's +y face
    cells = part(mesh, "solar_cells")
    np.testing.assert_allclose(cells.face_normals, np.tile([0.0, 1.0, 0.0], (len(cells.faces), 1)), atol=1e-12)
    np.testing.assert_allclose(cells.vertices[:, 1], Y / 2, atol=1e-12)
    assert np.abs(cells.vertices[:, 0]).min() == pytest.approx(X / 2)
    assert np.abs(cells.vertices[:, 0]).max() == pytest.approx(1.5 * X)
    assert part_area(mesh, "solar_cells") == pytest.approx(2 * X * Z, rel=1e-12)
    # back: the -y side plus the four 2 mm edges of each wing
    assert part_area(mesh, "panel_back") == pytest.approx(2 * (X * Z + 2 * (X + Z) * T), rel=1e-12)
    # the wings together (cells + back) are closed
    wings = mesh.submesh([np.flatnonzero(np.isin(mesh.metadata["pprender_material"], [1, 2]))], append=True)
    assert wings.is_watertight and wings.volume == pytest.approx(2 * X * Z * T, rel=1e-9)
    assert part_area(mesh, "bus") == pytest.approx(2 * (X * Y + Y * Z + Z * X), rel=1e-12)
    # antenna: a 16-sided prism inscribed in the 3 mm x 0.2 m cylinder
    n = N_ANT
    prism = 2 * n * R_ANT * math.sin(math.pi / n) * L_ANT + n * R_ANT**2 * math.sin(2 * math.pi / n)
    assert part_area(mesh, "antenna") == pytest.approx(prism, rel=1e-9)
    assert part_area(mesh, "antenna") < 2 * math.pi * R_ANT * (L_ANT + R_ANT)


def test_body_panels() -> None:
    X, Y, Z = DIMS["3U"]
    mesh = models.cubesat(units="3U", panels="body", antenna=False)
    check_common(mesh, 5)
    cells = part(mesh, "solar_cells")
    # each cell face points along +-x or +-y and lies t outside the bus face it covers
    n = cells.face_normals
    assert np.allclose(np.abs(n).max(axis=1), 1.0) and np.allclose(n[:, 2], 0.0)
    half = np.where(np.abs(n[:, 0]) > 0.5, X / 2, Y / 2)
    np.testing.assert_allclose(np.einsum("ij,ij->i", n, cells.triangles_center), half + T, atol=1e-12)
    expected = 2 * ((Y - 2 * M) * (Z - 2 * M) + (X - 2 * M) * (Z - 2 * M))
    assert part_area(mesh, "solar_cells") == pytest.approx(expected, rel=1e-12)


def test_default_triangle_count() -> None:
    mesh = models.cubesat()
    # stated in the docstring: 3072 (bus) + 2 * 4352 (wings) + 64 (antenna)
    assert len(mesh.faces) == 11_840
    assert 9_000 <= len(mesh.faces) <= 13_000  # "about 10k" for the benchmark
    assert len(models.cubesat(detail=3).faces) == 3_136
    assert len(models.cubesat(detail=5).faces) == 46_144


def test_wrap_reproducible_and_bounded() -> None:
    X, Y, Z = DIMS["3U"]
    amp = 0.0015
    a = models.cubesat(wrap=True, seed=7, wrap_amplitude=amp)
    b = models.cubesat(wrap=True, seed=7, wrap_amplitude=amp)
    c = models.cubesat(wrap=True, seed=8, wrap_amplitude=amp)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.metadata["pprender_material"], b.metadata["pprender_material"])
    assert a.metadata["pprender_parts"][0] == "blanket"
    blanket = part(a, "blanket")
    other = part(c, "blanket")
    assert np.abs(blanket.vertices - other.vertices).max() > amp / 2
    check_common(a, 4, convex=False)
    assert blanket.is_watertight and blanket.volume > 0
    # the displacement from the flat box (one level finer) is along the normals, at most amp
    box = models.cubesat(panels=None, antenna=False, detail=5)
    assert len(blanket.faces) == len(box.faces)
    d = blanket.vertices - box.vertices
    dist = np.linalg.norm(d, axis=1)
    assert dist.max() == pytest.approx(amp, rel=1e-9)
    assert dist.mean() > 0.1 * amp  # wrinkled all over, not only at a few vertices
    outside = np.maximum(np.abs(blanket.vertices) - np.array([X, Y, Z]) / 2, 0.0)
    assert outside.max() <= amp + 1e-12
    assert abs(blanket.volume - X * Y * Z) <= amp * 2 * (X * Y + Y * Z + Z * X)


@pytest.mark.parametrize("units", ["1U", "3U", "6U"])
@pytest.mark.parametrize("wrap", [False, True])
def test_ray_hits_bus_top(units: str, wrap: bool) -> None:
    X, Y, Z = DIMS[units]
    mesh = models.cubesat(units=units, wrap=wrap)
    origins = np.array([[0.0, 0.0, 1.0], [0.01, -0.02, 1.0]])
    dirs = np.tile([0.0, 0.0, -1.0], (2, 1))
    # the default engine (embree where embreex is installed) and the rtree-based one
    for engine in (mesh.ray, trimesh.ray.ray_triangle.RayMeshIntersector(mesh)):
        loc, ray, tri = engine.intersects_location(origins, dirs, multiple_hits=False)
        assert sorted(ray.tolist()) == [0, 1]
        tol = 0.0015 + 1e-5 if wrap else 1e-5  # embree works in float32
        np.testing.assert_allclose(loc[:, 2], Z / 2, atol=tol)
        assert set(mesh.metadata["pprender_material"][tri].tolist()) == {0}


def test_ray_hits_cells_and_back() -> None:
    X, Y, Z = DIMS["3U"]
    mesh = models.cubesat()
    mat = mesh.metadata["pprender_material"]
    parts = mesh.metadata["pprender_parts"]
    origins = np.array([[X, 1.0, 0.05], [-X, -1.0, -0.1]])
    dirs = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    loc, ray, tri = mesh.ray.intersects_location(origins, dirs, multiple_hits=False)
    order = np.argsort(ray)
    np.testing.assert_allclose(loc[order, 1], [Y / 2, Y / 2 - T], atol=1e-5)
    assert [parts[i] for i in mat[tri[order]]] == ["solar_cells", "panel_back"]


@pytest.mark.parametrize("subdivisions", [0, 2, 4])
def test_sphere(subdivisions: int) -> None:
    r = 0.7
    mesh = models.sphere(radius=r, subdivisions=subdivisions)
    check_common(mesh, 1)
    assert mesh.metadata["pprender_parts"] == ["surface"]
    assert len(mesh.faces) == 20 * 4**subdivisions
    np.testing.assert_allclose(np.linalg.norm(mesh.vertices, axis=1), r, rtol=1e-12)
    # The polyhedron is inscribed: convex and inside the sphere, so area < 4 pi r^2. Each
    # facet at distance d from the centre projects radially onto a spherical patch of area
    # int r^2 d / |p|^3 dA <= (r^2 / d^2) A_facet, so area >= 4 pi d_min^2.
    d_min = np.abs(np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles[:, 0])).min()
    assert 4 * math.pi * d_min**2 <= mesh.area < 4 * math.pi * r**2
    assert 4 / 3 * math.pi * d_min**3 <= mesh.volume < 4 / 3 * math.pi * r**3
    if subdivisions == 4:
        assert mesh.area == pytest.approx(4 * math.pi * r**2, rel=1.3e-3)  # docstring: 0.12 %


@pytest.mark.parametrize("detail", [0, 3])
def test_plate(detail: int) -> None:
    w, h, t = 1.2, 0.8, 0.003
    mesh = models.plate(width=w, height=h, thickness=t, detail=detail)
    check_common(mesh, 1)
    assert mesh.metadata["pprender_parts"] == ["front", "back", "edge"]
    assert len(mesh.faces) == 4 * 4**detail + 8 * 2**detail
    np.testing.assert_allclose(mesh.bounds, [[-w / 2, -h / 2, -t / 2], [w / 2, h / 2, t / 2]], atol=1e-12)
    assert part_area(mesh, "front") == pytest.approx(w * h, rel=1e-12)
    assert part_area(mesh, "back") == pytest.approx(w * h, rel=1e-12)
    assert part_area(mesh, "edge") == pytest.approx(2 * (w + h) * t, rel=1e-12)
    front = part(mesh, "front")
    np.testing.assert_allclose(front.face_normals[:, 2], 1.0, atol=1e-12)
    np.testing.assert_allclose(front.vertices[:, 2], t / 2, atol=1e-12)
    assert mesh.volume == pytest.approx(w * h * t, rel=1e-9)


@pytest.mark.parametrize("sections", [3, 8, 64])
def test_cone(sections: int) -> None:
    r, h, n = 0.4, 1.1, sections
    mesh = models.cone(radius=r, height=h, sections=n)
    check_common(mesh, 1)
    assert mesh.metadata["pprender_parts"] == ["side", "base"]
    assert len(mesh.faces) == 2 * n
    assert mesh.vertices[:, 2].max() == pytest.approx(h / 2)
    apex = mesh.vertices[np.argmax(mesh.vertices[:, 2])]
    np.testing.assert_allclose(apex, [0.0, 0.0, h / 2], atol=1e-12)
    base = part(mesh, "base")
    np.testing.assert_allclose(base.face_normals, np.tile([0.0, 0.0, -1.0], (len(base.faces), 1)), atol=1e-12)
    np.testing.assert_allclose(base.vertices[:, 2], -h / 2, atol=1e-12)
    # n triangles from the apex to the chords of the inscribed n-gon: chord 2 r sin(x),
    # apothem r cos(x), slant height sqrt(h^2 + r^2 cos^2 x), x = pi / n.
    x = math.pi / n
    side = n * r * math.sin(x) * math.sqrt(h**2 + r**2 * math.cos(x) ** 2)
    assert part_area(mesh, "side") == pytest.approx(side, rel=1e-12)
    assert part_area(mesh, "base") == pytest.approx(0.5 * n * r**2 * math.sin(2 * x), rel=1e-12)
    # Discretisation error against the circular cone pi r L: the ratio is
    # (sin x / x) * sqrt(h^2 + r^2 cos^2 x) / L, in [(1 - x^2/6)(cos x), 1], so >= 1 - 2x^2/3.
    exact = math.pi * r * math.hypot(r, h)
    assert 1 - 2 * x**2 / 3 <= part_area(mesh, "side") / exact <= 1
    assert mesh.volume == pytest.approx(0.5 * n * r**2 * math.sin(2 * x) * h / 3, rel=1e-12)


def test_describe() -> None:
    text = models.describe(models.cubesat())
    for name in ("bus", "solar_cells", "panel_back", "antenna", "11840"):
        assert name in text


BAD: list[tuple[Callable[..., Any], dict[str, Any], str]] = [
    (models.cubesat, {"units": "2U"}, r"units = '2U'.*'1U', '3U', '6U'"),
    (models.cubesat, {"units": 3}, r"units = 3"),
    (models.cubesat, {"panels": "wings"}, r"panels = 'wings'.*'deployed', 'body' or None"),
    (models.cubesat, {"antenna": "yes"}, r"antenna = 'yes'.*True or False"),
    (models.cubesat, {"wrap": 1}, r"wrap = 1.*True or False"),
    (models.cubesat, {"detail": -1}, r"detail = -1.*\[0, 7\]"),
    (models.cubesat, {"detail": 8}, r"detail = 8.*\[0, 7\]"),
    (models.cubesat, {"detail": 2.0}, r"detail = 2.0.*integer"),
    (models.cubesat, {"seed": -1}, r"seed = -1"),
    (models.cubesat, {"wrap": True, "wrap_amplitude": 0.0}, r"wrap_amplitude = 0.0.*\(0, 0.01\]"),
    (models.cubesat, {"wrap_amplitude": 0.05}, r"wrap_amplitude = 0.05.*\(0, 0.01\]"),
    (models.sphere, {"radius": 0.0}, r"radius = 0.0.*> 0"),
    (models.sphere, {"radius": float("nan")}, r"radius = nan"),
    (models.sphere, {"subdivisions": -2}, r"subdivisions = -2.*\[0, 7\]"),
    (models.plate, {"width": -1.0}, r"width = -1.0.*> 0"),
    (models.plate, {"height": "1"}, r"height = '1'.*positive finite number"),
    (models.plate, {"thickness": float("inf")}, r"thickness = inf"),
    (models.plate, {"detail": -1}, r"detail = -1.*\[0, 8\]"),
    (models.cone, {"radius": -0.1}, r"radius = -0.1.*> 0"),
    (models.cone, {"height": 0}, r"height = 0.*> 0"),
    (models.cone, {"sections": 2}, r"sections = 2.*\[3, 100000\]"),
    (models.cone, {"sections": True}, r"sections = True.*integer"),
]


@pytest.mark.parametrize("func, kwargs, match", BAD, ids=[f"{f.__name__}-{next(iter(k))}" for f, k, _ in BAD])
def test_bad_input(func: Callable[..., Any], kwargs: dict[str, Any], match: str) -> None:
    with pytest.raises(Error, match=match) as info:
        func(**kwargs)
    assert isinstance(info.value, ValueError)
