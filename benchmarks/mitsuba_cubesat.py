"""Mitsuba 3 references for inter-reflections on the demo 3U CubeSat.

``python benchmarks/mitsuba_cubesat.py --check`` runs :func:`self_check`: every stand-in
material of :func:`matched_materials` on a flat plate, single bounce, pprender against
Mitsuba at two angles, then the whole CubeSat at single bounce (pprender against Mitsuba
``max_depth`` 2, which also checks the attitude convention and the part assignment), and
whether Mitsuba's ``twosided`` wrappers change anything on the closed mesh.
``python benchmarks/mitsuba_cubesat.py --write docs/data/mitsuba-cubesat.json`` renders 50
random attitudes at ``max_depth`` 2, 3, 4 and 8 (:func:`compute_references`) and writes the
totals as JSON (no images).

Scene
-----
``pprender.models.cubesat("3U")`` with its defaults (bus, two deployed wings, whip antenna;
11,840 triangles; body origin at the bus centre, bounding radius 0.37025 m). Its parts,
``mesh.metadata["pprender_parts"]`` = ``bus, solar_cells, panel_back, antenna``, get the
stand-in materials of :func:`matched_materials`, which both renderers model identically
(single-bounce BRDF equal to float32 rounding, :func:`self_check`):

==============  ===========================================  =====================================
part            pprender                                     Mitsuba (each in ``twosided``)
==============  ===========================================  =====================================
bus             Beckmann alpha 0.15, eta 1.3763+10.2449j,    ``roughconductor`` beckmann 0.15,
                Smith (Walter G1), uncorrelated, "single"    eta 1.3763, k 10.2449
solar_cells     Beckmann alpha 0.05, eta 1.45 (real), same   ``roughconductor`` beckmann 0.05,
                masking, "single"                            eta 1.45, k 0
panel_back      terms ("diffuse",), diffuse_albedo 0.8,      ``diffuse``, reflectance 0.8
                eta 1 (F = 0, so the specular layer's
                albedo E_s = 0 and f = rho / pi exactly)
antenna         as the bus with alpha 0.3                    ``roughconductor`` beckmann 0.3
==============  ===========================================  =====================================

* The cells' cover glass is a surface reflection only (no transmission, no cell under it):
  a ``roughconductor`` with a real index (k = 0) has the dielectric Fresnel reflectance,
  with the same polarization (real ``r_s``, ``r_p``); pprender takes the real index as its
  ``eta``.
* The white paint is an ideal Lambertian, depolarizing: pprender's diffuse term is
  ``rho_d (1 - E_s(wi)) (1 - E_s(wo)) / (pi (1 - E_s,avg))``; with ``eta = 1`` the Fresnel
  reflectance, hence ``E_s``, is 0 and the term is ``rho_d / pi`` (the roughness and
  masking keywords then do not enter; they are set because the diffuse term needs an
  energy-conserving masking).
* The whole mesh is closed and wound outward per part: the bus and the antenna are closed
  boxes/cylinders, each wing is a closed 2 mm slab whose +y face is ``solar_cells`` and
  whose other faces (back and edges) are ``panel_back``. So a ray from outside only meets
  front faces; the ``twosided`` wrapper (used as in ``mitsuba_corners``) then changes
  nothing, and its polarization pitfall (mirrored Stokes frame on back faces) does not
  arise: :func:`self_check` renders one attitude with and without it (same seed, depth 4)
  and finds them equal. Contact faces (the wing's hinge edge lies on the bus's +x/-x face,
  the antenna's top cap on the bus's -z face) are coplanar but enclosed: not seen.
* Flat shading (``face_normals=True`` in Mitsuba, ``smooth=False`` in pprender): the
  antenna is a 16-sided prism in both.

Conventions (as ``benchmarks/mitsuba_corners.py``, whose scene and functions are reused)
---------------------------------------------------------------------------------------
Units m and m^2. Attitude: a quaternion ``(w, x, y, z)`` (pprender's order) or rotation
``R`` maps body to telescope coordinates, ``p_tel = R p_body`` (:func:`quaternion_to_rotation`,
checked against pprender's own conversion); the sensor and transmitter are at telescope
``+Z`` (monostatic), view direction in the body frame ``R[2]``. Mitsuba: orthographic sensor
over ``[-ext, ext]^2`` with ``ext`` the bounding radius (pprender's image half-width),
``resolution`` pixels across, box filter; a ``directional`` emitter along ``-Z`` of
irradiance 1; ``stokes(path)``, ``llvm_ad_mono_polarized``, ``independent`` sampler; one
PLY per part (the mesh rotated by ``R``: vertex positions updated per attitude). Cross-
section ``4 pi delta^2 sum(pixels)``, ``delta = 2 ext / resolution``, per Stokes component
for unpolarized illumination (the first column of the Mueller cross-section), basis
``(X, Y)`` of the telescope, ``S1 = I_X - I_Y``.

``max_depth``: 2 = single reflection, 3 = up to two, 4 = up to three, 8 = up to seven
(Russian roulette from depth 5, Mitsuba's default ``rr_depth``: unbiased). Renders of one
seed at different depths share the random numbers of the common path prefix, so
``T(d') - T(d)`` (same seed) carries only its own noise. Noise: the standard deviation of
the seed-averaged total, ``4 pi delta^2 sqrt(sum_pix var_pix / S)`` with the per-pixel
variance of the ``S`` seeds' images (``mitsuba_corners.mitsuba_reference``), for each
total and for each step between depths.

Pitfalls met
------------
* pprender's ``bounces`` counts reflections (1..3) while Mitsuba's ``max_depth`` counts
  path segments: pprender ``bounces=k`` corresponds to ``max_depth = k + 1``.
* pprender's surfaces along an inter-reflection path are evaluated without the double
  bounce term: with ``terms=("single",)`` (as here) nothing is left out.
* The 50 attitudes are drawn ``q = default_rng(2024).normal(size=(50, 4))``, each row
  divided by its Euclidean norm, with no sign canonicalization (``q`` and ``-q`` are the
  same rotation): :func:`attitudes`.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import math
import os
import platform
import sys
import tempfile
import time
from typing import Any, Sequence

import numpy as np
import trimesh

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mitsuba_corners as mc  # noqa: E402

PARTS = ("bus", "solar_cells", "panel_back", "antenna")
ALUMINIUM_ETA = mc.ALUMINIUM_ETA_1064  # 1.3763 + 10.2449j (Rakic 1995)
GLASS_ETA = 1.45
PAINT_ALBEDO = 0.8
ATTITUDE_SEED = 2024
N_ATTITUDES = 50
DEPTHS = (2, 3, 4, 8)


# --------------------------------------------------------------------------------------
# Materials and scene
# --------------------------------------------------------------------------------------


def _pp_microfacet(alpha: float, eta: complex) -> Any:
    import pprender

    return pprender.Material("beckmann", alpha=alpha, eta=complex(eta), shadowing="smith", correlation="none",
                             smith_g1="walter", terms=("single",))


def _pp_lambertian(albedo: float) -> Any:
    import pprender

    # eta = 1: F = 0, so the specular layer has zero albedo and the diffuse term is rho / pi
    return pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0.0j, shadowing="smith", correlation="none",
                             smith_g1="walter", terms=("diffuse",), diffuse_albedo=float(albedo))


def matched_materials() -> dict[str, tuple[Any, dict[str, Any], str]]:
    """Part -> (pprender.Material, Mitsuba BSDF dict (unwrapped), the pprender call as text)."""
    a = ALUMINIUM_ETA
    out = {
        "bus": (_pp_microfacet(0.15, a), mc.roughconductor(0.15, a),
                f"pprender.Material('beckmann', alpha=0.15, eta={a!r}, shadowing='smith', correlation='none', "
                "smith_g1='walter', terms=('single',))"),
        "solar_cells": (_pp_microfacet(0.05, complex(GLASS_ETA, 0.0)), mc.roughconductor(0.05, complex(GLASS_ETA, 0.0)),
                        f"pprender.Material('beckmann', alpha=0.05, eta={complex(GLASS_ETA, 0.0)!r}, shadowing='smith', "
                        "correlation='none', smith_g1='walter', terms=('single',))"),
        "panel_back": (_pp_lambertian(PAINT_ALBEDO), {"type": "diffuse", "reflectance": PAINT_ALBEDO},
                       f"pprender.Material('beckmann', alpha=0.3, eta=(1+0j), shadowing='smith', correlation='none', "
                       f"smith_g1='walter', terms=('diffuse',), diffuse_albedo={PAINT_ALBEDO})"),
        "antenna": (_pp_microfacet(0.3, a), mc.roughconductor(0.3, a),
                    f"pprender.Material('beckmann', alpha=0.3, eta={a!r}, shadowing='smith', correlation='none', "
                    "smith_g1='walter', terms=('single',))"),
    }
    return out


def cubesat_mesh() -> trimesh.Trimesh:
    from pprender import models

    return models.cubesat("3U")


def matched_scene() -> tuple[Any, dict[str, dict[str, Any]]]:
    """(pprender.Scene of the 3U CubeSat with the matched materials, part -> Mitsuba BSDF
    dict). The Mitsuba dicts are unwrapped; :func:`mitsuba_cubesat_totals` wraps each in
    ``twosided``."""
    import pprender

    mesh = cubesat_mesh()
    mats = matched_materials()
    parts = list(mesh.metadata["pprender_parts"])
    assert tuple(parts) == PARTS, parts
    scene = pprender.Scene(mesh, {p: mats[p][0] for p in parts})
    return scene, {p: dict(mats[p][1]) for p in parts}


def part_meshes(scene: Any) -> dict[str, trimesh.Trimesh]:
    """One mesh per part (body frame), from the pprender Scene's flattened faces and
    ``face_part`` (the assignment the renderer uses)."""
    out = {}
    for i, p in enumerate(scene.parts):
        faces = np.asarray(scene.faces)[np.asarray(scene.face_part) == i]
        used = np.unique(faces)
        remap = np.full(len(scene.vertices), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        out[p] = trimesh.Trimesh(np.asarray(scene.vertices)[used], remap[faces], process=False)
    return out


# --------------------------------------------------------------------------------------
# Attitudes
# --------------------------------------------------------------------------------------


def attitudes(n: int = N_ATTITUDES, seed: int = ATTITUDE_SEED) -> np.ndarray:
    """``q = numpy.random.default_rng(seed).normal(size=(n, 4))``, each row divided by its
    Euclidean norm; ``(w, x, y, z)``, no sign canonicalization (bench_render's
    ``random_quaternions`` with another seed)."""
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def quaternion_to_rotation(q: Any) -> np.ndarray:
    """(N, 3, 3) body-to-telescope rotations of unit quaternions ``(w, x, y, z)`` (the
    standard Hamilton formula; :func:`self_check` compares it with pprender's)."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], 1)


# --------------------------------------------------------------------------------------
# Mitsuba
# --------------------------------------------------------------------------------------


class CubesatRenderer:
    """Mitsuba scenes of the CubeSat (one per ``max_depth``, loaded once), re-posed per
    attitude by updating each part's vertex positions."""

    def __init__(self, depths: Sequence[int], resolution: int, threads: int | None = 1, two_sided: bool = True,
                 scene: Any = None, bsdfs: dict[str, dict[str, Any]] | None = None) -> None:
        mi = mc.mitsuba(threads)
        self.mi = mi
        if scene is None or bsdfs is None:
            scene, bsdfs = matched_scene()
        self.parts = list(scene.parts)
        self.ext = float(scene.radius)
        self.resolution = int(resolution)
        self.delta = 2.0 * self.ext / self.resolution
        self.scale = 4.0 * math.pi * self.delta**2
        meshes = part_meshes(scene)
        self.body: dict[int, dict[str, np.ndarray]] = {}
        self.scenes = {}
        with tempfile.TemporaryDirectory() as tmp:
            shapes = {}
            for p in self.parts:
                path = os.path.join(tmp, f"{p}.ply")
                meshes[p].export(path)
                b = {"type": "twosided", "bsdf": dict(bsdfs[p])} if two_sided else dict(bsdfs[p])
                shapes[f"part_{p}"] = {"type": "ply", "filename": path, "face_normals": True, "bsdf": b}
            for d in depths:
                self.scenes[int(d)] = mi.load_dict({
                    "type": "scene",
                    "integrator": {"type": "stokes", "integrator": {"type": "path", "max_depth": int(d)}},
                    "sensor": {
                        "type": "orthographic",
                        "to_world": mi.ScalarTransform4f.look_at(origin=[0, 0, 4 * self.ext], target=[0, 0, 0],
                                                                 up=[0, 1, 0])
                        @ mi.ScalarTransform4f.scale([self.ext, self.ext, 1.0]),
                        "film": {"type": "hdrfilm", "width": self.resolution, "height": self.resolution,
                                 "rfilter": {"type": "box"}},
                        "sampler": {"type": "independent"},
                    },
                    "emitter": {"type": "directional", "direction": [0, 0, -1], "irradiance": 1.0},
                    **shapes,
                })
        # Mitsuba (3.9) merges meshes whose BSDFs are equivalent into one shape with an
        # anonymous id (not the case for the matched materials, which all differ): rotate
        # every vertex buffer of the scene, whatever it is called.
        self.params = {d: mi.traverse(s) for d, s in self.scenes.items()}
        for d, prm in self.params.items():
            keys = [k for k in prm.keys() if k.endswith(".vertex_positions")]
            self.body[d] = {k: np.array(prm[k], dtype=np.float64).reshape(-1, 3) for k in keys}
        n_vert = {d: sum(len(v) for v in b.values()) for d, b in self.body.items()}
        expect = sum(len(m.vertices) for m in meshes.values())
        if any(v != expect for v in n_vert.values()):
            raise RuntimeError(f"Mitsuba scene vertex count {n_vert} differs from the parts' {expect}")
        self._pose: dict[int, int] = {}

    def pose(self, rotation: np.ndarray, depth: int, key: int) -> None:
        if self._pose.get(depth) == key:
            return
        prm = self.params[depth]
        r = np.asarray(rotation, dtype=np.float64)
        for k, body in self.body[depth].items():
            prm[k] = self.mi.Float((body @ r.T).astype(np.float32).ravel())
        prm.update()
        self._pose[depth] = key

    def render(self, rotation: np.ndarray, depth: int, spp: int, seed: int, key: int | None = None) -> np.ndarray:
        """(res, res, 4) Stokes image (float64 of Mitsuba's float32), radiance per pixel."""
        self.pose(rotation, depth, id(rotation) if key is None else key)
        img = np.asarray(self.mi.render(self.scenes[depth], spp=int(spp), seed=int(seed)))
        if img.shape[-1] != 13:
            raise RuntimeError(f"unexpected film channels {img.shape}: expected Y + S0..S3 x 3")
        return img[..., [1, 4, 7, 10]].astype(np.float64)


def mitsuba_cubesat_totals(rotations: Any, max_depth: int, spp: int, resolution: int = 128, seed: int = 1, *,
                           threads: int | None = 1, two_sided: bool = True) -> np.ndarray:
    """(N, 4) Stokes cross-sections (m^2) of the matched CubeSat (:func:`matched_scene`)
    for unpolarized monostatic illumination, Mitsuba ``path`` with ``max_depth``, for each
    rotation ((N, 3, 3) or (3, 3), body to telescope) or quaternion ((N, 4), ``(w, x, y, z)``)."""
    a = np.asarray(rotations, dtype=np.float64)
    rots = quaternion_to_rotation(a) if a.shape[-1] == 4 else a.reshape(-1, 3, 3)
    rend = CubesatRenderer([max_depth], resolution, threads, two_sided)
    out = np.zeros((len(rots), 4))
    for i, r in enumerate(rots):
        out[i] = rend.scale * rend.render(r, max_depth, spp, seed, key=i).sum(axis=(0, 1))
    return out


def mitsuba_cubesat_reference(rotations: np.ndarray, depths: Sequence[int], spp: int, resolution: int,
                              seeds: Sequence[int] = (1, 2), threads: int | None = 1, log: Any = None) -> dict:
    """Totals per depth, seed-averaged, with noise (std of the seed average from the
    per-pixel seed variance), per seed, and the steps between consecutive depths with their
    own noise. Arrays: ``totals`` (N, D, 4), ``noise`` (N, D, 4), ``totals_per_seed``
    (N, S, D, 4), ``steps`` (N, D-1, 4), ``steps_noise`` (N, D-1, 4); ``pair_noise``: for
    every pair of depths ``(a, b)``, a < b, the (N, 4) noise of ``T(b) - T(a)`` (same
    seeds), from the per-pixel variance of the difference images."""
    rots = np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3)
    depths = [int(d) for d in depths]
    rend = CubesatRenderer(depths, resolution, threads)
    n, nd, ns = len(rots), len(depths), len(seeds)
    tot = np.zeros((n, ns, nd, 4))
    noise = np.zeros((n, nd, 4))
    steps_noise = np.zeros((n, nd - 1, 4))
    pairs = [(a, b) for ia, a in enumerate(depths) for b in depths[ia + 1:]]
    pair_noise = {pr: np.zeros((n, 4)) for pr in pairs}
    t0 = time.perf_counter()
    for i, r in enumerate(rots):
        imgs = np.zeros((ns, nd, resolution, resolution, 4))
        for s, seed in enumerate(seeds):
            for j, d in enumerate(depths):
                imgs[s, j] = rend.render(r, d, spp, seed, key=i)
        tot[i] = rend.scale * imgs.sum(axis=(-3, -2))
        noise[i] = rend.scale * np.sqrt(np.var(imgs, axis=0, ddof=1).sum(axis=(-3, -2)) / ns)
        steps_noise[i] = rend.scale * np.sqrt(np.var(np.diff(imgs, axis=1), axis=0, ddof=1).sum(axis=(-3, -2)) / ns)
        for a, b in pairs:
            dif = imgs[:, depths.index(b)] - imgs[:, depths.index(a)]
            pair_noise[(a, b)][i] = rend.scale * np.sqrt(np.var(dif, axis=0, ddof=1).sum(axis=(-3, -2)) / ns)
        if log is not None:
            el = time.perf_counter() - t0
            log(f"attitude {i + 1}/{n}: S0 by depth " + ", ".join(f"{x:.4g}" for x in tot[i].mean(0)[:, 0])
                + f"  ({el:.0f} s, ~{el / (i + 1) * (n - i - 1):.0f} s left)")
    mean = tot.mean(axis=1)
    return {"totals": mean, "noise": noise, "totals_per_seed": tot, "steps": np.diff(mean, axis=1),
            "steps_noise": steps_noise, "pair_noise": pair_noise, "scale": rend.scale, "extent": rend.ext}


