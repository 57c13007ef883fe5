"""Rendered Stokes images against Mitsuba 3 (llvm_ad_mono_polarized, stokes integrator).

A sphere of ``roughconductor`` (Beckmann, Smith masking with Walter's G1: the
pprender material with ``shadowing="smith", smith_g1="walter"``, single bounce) is lit by
a directional emitter along the view direction of an orthographic sensor (monostatic,
unpolarized). Mitsuba's pixel value is the radiance ``f cos(theta_i) E`` (E = 1), so
``4 pi delta^2`` times it is pprender's differential cross-section. Compared: the image
sums (S0) and, per pixel, S0 and the degree of polarization ``|S1..3| / S0`` (invariant to
the Stokes basis, whose conventions differ), within Mitsuba's noise measured from two
seeds.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import pprender
from pprender import models
from bench_render import mitsuba_monostatic_scene

RES = 64


@pytest.mark.parametrize("alpha", [0.2, 0.5])
def test_sphere_stokes_image_matches_mitsuba(mitsuba, tmp_path, alpha):
    mi = mitsuba
    a = 0.5
    eta = 0.2 + 3.4j
    mesh = models.sphere(radius=a, subdivisions=5)
    path = str(tmp_path / "sphere.ply")
    mesh.export(path)
    ext = float(np.linalg.norm(mesh.vertices, axis=1).max())
    # the same Mitsuba scene as the renderer benchmark (orthographic sensor, directional
    # emitter along the view, stokes over path with max_depth 2; vertex normals)
    scene = mitsuba_monostatic_scene(mi, path, ext, RES, {
        "type": "roughconductor", "distribution": "beckmann", "alpha": alpha,
        "eta": eta.real, "k": eta.imag}, smooth=True)

    def stokes(seed: int) -> np.ndarray:
        img = np.asarray(mi.render(scene, spp=256, seed=seed))
        # channels: Y, then S0, S1, S2, S3 as three (equal, mono) film channels each
        return img[..., [1, 4, 7, 10]].astype(np.float64)

    s1, s2 = stokes(1), stokes(2)
    mit = 0.5 * (s1 + s2)
    noise = np.abs(s1 - s2) / math.sqrt(2.0)  # per-pixel std estimate of one render

    mat = pprender.Material("beckmann", alpha=alpha, eta=eta, shadowing="smith", correlation="none",
                            smith_g1="walter", terms=("single",))
    sc = pprender.Scene(mesh, mat, smooth=True)
    res = pprender.render(sc, pprender.Lidar(resolution=RES), np.eye(3)[None], outputs=("mueller",))
    assert abs(res.extent - ext) < 1e-9
    ours = res.mueller[0][..., :, 0].astype(np.float64) / (4 * math.pi * res.pixel_size**2)  # unpolarized in

    cov = (mit[..., 0] > 0) & (ours[..., 0] > 0)
    # total: Mitsuba's noise on the sum is tiny (256 spp x ~3000 pixels)
    tm, to = mit[cov, 0].sum(), ours[cov, 0].sum()
    assert abs(to - tm) < 5e-3 * tm, (to, tm)
    # per pixel, away from the silhouette (where a pixel straddles the limb and the two
    # renderers' pixel footprints differ): within 5 sigma of the averaged renders
    inner = cov & (ours[..., 0] > 0.05 * ours[..., 0].max())
    d0 = np.abs(ours[..., 0] - mit[..., 0])[inner]
    sig = noise[..., 0][inner] / math.sqrt(2.0) + 2e-3 * mit[..., 0][inner]
    assert np.mean(d0 < 5 * sig) > 0.99
    dop_m = np.linalg.norm(mit[..., 1:], axis=-1)[inner] / mit[..., 0][inner]
    dop_o = np.linalg.norm(ours[..., 1:], axis=-1)[inner] / ours[..., 0][inner]
    assert np.median(np.abs(dop_m - dop_o)) < 0.01
    assert abs(np.mean(dop_m) - np.mean(dop_o)) < 0.01
