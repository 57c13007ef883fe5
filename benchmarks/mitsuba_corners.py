"""Mitsuba 3 references for inter-reflections in corners: dihedral and trihedral.

``python benchmarks/mitsuba_corners.py --check`` runs :func:`self_check` (analytic trihedral
effective area against a brute-force ray trace; Mitsuba's ``max_depth`` semantics and
absolute scale on a flat plate). ``python benchmarks/mitsuba_corners.py --write
docs/data/mitsuba-corners.json`` renders the references (:func:`compute_references`) and
writes them as JSON (totals only, no images).

Conventions
-----------
* Units: metres; cross-sections in m^2.
* Body frame: the meshes are built about their reference point (the body origin): the
  midpoint of the dihedral's edge, the trihedral's vertex. Every plate is a single-sided
  square (two triangles) whose *front* face (counter-clockwise winding, ``face_normals``)
  is the reflecting inner face of the corner; there are no separate back faces.
* Telescope frame as in pprender (``python/pprender/lidar/__init__.py``): ``Z`` from the
  target toward the receiver, ``X`` right, ``Y`` up in the images; an attitude is a
  rotation ``R`` with ``p_tel = R p_body``, so the view direction in the body frame (from
  the target toward the sensor) is ``d = R^T Z``, the third row of ``R``.
* Monostatic, unpolarized transmitter: the Mitsuba scene is the one of
  ``tests/test_mitsuba_render.py`` / ``bench_render.mitsuba_monostatic_scene``: an
  orthographic sensor at ``+Z`` looking down ``-Z`` over ``[-ext, ext]^2`` (``ext`` the
  radius of the mesh's bounding sphere about the body origin, box pixel filter), a
  ``directional`` emitter propagating along ``-Z`` with irradiance 1 (W m^-2 on a plane
  perpendicular to the beam), the ``stokes`` integrator around ``path``, variant
  ``llvm_ad_mono_polarized``. A pixel's radiance is ``f cos(theta_i) E``, so
  ``4 pi delta^2 sum(pixels)`` (``delta = 2 ext / resolution``) is the lidar cross-section
  of the whole view in m^2, per Stokes component.
* Stokes basis of the output: the ``stokes`` integrator rotates the result to
  ``x = ray.d x up_sensor``; with this sensor (``look_at`` from ``+Z``, up ``+Y``) that is
  ``x = +X``, ``y = Z x x = +Y``: pprender's received-beam basis ``(X, Y)``, with
  ``S1 = I_X - I_Y``. Checked: the 90 deg dihedral seen along its symmetry plane, edge
  along ``Y``, returns ``S1 / S0 = -0.0359`` (alpha 0.1), against ``-0.0360`` for two
  specular reflections at 45 deg in Jones calculus (the s-polarization, along the edge,
  reflects more).
  Images: row 0 at the top (``+Y``), column 0 at the left (``-X``).

What ``max_depth`` means (Mitsuba's ``path`` integrator)
--------------------------------------------------------
``max_depth`` is the longest path in segments, sensor to emitter, i.e. the number of
surface reflections plus one: 1 renders only emitters seen directly (nothing here: a directional emitter is a delta light, never hit),
2 is direct illumination only (one surface reflection, next-event estimation toward the
emitter), 3 adds paths with two reflections (one inter-reflection), 4 three reflections.
A directional emitter is reached only by next-event estimation (shadow rays, which
include the occlusion by the other plates), never by BSDF sampling, so with a delta
emitter every surface BSDF must be non-delta: smooth ``conductor`` returns nothing;
rough conductors are used. Russian roulette starts at ``rr_depth`` 5 (default), beyond
the depths used. Verified by :func:`self_check` (flat plate: depth 1 gives 0, depths 2
and 3 agree, and depth 2 equals the analytic ``A F(0) / alpha^2`` face-on) and by the
references (90 deg dihedral at theta = 0, alpha 0.1: depth 2 gives 0, depth 3 the
double bounce, 7.34 m^2, and depth 4 adds only 7e-10 m^2: there is no specular triple
bounce; at alpha 0.3 the roughness makes the triple part 4 % of the double).

Renders of the same scene and seed at different ``max_depth`` consume the same random
numbers for the common path prefix, so ``T(depth n+1) - T(depth n)`` (same seed) is the
n+1-bounce part alone, with only its own noise. Noise: two seeds per configuration; the
standard deviation of the seed-averaged total is estimated from the per-pixel seed
differences, ``4 pi delta^2 sqrt(sum_pix (a - b)^2 / 2) / sqrt(2)`` (pixels are
independent with the ``independent`` sampler), which has many more degrees of freedom
than the difference of the two totals (also recorded).

Pitfalls
--------
* ``twosided``: Mitsuba's conductors reflect from the front side only. The BSDFs are
  wrapped in ``twosided`` (``two_sided=True``) so a plate's back face also reflects, but
  in the polarized variant (3.9.0) a back-face hit gets a mirrored local frame: S0 is
  unchanged, while S1..S3 after two bounces differ from the same geometry built with
  front faces (measured: S1 by 1.6-3 %, S2 of the opposite sign). Hence the meshes put
  the front faces on the inner (lit) side, and :func:`mitsuba_totals` warns when a view
  lights a back face. For every recorded view the view direction has a positive dot
  product with every inner normal, so only front faces are lit (the corners' convex hulls
  contain them, so inter-reflected rays stay on inner faces too).
* The directional emitter's ``irradiance`` is per unit area perpendicular to the beam.
  Its ``direction`` is the propagation direction (``-Z`` here), not toward the light.
* Film channels in ``mono_polarized``: ``Y`` then ``S0, S1, S2, S3`` three times each
  (13 channels); indices 1, 4, 7, 10 are used.
* The PLY shape is loaded with ``face_normals=True``: vertex normals would be averaged
  across the shared edge (and the trihedral's shared vertex) and bend the plates.
* A smooth ``conductor`` gives exactly 0 with a directional emitter (delta BSDF against
  a delta light), and a rough one at a small alpha makes the off-specular orders
  underflow to exact zeros (e.g. single bounce on the 45 deg plates at alpha 0.1).
* Polarized illumination (:func:`mitsuba_polarized_totals`, the polarizer-sheet set-up):
  at exact backscatter the polarized ``roughconductor`` (3.9.0) takes a wrong Fresnel
  frame where the two directions are equal in float32 (its fallback s-axis, the local
  ``x``, is perpendicular to the half vector only for a face-on surface), which turns the
  linear polarization of single bounces off tilted surfaces; the first Mueller column
  (unpolarized illumination, :func:`mitsuba_totals`) is unaffected. The polarized set-up
  therefore averages two illuminations tilted by +-2e-3 rad.

The trihedral's triple-bounce effective area
--------------------------------------------
:func:`trihedral_effective_area`: for a view ``d`` (unit, body frame, from the corner
toward the sensor) inside the open octant, the three inner faces are the back faces of the
cube ``[0, s]^3`` and cover its silhouette ``H`` (a convex hexagon, the projection of the
cube along ``d``). Unfold the three mirrors: a ray entering the corner is retro-reflected
after exactly three reflections iff its line passes through both ``[0, s]^3`` and
``[-s, 0]^3``, i.e. iff its projection lies in ``H`` and in ``-H`` (the point reflection
through the projected vertex). ``A_eff = area(H cap -H)`` exactly. Checked against
:func:`trace_specular`, a brute-force specular ray trace of the mesh.

pprender is incoherent (geometric optics on rough surfaces), so the coherent peak
``4 pi A_eff^2 / lambda^2`` is not what is compared. :func:`small_slope_estimate` gives a
rough incoherent expectation for each bounce order: each ray of the brute-force trace that
leaves after k specular reflections contributes ``4 pi dA prod(R_i) p(d)``, with ``R_i``
the unpolarized Fresnel reflectance at its incidence angles and ``p`` the density (per
steradian) of its exit direction at the retro direction when every reflection deflects
the ray by twice a Beckmann facet tilt (slopes Gaussian, variance ``alpha^2 / 2`` per
axis), linearized and propagated through the later mirrors. For a face-on plate it is
exactly ``A F / alpha^2``. It ignores masking/shadowing, edge losses and order changes
caused by the roughness: a scale check, not a reference (measured: Mitsuba / estimate
0.91-1.0 for the retro-reflected orders here).

Run time of ``--write`` with the defaults (1024 spp, 128 x 128, seeds 1 and 2, one drjit
thread): about 165 s on a 2-core machine; ``--check`` about 3 s.
"""