# --------------------------------------------------------------------------------------
# pprender side
# --------------------------------------------------------------------------------------


#: pprender settings for the single-bounce comparisons: the f64 CPU twin with 16 visibility
#: samples in each of 8 x 8 sub-pixels. At 128 px the random-attitude returns of the CubeSat
#: are dominated by the 2 mm panel edges (Lambertian, about a third of a pixel wide), so
#: sub-pixel coverage matters: 16 samples per pixel without supersampling are off by up to
#: 3 %, and coverage="analytic" loses 5-24 % at 128 px (it finds a pixel's triangles from the
#: pixel centres around it, and misses slivers that no centre sees); converged (8 x 8 or
#: 512 px) pprender agrees with Mitsuba to its noise (:func:`self_check`).
PPRENDER_SETTINGS: dict[str, Any] = {"coverage": "sampled", "pixel_samples": 16, "supersampling": 8,
                                     "arithmetic": "f64"}


#: pprender settings for the flat plates: exact coverage of large faces (an aligned edge
#: with sampled coverage errs by ~1e-4 of the total at 64 px).
PLATE_SETTINGS: dict[str, Any] = {"coverage": "analytic", "pixel_samples": None, "supersampling": 1,
                                  "arithmetic": "f64"}


def pprender_totals(scene: Any, rotations: Any, resolution: int, **lidar: Any) -> np.ndarray:
    """(N, 4) Stokes cross-sections for unpolarized illumination: the first column of
    pprender's (N, 4, 4) Mueller cross-section (``lidar`` goes to ``pprender.Lidar``, over
    :data:`PPRENDER_SETTINGS`)."""
    import pprender

    kw = {**PPRENDER_SETTINGS, **lidar}
    res = pprender.render(scene, pprender.Lidar(resolution=resolution, **kw),
                          np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3), outputs=("cross_section",))
    return np.asarray(res.cross_section)[:, :, 0]


