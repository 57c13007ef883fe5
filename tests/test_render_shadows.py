"""Transmitter cast shadows (bistatic_angle > 0) against trimesh/embree ray casting and
analytic cases.

The renderer decides shadows from a second raster from the transmitter (shaders/shade.wgsl:
a point is shadowed when a triangle nominated by the transmitter's id map around it covers
it and lies closer to the transmitter). The reference here is independent of that code:
trimesh finds each pixel centre's visible point (receiver ray) and casts a ray from it,
offset along the face normal, toward the transmitter (``intersects_any``). With a
Lambertian material (M00 > 0 wherever lit) the renderer's lit mask is ``M00 > 0`` on
covered pixels. Flat shading throughout, so both sides test the same geometric normals.

Measured (lavapipe; covered pixels compared per attitude, 4 plate-over-sphere attitudes at
128 px, 6 CubeSat attitudes at 192 px): lit/shadowed mismatches at most 4 pixels per
attitude (0.11% of the covered pixels), all on a shadow's edge: plate over sphere 2, 1
and 7 in all at 5, 20 and 60 deg (250, 1213 and 5349 shadowed pixels); 3U CubeSat 6, 9
and 8 (30, 174 and 8153 shadowed), most of them the one-pixel-wide shadow of the whip
antenna, thinner than a texel of the transmitter's map (a documented limit).
"""
# The shadow rule is checked at pixel centres (one visibility sample, as the embree rays
# here); with more samples a pixel's shaded points are the means of its samples, checked
# against the f64 twin, shadows included, by samples_kernel_matches_twin
# (src/render/compare_gpu_cpu.rs).


from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import pprender
import raycast
from pprender import models

LAMBERT = pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0j, terms=["diffuse"],
                            diffuse_albedo=0.5)


def lambert_sphere_bistatic(a: float, rho: float, beta: float) -> float:
    """Lambertian sphere: sigma = 4 rho a^2 int max(0, n.wi) max(0, n.wo) dOmega
    = 8/3 rho a^2 (sin beta + (pi - beta) cos beta)."""
    return 8.0 / 3.0 * rho * a * a * (math.sin(beta) + (math.pi - beta) * math.cos(beta))


def plate_in_front_of_sphere() -> trimesh.Trimesh:
    # a 0.4 x 0.4 x 0.01 m plate hovering over a 0.5 m sphere, off to +x: from the receiver
    # it covers part of the sphere; toward a transmitter displaced to +X its shadow falls on
    # the sphere beside it
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    plate = trimesh.creation.box(extents=(0.4, 0.4, 0.01))
    plate.apply_translation((0.3, 0.1, 0.75))
    return trimesh.util.concatenate([sphere, plate])


def reference_lit(mesh: trimesh.Trimesh, rot: np.ndarray, beta: float, n: int, ext: float):
    """Per pixel centre (n x n, conventions of src/render/mod.rs): the range of the visible
    point (NaN if none) and whether it is lit (facing the transmitter and the ray from it
    toward the transmitter, offset 1e-5 ext along the normal, hits nothing)."""
    m = raycast.rotated(mesh, rot)
    origins, dirs = raycast.pixel_rays(ext, n)
    loc, idx_ray, idx_tri = m.ray.intersects_location(origins, dirs, multiple_hits=False)
    wi = np.array([math.sin(beta), 0.0, math.cos(beta)])
    wo = np.array([0.0, 0.0, 1.0])
    rng = np.full(n * n, np.nan)
    rng[idx_ray] = -loc @ (wi + wo) / 2
    nrm = m.face_normals[idx_tri]
    nrm *= np.where(nrm[:, 2] < 0, -1.0, 1.0)[:, None]  # the side the receiver sees
    facing = nrm @ wi > 0
    blocked = m.ray.intersects_any(loc + 1e-5 * ext * nrm, np.tile(wi, (len(loc), 1)))
    lit = np.zeros(n * n, bool)
    lit[idx_ray] = facing & ~blocked
    return rng.reshape(n, n), lit.reshape(n, n)