from __future__ import annotations

import argparse
import glob
import importlib.metadata
import json
import math
import os
import platform
import re
import sys
import tempfile
import time
import warnings
from typing import Any, NamedTuple, Sequence

import numpy as np
import trimesh

# Aluminium at 1064 nm: Rakic 1995, Appl. Opt. 34, 4755 (refractiveindex.info main/Al/Rakic);
# the value of pprender.materials.optical_constants("aluminium", 1064e-9).
ALUMINIUM_ETA_1064 = complex(1.3763, 10.2449)
ALUMINIUM_SOURCE = "Rakic 1995, Appl. Opt. 34, 4755 (pprender.materials 'aluminium' at 1064 nm)"

MITSUBA_VARIANT = "llvm_ad_mono_polarized"


# --------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------


def _unit(v: Any) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _square(corner: np.ndarray, e1: np.ndarray, e2: np.ndarray, normal: np.ndarray,
            vertices: list, faces: list) -> None:
    """Append the parallelogram ``corner + [0,1] e1 + [0,1] e2`` as two triangles whose
    counter-clockwise winding gives the face normal ``normal``."""
    base = len(vertices)
    vertices.extend([corner, corner + e1, corner + e1 + e2, corner + e2])
    tris = [[0, 1, 2], [0, 2, 3]]
    if np.dot(np.cross(e1, e2), normal) < 0:
        tris = [t[::-1] for t in tris]
    faces.extend([[base + i for i in t] for t in tris])


def dihedral(side: float = 0.3, opening_deg: float = 90.0) -> trimesh.Trimesh:
    """Two ``side x side`` square plates sharing an edge along the body ``y`` axis (the
    edge from ``(0, -side/2, 0)`` to ``(0, side/2, 0)``: the body origin is the edge
    midpoint), opening toward ``+z``, symmetric about the plane ``x = 0``: each plate at
    ``opening/2`` from the ``z`` axis. Single-sided: the front faces are the inner faces,
    normals ``(-cos(a), 0, sin(a))`` (plate at ``x > 0``) and ``(cos(a), 0, sin(a))``,
    ``a = opening/2``."""
    a = math.radians(opening_deg) / 2.0
    ey = np.array([0.0, side, 0.0])
    corner = np.array([0.0, -side / 2.0, 0.0])
    vertices: list = []
    faces: list = []
    for sgn in (1.0, -1.0):
        along = side * np.array([sgn * math.sin(a), 0.0, math.cos(a)])
        normal = np.array([-sgn * math.cos(a), 0.0, math.sin(a)])
        _square(corner, along, ey, normal, vertices, faces)
    return trimesh.Trimesh(np.array(vertices), np.array(faces), process=False)


def trihedral(side: float = 0.3) -> trimesh.Trimesh:
    """Square trihedral corner reflector: the three faces of the cube ``[0, side]^3``
    that contain the vertex at the body origin (the plates ``x = 0``, ``y = 0``, ``z = 0``),
    front faces inward (normals ``+x``, ``+y``, ``+z``). Symmetry axis:
    :func:`trihedral_axis`."""
    vertices: list = []
    faces: list = []
    o = np.zeros(3)
    e = np.eye(3) * side
    for k in range(3):
        i, j = (k + 1) % 3, (k + 2) % 3
        _square(o, e[i], e[j], np.eye(3)[k], vertices, faces)
    return trimesh.Trimesh(np.array(vertices), np.array(faces), process=False)


def trihedral_axis() -> np.ndarray:
    """The square trihedral's symmetry axis ``(1, 1, 1)/sqrt(3)`` (body frame, out of the
    corner)."""
    return np.ones(3) / math.sqrt(3.0)


def extent(mesh: trimesh.Trimesh) -> float:
    """Radius of the mesh's bounding sphere about the body origin (pprender's image
    half-width)."""
    return float(np.linalg.norm(np.asarray(mesh.vertices), axis=1).max())


