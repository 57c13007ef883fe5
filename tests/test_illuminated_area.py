"""The renderer's ``"illuminated_area"`` output: the effective illuminated area per range
bin, accumulated beside the profile (``RenderResult.illuminated_area``), against the
same quantity computed from the images (``speckle.illuminated_area``'s image path) and
against the continuum answer of a flat plate face-on and tilted."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import erf

import pprender
from pprender import _core, models
from pprender.inverse import speckle as sp

TILT = 0.6  # rad, about X
WIDTH, HEIGHT = 1.0, 0.5  # m


def lambertian() -> pprender.Material:
    return pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0j, terms=["diffuse"], diffuse_albedo=0.5)


@pytest.fixture(scope="module")
def scene() -> pprender.Scene:
    return pprender.Scene(models.plate(WIDTH, HEIGHT, thickness=1e-4), lambertian())


@pytest.fixture(scope="module")
def both(scene):
    """Face-on and tilted plate, 64 px, 2.5 cm bins, the default 100 ps pulse: every output."""
    rot = np.stack([np.eye(3), Rotation.from_rotvec([TILT, 0.0, 0.0]).as_matrix()])
    lid = pprender.Lidar(resolution=64, bin_width=0.025)
    return pprender.render(scene, lid, rot, outputs=("profile", "mueller", "range", "illuminated_area"))


def _image_area(res: pprender.RenderResult) -> np.ndarray:
    """``speckle.illuminated_area``'s computation from the images (the render output removed)."""
    bare = pprender.RenderResult(
        cross_section=res.cross_section, bin_edges=res.bin_edges, pixel_size=res.pixel_size,
        extent=res.extent, device=res.device, profile=res.profile, mueller=res.mueller,
        range=res.range, coverage=res.coverage,
    )
    return sp.illuminated_area(bare)


def _plate_oracle(edges: np.ndarray, tilt: float, fwhm_s: float = 100e-12) -> np.ndarray:
    """A uniformly bright plate's ``(int w_j dA)^2 / int w_j^2 dA`` per bin, on 10^4 strips of
    constant range across the projected plate (r = -y' tan(tilt)), w_j the Gaussian pulse's
    share of bin j at a point."""
    h = HEIGHT * math.cos(tilt)
    y = (np.arange(10000) + 0.5) / 10000 * h - h / 2
    r = -y * math.tan(tilt)
    sigma = pprender.SPEED_OF_LIGHT * fwhm_s / 2 / (2 * math.sqrt(2 * math.log(2)))
    w = np.diff(0.5 * (1 + erf((edges[:, None] - r[None, :]) / (sigma * math.sqrt(2)))), axis=0)
    da = WIDTH * h / len(y)
    num, den = (w.sum(1) * da) ** 2, (w * w).sum(1) * da
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def test_face_on_plate_is_its_area_in_every_bin(both) -> None:
    area, s0 = both.illuminated_area[0], both.profile[0, :, 0, 0]
    # every bin its return reaches down to 1e-5 of the peak (here the pulse's tails at
    # 9e-5: the moment is quadratic in the weights, and its fixed-point additions of
    # 2^-61 of a pixel's bound times the pixels round it by under 1e-6 there)
    lit = s0 > 1e-5 * s0.max()
    assert lit.sum() >= 4  # the pulse spreads the plate's one range over bins
    # the pixelized plate's area (pixel centres inside it, 64 px over 1.1 m): one value in
    # every bin, to f32 rounding of the pixel values
    covered = float(both.coverage[0].sum()) * both.pixel_size**2
    np.testing.assert_allclose(area[lit], covered, rtol=1e-6)
    # and the plate's own area within the pixelization of its outline
    np.testing.assert_allclose(area[lit], WIDTH * HEIGHT, rtol=2e-3)
    assert np.all(area[~lit & (s0 <= 0)] == 0)


def test_render_output_equals_the_image_computation_face_on(both) -> None:
    # Face-on every pixel is at one range (no footprint): the render's weights are the
    # image path's, and the two differ by f32 rounding of the pixel values (the image is
    # f32, the profile and moment fixed point at 2^-40 of a pixel's largest value):
    # measured 5e-8
    s0 = both.profile[0, :, 0, 0]
    lit = s0 > 1e-5 * s0.max()
    np.testing.assert_allclose(both.illuminated_area[0][lit], _image_area(both)[0][lit], rtol=1e-6)


def test_tilted_plate_against_the_continuum(both) -> None:
    # Tilted, a pixel spans 1.2 cm of range, near the pulse's 1.5 cm FWHM: the render takes
    # the squared weight's mean over each pixel's footprint (a two-point rule), the image
    # path the weight at the pixel's centre. Both approach the strip integral; where the
    # return is strong (bins above 2% of the peak) within the outline's pixelization
    area, s0 = both.illuminated_area[1], both.profile[1, :, 0, 0]
    want = _plate_oracle(both.bin_edges, TILT)
    image = _image_area(both)[1]
    # the bins the whole plate's width spans (measured: the render within 0.26% of the
    # strip integral, the image path 1.7%), and the two edge bins (measured 3.9% and 2.7%:
    # the outline's pixelization, one pixel row at each edge)
    inner = s0 > 0.9 * s0.max()
    strong = s0 > 0.02 * s0.max()
    assert inner.sum() >= 8 and strong.sum() == inner.sum() + 2
    np.testing.assert_allclose(area[inner], want[inner], rtol=5e-3)
    assert np.max(np.abs(area[inner] / want[inner] - 1)) < np.max(np.abs(image[inner] / want[inner] - 1))
    np.testing.assert_allclose(area[strong], want[strong], rtol=0.05)
    np.testing.assert_allclose(area[strong], image[strong], rtol=0.03)