def compare(mesh: trimesh.Trimesh, q: np.ndarray, beta: float, n: int):
    """Render (Lambertian, flat) and compare the lit masks with ray casting per attitude.
    Returns per attitude (covered, reference-shadowed, mismatches, mismatches away from
    any shadow or silhouette boundary)."""
    scene = pprender.Scene((mesh.vertices, mesh.faces), LAMBERT)
    res = pprender.render(scene, pprender.Lidar(pixel_samples=1, resolution=n, bistatic_angle=beta), q,
                          outputs=("mueller", "range"))
    rots = pprender._core.quaternions_to_rotations(q)
    stats = []
    for i, rot in enumerate(rots):
        want_r, want_lit = reference_lit(mesh, rot, beta, n, res.extent)
        got_r = res.range[i]
        got_lit = res.mueller[i, :, :, 0, 0] > 0
        # the same visible surface (receiver visibility is tested in test_render.py)
        both = ~np.isnan(want_r) & ~np.isnan(got_r) & (np.abs(got_r - want_r) < 1e-4 * res.extent)
        mis = both & (got_lit != want_lit)
        # "near a boundary": the reference's 3x3 neighbourhood holds both states, or empty
        # pixels (a silhouette), or pixels of another surface
        pad_l = np.pad(want_lit & both, 1)
        pad_d = np.pad(~want_lit & both, 1)
        pad_o = np.pad(~both, 1, constant_values=True)
        any_l, any_d, any_o = (np.zeros_like(both) for _ in range(3))
        for di in range(3):
            for dj in range(3):
                s = (slice(di, di + n), slice(dj, dj + n))
                any_l |= pad_l[s]
                any_d |= pad_d[s]
                any_o |= pad_o[s]
        near = (any_l & any_d) | any_o
        stats.append((int(both.sum()), int((both & ~want_lit).sum()), int(mis.sum()),
                      int((mis & ~near).sum())))
    return stats


def attitudes(k: int, seed: int) -> np.ndarray:
    q = np.random.default_rng(seed).normal(size=(k, 4))
    q[0] = (1.0, 0.0, 0.0, 0.0)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


@pytest.mark.parametrize("beta_deg", [5.0, 20.0, 60.0])
def test_plate_over_sphere_shadow_matches_ray_casting(beta_deg):
    mesh = plate_in_front_of_sphere()
    # identity and small tilts: the shadow stays on the visible side of the sphere
    h = [(1.0, 0.0, 0.0, 0.0), (math.cos(0.1), 0.0, 0.0, math.sin(0.1)),
         (math.cos(0.15), math.sin(0.15), 0.0, 0.0), (math.cos(0.2), 0.0, math.sin(0.2), 0.0)]
    stats = compare(mesh, np.array(h), math.radians(beta_deg), 128)
    print(f"plate+sphere beta {beta_deg}: (covered, shadowed, mismatches, away) {stats}")
    for cov, shadowed, mis, away in stats:
        assert shadowed > (20 if beta_deg == 5.0 else 200)  # the scene does cast a shadow
        assert mis <= 0.005 * cov  # measured <= 0.11%
        assert away == 0


@pytest.mark.parametrize("beta_deg", [5.0, 20.0, 60.0])
def test_cubesat_shadows_match_ray_casting(beta_deg):
    mesh = models.cubesat("3U")  # deployed panels: they shadow the bus and each other
    stats = compare(mesh, attitudes(6, 11), math.radians(beta_deg), 192)
    print(f"3U cubesat beta {beta_deg}: (covered, shadowed, mismatches, away) {stats}")
    assert sum(s[1] for s in stats) > 20
    for cov, _, mis, away in stats:
        assert mis <= 0.005 * cov  # measured <= 0.11%
        assert away == 0


@pytest.mark.parametrize("beta_deg", [20.0, 60.0])
def test_convex_body_is_not_self_shadowed(beta_deg):
    # a smooth-shaded sphere casts no shadow on itself: nothing goes dark but a band of
    # pixels at the terminator thinner than a facet (where the shading normal faces the
    # transmitter and the facet does not: rule 0 of shaders/shade.wgsl)
    a, rho, beta = 0.5, 0.5, math.radians(beta_deg)
    scene = pprender.Scene(models.sphere(radius=a, subdivisions=7), LAMBERT, smooth=True)
    n = 256
    res = pprender.render(scene, pprender.Lidar(pixel_samples=1, polarization=[1, 0, 0, 0], bistatic_angle=beta,
                                                resolution=n),
                          np.eye(3)[None], outputs=("stokes", "range"))
    x = -res.extent + (np.arange(n) + 0.5) * res.pixel_size
    X, Y = np.meshgrid(x, -x)
    Z = np.sqrt(np.maximum(a * a - X * X - Y * Y, 0.0))
    cos_i = (X * math.sin(beta) + Z * math.cos(beta)) / a
    covered = ~np.isnan(res.range[0])
    dark = covered & (res.stokes[0, ..., 0] == 0)
    assert not np.any(dark & (cos_i > 0.01))
    # and the total is the analytic bistatic one (measured -3.5e-5 at 20 deg, -9.1e-5 at
    # 60 deg; before the tables' below-horizon nodes were extrapolated (src/brdf/table.rs,
    # extend_below_horizon) 60 deg lost 0.5% at the terminator)
    ref = lambert_sphere_bistatic(a, rho, beta)
    assert abs(res.cross_section[0, 0] - ref) < 1e-3 * ref


