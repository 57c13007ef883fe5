"""Procedural satellite meshes for the renderer, built with trimesh.

Conventions (every function in this module):

* Units: metres.
* Body frame: right-handed. For :func:`cubesat` the bus's long axis is +z and the origin
  is the centroid of the bus box (the object's reference point for range). For
  :func:`sphere`, :func:`plate` and :func:`cone` the origin is the centre of the
  bounding box.
* Every function returns a :class:`trimesh.Trimesh` with

  - ``mesh.metadata["pprender_parts"]``: list of part names (``str``), e.g.
    ``["bus", "solar_cells", "panel_back", "antenna"]``; only the parts present are listed;
  - ``mesh.metadata["pprender_material"]``: ``numpy.int32`` array of shape
    ``(n_faces,)``, each face's index into that list.

* Geometry: every body (bus, each panel, antenna, ...) is a closed triangle mesh with
  consistent outward winding (face normals point out of the body), no zero-area faces and
  finite vertices. Bodies are kept as separate vertex sets (they may touch or overlap; no
  boolean unions and no shared vertices between bodies), so each connected component of
  the mesh is one closed body. A material part may be open (e.g. the cell side of a panel):
  thin things (solar panels, plates) are thin closed boxes whose two sides are separate
  faces with their own parts (front = cells, back = ``panel_back``), so nothing relies on
  two-sided rendering.
* Flat faces are tessellated with :func:`trimesh.remesh.subdivide` (each subdivision
  splits every triangle into four), so the triangle count is controlled by an integer
  level.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import trimesh

from ._core import Error

__all__ = ["BUS_EXTENTS", "cone", "cubesat", "describe", "plate", "sphere"]

#: Bus box extents (x, y, z) in metres for each supported CubeSat size.
BUS_EXTENTS: dict[str, tuple[float, float, float]] = {
    "1U": (0.1, 0.1, 0.1135),
    "3U": (0.1, 0.1, 0.3405),
    "6U": (0.2263, 0.1, 0.366),
}

#: Solar panel thickness (m).
PANEL_THICKNESS = 0.002
#: Margin (m) between the edge of a bus face and a body-mounted panel on it.
BODY_PANEL_MARGIN = 0.005
#: Whip antenna: radius (m), length (m) and number of sides of its cylinder.
ANTENNA_RADIUS = 0.0015
ANTENNA_LENGTH = 0.2
ANTENNA_SECTIONS = 16
#: Wrinkle wavelengths (m) of the thermal blanket noise (``cubesat(wrap=True)``).
WRAP_WAVELENGTHS = (0.04, 0.12)
_WRAP_WAVES = 32

_MAX_DETAIL = 7


# --------------------------------------------------------------------------- validation


def _positive(name: str, value: object, upper: float = math.inf) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise Error(f"invalid {name} = {value!r}: must be a positive finite number (metres)")
    v = float(value)
    if not (math.isfinite(v) and 0.0 < v <= upper):
        rng = "> 0" if upper == math.inf else f"in (0, {upper}]"
        raise Error(f"invalid {name} = {value!r}: must be a finite number {rng} (metres)")
    return v


def _integer(name: str, value: object, lo: int, hi: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise Error(f"invalid {name} = {value!r}: must be an integer in [{lo}, {hi}]")
    v = int(value)
    if not lo <= v <= hi:
        raise Error(f"invalid {name} = {value!r}: must be an integer in [{lo}, {hi}]")
    return v


def _flag(name: str, value: object) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise Error(f"invalid {name} = {value!r}: must be True or False")
    return bool(value)


# --------------------------------------------------------------------------- building blocks


def _subdivide(vertices: np.ndarray, faces: np.ndarray, levels: int) -> tuple[np.ndarray, np.ndarray]:
    for _ in range(levels):
        vertices, faces = trimesh.remesh.subdivide(vertices, faces)
    return vertices, faces


def _box(extents: Sequence[float], levels: int) -> trimesh.Trimesh:
    """Closed box centred on the origin, 12 * 4**levels triangles."""
    box = trimesh.creation.box(extents=extents)
    v, f = _subdivide(box.vertices, box.faces, levels)
    return trimesh.Trimesh(vertices=v, faces=f, process=False)


def _slab(width: float, height: float, thickness: float, levels: int) -> tuple[trimesh.Trimesh, np.ndarray]:
    """Thin closed box: a ``width`` (x) by ``height`` (y) rectangle subdivided ``levels``
    times and extruded by ``thickness`` along z, centred on the origin.

    Returns the mesh and each face's side: 0 = front (+z), 1 = back (-z), 2 = edge.
    Triangles: ``4 * 4**levels`` on the two sides plus ``8 * 2**levels`` on the edges.
    """
    w, h = width / 2.0, height / 2.0
    v2 = np.array([[-w, -h], [w, -h], [w, h], [-w, h]], dtype=np.float64)
    f2 = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
    v2, f2 = _subdivide(v2, f2, levels)
    shift = trimesh.transformations.translation_matrix([0.0, 0.0, -thickness / 2.0])
    mesh = trimesh.creation.extrude_triangulation(v2, f2, thickness, transform=shift)
    nz = mesh.face_normals[:, 2]
    side = np.full(len(mesh.faces), 2, dtype=np.int32)
    side[nz > 0.5] = 0
    side[nz < -0.5] = 1
    return mesh, side


def _frame(normal: Sequence[float], center: Sequence[float]) -> np.ndarray:
    """Rigid transform taking local +z to ``normal`` and local +y to body +z (``normal``
    must be perpendicular to z), then translating to ``center``."""
    n = np.asarray(normal, dtype=np.float64)
    up = np.array([0.0, 0.0, 1.0])
    m = np.eye(4)
    m[:3, 0] = np.cross(up, n)
    m[:3, 1] = up
    m[:3, 2] = n
    m[:3, 3] = center
    return m


def _assemble(bodies: list[tuple[trimesh.Trimesh, np.ndarray]], parts: list[str]) -> trimesh.Trimesh:
    mesh = trimesh.util.concatenate([b for b, _ in bodies])
    assert isinstance(mesh, trimesh.Trimesh)
    material = np.concatenate([m for _, m in bodies]).astype(np.int32)
    # keep only the parts that are used, in the given order
    used = [i for i in range(len(parts)) if np.any(material == i)]
    remap = np.full(len(parts), -1, dtype=np.int32)
    remap[used] = np.arange(len(used), dtype=np.int32)
    mesh.metadata.clear()
    mesh.metadata["pprender_parts"] = [parts[i] for i in used]
    mesh.metadata["pprender_material"] = remap[material]
    return mesh


def _wrinkle(mesh: trimesh.Trimesh, amplitude: float, seed: int) -> trimesh.Trimesh:
    """Displace every vertex along its (angle-weighted) vertex normal by a smooth random
    field: a sum of plane waves with random directions, phases and wavelengths in
    ``WRAP_WAVELENGTHS`` (amplitude proportional to wavelength), scaled so that the largest
    displacement is exactly ``amplitude``. Connectivity is unchanged, so the mesh stays
    closed."""
    rng = np.random.default_rng(seed)
    dirs = rng.normal(size=(_WRAP_WAVES, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    lo, hi = WRAP_WAVELENGTHS
    lam = np.exp(rng.uniform(np.log(lo), np.log(hi), size=_WRAP_WAVES))
    phase = rng.uniform(0.0, 2.0 * np.pi, size=_WRAP_WAVES)
    amp = lam * rng.uniform(0.5, 1.0, size=_WRAP_WAVES)
    v = mesh.vertices
    field = np.sin(v @ (dirs.T * (2.0 * np.pi / lam)) + phase) @ amp
    field *= amplitude / np.max(np.abs(field))
    displaced = v + mesh.vertex_normals * field[:, None]
    return trimesh.Trimesh(vertices=displaced, faces=mesh.faces, process=False)


# --------------------------------------------------------------------------- models


def cubesat(
    units: str = "3U",
    panels: str | None = "deployed",
    antenna: bool = True,
    wrap: bool = False,
    detail: int = 4,
    seed: int = 0,
    wrap_amplitude: float = 0.0015,
) -> trimesh.Trimesh:
    """A CubeSat: bus box, optional solar panels and a whip antenna.

    The bus is centred on the origin with its long axis along +z. Parts, in this order when
    present: ``"bus"`` or ``"blanket"``, ``"solar_cells"``, ``"panel_back"``, ``"antenna"``.

    Parameters
    ----------
    units : {"1U", "3U", "6U"}, optional
        ``"1U"`` (bus 0.1 x 0.1 x 0.1135 m), ``"3U"`` (0.1 x 0.1 x 0.3405 m, the default) or
        ``"6U"`` (0.2263 x 0.1 x 0.366 m), extents along (x, y, z) (:data:`BUS_EXTENTS`).
    panels : {"deployed", "body", None}, optional
        Panel parts: ``"solar_cells"`` (the cell side) and ``"panel_back"`` (the back side
        and the 2 mm edges).

        * ``"deployed"`` (default): two wings, each the size of the bus's +y face (bus x
          extent by bus z extent), 2 mm thick, hinged at the two edges ``x = +-X/2, y = +Y/2``
          of the bus and extending outward in x (the +x wing spans ``x in [X/2, 3X/2]``). The
          cells face +y and are flush with the bus's +y face (wing ``y in [Y/2 - 2 mm, Y/2]``).
        * ``"body"``: a 2 mm panel on each of the four long faces (+-x, +-y), inset by 5 mm
          from the face's edges, cells facing outward (the panels lie outside the bus box).
        * ``None``: no panels.
    antenna : bool, optional
        A whip, a cylinder of 3 mm diameter and 0.2 m length with 16 sides (part
        ``"antenna"``), along -z from the centre of the bus's -z face
        (``z in [-Z/2 - 0.2, -Z/2]``). Default True.
    wrap : bool, optional
        Replace the bus by a wrinkled thermal blanket (part ``"blanket"`` instead of
        ``"bus"``): the bus box subdivided one level more than ``detail`` and every vertex
        displaced along its normal by smooth random noise (wavelengths 4-12 cm), the largest
        displacement being ``wrap_amplitude``. Default False.
    detail : int, optional
        Tessellation level, an integer in [0, 7]. The bus box has ``12 * 4**detail``
        triangles (``12 * 4**(detail + 1)`` when wrapped); each panel is subdivided one level
        more, ``4 * 4**(detail + 1) + 8 * 2**(detail + 1)`` triangles; the antenna has 64.
        With the defaults (3U, deployed panels, antenna, ``detail=4``) that is
        3072 + 2 * 4352 + 64 = 11,840 triangles (the ~10k-triangle benchmark CubeSat);
        ``detail=3`` gives 3,136 and ``detail=5`` 46,144.
    seed : int, optional
        Seed of the blanket's noise, drawn from ``numpy.random.default_rng(seed)``: the same
        seed gives the same mesh. Default 0.
    wrap_amplitude : float, optional
        Largest displacement of the blanket (m), in (0, 0.01]. Default 0.0015 (1.5 mm).

    Returns
    -------
    trimesh.Trimesh
        The mesh, with its parts in ``metadata`` (module docstring).

    Raises
    ------
    pprender.Error
        For bad arguments.
    """
    if not isinstance(units, str) or units.upper() not in BUS_EXTENTS:
        raise Error(f"invalid units = {units!r}: must be one of {', '.join(map(repr, BUS_EXTENTS))}")
    if panels not in ("deployed", "body", None):
        raise Error(f"invalid panels = {panels!r}: must be 'deployed', 'body' or None")
    has_antenna = _flag("antenna", antenna)
    wrapped = _flag("wrap", wrap)
    level = _integer("detail", detail, 0, _MAX_DETAIL)
    seed_ = _integer("seed", seed, 0, 2**63 - 1)
    amplitude = _positive("wrap_amplitude", wrap_amplitude, 0.01)

    X, Y, Z = BUS_EXTENTS[units.upper()]
    t = PANEL_THICKNESS
    parts = ["blanket" if wrapped else "bus", "solar_cells", "panel_back", "antenna"]
    BUS, CELLS, BACK, ANTENNA = 0, 1, 2, 3
    side_to_part = np.array([CELLS, BACK, BACK], dtype=np.int32)

    if wrapped:
        bus = _wrinkle(_box((X, Y, Z), level + 1), amplitude, seed_)
    else:
        bus = _box((X, Y, Z), level)
    bodies: list[tuple[trimesh.Trimesh, np.ndarray]] = [(bus, np.full(len(bus.faces), BUS, dtype=np.int32))]

    # (width, height, outward normal of the cells, centre) of each panel
    slabs: list[tuple[float, float, tuple[float, float, float], tuple[float, float, float]]] = []
    if panels == "deployed":
        for s in (1.0, -1.0):
            slabs.append((X, Z, (0.0, 1.0, 0.0), (s * X, Y / 2 - t / 2, 0.0)))
    elif panels == "body":
        m = BODY_PANEL_MARGIN
        for s in (1.0, -1.0):
            slabs.append((Y - 2 * m, Z - 2 * m, (s, 0.0, 0.0), (s * (X / 2 + t / 2), 0.0, 0.0)))
            slabs.append((X - 2 * m, Z - 2 * m, (0.0, s, 0.0), (0.0, s * (Y / 2 + t / 2), 0.0)))
    for width, height, normal, center in slabs:
        slab, side = _slab(width, height, t, level + 1)
        slab.apply_transform(_frame(normal, center))
        bodies.append((slab, side_to_part[side]))

    if has_antenna:
        whip = trimesh.creation.cylinder(
            radius=ANTENNA_RADIUS,
            height=ANTENNA_LENGTH,
            sections=ANTENNA_SECTIONS,
            transform=trimesh.transformations.translation_matrix([0.0, 0.0, -Z / 2 - ANTENNA_LENGTH / 2]),
        )
        bodies.append((whip, np.full(len(whip.faces), ANTENNA, dtype=np.int32)))

    return _assemble(bodies, parts)


def sphere(radius: float = 0.5, subdivisions: int = 4) -> trimesh.Trimesh:
    """An icosphere of ``radius`` (m) centred on the origin.

    Its vertices lie on the sphere, so its area is slightly below ``4 pi r**2`` (by 0.12 % at
    the default). One part, ``"surface"``.

    Parameters
    ----------
    radius : float, optional
        Radius (m), > 0. Default 0.5.
    subdivisions : int, optional
        Integer in [0, 7]: ``20 * 4**subdivisions`` triangles (default 4: 5,120 triangles).

    Returns
    -------
    trimesh.Trimesh
        The mesh, with its parts in ``metadata`` (module docstring).

    Raises
    ------
    pprender.Error
        For bad arguments.
    """
    r = _positive("radius", radius)
    n = _integer("subdivisions", subdivisions, 0, _MAX_DETAIL)
    mesh = trimesh.creation.icosphere(subdivisions=n, radius=r)
    return _assemble([(mesh, np.zeros(len(mesh.faces), dtype=np.int32))], ["surface"])


def plate(width: float = 1.0, height: float = 1.0, thickness: float = 0.002, detail: int = 0) -> trimesh.Trimesh:
    """A flat plate: a thin closed box centred on the origin, the front facing +z.

    Parts: ``"front"`` (the +z side, ``z = thickness / 2``), ``"back"`` (the -z side) and
    ``"edge"`` (the four thin sides).

    Parameters
    ----------
    width : float, optional
        Size along x (m). Default 1.
    height : float, optional
        Size along y (m). Default 1.
    thickness : float, optional
        Size along z (m). Default 0.002.
    detail : int, optional
        Integer in [0, 8]: subdivisions of the rectangle, ``4 * 4**detail + 8 * 2**detail``
        triangles (default 0: 12 triangles).

    Returns
    -------
    trimesh.Trimesh
        The mesh, with its parts in ``metadata`` (module docstring).

    Raises
    ------
    pprender.Error
        For bad arguments.
    """
    w = _positive("width", width)
    h = _positive("height", height)
    t = _positive("thickness", thickness)
    level = _integer("detail", detail, 0, _MAX_DETAIL + 1)
    mesh, side = _slab(w, h, t, level)
    return _assemble([(mesh, side)], ["front", "back", "edge"])


def cone(radius: float = 0.5, height: float = 1.0, sections: int = 64) -> trimesh.Trimesh:
    """A right circular cone, axis +z, apex at ``z = +height / 2`` and base at ``z = -height / 2``.

    The base circle is a regular polygon of ``sections`` sides inscribed in it;
    ``2 * sections`` triangles. Parts: ``"side"`` and ``"base"``. The lateral area of the
    polygonal cone is ``n r sin(pi/n) sqrt(h**2 + r**2 cos(pi/n)**2)`` (``n = sections``),
    which falls below ``pi r sqrt(r**2 + h**2)`` by a relative amount of at most
    ``(2/3) (pi/n)**2`` (0.16 % at the default).

    Parameters
    ----------
    radius : float, optional
        Base radius (m). Default 0.5.
    height : float, optional
        Height (m). Default 1.
    sections : int, optional
        Sides of the base polygon, an integer in [3, 100000]. Default 64.

    Returns
    -------
    trimesh.Trimesh
        The mesh, with its parts in ``metadata`` (module docstring).

    Raises
    ------
    pprender.Error
        For bad arguments.
    """
    r = _positive("radius", radius)
    h = _positive("height", height)
    n = _integer("sections", sections, 3, 100_000)
    mesh = trimesh.creation.cone(
        radius=r,
        height=h,
        sections=n,
        transform=trimesh.transformations.translation_matrix([0.0, 0.0, -h / 2]),
    )
    part = (mesh.face_normals[:, 2] < -0.5).astype(np.int32)  # the base faces point -z
    return _assemble([(mesh, part)], ["side", "base"])


def describe(mesh: trimesh.Trimesh) -> str:
    """One line per part of a model from this module: triangle count and area (m^2).

    The lines are followed by the totals and the bounding box.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A mesh from this module (with ``metadata["pprender_parts"]`` and
        ``metadata["pprender_material"]``).

    Returns
    -------
    str
        The description.
    """
    parts: list[str] = mesh.metadata["pprender_parts"]
    material = np.asarray(mesh.metadata["pprender_material"])
    area = mesh.area_faces
    lines = []
    for i, name in enumerate(parts):
        sel = material == i
        lines.append(f"{name:>12}: {int(sel.sum()):7d} triangles, {area[sel].sum():.6g} m^2")
    lo, hi = mesh.bounds
    lines.append(f"{'total':>12}: {len(mesh.faces):7d} triangles, {mesh.area:.6g} m^2")
    lines.append(f"{'bounds':>12}: {np.round(lo, 6).tolist()} .. {np.round(hi, 6).tolist()} m")
    return "\n".join(lines)