def test_profile_only_render_gives_the_same_area(scene, both) -> None:
    lid = pprender.Lidar(resolution=64, bin_width=0.025)
    rot = np.stack([np.eye(3), Rotation.from_rotvec([TILT, 0.0, 0.0]).as_matrix()])
    only = pprender.render(scene, lid, rot, outputs=("illuminated_area",))
    # the profile it needs is computed but not returned unless asked for; the kernel's sums
    # are the same integers whatever else it writes
    assert only.profile is None and only.mueller is None and only.range is None
    np.testing.assert_array_equal(only.illuminated_area, both.illuminated_area)
    with_profile = pprender.render(scene, lid, rot, outputs=("profile", "illuminated_area"))
    np.testing.assert_array_equal(with_profile.profile, both.profile)
    # asking for it changes no other output (bit for bit)
    plain = pprender.render(scene, lid, rot, outputs=("profile",))
    assert plain.illuminated_area is None
    np.testing.assert_array_equal(plain.profile, both.profile)
    np.testing.assert_array_equal(plain.cross_section, both.cross_section)


def test_speckle_uses_the_render_output_and_falls_back_to_the_images(both) -> None:
    a = sp.illuminated_area(both)
    np.testing.assert_array_equal(a, both.illuminated_area)
    assert a is not both.illuminated_area  # a copy
    # pulse_fwhm=None bins by range from the images even with the output present
    np.testing.assert_array_equal(sp.illuminated_area(both, pulse_fwhm=None),
                                  sp.illuminated_area(_strip(both), pulse_fwhm=None))
    # a bad pulse_fwhm is refused either way
    with pytest.raises(pprender.Error, match="pulse_fwhm"):
        sp.illuminated_area(both, pulse_fwhm=-1.0)
    # neither the output nor images: the error says what to render
    bare = pprender.RenderResult(cross_section=both.cross_section, bin_edges=both.bin_edges,
                                 pixel_size=both.pixel_size, extent=both.extent, device="", profile=both.profile)
    with pytest.raises(pprender.Error, match=r'outputs=\("profile", "illuminated_area"\)'):
        sp.illuminated_area(bare)


def _strip(res: pprender.RenderResult) -> pprender.RenderResult:
    out = pprender.RenderResult(**{k: getattr(res, k) for k in res.__dataclass_fields__})
    out.illuminated_area = None
    return out


def test_saved_and_loaded_with_the_result(both) -> None:
    back = pprender.RenderResult.from_xarray(both.to_xarray())
    np.testing.assert_array_equal(back.illuminated_area, both.illuminated_area)
    assert both.to_xarray()["illuminated_area"].dims == ("attitude", "range")


def test_inter_reflections_leave_the_direct_area(scene, both) -> None:
    # a flat plate reflects nothing onto itself: with bounces = 2 the area is the direct
    # light's, from the direct part of the profile (by_bounce), as with one bounce
    lid = pprender.Lidar(resolution=64, bin_width=0.025)
    r = pprender.render(scene, lid, np.eye(3)[None], outputs=("profile", "illuminated_area"),
                        settings=dataclasses.replace(lid.settings, bounces=2))
    assert r.by_bounce is not None
    # (its bins span twice the radius more: the same edges to rounding, more of them on
    # each side; f32 bin edges in the kernel, so the areas agree to f32 rounding)
    k = (len(r.bin_edges) - len(both.bin_edges)) // 2
    np.testing.assert_allclose(r.bin_edges[k:len(r.bin_edges) - k], both.bin_edges, rtol=0, atol=1e-12)
    assert not np.any(r.illuminated_area[0, :k]) and not np.any(r.illuminated_area[0, -k:])
    np.testing.assert_allclose(r.illuminated_area[0, k:-k], both.illuminated_area[0], rtol=1e-6)


def test_area_without_the_profile_is_refused_by_the_core() -> None:
    kw = dict(resolution=8, supersampling=1, samples=1, bistatic_angle=0.0, polarization=None,
              intensity_only=False, sigma_range=0.01, bin_width=0.02, image=True, range=True, device="cpu")
    with pytest.raises(pprender.Error, match="illuminated_area"):
        _core.RenderRequest(profile=False, illuminated_area=True, **kw)
    _core.RenderRequest(profile=True, illuminated_area=True, **kw)
    with pytest.raises(pprender.Error, match="outputs"):
        pprender.render(pprender.Scene(models.plate(1.0, 0.5), lambertian()), pprender.Lidar(resolution=8),
                        np.eye(3)[None], outputs=("illuminated_areas",))