def test_fully_shadowed_sphere_returns_nothing():
    # a 1.2 m plate facing the transmitter at 1.5 m along wi hides the whole 0.5 m sphere
    # from it, without hiding it from the receiver: every sphere pixel is covered (range
    # reported) and dark, and the total is the plate's own 4 rho A cos(beta)
    beta, rho, side = math.radians(60.0), 0.5, 1.2
    wi = np.array([math.sin(beta), 0.0, math.cos(beta)])
    plate = trimesh.creation.box(extents=(side, side, 1e-3))
    spin = trimesh.transformations.rotation_matrix(0.3, (0, 0, 1))  # generic pixel-grid edges
    tilt = trimesh.transformations.rotation_matrix(beta, (0, 1, 0))  # normal z -> wi
    plate.apply_transform(tilt @ spin)
    plate.apply_translation(1.5 * wi)
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=0.5)
    mesh = trimesh.util.concatenate([sphere, plate])
    scene = pprender.Scene((mesh.vertices, mesh.faces), LAMBERT)
    n = 512
    shad = pprender.render(scene, pprender.Lidar(pixel_samples=1, resolution=n, bistatic_angle=beta),
                           np.eye(3)[None], outputs=("mueller", "range"))
    mono = pprender.render(scene, pprender.Lidar(pixel_samples=1, resolution=n), np.eye(3)[None],
                           outputs=("range",))
    x = -shad.extent + (np.arange(n) + 0.5) * shad.pixel_size
    on_sphere = np.broadcast_to(x < 0.75, (n, n)) & ~np.isnan(shad.range[0])
    # the sphere's disc: pi a^2 / pix^2 pixels, all covered, all dark
    assert abs(on_sphere.sum() * shad.pixel_size**2 - math.pi * 0.25) < 2e-3
    assert np.all(shad.mueller[0][on_sphere] == 0)
    # coverage does not depend on the transmitter
    np.testing.assert_array_equal(np.isnan(shad.range), np.isnan(mono.range))
    ref = 4 * rho * side * side * math.cos(beta)
    assert abs(shad.cross_section[0, 0, 0] - ref) < 2e-3 * ref
    # the same sphere without the plate returns its analytic bistatic cross-section
    alone = pprender.render(pprender.Scene((sphere.vertices, sphere.faces), LAMBERT),
                            pprender.Lidar(pixel_samples=1, resolution=256, bistatic_angle=beta), np.eye(3)[None],
                            outputs=())
    assert alone.cross_section[0, 0, 0] > 0.9 * lambert_sphere_bistatic(0.5, rho, beta)


def test_monostatic_has_no_shadow_pass_and_is_unchanged_by_tiny_beta():
    # beta = 0 compiles the shadow test out (override constant SHADOWS); a tiny beta runs
    # it, and on a convex body it must change nothing but rounding of wi
    scene = pprender.Scene(models.sphere(radius=0.5, subdivisions=5), LAMBERT)
    q = attitudes(2, 5)
    a = pprender.render(scene, pprender.Lidar(pixel_samples=1, resolution=96), q, outputs=("mueller",))
    b = pprender.render(scene, pprender.Lidar(pixel_samples=1, resolution=96, bistatic_angle=1e-6), q,
                        outputs=("mueller",))
    np.testing.assert_array_equal(a.mueller[..., 0, 0] > 0, b.mueller[..., 0, 0] > 0)
    np.testing.assert_allclose(b.cross_section, a.cross_section, rtol=1e-5, atol=1e-9)
