"""Sampled pulse shapes (``Lidar(pulse_samples=..., pulse_sample_spacing=...)``).

The sampled pulse's profile is accumulated on the host in f64 (src/render/gpu/readback.rs,
``host_profile``) from the kernel's per-pixel range footprints. The references here are
independent of that code: a tilted Lambertian plate (flat range density over W sin t)
convolved in NumPy with the piecewise-linear pulse (its CDF by fine cumulative
integration), and the on-device Gaussian profile, which a finely sampled Gaussian must
approach as the square of the sample spacing (linear interpolation adds dt^2/6 of
variance).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import pprender
from pprender import models

C = pprender.SPEED_OF_LIGHT
SIGMA_T = 100e-12 / (2.0 * math.sqrt(2.0 * math.log(2.0)))


def lambertian(rho: float) -> pprender.Material:
    return pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0j, terms=["diffuse"], diffuse_albedo=rho)


def rot(tilt: float, spin: float) -> np.ndarray:
    c, s = math.cos(tilt), math.sin(tilt)
    rx = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    c, s = math.cos(spin), math.sin(spin)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return rz @ rx


def sampled_gaussian(dt: float) -> np.ndarray:
    k = int(math.ceil(7 * SIGMA_T / dt))
    t = np.arange(-k, k + 1) * dt
    return np.exp(-0.5 * (t / SIGMA_T) ** 2)


def piecewise_linear_cdf(samples: np.ndarray, dt_range: float, fine: int = 64):
    """CDF of the hat-interpolated pulse, centroid at 0: (grid, cdf) by the trapezoid rule
    on a fine grid (exact for the piecewise-linear shape at the knots, and at the fine
    nodes up to O((dt/fine)^2))."""
    s = np.concatenate([[0.0], np.asarray(samples, float), [0.0]])
    knots = dt_range * np.arange(len(s))
    x = np.linspace(knots[0], knots[-1], (len(s) - 1) * fine + 1)
    p = np.interp(x, knots, s)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(x))])
    area = cdf[-1]
    mu = np.trapezoid(x * p, x) / area
    return x - mu, cdf / area


def test_sampled_pulse_on_a_tilted_plate_matches_the_numpy_convolution():
    # an asymmetric pulse (fast rise, exponential tail), 4 ps sampling
    width, rho, tilt = 0.4, 0.5, math.radians(50.0)
    dt = 4e-12
    t = np.arange(0, 120) * dt
    samples = (1 - np.exp(-t / 15e-12)) * np.exp(-t / 60e-12)
    scene = pprender.Scene(models.plate(width=width, height=width, thickness=1e-6), lambertian(rho))
    sensor = pprender.Lidar(polarization=[1, 0, 0, 0], pulse_samples=samples, pulse_sample_spacing=dt,
                            bin_width=0.004, resolution=160)
    res = pprender.render(scene, sensor, rot(tilt, 0.3)[None], outputs=("profile",))
    sigma_ref = 4 * rho * math.cos(tilt) ** 2 * width**2
    total = res.cross_section[0, 0]
    assert abs(total - sigma_ref) < 1e-3 * sigma_ref
    prof = res.profile[0, :, 0]
    assert abs(prof.sum() - total) < 1e-6 * total  # the total is summed in f32 per workgroup
    # reference: flat density over depth W sin t, convolved with the pulse, binned
    depth = width * math.sin(tilt)
    x, cdf = piecewise_linear_cdf(samples, C * dt / 2)
    r = np.linspace(-depth / 2, depth / 2, 4001)
    w = np.gradient(r) * sigma_ref / depth
    big = np.interp(res.bin_edges[:, None] - r[None, :], x, cdf, left=0.0, right=1.0)
    ref = (np.diff(big, axis=0) * w[None, :]).sum(axis=1)
    # same limit as the Gaussian plate (visibility samples at the edges): measured 7.3e-4
    # in L1 relative to the total (1.3e-3 with the earlier sample pattern)
    assert np.abs(prof - ref).sum() / sigma_ref < 4e-3
    # the pulse's asymmetry shows: the profile's centroid sits at the pulse's (0) and its
    # skewness is the pulse's, positive: the third central moments, each about its own
    # centroid, within 2% (taken about the render's centroid for both, as this test first
    # did, the reference's moved by 4% per 1e-5 of the depth that the render's centroid
    # moved). The third moment weighs the plate's edge pixels, whose range footprints the
    # 8 samples approximate: it is -1.3% here (+0.04% before thin pixels were clipped
    # whole), -0.35% at 320 pixels, -0.8% at 640 before and after that change, +0.2% with
    # analytic coverage
    rc = res.range_axis
    m1 = (prof * rc).sum() / prof.sum()
    assert abs(m1) < 2e-3 * depth
    m3 = (prof * (rc - m1) ** 3).sum() / prof.sum()
    m1_ref = (ref * rc).sum() / ref.sum()
    m3_ref = (ref * (rc - m1_ref) ** 3).sum() / ref.sum()
    assert m3 > 0 and abs(m3 - m3_ref) < 0.02 * abs(m3_ref), (m3, m3_ref)


def test_finely_sampled_gaussian_converges_to_the_gaussian_as_dt_squared():
    import trimesh

    scene = pprender.Scene(trimesh.creation.icosphere(subdivisions=4, radius=0.2), lambertian(0.5))
    q = np.array([[1.0, 0, 0, 0]])
    # one visibility sample per pixel: with more, a pixel that sees several triangles has one
    # footprint per triangle on the device but a single merged one on the host's sampled
    # path (src/render/gpu/readback.rs, host_profile), which would mask the dt^2 convergence here
    ref = pprender.render(scene, pprender.Lidar(resolution=96, pixel_samples=1), q, outputs=("profile",))
    pa = ref.profile[0, :, 0, 0]
    errs = []
    for dt in (4e-12, 2e-12):
        sensor = pprender.Lidar(resolution=96, pulse_samples=sampled_gaussian(dt), pulse_sample_spacing=dt,
                                bin_width=ref.bin_edges[1] - ref.bin_edges[0], pixel_samples=1)
        res = pprender.render(scene, sensor, q, outputs=("profile",))
        assert res.bin_edges[0] <= ref.bin_edges[0]
        off = int(round((ref.bin_edges[0] - res.bin_edges[0]) / (ref.bin_edges[1] - ref.bin_edges[0])))
        np.testing.assert_allclose(res.bin_edges[off:off + len(pa) + 1], ref.bin_edges, rtol=0, atol=1e-12)
        pb = res.profile[0, :, 0, 0]
        assert np.abs(pb[:off]).max(initial=0) < 1e-9 * pa.max()  # nothing outside
        errs.append(np.abs(pb[off:off + len(pa)] - pa).max() / pa.max())
        # same pixels; the totals are sums of differently rounded fixed-point additions (the
        # Gaussian's is its profile's sum: ~20 additions per pixel, each rounded to 2^-40 of
        # the brightest possible pixel), so they agree to that quantum, not to f64 rounding
        np.testing.assert_allclose(res.cross_section, ref.cross_section, rtol=0,
                                   atol=1e-7 * ref.cross_section[0, 0, 0])
    # the sphere's sharp leading edge makes the dt^2/6 variance excess visible:
    # measured 2.1e-4 and 5.4e-5 of the peak; the ratio is the order of convergence
    assert errs[1] < 2e-4
    assert 3.5 < errs[0] / errs[1] < 4.5


def test_sampled_pulse_batches_images_and_sums():
    mesh = models.cubesat("1U")
    scene = pprender.Scene(mesh, lambertian(0.4))
    q = np.random.default_rng(3).normal(size=(3, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    samples = [0.0, 1.0, 3.0, 2.0, 1.0, 0.5, 0.2]
    sensor = pprender.Lidar(resolution=64, pulse_samples=samples, pulse_sample_spacing=20e-12, supersampling=2)
    both = pprender.render(scene, sensor, q, outputs=("profile", "mueller", "range"))
    gauss = pprender.render(scene, pprender.Lidar(resolution=64, supersampling=2), q, outputs=("mueller", "range"))
    # the pulse changes the profile only: images and range maps are those of the Gaussian sensor
    np.testing.assert_array_equal(both.mueller, gauss.mueller)
    np.testing.assert_array_equal(both.range, gauss.range)
    np.testing.assert_allclose(both.profile.sum(axis=1), both.cross_section, rtol=0,
                               atol=1e-6 * both.cross_section[:, 0, 0].max())
    for i in range(len(q)):
        one = pprender.render(scene, sensor, q[i:i + 1], outputs=("profile",))
        np.testing.assert_array_equal(one.profile[0], both.profile[i])


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(pulse_samples=[1.0, -1.0, 2.0], pulse_sample_spacing=1e-11), "pulse_samples"),
        (dict(pulse_samples=[0.0, 0.0], pulse_sample_spacing=1e-11), "pulse_samples"),
        (dict(pulse_samples=[1.0, float("nan")], pulse_sample_spacing=1e-11), "pulse_samples"),
        (dict(pulse_samples=[[1.0, 2.0]], pulse_sample_spacing=1e-11), "pulse_samples"),
        (dict(pulse_samples=[], pulse_sample_spacing=1e-11), "pulse_samples"),
        (dict(pulse_samples=[1.0, 2.0]), "pulse_sample_spacing"),
        (dict(pulse_samples=[1.0, 2.0], pulse_sample_spacing=0.0), "pulse_sample_spacing"),
        (dict(pulse_samples=[1.0, 2.0], pulse_sample_spacing=float("inf")), "pulse_sample_spacing"),
    ],
)
def test_bad_pulse_input_names_the_parameter(kwargs, name):
    with pytest.raises(pprender.Error, match=name):
        pprender.Lidar(**kwargs)


def test_sampled_pulse_with_bistatic_shadows_sums_to_the_total():
    # the host accumulation reads the kernel's image, so shadowed pixels (zero) add nothing
    scene = pprender.Scene(models.cubesat("3U"), lambertian(0.4))
    q = np.array([[0.9, 0.3, 0.2, 0.1]])
    q /= np.linalg.norm(q)
    kw = dict(resolution=96, bistatic_angle=math.radians(40.0))
    sampled = pprender.render(scene, pprender.Lidar(pulse_samples=[1.0, 2.0, 1.0], pulse_sample_spacing=30e-12, **kw),
                              q, outputs=("profile", "mueller", "range"))
    gauss = pprender.render(scene, pprender.Lidar(**kw), q, outputs=("mueller",))
    np.testing.assert_array_equal(sampled.mueller, gauss.mueller)
    assert np.any(sampled.mask & (sampled.mueller[..., 0, 0] == 0))  # covered but dark: shadowed
    np.testing.assert_allclose(sampled.profile.sum(axis=1), sampled.cross_section, rtol=0,
                               atol=1e-6 * sampled.cross_section[0, 0, 0])