# --------------------------------------------------------------------------------------
# Self-check (CLI --check)
# --------------------------------------------------------------------------------------


def _plate(side: float = 0.2) -> trimesh.Trimesh:
    h = side / 2
    return trimesh.Trimesh(np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], dtype=np.float64),
                           np.array([[0, 1, 2], [0, 2, 3]]), process=False)


def _plate_angles(part: str) -> tuple[float, float]:
    """Face-on and an angle where the return is still ~10 % of it (tan(theta) = 1.5 alpha for
    the microfacet materials), 50 deg for the Lambertian."""
    alpha = {"bus": 0.15, "solar_cells": 0.05, "antenna": 0.3}.get(part)
    return (0.0, 50.0) if alpha is None else (0.0, round(math.degrees(math.atan(1.5 * alpha)), 1))


def _direction(theta_deg: float, phi_deg: float) -> np.ndarray:
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def self_check(spp: int = 256, resolution: int = 64, cubesat_spp: int = 1024, threads: int | None = 1,
               log: Any = print) -> dict:
    """The quaternion convention (against pprender's conversion); flat-plate single-bounce
    agreement per stand-in material at two angles (pprender with :data:`PLATE_SETTINGS`
    against Mitsuba ``max_depth`` 2, two seeds; asserted within 5 noise sigma + 2e-4); the
    whole CubeSat at single bounce for three attitudes; twosided against one-sided Mitsuba
    BSDFs on the CubeSat (attitude 3, ``max_depth`` 4, same seed)."""
    import pprender

    out: dict[str, Any] = {"plates": [], "cubesat_single": [], "twosided": None}
    # quaternion convention
    q = attitudes(8, 7)
    try:
        from pprender.lidar.dispatch import _rotations

        rp = _rotations(q)
        assert np.allclose(rp, quaternion_to_rotation(q), atol=1e-12), "quaternion convention differs from pprender's"
        log("quaternion_to_rotation == pprender's conversion (8 random quaternions): ok")
    except ImportError:
        log("pprender.lidar.dispatch._rotations not found: quaternion convention not cross-checked")

    phi = 30.0
    plate = _plate()
    area = 0.04
    log(f"\nflat plate {math.sqrt(area):.1f} m square, single bounce (Mitsuba max_depth 2, {spp} spp, seeds 1 and 2, "
        f"{resolution}x{resolution}; pprender f64, coverage='analytic'), view at theta from the normal, azimuth {phi:.0f} deg; "
        "sigma in m^2; analytic = 4 pi A cos^2(theta) f")
    head = (f"{'part':<12} {'theta':>5} {'pprender S0':>12} {'Mitsuba S0':>12} {'noise':>9} {'ratio-1':>9} "
            f"{'(r-1)/noise':>11} {'|S1..3|/S0 pp':>13} {'|S1..3|/S0 mi':>13} {'analytic S0':>12}")
    log(head)
    for part, (mat, bsdf, _) in matched_materials().items():
        sc = pprender.Scene(plate, mat)
        for theta in _plate_angles(part):
            d = _direction(theta, phi)
            r = mc.view_rotation(d, up=(0.0, 0.0, 1.0)) if theta > 0 else np.eye(3)
            pp = pprender_totals(sc, r[None], resolution, **PLATE_SETTINGS)[0]
            t, im = zip(*(mc.mitsuba_totals(plate, bsdf, r, 2, spp, resolution, s, return_images=True, threads=threads)
                          for s in (1, 2)))
            mt = 0.5 * (t[0][0] + t[1][0])
            scale = 4 * math.pi * (2 * mc.extent(plate) / resolution) ** 2
            nz = scale * math.sqrt(np.var(np.stack([im[0][0], im[1][0]]), axis=0, ddof=1)[..., 0].sum() / 2)
            c = math.cos(math.radians(theta))
            if bsdf["type"] == "diffuse":
                ana = 4.0 * area * PAINT_ALBEDO * c * c
            else:
                m3 = pprender.brdf(mat, d[None], d[None], frame="mitsuba")[0]
                ana = 4 * math.pi * area * c * c * m3[0, 0]
            ratio = pp[0] / mt[0]
            row = {"part": part, "theta_deg": theta, "phi_deg": phi, "pprender": pp.tolist(), "mitsuba": mt.tolist(),
                   "mitsuba_noise_S0": nz, "ratio": ratio, "analytic_S0": ana}
            out["plates"].append(row)
            log(f"{part:<12} {theta:5.1f} {pp[0]:12.6g} {mt[0]:12.6g} {nz:9.2g} {ratio - 1:9.2e} "
                f"{(pp[0] - mt[0]) / max(nz, 1e-300):11.2f} {np.linalg.norm(pp[1:]) / pp[0]:13.2e} "
                f"{np.linalg.norm(mt[1:]) / mt[0]:13.2e} {ana:12.6g}")
            assert abs(pp[0] - mt[0]) < 5 * nz + 2e-4 * mt[0], row
            assert abs(pp[0] - ana) < 1e-6 * ana, row

    # the whole CubeSat, single bounce
    scene, bsdfs = matched_scene()
    rots = quaternion_to_rotation(attitudes()[:3])
    res = 128
    log(f"\nCubeSat single bounce, first 3 of the 50 attitudes, {res}x{res}: Mitsuba max_depth 2 ({cubesat_spp} spp, "
        "seeds 1 and 2) vs pprender f64 with 16 samples x 8x8 sub-pixels (converged coverage); last columns: "
        "pprender with coverage='analytic' and with 16 samples without sub-pixels (ratio - 1)")
    log(f"{'attitude':>8} {'pprender S0':>12} {'Mitsuba S0':>12} {'noise':>9} {'ratio-1':>9} {'(r-1)/noise':>11} "
        f"{'analytic':>9} {'16 spp':>9}")
    ref = mitsuba_cubesat_reference(rots, [2], cubesat_spp, res, (1, 2), threads)
    pp = pprender_totals(scene, rots, res)
    pa = pprender_totals(scene, rots, res, coverage="analytic", pixel_samples=None, supersampling=1)
    p16 = pprender_totals(scene, rots, res, supersampling=1)
    for i in range(len(rots)):
        mt, nz = ref["totals"][i, 0], ref["noise"][i, 0, 0]
        out["cubesat_single"].append({"attitude": i, "pprender": pp[i].tolist(), "mitsuba": mt.tolist(),
                                      "mitsuba_noise_S0": nz, "ratio": pp[i, 0] / mt[0],
                                      "ratio_analytic_coverage": pa[i, 0] / mt[0], "ratio_16_samples": p16[i, 0] / mt[0]})
        log(f"{i:8d} {pp[i, 0]:12.6g} {mt[0]:12.6g} {nz:9.2g} {pp[i, 0] / mt[0] - 1:9.2e} "
            f"{(pp[i, 0] - mt[0]) / nz:11.2f} {pa[i, 0] / mt[0] - 1:9.2e} {p16[i, 0] / mt[0] - 1:9.2e}")

    # twosided or not: identical on the closed mesh? (attitude 3 has a large inter-reflection)
    r = quaternion_to_rotation(attitudes()[3])
    a = mitsuba_cubesat_totals(r, 4, cubesat_spp, res, 1, threads=threads, two_sided=True)[0]
    b = mitsuba_cubesat_totals(r, 4, cubesat_spp, res, 1, threads=threads, two_sided=False)[0]
    out["twosided"] = {"two_sided": a.tolist(), "one_sided": b.tolist()}
    log(f"\nCubeSat attitude 3, max_depth 4, {cubesat_spp} spp, seed 1: twosided {a.round(8).tolist()}, one-sided {b.round(8).tolist()}, "
        f"max |diff| / S0 = {np.abs(a - b).max() / a[0]:.2e}")
    return out