def view_rotation(direction: Any, up: Any = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Rotation ``R`` (body to telescope) whose view direction ``R^T Z`` is ``direction``
    (unit, body frame, from the target toward the sensor), with ``up`` (body frame)
    projecting onto the image's ``+Y``."""
    z = _unit(direction)
    x = np.cross(np.asarray(up, dtype=np.float64), z)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("up is parallel to the view direction")
    x = _unit(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def dihedral_rotation(theta_deg: float, tilt_deg: float = 0.0) -> np.ndarray:
    """Attitude of a dihedral view: ``R = (Ry(theta) Rx(-tilt))^T``. The view direction
    (body frame) is ``d = (cos(tilt) sin(theta), sin(tilt), cos(tilt) cos(theta))``:
    azimuth ``theta`` from ``+z`` in the ``x-z`` plane (perpendicular to the edge), then
    tilted out of that plane by ``tilt`` toward ``+y`` (at ``theta = 0`` this is a rotation
    about the body ``x`` axis). The telescope ``X`` axis, ``(cos theta, 0, -sin theta)``,
    stays perpendicular to the edge, so the edge is near-vertical in the image."""
    t, p = math.radians(theta_deg), math.radians(tilt_deg)
    ry = np.array([[math.cos(t), 0, math.sin(t)], [0, 1, 0], [-math.sin(t), 0, math.cos(t)]])
    rx = np.array([[1, 0, 0], [0, math.cos(-p), -math.sin(-p)], [0, math.sin(-p), math.cos(-p)]])
    return (ry @ rx).T


def trihedral_direction(off_axis_deg: float, azimuth_deg: float = 0.0) -> np.ndarray:
    """View direction ``off_axis_deg`` from :func:`trihedral_axis`. Azimuth 0 tilts it in
    the symmetry plane through the axis and the ``z`` edge, toward ``+z`` (the plane
    ``x = y``); other azimuths rotate the tilt about the axis (toward ``+x`` for positive
    angles)."""
    a = trihedral_axis()
    b = _unit(np.array([-1.0, -1.0, 2.0]))  # in the x = y plane, toward +z
    c = np.cross(a, b)
    az = math.radians(azimuth_deg)
    t = math.radians(off_axis_deg)
    return _unit(math.cos(t) * a + math.sin(t) * (math.cos(az) * b + math.sin(az) * c))


def trihedral_rotation(off_axis_deg: float, azimuth_deg: float = 0.0) -> np.ndarray:
    """Attitude for :func:`trihedral_direction`, the ``z`` edge up in the image."""
    return view_rotation(trihedral_direction(off_axis_deg, azimuth_deg), up=(0.0, 0.0, 1.0))


# --------------------------------------------------------------------------------------
# Analytic effective area (convex polygons in the plane perpendicular to the view)
# --------------------------------------------------------------------------------------


class EffectiveArea(NamedTuple):
    area: float  # m^2, projected area of the rays reflected exactly three times (retro)
    fraction: float  # area / projected area of the whole corner


def _plane_basis(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = _unit(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = _unit(np.cross(helper, d))
    return u, np.cross(d, u)


def _convex_hull_2d(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull (Andrew's monotone chain)."""
    pts = sorted(map(tuple, np.round(points, 15)))
    if len(pts) <= 2:
        return np.array(pts)

    def cross(o: tuple, a: tuple, b: tuple) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def _clip_convex(subject: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: ``subject`` (any simple polygon) clipped by the convex,
    counter-clockwise polygon ``clip``."""
    out = [tuple(p) for p in subject]
    n = len(clip)
    for i in range(n):
        a, b = clip[i], clip[(i + 1) % n]
        inp, out = out, []
        if not inp:
            break

        def side(p: tuple) -> float:
            return (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])

        for j in range(len(inp)):
            p, q = inp[j], inp[(j + 1) % len(inp)]
            sp, sq = side(p), side(q)
            if sp >= 0:
                out.append(p)
            if (sp >= 0) != (sq >= 0):
                t = sp / (sp - sq)
                out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
    return np.array(out)


def _polygon_area(poly: np.ndarray) -> float:
    if len(poly) < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def trihedral_projected_area(side: float, direction: Any) -> float:
    """Sum of the projected areas of the square trihedral's three plates along
    ``direction``, ``side^2 (|d_x| + |d_y| + |d_z|)``: the area of its silhouette (the
    cube's) when ``direction`` lies in the open octant, where they do not overlap."""
    return float(side**2 * np.abs(_unit(direction)).sum())


def trihedral_effective_area(side: float, direction: Any) -> EffectiveArea:
    """Effective area of the triple-bounce (retro-reflected) return of a perfectly
    reflecting square trihedral (:func:`trihedral`) seen along ``direction`` (body frame,
    from the corner toward the sensor): ``area(H cap -H)``, ``H`` the projected aperture
    (silhouette of the cube ``[0, side]^3``), ``-H`` its point reflection through the
    projected vertex; 0 when a plate is seen from behind (some component of ``direction``
    not positive). Returns ``(area, fraction of the projected area)``."""
    d = _unit(direction)
    if not np.all(d > 1e-12):
        return EffectiveArea(0.0, 0.0)
    u, v = _plane_basis(d)
    cube = side * np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.float64)
    hull = _convex_hull_2d(np.stack([cube @ u, cube @ v], axis=1))
    inter = _clip_convex(hull, -hull)  # -hull: still counter-clockwise (rotation by pi)
    area = _polygon_area(inter)
    return EffectiveArea(area, area / _polygon_area(hull))


# --------------------------------------------------------------------------------------
# Brute-force specular ray trace and the small-slope estimate
# --------------------------------------------------------------------------------------


def _intersect(origins: np.ndarray, dirs: np.ndarray, tris: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """Möller-Trumbore, every ray against every triangle (both sides). Returns the nearest
    ``t > eps`` (inf on a miss) and the triangle index."""
    v0 = tris[:, 0]
    e1 = tris[:, 1] - v0
    e2 = tris[:, 2] - v0
    p = np.cross(dirs[:, None, :], e2[None])
    det = np.einsum("tk,ntk->nt", e1, p)
    ok = np.abs(det) > 1e-14
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origins[:, None, :] - v0[None]
    uu = np.einsum("ntk,ntk->nt", s, p) * inv
    q = np.cross(s, e1[None])
    vv = np.einsum("nk,ntk->nt", dirs, q) * inv
    t = np.einsum("tk,ntk->nt", e2, q) * inv
    valid = ok & (uu >= 0) & (vv >= 0) & (uu + vv <= 1) & (t > eps)
    t = np.where(valid, t, np.inf)
    idx = np.argmin(t, axis=1)
    return t[np.arange(len(t)), idx], idx


GRID_ANGLE = 0.5  # rad, rotation of the brute-force ray grid about the view direction


class Trace(NamedTuple):
    cell_area: float  # m^2 per ray
    reflections: np.ndarray  # (N,) number of reflections before escaping (max_reflections + 1: still bouncing)
    exit_dir: np.ndarray  # (N, 3) propagation direction after the last reflection
    normals: np.ndarray | None  # (N, max_reflections, 3) normals at the hits, facing the incoming ray
    incoming: np.ndarray | None  # (N, max_reflections, 3) propagation directions before each hit


def trace_specular(mesh: trimesh.Trimesh, direction: Any, n: int = 1000, max_reflections: int = 4,
                   record_path: bool = False, chunk: int = 50_000) -> Trace:
    """Brute-force geometric optics: an ``n x n`` grid of parallel rays (cell centres over
    ``[-ext, ext]^2`` in the plane perpendicular to ``direction``) propagating along
    ``-direction`` into the mesh, reflected specularly by every triangle (both sides) up to
    ``max_reflections`` times. Independent of the analytic constructions. The grid is
    turned by :data:`GRID_ANGLE` about the view so that the straight edges of the corners'
    silhouettes do not run along grid lines (aligned edges give area errors of order
    ``h`` per unit length, ``h`` the ray spacing; ~0.3 % here at ``n = 1000``, against
    ~1e-5 with the turned grid)."""
    d = _unit(direction)
    tris = np.asarray(mesh.triangles, dtype=np.float64)
    fn = np.asarray(mesh.face_normals, dtype=np.float64)
    ext = extent(mesh)
    u0, v0 = _plane_basis(d)
    ca, sa = math.cos(GRID_ANGLE), math.sin(GRID_ANGLE)
    u, v = ca * u0 + sa * v0, -sa * u0 + ca * v0
    h = 2.0 * ext / n
    c = (np.arange(n) + 0.5) * h - ext
    gu, gv = np.meshgrid(c, c, indexing="ij")
    starts = gu.reshape(-1, 1) * u + gv.reshape(-1, 1) * v + 2.0 * ext * d
    total = len(starts)
    refl = np.empty(total, dtype=np.int64)
    exit_dir = np.empty((total, 3))
    normals = np.zeros((total, max_reflections, 3)) if record_path else None
    incoming = np.zeros((total, max_reflections, 3)) if record_path else None
    eps = 1e-9 * ext
    for lo in range(0, total, chunk):
        hi = min(total, lo + chunk)
        o = starts[lo:hi].copy()
        k = np.broadcast_to(-d, o.shape).copy()
        alive = np.arange(hi - lo)
        count = np.zeros(hi - lo, dtype=np.int64)
        for b in range(max_reflections + 1):
            if len(alive) == 0:
                break
            t, idx = _intersect(o[alive], k[alive], tris, eps)
            hit = np.isfinite(t)
            gone = alive[~hit]
            exit_dir[lo + gone] = k[gone]
            count[gone] = b
            alive, t, idx = alive[hit], t[hit], idx[hit]
            if b == max_reflections:
                count[alive] = max_reflections + 1
                exit_dir[lo + alive] = k[alive]
                break
            nrm = fn[idx]
            kd = np.einsum("nk,nk->n", k[alive], nrm)
            nrm = np.where((kd < 0)[:, None], nrm, -nrm)
            kd = -np.abs(kd)
            if record_path:
                normals[lo + alive, b] = nrm  # type: ignore[index]
                incoming[lo + alive, b] = k[alive]  # type: ignore[index]
            o[alive] = o[alive] + t[:, None] * k[alive]
            k[alive] = k[alive] - 2.0 * kd[:, None] * nrm
        refl[lo:hi] = count
    return Trace(h * h, refl, exit_dir, normals, incoming)


def brute_force_effective_area(mesh: trimesh.Trimesh, direction: Any, n: int = 1000) -> float:
    """Projected area (m^2) of the rays that leave after exactly three specular
    reflections antiparallel to the incident beam (exit direction ``+direction``)."""
    d = _unit(direction)
    tr = trace_specular(mesh, d, n=n, max_reflections=4)
    retro = (tr.reflections == 3) & (tr.exit_dir @ d > 1.0 - 1e-9)
    return float(retro.sum() * tr.cell_area)


def fresnel_unpolarized(cos_i: np.ndarray, eta: complex) -> np.ndarray:
    """Unpolarized Fresnel reflectance ``(|r_s|^2 + |r_p|^2) / 2`` of a conductor."""
    ci = np.asarray(cos_i, dtype=np.float64).astype(complex)
    ct = np.sqrt(1.0 - (1.0 - ci**2) / eta**2)
    rs = (ci - eta * ct) / (ci + eta * ct)
    rp = (eta * ci - ct) / (eta * ci + ct)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def small_slope_estimate(mesh: trimesh.Trimesh, direction: Any, alpha: float, eta: complex, n: int = 300,
                         max_reflections: int = 3) -> dict[int, dict[str, float]]:
    """Incoherent small-slope geometric-optics estimate (see the module docstring) of the
    monostatic cross-section (S0, m^2) of each bounce order ``k = 1..max_reflections``,
    with the projected area of the rays that make exactly ``k`` specular reflections."""
    d = _unit(direction)
    tr = trace_specular(mesh, d, n=n, max_reflections=max_reflections, record_path=True)
    out: dict[int, dict[str, float]] = {}
    assert tr.normals is not None and tr.incoming is not None
    for k in range(1, max_reflections + 1):
        sel = np.nonzero(tr.reflections == k)[0]
        if len(sel) == 0:
            out[k] = {"area": 0.0, "sigma": 0.0}
            continue
        nrm = tr.normals[sel, :k]
        kin = tr.incoming[sel, :k]
        kout = tr.exit_dir[sel]
        cov = np.zeros((len(sel), 3, 3))
        refl = np.ones(len(sel))
        for i in range(k):
            ni, ki = nrm[:, i], kin[:, i]
            kn = np.einsum("nk,nk->n", ki, ni)
            refl *= fresnel_unpolarized(np.abs(kn), eta)
            # tangent basis at the hit
            helper = np.where((np.abs(ni[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
            t1 = np.cross(helper, ni)
            t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
            t2 = np.cross(ni, t1)
            cols = []
            for tj in (t1, t2):
                kt = np.einsum("nk,nk->n", ki, tj)
                cols.append(-2.0 * (kt[:, None] * ni + kn[:, None] * tj))
            jac = np.stack(cols, axis=2)  # (m, 3, 2): d(k_out) / d(slopes)
            for j in range(i + 1, k):  # later mirrors
                nj = nrm[:, j]
                jac = jac - 2.0 * nj[:, :, None] * np.einsum("nk,nkc->nc", nj, jac)[:, None, :]
            cov += 0.5 * alpha**2 * np.einsum("nac,nbc->nab", jac, jac)
        e1, e2 = _batch_basis(kout)
        basis = np.stack([e1, e2], axis=2)  # (m, 3, 2)
        c2 = np.einsum("nka,nkl,nlb->nab", basis, cov, basis)
        mu = np.einsum("nka,nk->na", basis, d[None] - kout)
        det = c2[:, 0, 0] * c2[:, 1, 1] - c2[:, 0, 1] * c2[:, 1, 0]
        inv = np.stack([np.stack([c2[:, 1, 1], -c2[:, 0, 1]], 1), np.stack([-c2[:, 1, 0], c2[:, 0, 0]], 1)], 1)
        inv /= det[:, None, None]
        q = np.einsum("na,nab,nb->n", mu, inv, mu)
        dens = np.exp(-0.5 * q) / (2.0 * math.pi * np.sqrt(det))
        out[k] = {"area": float(len(sel) * tr.cell_area),
                  "sigma": float(4.0 * math.pi * tr.cell_area * np.sum(refl * dens))}
    return out


def _batch_basis(k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.where((np.abs(k[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    e1 = np.cross(helper, k)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(k, e1)


# --------------------------------------------------------------------------------------
# Mitsuba
# --------------------------------------------------------------------------------------

_MI: Any = None


def _prepare_llvm() -> None:
    """drjit >= 1.5 aborts the process with LLVM 15/16: point it at LLVM >= 17 if one is
    installed (mitsuba 3.9.0 / drjit 1.4.0 work with LLVM 15). Same logic as
    ``bench.MitsubaBench._prepare_llvm``, repeated to avoid importing pprender."""
    version = importlib.metadata.version("drjit")
    major_minor = tuple(int("".join(c for c in p if c.isdigit()) or 0) for p in version.split(".")[:2])
    if major_minor < (1, 5) or os.environ.get("DRJIT_LIBLLVM_PATH"):
        return
    found = sorted(glob.glob("/usr/lib/llvm-1[7-9]/lib/libLLVM*.so*")
                   + glob.glob("/usr/lib/x86_64-linux-gnu/libLLVM*1[7-9]*.so*"))
    if not found:
        raise ImportError(f"drjit {version} needs LLVM >= 17 (set DRJIT_LIBLLVM_PATH) or pin drjit==1.4.0")
    os.environ["DRJIT_LIBLLVM_PATH"] = found[-1]


def mitsuba(threads: int | None = None) -> Any:
    """The ``mitsuba`` module with :data:`MITSUBA_VARIANT` set; ``threads`` sets drjit's
    thread pool size (``None``: leave it)."""
    global _MI
    if _MI is None:
        _prepare_llvm()
        import drjit as dr
        import mitsuba as mi

        mi.set_log_level(mi.LogLevel.Error)  # silences the 'monochrome film' warning
        _MI = (mi, dr)
    mi, dr = _MI
    mi.set_variant(MITSUBA_VARIANT)
    if threads is not None:
        dr.set_thread_count(int(threads))
    return mi


def roughconductor(alpha: float, eta: complex = ALUMINIUM_ETA_1064, distribution: str = "beckmann") -> dict[str, Any]:
    """Mitsuba ``roughconductor`` dict (Smith masking with Walter's G1, visible-normal
    sampling)."""
    return {"type": "roughconductor", "distribution": distribution, "alpha": float(alpha),
            "eta": float(eta.real), "k": float(eta.imag)}


def _lit_back_faces(mesh: trimesh.Trimesh, rotation: np.ndarray) -> int:
    d = np.asarray(rotation)[2]
    return int(np.sum(np.asarray(mesh.face_normals) @ d < -1e-9))  # edge-on faces are not lit


def mitsuba_totals(mesh: trimesh.Trimesh, bsdf: dict[str, Any], rotations: Any, max_depth: int, spp: int,
                   resolution: int, seed: int, *, return_images: bool = False, two_sided: bool = True,
                   threads: int | None = None) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Monostatic Mitsuba render of ``mesh`` (body frame) for each attitude in
    ``rotations`` ((N, 3, 3) or (3, 3), body to telescope), unpolarized illumination.

    Returns the (N, 4) Stokes cross-sections ``4 pi delta^2 sum(pixels)`` in m^2 (float64
    sums of the float32 image), and with ``return_images`` also the (N, res, res, 4)
    images of ``f cos(theta_i) E`` (``E = 1``; row 0 at ``+Y``, column 0 at ``-X``; Stokes
    basis ``(X, Y)``). ``max_depth`` is the ``path`` integrator's (2: single reflection,
    3: up to two, 4: up to three). ``bsdf`` is wrapped in ``twosided`` when ``two_sided``
    (see the module docstring for its polarization caveat on back faces). The scene is
    loaded once; each attitude rotates the mesh vertices in place (the sensor stays put)."""
    mi = mitsuba(threads)
    rots = np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3)
    ext = extent(mesh)
    b = _wrapped_bsdf(mesh, bsdf, rots, two_sided)
    scene_dict = {
        "type": "scene",
        "integrator": {"type": "stokes", "integrator": {"type": "path", "max_depth": int(max_depth)}},
        "sensor": {
            "type": "orthographic",
            "to_world": mi.ScalarTransform4f.look_at(origin=[0, 0, 4 * ext], target=[0, 0, 0], up=[0, 1, 0])
            @ mi.ScalarTransform4f.scale([ext, ext, 1.0]),
            "film": {"type": "hdrfilm", "width": int(resolution), "height": int(resolution),
                     "rfilter": {"type": "box"}},
            "sampler": {"type": "independent"},
        },
        "emitter": {"type": "directional", "direction": [0, 0, -1], "irradiance": 1.0},
    }
    totals, images = _render_attitudes(mi, scene_dict, mesh, b, rots, spp, seed, resolution, return_images)
    if images is not None:
        return totals, images
    return totals


def _wrapped_bsdf(mesh: trimesh.Trimesh, bsdf: dict[str, Any], rots: np.ndarray, two_sided: bool) -> dict[str, Any]:
    """``bsdf`` wrapped in ``twosided`` when ``two_sided``, warning for every attitude that
    lights a back face (the module docstring's polarization caveat)."""
    for r in rots:
        if two_sided and _lit_back_faces(mesh, r):
            warnings.warn("a back face is lit: Mitsuba's twosided gives it a mirrored Stokes frame "
                          "(S1..S3 after several bounces are unreliable)", stacklevel=3)
    return {"type": "twosided", "bsdf": dict(bsdf)} if two_sided else dict(bsdf)


def _render_attitudes(mi: Any, scene_dict: dict[str, Any], mesh: trimesh.Trimesh, bsdf: dict[str, Any],
                      rots: np.ndarray, spp: int, seed: int, resolution: int,
                      return_images: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """Load ``scene_dict`` with ``mesh`` (PLY, face normals, ``bsdf``) as its ``shape``, then
    render it at each attitude of ``rots`` by rotating the shape's vertices in place (the
    sensor stays put): the (N, 4) Stokes cross-sections ``4 pi delta^2 sum(pixels)`` (m^2,
    float64 sums of the float32 images) and, with ``return_images``, the (N, res, res, 4)
    images (else None)."""
    delta = 2.0 * extent(mesh) / resolution
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "mesh.ply")
        trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=False).export(path)
        scene = mi.load_dict({**scene_dict, "shape": {"type": "ply", "filename": path, "face_normals": True,
                                                       "bsdf": bsdf}})
    params = mi.traverse(scene)
    body = np.array(params["shape.vertex_positions"], dtype=np.float64).reshape(-1, 3)
    totals = np.zeros((len(rots), 4))
    images = np.zeros((len(rots), resolution, resolution, 4), dtype=np.float32) if return_images else None
    for i, r in enumerate(rots):
        params["shape.vertex_positions"] = mi.Float((body @ r.T).astype(np.float32).ravel())
        params.update()
        img = np.asarray(mi.render(scene, spp=int(spp), seed=int(seed)))
        if img.shape[-1] != 13:
            raise RuntimeError(f"unexpected film channels {img.shape}: expected Y + S0..S3 x 3")
        st = img[..., [1, 4, 7, 10]]
        totals[i] = 4.0 * math.pi * delta**2 * st.astype(np.float64).sum(axis=(0, 1))
        if images is not None:
            images[i] = st
    return totals, images


# Angle (rad) between the polarized set-up's illumination and the line of sight, taken with
# both signs (mitsuba_polarized_totals: Mitsuba's microfacet Fresnel frame is wrong at
# exact backscatter).
POLARIZED_EMITTER_TILT = 2e-3


def mitsuba_polarized_totals(mesh: trimesh.Trimesh, bsdf: dict[str, Any], rotations: Any, max_depth: int, spp: int,
                             resolution: int, seed: int, *, polarizer_deg: float | None = 0.0,
                             flip_sheet: bool = False, sheet_analyzes: bool = False,
                             emitter_tilt: float = POLARIZED_EMITTER_TILT, return_images: bool = False,
                             two_sided: bool = True,
                             threads: int | None = None) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Mitsuba render of ``mesh`` under linearly polarized illumination (the polarizer-sheet
    set-up); otherwise as :func:`mitsuba_totals`.

    Mitsuba's emitters are unpolarized, so :func:`mitsuba_totals` sees only the first column
    of the Mueller matrix. Here an ideal linear polarizer sheet (a ``rectangle`` with the
    ``polarizer`` BSDF: a null interface whose ``eval_null_transmission`` is the polarizer's
    Mueller matrix) lies across the whole beam at ``z = 3 ext``, between the orthographic
    camera's origin (``z = 4 ext``) and its near-clip plane (``near_clip = 2 ext``: the
    plane ``z = 2 ext``, above every point of the mesh). Camera rays start on the near-clip
    plane and never cross the sheet; the next-event (shadow) rays toward the
    ``directional`` emitter do, and ``volpath`` (inside ``stokes``) multiplies their
    throughput by the sheet's Mueller matrix. So the sheet polarizes the illumination only,
    and the result is ``M s_t``, ``s_t`` the sheet's output, in the receiver's ``(X, Y)``
    basis. The emitter's irradiance is 2, so that ``s_t`` has ``S0 = 1`` (the sheet passes
    half of an unpolarized beam).

    Sheet and angle: the rectangle's frame has local ``x`` along ``+X``, ``y`` along ``+Y``,
    normal ``+Z`` (``flip_sheet``: turned by 180 deg about ``X``: ``y`` along ``-Y``, normal
    ``-Z``). Mitsuba's polarizer absorbs along its local ``(sin theta, cos theta, 0)`` and
    transmits along ``forward x absorbing``, ``forward`` the propagation direction
    (``src/bsdfs/polarizer.cpp``); with ``forward = -Z`` the transmitted field is along
    ``(cos theta, -sin theta)`` in ``(X, Y)``, i.e. at ``+theta`` from ``x`` in pprender's
    transmit basis ``(x, y) = (X, -Y)``: ``s_t = (1, cos 2 theta, sin 2 theta, 0)`` there
    (``flip_sheet``: ``theta`` of the other sign). So ``polarizer_deg`` 0, 90 and 45 are
    pprender's ``polarization`` ``[1, 1, 0, 0]`` (H), ``[1, -1, 0, 0]`` (V) and
    ``[1, 0, 1, 0]`` (+45); checked on flat plates in
    ``tests/test_interreflections_co_cross.py``.

    Exact backscatter goes wrong in Mitsuba's polarized ``roughconductor`` (3.9.0,
    ``src/bsdfs/roughconductor.cpp``): the s-axis of its Fresnel matrix is
    ``cross(H, -wo)``; where ``wi`` and ``wo`` are equal in float32 (many samples of an
    exactly monostatic render) it is exactly zero and the code falls back to the local
    ``x`` axis, which is perpendicular to ``H`` only when ``H`` is the surface normal.
    Measured with ``bsdf.eval`` on alpha 0.3 at 30 deg incidence: an H input returns as
    ``(1, -0.5, -0.866, 0)`` with ``wi == wo`` and as ``(1, 1, 0, 0)`` with ``wo`` 1e-7
    away; a plate turned 30 deg about ``Y`` rendered exactly monostatic returns
    ``S1/S0 = 0.25, S2/S0 = -0.43`` (a mixture). The first column (unpolarized light, hence
    :func:`mitsuba_totals`) is unaffected. So the emitter propagates along
    ``(+-sin t, 0, -cos t)``, ``t = emitter_tilt``, and the two renders (same seed) are
    averaged: the tilt's first-order effect on the lobes (1.7 % at t = 2e-3 on that
    plate) cancels, leaving ``O(t^2)`` (measured without the sheet, same seeds: the
    dihedral's S0 up to two bounces moves by under 1e-4 relative, alpha 0.1 and 0.3,
    against ``path``; with ``emitter_tilt = 0`` and no sheet ``volpath`` gives ``path``'s
    numbers exactly). Paths of two or more reflections are not monostatic at any vertex.
    ``emitter_tilt = 0`` renders once, exactly monostatic.

    Parameters
    ----------
    mesh, bsdf, rotations, max_depth, spp, resolution, seed, return_images, two_sided, threads
        As :func:`mitsuba_totals` (``max_depth`` is ``volpath``'s, with the meaning of
        ``path``'s: the sheet is a null interaction and does not count).
    polarizer_deg : float or None, optional
        The polarizer's ``theta`` (deg). None: no sheet (unpolarized illumination of
        irradiance 1, through ``volpath``). Default 0 (H).
    flip_sheet : bool, optional
        Turn the sheet by 180 deg about ``X`` (see above). Default False.
    sheet_analyzes : bool, optional
        A check of the set-up: ``near_clip`` 0.01 instead, so that the camera rays cross
        the sheet too (handled by the polarizer's ``sample``, a null event that ``max_depth``
        does not count) and it also analyzes the received light: S0 is then the intensity
        co-polarized with the transmitted state (the linear polarizer's Mueller matrix
        carries a factor 1/2), e.g. ``(S0 + S1)/2`` of the default set-up for ``theta`` 0,
        with S1 = S0. Default False.
    emitter_tilt : float, optional
        Half the angle (rad) between the two illuminations averaged, >= 0. Default
        :data:`POLARIZED_EMITTER_TILT`.

    Returns
    -------
    numpy.ndarray or tuple of numpy.ndarray
        (N, 4) Stokes cross-sections (m^2 per unit transmitted ``S0``), and with
        ``return_images`` also the (N, res, res, 4) images.
    """
    mi = mitsuba(threads)
    rots = np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3)
    ext = extent(mesh)
    b = _wrapped_bsdf(mesh, bsdf, rots, two_sided)
    if emitter_tilt < 0:
        raise ValueError(f"emitter_tilt must be >= 0, got {emitter_tilt}")
    T = mi.ScalarTransform4f
    tilts = [emitter_tilt, -emitter_tilt] if emitter_tilt > 0 else [0.0]
    totals = np.zeros((len(rots), 4))
    images = np.zeros((len(rots), resolution, resolution, 4), dtype=np.float32) if return_images else None
    for tilt in tilts:
        scene_dict: dict[str, Any] = {
            "type": "scene",
            "integrator": {"type": "stokes", "integrator": {"type": "volpath", "max_depth": int(max_depth)}},
            "sensor": {
                "type": "orthographic",
                "near_clip": 0.01 if sheet_analyzes else 2.0 * ext,
                "to_world": T.look_at(origin=[0, 0, 4 * ext], target=[0, 0, 0], up=[0, 1, 0])
                @ T.scale([ext, ext, 1.0]),
                "film": {"type": "hdrfilm", "width": int(resolution), "height": int(resolution),
                         "rfilter": {"type": "box"}},
                "sampler": {"type": "independent"},
            },
            "emitter": {"type": "directional", "direction": [math.sin(tilt), 0.0, -math.cos(tilt)],
                        "irradiance": 1.0 if polarizer_deg is None else 2.0},
        }
        if polarizer_deg is not None:
            to_world = T.translate([0, 0, 3 * ext]) @ T.scale([2 * ext, 2 * ext, 1.0])
            if flip_sheet:
                to_world = to_world @ T.rotate([1, 0, 0], 180.0)
            scene_dict["sheet"] = {"type": "rectangle", "to_world": to_world,
                                   "bsdf": {"type": "polarizer", "theta": float(polarizer_deg)}}
        t, im = _render_attitudes(mi, scene_dict, mesh, b, rots, spp, seed, resolution, return_images)
        totals += t / len(tilts)
        if images is not None and im is not None:
            images += im / len(tilts)
    if images is not None:
        return totals, images
    return totals


def mitsuba_reference(mesh: trimesh.Trimesh, bsdf: dict[str, Any], rotations: Any, depths: Sequence[int],
                      spp: int, resolution: int, seeds: Sequence[int] = (1, 2), threads: int | None = None) -> dict:
    """Totals for every depth in ``depths`` and attitude, averaged over ``seeds``, with
    noise estimates (standard deviation of the seed average) and the parts added by each
    depth step (``T(depth) - T(previous depth)``, same seed, with their own noise).

    Returns ``{"totals": (D, N, 4), "noise": (D, N, 4), "totals_per_seed": (S, D, N, 4),
    "steps": (D-1, N, 4), "steps_noise": (D-1, N, 4)}``; noise from per-pixel seed
    differences (two or more seeds)."""
    rots = np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3)
    delta = 2.0 * extent(mesh) / resolution
    scale = 4.0 * math.pi * delta**2
    tot = np.zeros((len(seeds), len(depths), len(rots), 4))
    imgs = np.zeros((len(seeds), len(depths), len(rots), resolution, resolution, 4))
    for s, seed in enumerate(seeds):
        for j, depth in enumerate(depths):
            t, im = mitsuba_totals(mesh, bsdf, rots, depth, spp, resolution, seed, return_images=True,
                                   threads=threads)
            tot[s, j], imgs[s, j] = t, im

    def noise_of_mean(x: np.ndarray) -> np.ndarray:  # x: (S, ..., res, res, 4)
        var_pix = np.var(x, axis=0, ddof=1)  # per-pixel variance of one render
        return scale * np.sqrt(var_pix.sum(axis=(-3, -2)) / len(seeds))

    steps_img = np.diff(imgs, axis=1)
    return {"totals": tot.mean(axis=0), "noise": noise_of_mean(imgs), "totals_per_seed": tot,
            "steps": np.diff(tot, axis=1).mean(axis=0), "steps_noise": noise_of_mean(steps_img)}


# --------------------------------------------------------------------------------------
# References (CLI --write)
# --------------------------------------------------------------------------------------

SIDE = 0.3
DIHEDRAL_ALPHAS = (0.1, 0.3)
DIHEDRAL_VIEWS = [(float(t), 0.0) for t in range(0, 50, 5)] + [(20.0, 10.0), (20.0, 20.0)]
TRIHEDRAL_ALPHA = 0.05
TRIHEDRAL_OFF_AXIS = (0.0, 10.0, 20.0)
DEPTHS = (2, 3, 4)


def _bsdf_record(bsdf: dict[str, Any]) -> dict[str, Any]:
    return {**bsdf, "wrapper": "twosided"}


def _dumps(data: dict) -> str:
    """JSON with every list of numbers on one line."""
    text = json.dumps(data, indent=1)
    number_list = re.compile(r"\[\s*(-?[\d.eE+-]+(?:,\s*-?[\d.eE+-]+)*)\s*\]")
    text = number_list.sub(lambda m: "[" + ", ".join(x.strip() for x in m.group(1).split(",")) + "]", text)
    # rotation matrices: a list of one-line lists
    return re.sub(r"\[\s*(\[[^\[\]]*\](?:,\s*\[[^\[\]]*\])*)\s*\]",
                  lambda m: "[" + re.sub(r"\],\s*\[", "], [", m.group(1)) + "]", text)


def _round(x: Any, digits: int = 7) -> Any:
    return np.round(np.asarray(x, dtype=np.float64), digits).tolist()


def _sig(x: Any, digits: int = 6) -> Any:
    """Round to significant digits (JSON-friendly lists)."""
    a = np.asarray(x, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        mag = np.where(a != 0, 10.0 ** (digits - 1 - np.floor(np.log10(np.abs(a)))), 1.0)
    return (np.round(a * mag) / mag).tolist()


def compute_references(spp: int = 1024, resolution: int = 128, seeds: Sequence[int] = (1, 2),
                       threads: int | None = 1, trihedral_spp: int | None = None, log: Any = print) -> dict:
    """All references: the dihedral (two roughnesses, 12 views) and the trihedral (three
    views), ``max_depth`` 2, 3, 4, two seeds each."""
    t_start = time.perf_counter()
    mi = mitsuba(threads)
    import drjit as dr

    entries: list[dict] = []
    summary: list[dict] = []
    # ---- dihedral
    mesh = dihedral(SIDE, 90.0)
    meshes: dict[str, dict] = {}
    meshes["dihedral"] = {"function": "dihedral(side, opening_deg)", "side": SIDE, "opening_deg": 90.0,
                          "extent": extent(mesh), "body_origin": "edge midpoint (edge along body y)",
                          "faces": "single-sided square plates, front (CCW) faces inward",
                          "views": "d = (cos(tilt) sin(theta), sin(tilt), cos(tilt) cos(theta)), "
                                   "R = dihedral_rotation(theta, tilt)"}
    mesh_rec = "dihedral"
    rots = np.stack([dihedral_rotation(t, p) for t, p in DIHEDRAL_VIEWS])
    for alpha in DIHEDRAL_ALPHAS:
        bsdf = roughconductor(alpha)
        t0 = time.perf_counter()
        ref = mitsuba_reference(mesh, bsdf, rots, DEPTHS, spp, resolution, seeds, threads)
        log(f"dihedral alpha {alpha}: {time.perf_counter() - t0:.1f} s")
        for v, (theta, tilt) in enumerate(DIHEDRAL_VIEWS):
            view = {"theta_deg": theta, "tilt_deg": tilt, "direction_body": _round(rots[v][2], 9)}
            for j, depth in enumerate(DEPTHS):
                entries.append({"mesh": mesh_rec, "bsdf": _bsdf_record(bsdf), "view": view,
                                "rotation": _round(rots[v], 9), "max_depth": depth, "spp": spp,
                                "resolution": resolution, "seeds": list(seeds),
                                "totals": _sig(ref["totals"][j, v]), "noise": _sig(ref["noise"][j, v], 3),
                                "totals_per_seed": _sig(ref["totals_per_seed"][:, j, v])})
            go = small_slope_estimate(mesh, rots[v][2], alpha, ALUMINIUM_ETA_1064)
            summary.append({
                "mesh": "dihedral", "alpha": alpha, **view,
                "S0_by_depth": _sig(ref["totals"][:, v, 0]), "S0_noise_by_depth": _sig(ref["noise"][:, v, 0], 3),
                "single_S0": _sig(ref["totals"][0, v, 0]),
                "double_S0": _sig(ref["steps"][0, v, 0]), "double_S0_noise": _sig(ref["steps_noise"][0, v, 0], 3),
                "triple_S0": _sig(ref["steps"][1, v, 0]), "triple_S0_noise": _sig(ref["steps_noise"][1, v, 0], 3),
                "double_stokes": _sig(ref["steps"][0, v]),
                "geometric_area_by_reflections": {str(k): _sig(go[k]["area"]) for k in go},
                "small_slope_sigma_by_reflections": {str(k): _sig(go[k]["sigma"], 4) for k in go},
            })
    # ---- trihedral
    mesh = trihedral(SIDE)
    meshes["trihedral"] = {"function": "trihedral(side)", "side": SIDE, "extent": extent(mesh),
                           "body_origin": "vertex", "axis": _round(trihedral_axis(), 9),
                           "faces": "single-sided square plates, front (CCW) faces inward",
                           "views": "off_axis_deg from the axis in the plane x = y, toward +z: "
                                    "R = trihedral_rotation(off_axis_deg) (z edge up in the image)"}
    mesh_rec = "trihedral"
    rots = np.stack([trihedral_rotation(a) for a in TRIHEDRAL_OFF_AXIS])
    bsdf = roughconductor(TRIHEDRAL_ALPHA)
    tspp = trihedral_spp or spp
    t0 = time.perf_counter()
    ref = mitsuba_reference(mesh, bsdf, rots, DEPTHS, tspp, resolution, seeds, threads)
    log(f"trihedral alpha {TRIHEDRAL_ALPHA}: {time.perf_counter() - t0:.1f} s")
    for v, off in enumerate(TRIHEDRAL_OFF_AXIS):
        d = rots[v][2]
        view = {"off_axis_deg": off, "direction_body": _round(d, 9)}
        for j, depth in enumerate(DEPTHS):
            entries.append({"mesh": mesh_rec, "bsdf": _bsdf_record(bsdf), "view": view,
                            "rotation": _round(rots[v], 9), "max_depth": depth, "spp": tspp,
                            "resolution": resolution, "seeds": list(seeds),
                            "totals": _sig(ref["totals"][j, v]), "noise": _sig(ref["noise"][j, v], 3),
                            "totals_per_seed": _sig(ref["totals_per_seed"][:, j, v])})
        ea = trihedral_effective_area(SIDE, d)
        go = small_slope_estimate(mesh, d, TRIHEDRAL_ALPHA, ALUMINIUM_ETA_1064)
        triple = float(ref["steps"][1, v, 0])
        summary.append({
            "mesh": "trihedral", "alpha": TRIHEDRAL_ALPHA, **view,
            "S0_by_depth": _sig(ref["totals"][:, v, 0]), "S0_noise_by_depth": _sig(ref["noise"][:, v, 0], 3),
            "single_S0": _sig(ref["totals"][0, v, 0]),
            "double_S0": _sig(ref["steps"][0, v, 0]), "double_S0_noise": _sig(ref["steps_noise"][0, v, 0], 3),
            "triple_S0": _sig(triple), "triple_S0_noise": _sig(ref["steps_noise"][1, v, 0], 3),
            "triple_stokes": _sig(ref["steps"][1, v]),
            "A_eff": _sig(ea.area), "A_eff_fraction": _sig(ea.fraction),
            "projected_area": _sig(trihedral_projected_area(SIDE, d)),
            "four_pi_A_eff": _sig(4 * math.pi * ea.area),
            "triple_over_four_pi_A_eff": _sig(triple / (4 * math.pi * ea.area)),
            "small_slope_triple_sigma": _sig(go[3]["sigma"], 4),
            "triple_over_small_slope": _sig(triple / go[3]["sigma"], 4) if go[3]["sigma"] > 0 else None,
            "geometric_area_by_reflections": {str(k): _sig(go[k]["area"]) for k in go},
            "small_slope_sigma_by_reflections": {str(k): _sig(go[k]["sigma"], 4) for k in go},
        })
    elapsed = time.perf_counter() - t_start
    return {
        "description": "Mitsuba 3 monostatic references for corner inter-reflections "
                       "(benchmarks/mitsuba_corners.py; conventions in its module docstring)",
        "conventions": {
            "cross_section": "4 pi delta^2 sum(pixel Stokes), m^2, delta = 2 extent / resolution",
            "rotation": "body to telescope, p_tel = R p_body; view direction (body) = R[2]",
            "stokes_basis": "received beam (X, Y) of the telescope frame, S1 = I_X - I_Y",
            "illumination": "unpolarized, directional emitter along -Z with irradiance 1",
            "max_depth": "path integrator: 2 = one reflection, 3 = up to two, 4 = up to three",
            "noise": "standard deviation of the seed-averaged total, from per-pixel seed differences",
            "steps": "double = T(depth 3) - T(depth 2), triple = T(4) - T(3), same seeds "
                     "(shared random numbers: each step carries only its own noise)",
            "small_slope": "incoherent GO estimate (module docstring), a scale check only",
        },
        "eta": {"value": [ALUMINIUM_ETA_1064.real, ALUMINIUM_ETA_1064.imag], "source": ALUMINIUM_SOURCE,
                "wavelength_m": 1064e-9},
        "meshes": meshes,
        "mitsuba": {"version": getattr(mi, "__version__", "?"), "drjit": getattr(dr, "__version__", "?"),
                    "variant": MITSUBA_VARIANT, "threads": int(dr.thread_count()),
                    "integrator": "stokes(path)", "sampler": "independent", "rfilter": "box"},
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
        "elapsed_s": round(elapsed, 1),
        "summary": summary,
        "entries": entries,
    }


# --------------------------------------------------------------------------------------
# Self-check (CLI --check)
# --------------------------------------------------------------------------------------


def self_check(with_mitsuba: bool = True, n: int = 1000, threads: int | None = 1, log: Any = print) -> None:
    """Asserts that the analytic trihedral effective area equals the brute-force ray
    trace within 0.5 % at 0, 10, 20 deg off axis (plus one off-plane azimuth), and, with
    ``with_mitsuba``, Mitsuba's ``max_depth`` semantics and scale on a face-on plate."""
    mesh = trihedral(SIDE)
    log(f"trihedral side {SIDE} m, brute force {n}x{n} rays")
    log(f"{'off-axis':>9} {'azimuth':>8} {'A_eff analytic':>15} {'brute force':>12} {'rel diff':>9} {'fraction':>9}")
    for off, az in [(0.0, 0.0), (10.0, 0.0), (20.0, 0.0), (20.0, 30.0)]:
        d = trihedral_direction(off, az)
        ea = trihedral_effective_area(SIDE, d)
        bf = brute_force_effective_area(mesh, d, n=n)
        rel = (bf - ea.area) / ea.area
        log(f"{off:9.1f} {az:8.1f} {ea.area:15.6f} {bf:12.6f} {rel:9.2e} {ea.fraction:9.4f}")
        assert abs(rel) < 5e-3, (off, az, ea.area, bf)
        proj = trihedral_projected_area(SIDE, d)
        assert abs(ea.area / ea.fraction - proj) < 1e-9 * proj
    assert abs(trihedral_effective_area(SIDE, trihedral_axis()).fraction - 1.0) < 1e-9  # hexagon, 100 %
    log("analytic effective area == brute force within 0.5 %: ok")
    if not with_mitsuba:
        return
    # Mitsuba max_depth semantics on a flat square plate seen face-on: depth 1 renders
    # nothing (a directional emitter is never hit), depths 2 and 3 agree (no
    # inter-reflection possible), depth 2 = A F(0) / alpha^2 (Walter's G1 = 1 at normal).
    alpha = 0.3
    plate = trimesh.Trimesh(np.array([[-0.1, -0.1, 0], [0.1, -0.1, 0], [0.1, 0.1, 0], [-0.1, 0.1, 0]]),
                            np.array([[0, 1, 2], [0, 2, 3]]), process=False)
    bsdf = roughconductor(alpha)
    t = {depth: mitsuba_totals(plate, bsdf, np.eye(3), depth, 256, 32, 1, threads=threads)[0] for depth in (1, 2, 3)}
    f0 = float(fresnel_unpolarized(np.array(1.0), ALUMINIUM_ETA_1064))
    expect = 0.04 * f0 / alpha**2
    log(f"flat plate face-on, alpha {alpha}: depth 1 {t[1][0]:.3g}, depth 2 {t[2][0]:.5f}, depth 3 {t[3][0]:.5f}, "
        f"analytic A F(0)/alpha^2 {expect:.5f}")
    assert t[1][0] == 0.0
    assert np.allclose(t[2], t[3], rtol=1e-6, atol=1e-9)
    assert abs(t[2][0] - expect) < 5e-3 * expect
    # the same plate through the small-slope estimate (exact for a face-on plate)
    est = small_slope_estimate(plate, [0, 0, 1], alpha, ALUMINIUM_ETA_1064, n=200, max_reflections=1)[1]
    assert abs(est["sigma"] / est["area"] - f0 / alpha**2) < 1e-9 * f0 / alpha**2, (est, expect)
    log("Mitsuba max_depth semantics and absolute scale: ok")


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="run self_check()")
    ap.add_argument("--no-mitsuba-check", action="store_true", help="--check without the Mitsuba part")
    ap.add_argument("--write", metavar="PATH", help="compute the references and write them as JSON")
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--trihedral-spp", type=int, default=None, help="default: --spp")
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--threads", type=int, default=1, help="drjit threads (default 1)")
    args = ap.parse_args(argv)
    if not (args.check or args.write):
        ap.error("nothing to do: give --check and/or --write PATH")
    if args.check:
        t0 = time.perf_counter()
        self_check(with_mitsuba=not args.no_mitsuba_check, threads=args.threads)
        print(f"self-check: {time.perf_counter() - t0:.1f} s")
    if args.write:
        t0 = time.perf_counter()
        data = compute_references(args.spp, args.resolution, args.seeds, args.threads, args.trihedral_spp)
        os.makedirs(os.path.dirname(os.path.abspath(args.write)), exist_ok=True)
        with open(args.write, "w") as f:
            f.write(_dumps(data) + "\n")
        print(f"wrote {args.write} ({len(data['entries'])} entries) in {time.perf_counter() - t0:.1f} s")
        for s in data["summary"]:
            lab = (f"theta {s['theta_deg']:4.0f} tilt {s['tilt_deg']:3.0f}" if s["mesh"] == "dihedral"
                   else f"off-axis {s['off_axis_deg']:4.0f}      ")
            print(f"{s['mesh']:9} a={s['alpha']:<4} {lab}  S0(d2,d3,d4) = "
                  + ", ".join(f"{x:.4g}" for x in s["S0_by_depth"])
                  + f"  noise(d4) {s['S0_noise_by_depth'][-1]:.2g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