# --------------------------------------------------------------------------------------
# References (CLI --write)
# --------------------------------------------------------------------------------------


def _pct(x: np.ndarray) -> dict[str, float]:
    x = np.asarray(x, dtype=np.float64)
    return {"median": float(np.median(x)), "p90": float(np.percentile(x, 90)), "max": float(np.max(x)),
            "min": float(np.min(x))}


def compute_references(spp: int = 1536, resolution: int = 128, seeds: Sequence[int] = (1, 2),
                       threads: int | None = 1, n: int = N_ATTITUDES, log: Any = print) -> dict:
    t_start = time.perf_counter()
    mi = mc.mitsuba(threads)
    import drjit as dr
    import pprender

    q = attitudes(n)
    rots = quaternion_to_rotation(q)
    ref = mitsuba_cubesat_reference(rots, DEPTHS, spp, resolution, seeds, threads, log=log)
    T = ref["totals"]  # (N, D, 4)
    iS = {d: j for j, d in enumerate(DEPTHS)}
    s0 = T[..., 0]
    t8 = s0[:, iS[8]]
    pn = {k: v[:, 0] for k, v in ref["pair_noise"].items()}  # noise of T(b) - T(a), S0
    frac = {
        "multi_2plus": (t8 - s0[:, iS[2]]) / t8,
        "third": (s0[:, iS[4]] - s0[:, iS[3]]) / t8,
        "beyond_3": (t8 - s0[:, iS[4]]) / t8,
        "second": (s0[:, iS[3]] - s0[:, iS[2]]) / t8,
    }
    frac_noise = {  # of the numerator (the denominator's relative noise is ~0.3 %)
        "multi_2plus": pn[(2, 8)] / t8,
        "third": pn[(3, 4)] / t8,
        "beyond_3": pn[(4, 8)] / t8,
        "second": pn[(2, 3)] / t8,
    }
    mats = matched_materials()
    entries = []
    for i in range(n):
        entries.append({
            "index": i,
            "quaternion": mc._round(q[i], 12),
            "rotation": mc._round(rots[i], 12),
            "view_direction_body": mc._round(rots[i][2], 9),
            "by_depth": {str(d): {"totals": mc._sig(T[i, j]), "noise": mc._sig(ref["noise"][i, j], 3),
                                  "totals_per_seed": mc._sig(ref["totals_per_seed"][i, :, j])}
                         for j, d in enumerate(DEPTHS)},
            "steps": {f"{a}-{b}": {"stokes": mc._sig(ref["steps"][i, j]), "noise": mc._sig(ref["steps_noise"][i, j], 3)}
                      for j, (a, b) in enumerate(zip(DEPTHS[:-1], DEPTHS[1:]))},
            "S0_fractions": {k: mc._sig(v[i], 4) for k, v in frac.items()},
            "S0_fraction_noise": {k: mc._sig(v[i], 3) for k, v in frac_noise.items()},
        })
    elapsed = time.perf_counter() - t_start
    rel_noise = ref["noise"][..., 0] / np.maximum(s0, 1e-300)
    return {
        "description": "Mitsuba 3 monostatic references for the demo 3U CubeSat with matched stand-in materials, "
                       "inter-reflections by max_depth (benchmarks/mitsuba_cubesat.py; conventions in its module "
                       "docstring)",
        "conventions": {
            "cross_section": "4 pi delta^2 sum(pixel Stokes), m^2, delta = 2 extent / resolution",
            "attitude": "quaternion (w, x, y, z) / rotation R body to telescope, p_tel = R p_body; "
                        "view direction (body) = R[2]; sensor and transmitter at telescope +Z",
            "attitudes": f"q = numpy.random.default_rng({ATTITUDE_SEED}).normal(size=({n}, 4)); "
                         "q /= numpy.linalg.norm(q, axis=1, keepdims=True); no sign canonicalization",
            "stokes_basis": "received beam (X, Y) of the telescope frame, S1 = I_X - I_Y",
            "illumination": "unpolarized (first Mueller column), directional emitter along -Z, irradiance 1",
            "max_depth": "path integrator segments: 2 = one reflection (pprender bounces=1), 3 = up to two "
                         "(bounces=2), 4 = up to three (bounces=3), 8 = up to seven (Russian roulette from depth 5)",
            "noise": "standard deviation of the seed-averaged total, from per-pixel seed variances",
            "steps": "'a-b' = T(depth b) - T(depth a), same seeds (shared random numbers), with its own noise",
            "S0_fractions": "multi_2plus = (T8 - T2)/T8, second = (T3 - T2)/T8, third = (T4 - T3)/T8, "
                            "beyond_3 = (T8 - T4)/T8, of S0; their noise: that of the numerator T(b) - T(a) (per-pixel seed "
                            "variance of the difference images) over T8",
        },
        "mesh": {"model": "pprender.models.cubesat('3U') (defaults: deployed panels, antenna, detail 4)",
                 "n_faces": int(len(cubesat_mesh().faces)),
                 "extent": ref["extent"], "parts": list(PARTS), "shading": "flat (face normals)"},
        "materials": {p: {"pprender": mats[p][2], "mitsuba": {**mats[p][1], "wrapper": "twosided"}} for p in PARTS},
        "render": {"depths": list(DEPTHS), "spp": int(spp), "resolution": int(resolution), "seeds": list(seeds)},
        "mitsuba": {"version": getattr(mi, "__version__", "?"), "drjit": getattr(dr, "__version__", "?"),
                    "variant": mc.MITSUBA_VARIANT, "threads": int(dr.thread_count()),
                    "integrator": "stokes(path)", "sampler": "independent", "rfilter": "box"},
        "versions": {"pprender": importlib.metadata.version("pprender"), "numpy": np.__version__,
                     "trimesh": trimesh.__version__, "python": platform.python_version()},
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
        "elapsed_s": round(elapsed, 1),
        "summary": {
            "S0_fractions_over_attitudes": {k: _pct(v) for k, v in frac.items()},
            "S0_fraction_noise_over_attitudes": {k: _pct(v) for k, v in frac_noise.items()},
            "relative_noise_S0_by_depth": {str(d): _pct(rel_noise[:, j]) for j, d in enumerate(DEPTHS)},
            "S0_by_depth_over_attitudes": {str(d): _pct(s0[:, j]) for j, d in enumerate(DEPTHS)},
        },
        "entries": entries,
    }


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="run self_check()")
    ap.add_argument("--write", metavar="PATH", help="compute the references and write them as JSON")
    ap.add_argument("--spp", type=int, default=1536)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--n", type=int, default=N_ATTITUDES, help="number of attitudes (the first n of the 50)")
    ap.add_argument("--threads", type=int, default=1, help="drjit threads (default 1)")
    args = ap.parse_args(argv)
    if not (args.check or args.write):
        ap.error("nothing to do: give --check and/or --write PATH")
    if args.check:
        t0 = time.perf_counter()
        self_check(threads=args.threads)
        print(f"self-check: {time.perf_counter() - t0:.1f} s")
    if args.write:
        t0 = time.perf_counter()
        data = compute_references(args.spp, args.resolution, args.seeds, args.threads, args.n)
        os.makedirs(os.path.dirname(os.path.abspath(args.write)), exist_ok=True)
        with open(args.write, "w") as f:
            f.write(mc._dumps(data) + "\n")
        print(f"wrote {args.write} ({len(data['entries'])} attitudes) in {time.perf_counter() - t0:.1f} s")
        for k, v in data["summary"]["S0_fractions_over_attitudes"].items():
            nz = data["summary"]["S0_fraction_noise_over_attitudes"][k]
            print(f"{k:>12}: median {v['median']:.4g}  p90 {v['p90']:.4g}  max {v['max']:.4g}   "
                  f"(noise median {nz['median']:.2g}, max {nz['max']:.2g})")
        for d, v in data["summary"]["relative_noise_S0_by_depth"].items():
            print(f"relative S0 noise, depth {d}: median {v['median']:.2g}, max {v['max']:.2g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
