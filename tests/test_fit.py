"""pprender.fit: Poisson likelihood, the rendering forward model, nlopt and emcee.

References are independent of the module: scipy.stats.poisson for the likelihood, direct
pprender.render calls and the Lambertian sphere's closed forms for the forward model,
the rotation-vector identity R exp([r]) = exp([R r]) R for the attitude frames, and the
curvature of the log-likelihood for the Fisher information.

Fit problem (module fixture): a bare 1U CubeSat (no panels, no antenna) of aluminium-like
metal with the single-bounce term only (materials with the "multiple" term take ~0.4 s
each to build), rendered at resolution 48 with 2x2 supersampling, co/cross linear
channels, 2e4 expected signal counts. Its free parameters (rx, scale) are well
conditioned (Fisher correlation 0.52); rx with ry is nearly degenerate (-0.997) for this
attitude, which is physics (both tilt the same faces), not a test subject.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import poisson

import pprender
from pprender import fit, materials, models
from pprender import instrument as ins
from pprender import lidar as lidar_module

# one visibility sample per sub-pixel: the tolerances below were measured with it
LIDAR = pprender.Lidar(resolution=48, supersampling=2, pixel_samples=1)
TRUTH = {"rx": 0.4, "ry": 0.3, "rz": 0.2, "alpha": 0.3, "scale": 1.0}


def metal(alpha: float = 0.3) -> pprender.Material:
    return pprender.Material("beckmann", alpha=alpha, eta=1.38 + 10.2j, terms=["single"])


def lambertian(rho: float) -> pprender.Material:
    return pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0j, terms=["diffuse"], diffuse_albedo=rho)


# ---------------------------------------------------------------------- likelihood


def test_poisson_log_likelihood_matches_scipy(rng):
    lam = rng.uniform(0.0, 50.0, size=(3, 40, 4))
    k = rng.poisson(lam)
    ref = poisson.logpmf(k, lam).sum(axis=(-2, -1))
    np.testing.assert_allclose(fit.poisson_log_likelihood(k, lam), ref, rtol=1e-12)
    # one (B, C) array gives a float; large counts (Stirling regime) too
    big = np.array([[10**6, 3], [0, 2 * 10**6]])
    mu = np.array([[1.001e6, 2.5], [0.3, 1.999e6]])
    assert fit.poisson_log_likelihood(big, mu) == pytest.approx(poisson.logpmf(big, mu).sum(), rel=1e-12)
    # counts broadcast against a batch of expectations (as ForwardModel uses it)
    np.testing.assert_allclose(fit.poisson_log_likelihood(k[0], lam), poisson.logpmf(k[0], lam).sum(axis=(1, 2)),
                               rtol=1e-12)


def test_poisson_log_likelihood_edges():
    # expected 0 and no counts: the pmf is 1, contribution 0
    assert fit.poisson_log_likelihood([[0, 3]], [[0.0, 2.0]]) == pytest.approx(poisson.logpmf(3, 2.0), rel=1e-14)
    # expected 0 and counts: impossible, -inf (not NaN)
    v = fit.poisson_log_likelihood([[1, 3]], [[0.0, 2.0]])
    assert v == -math.inf
    # tiny expectation with no counts tends to 0 continuously
    assert fit.poisson_log_likelihood([[0]], [[1e-300]]) == pytest.approx(-1e-300, abs=1e-310)


@pytest.mark.parametrize(
    "counts, expected, match",
    [
        ([[-1, 2]], [[1.0, 1.0]], "counts"),
        ([[1.5, 2]], [[1.0, 1.0]], "counts"),
        ([[1, 2]], [[np.nan, 1.0]], "expected"),
        ([[1, 2]], [[-1.0, 1.0]], "expected"),
        ([[1, 2, 3]], [[1.0, 1.0]], "broadcast"),
        ([1, 2], [1.0, 1.0], "shape"),
    ],
)
def test_poisson_log_likelihood_bad_inputs(counts, expected, match):
    with pytest.raises(pprender.Error, match=match):
        fit.poisson_log_likelihood(counts, expected)


# ---------------------------------------------------------------------- materials and attitudes


def test_rebuilt_materials_keep_every_setting():
    wi = np.array([[0.3, 0.1, math.sqrt(1 - 0.1)], [0.0, 0.0, 1.0]])
    wo = np.array([[-0.2, 0.3, math.sqrt(1 - 0.13)], [0.5, 0.0, math.sqrt(0.75)]])
    for m in (
        materials.get("aluminium"),
        materials.get("white_paint"),
        pprender.Material("blinn_phong", m=30.0, eta=1.5 + 0j, shadowing="smith"),
        lambertian(0.4),
    ):
        same = fit._material_with(m, None, None)
        np.testing.assert_array_equal(pprender.brdf(same, wi, wo), pprender.brdf(m, wi, wo))
    # new roughness and index: as if built directly
    m = materials.get("aluminium")
    new = fit._material_with(m, 0.25, 1.1 + 7.0j)
    direct = materials.get("aluminium", alpha=0.25, eta=1.1 + 7.0j)
    np.testing.assert_array_equal(pprender.brdf(new, wi, wo), pprender.brdf(direct, wi, wo))


def test_attitude_frames_and_attitude_error():
    mesh = models.plate(0.1, 0.1)
    inst = ins.Instrument(pulse_energy=1e-3, target_range=1e5)
    r_ref = Rotation.from_rotvec([0.3, -0.5, 1.1]).as_matrix()
    kw = dict(free=("rx", "ry", "rz"), reference_attitude=r_ref)
    tel = fit.ForwardModel(mesh, metal(), inst, [-0.1, 0.1], attitude_frame="telescope", **kw)
    body = fit.ForwardModel(mesh, metal(), inst, [-0.1, 0.1], attitude_frame="body", **kw)
    r = np.array([0.2, -0.1, 0.4])
    # R_ref exp([r]) = exp([R_ref r]) R_ref: a body-frame rotation vector r is R_ref r in the telescope frame
    np.testing.assert_allclose(body.rotations(r), tel.rotations(r_ref @ r), atol=1e-14)
    np.testing.assert_allclose(tel.rotations(np.zeros(3))[0], r_ref, atol=1e-15)
    # attitude_error: the angle of R_a R_b^T, from matrices or (w, x, y, z) quaternions
    a = Rotation.from_rotvec([0.0, 0.0, 0.3])
    assert fit.attitude_error(a.as_matrix(), np.eye(3)) == pytest.approx(0.3, abs=1e-14)
    qa = a.as_quat()[[3, 0, 1, 2]]
    assert fit.attitude_error(qa, [1.0, 0, 0, 0]) == pytest.approx(0.3, abs=1e-14)
    np.testing.assert_allclose(fit.attitude_error(tel.rotations([r, r]), body.rotations([r, r])),
                               [fit.attitude_error(tel.rotations(r)[0], body.rotations(r)[0])] * 2)
    # "roll": the swing (rx, ry, 0) then the roll rz about the line of sight Z, before R_ref
    roll = fit.ForwardModel(mesh, metal(), inst, [-0.1, 0.1], attitude_frame="roll", **kw)
    expect = Rotation.from_euler("Z", 0.4) * Rotation.from_rotvec([0.2, -0.1, 0.0]) * Rotation.from_matrix(r_ref)
    np.testing.assert_allclose(roll.rotations(r)[0], expect.as_matrix(), atol=1e-14)
    # the roll turns the body about Z and nothing else: where Z meets the body is kept
    z_body = roll.rotations([[0.2, -0.1, -1.3], [0.2, -0.1, 2.0]]).transpose(0, 2, 1)[:, :, 2]
    np.testing.assert_allclose(z_body[0], z_body[1], atol=1e-14)


# ---------------------------------------------------------------------- forward model


@pytest.fixture(scope="module")
def cube():
    """The fit problem of the module docstring: model, truth, data render, instrument."""
    mesh = models.cubesat("1U", panels=None, antenna=False, detail=0)
    base = ins.Instrument(pulse_energy=1e-3, target_range=5e5, jitter=20e-12, background_rate=1e5, n_pulses=10**5)
    rot = Rotation.from_rotvec([TRUTH["rx"], TRUTH["ry"], TRUTH["rz"]]).as_matrix()[None]
    sensor = pprender.Lidar(resolution=48, supersampling=2, pixel_samples=1, polarization=base.channels.transmit)
    res = pprender.render(pprender.Scene(mesh, metal()), sensor, rot, outputs=("profile",))
    inst = base.scaled_to(2e4, res)
    free = ("rx", "scale")
    model = fit.ForwardModel(
        mesh, metal(), inst, res.bin_edges, free, lidar=LIDAR,
        fixed={k: v for k, v in TRUTH.items() if k not in free and k != "alpha"},
        bounds={"rx": (-1.0, 1.0), "scale": (0.5, 2.0)},
    )
    truth = np.array([TRUTH["rx"], TRUTH["scale"]])
    return model, truth, res, inst


def test_model_equals_a_direct_render(cube):
    model, truth, res, inst = cube
    # the model renders with analytic coverage (and the f64 CPU renderer on a CPU device)
    assert model.settings.coverage == "analytic"
    direct = pprender.render(model.scene((None, None, None, None)), model.lidar, model.rotations(truth),
                             outputs=("profile",), settings=model.settings)
    np.testing.assert_allclose(model.expected(truth), ins.expected_counts(direct, inst)[0], rtol=1e-12)
    # settings="lidar": the lidar's own sampled settings, which warn for a free attitude
    with pytest.warns(fit.FitWarning, match="piecewise flat"):
        own = fit.ForwardModel(models.cubesat("1U", panels=None, antenna=False, detail=0), metal(), inst,
                               res.bin_edges, ("rx", "scale"), lidar=LIDAR, settings="lidar",
                               fixed={"ry": TRUTH["ry"], "rz": TRUTH["rz"]}, bounds={"rx": (-1.0, 1.0), "scale": (0.5, 2.0)})
    np.testing.assert_allclose(own.expected(truth), ins.expected_counts(res, inst)[0], rtol=1e-12)
    # a batch gives (n, B, C); the bounds are the prior
    assert model.expected(np.array([truth, truth])).shape == (2,) + res.profile.shape[1:2] + (2,)
    with pytest.raises(pprender.Error, match="bounds"):
        model.expected([1.5, 1.0])


def test_scale_is_exact_on_a_lambertian_sphere():
    """Scale s: sigma = 8/3 pi (s a)^2 rho, and the signal's range centroid is -3 s a / 4
    (d sigma / dr ~ r^2 on [-s a, 0]); and the scaled mesh renders like a sphere built at
    radius s a."""
    a, rho, s = 0.1, 0.6, 1.7
    inst = ins.Instrument(pulse_energy=1e-3, target_range=2e5)
    lid = pprender.Lidar(resolution=64)
    mesh = models.sphere(radius=a, subdivisions=4)
    big = pprender.Scene(models.sphere(radius=s * a, subdivisions=4), lambertian(rho), smooth=True)
    ref = pprender.render(big, pprender.Lidar(resolution=64, polarization=inst.channels.transmit), np.eye(3)[None],
                          outputs=("profile",))
    model = fit.ForwardModel(mesh, lambertian(rho), inst, ref.bin_edges, ("scale",), lidar=lid, smooth=True)
    # rendered as the model renders (analytic coverage)
    ref = pprender.render(big, pprender.Lidar(resolution=64, polarization=inst.channels.transmit), np.eye(3)[None],
                          outputs=("profile",), settings=model.settings)
    lam = model.expected([s])
    # the scaled icosphere is the icosphere of radius s a (vertices scale exactly): equal to
    # float32 rounding of the rendered values
    np.testing.assert_allclose(lam, ins.expected_counts(ref, inst)[0], rtol=1e-5, atol=1e-9 * lam.max())
    sigma = 8.0 / 3.0 * math.pi * (s * a) ** 2 * rho
    # 3e-3: the icosphere (subdivisions 4) renders 1.4e-3 low (tests/test_instrument.py)
    assert lam.sum() == pytest.approx(sigma * inst.counts_per_cross_section, rel=3e-3)
    r = 0.5 * (ref.bin_edges[1:] + ref.bin_edges[:-1])
    centroid = float((lam.sum(axis=1) * r).sum() / lam.sum())
    # the symmetric pulse keeps the centroid; 2e-3 of s a: mesh sagitta and binning
    assert centroid == pytest.approx(-0.75 * s * a, abs=2e-3 * s * a)
    # and on the cube: sigma ~ s^2 for a non-spherical shape (rasterization scales with it)
    lam1, lam2 = model.expected(np.array([[1.0], [1.3]]))
    assert lam2.sum() / lam1.sum() == pytest.approx(1.3**2, rel=1e-5)


def test_vectorized_log_prob_renders_once_and_equals_single_calls(cube, monkeypatch):
    model, truth, res, inst = cube
    meas = ins.measure(res, inst, seed=2)[0]
    calls = []
    real = lidar_module.render

    def counting(*args, **kwargs):
        calls.append(len(args[2]))
        return real(*args, **kwargs)

    monkeypatch.setattr(lidar_module, "render", counting)
    att = fit.ForwardModel(model_mesh(), metal(), inst, res.bin_edges, ("rx", "rz"), lidar=LIDAR,
                           bounds={"rx": (-1, 1), "rz": (-1, 1)}, fixed={"ry": 0.3})
    rng = np.random.default_rng(0)
    thetas = np.array([0.4, 0.2]) + 0.02 * rng.standard_normal((12, 2))
    batch = att.log_prob(thetas, meas)
    assert calls == [12]  # all walkers in one render call
    single = [att.log_prob(t, meas) for t in thetas]
    assert all(isinstance(v, float) for v in single)
    np.testing.assert_array_equal(batch, single)  # the renderer's batches equal single calls
    # material parameters: one render per distinct material and scale
    calls.clear()
    mat = fit.ForwardModel(model_mesh(), metal(), inst, res.bin_edges, ("rx", "alpha"), lidar=LIDAR,
                           bounds={"rx": (-1, 1), "alpha": (0.1, 0.6)}, fixed={"ry": 0.3, "rz": 0.2},
                           alpha_step=None)  # every alpha rendered exactly
    th = np.array([[0.40, 0.30], [0.41, 0.35], [0.39, 0.30], [0.42, 0.35], [0.40, 0.25], [0.40, 0.30]])
    batch = mat.log_prob(th, meas)
    assert sorted(calls) == [1, 2, 3]
    np.testing.assert_array_equal(batch, [mat.log_prob(t, meas) for t in th])
    # interpolated in alpha (the default for materials slow to build; asked for here): one
    # render per alpha node, the walkers of a node together; a batch equals single calls
    calls.clear()
    nodes = fit.ForwardModel(model_mesh(), metal(), inst, res.bin_edges, ("rx", "alpha"), lidar=LIDAR,
                             bounds={"rx": (-1, 1), "alpha": (0.1, 0.6)}, fixed={"ry": 0.3, "rz": 0.2},
                             alpha_step=0.05)
    batch = nodes.log_prob(th, meas)
    j = np.floor(np.log(th[:, 1]) / 0.05)
    distinct = {int(k) for jj in j for k in (jj - 1, jj, jj + 1, jj + 2)}
    assert len(calls) == len(distinct) and sum(calls) == 4 * len(th)
    np.testing.assert_allclose(batch, [nodes.log_prob(t, meas) for t in th], rtol=1e-12)
    # the material is rebuilt: alpha = 0.3 here is the fixture's own material
    np.testing.assert_array_equal(mat.expected([0.4, 0.3]), att.expected([0.4, 0.2]))


def model_mesh():
    return models.cubesat("1U", panels=None, antenna=False, detail=0)


def test_log_prob_gives_minus_inf_for_invalid_parameters(cube, monkeypatch):
    model, truth, res, inst = cube
    meas = ins.measure(res, inst, seed=3)[0]
    calls = []
    real = lidar_module.render
    monkeypatch.setattr(lidar_module, "render", lambda *a, **k: calls.append(1) or real(*a, **k))
    out = model.log_prob(np.array([[1.5, 1.0], [0.4, 3.0], [np.nan, 1.0], [0.4, np.inf]]), meas)
    np.testing.assert_array_equal(out, [-np.inf] * 4)
    assert calls == []  # nothing outside the prior is rendered
    # bounds that allow unphysical roughness: -inf from the material, no exception
    m = fit.ForwardModel(model_mesh(), metal(), inst, res.bin_edges, ("alpha",), lidar=LIDAR,
                         bounds={"alpha": (-1.0, 1.0)}, fixed={"rx": 0.4, "ry": 0.3, "rz": 0.2})
    lp = m.log_prob(np.array([[-0.5], [0.3]]), meas)
    assert lp[0] == -np.inf and np.isfinite(lp[1])
    assert m.log_prob([-0.5], meas) == -np.inf
    # shapes and data are programming errors: they raise
    with pytest.raises(pprender.Error, match="theta"):
        model.log_prob(np.zeros((3, 3)), meas)
    with pytest.raises(pprender.Error, match="counts"):
        model.log_prob(truth, ins.measure(res, inst, seed=3))  # batched: index it first
    with pytest.raises(pprender.Error, match="bin_edges"):
        model.log_prob(truth, ins.measure(res.profile[:, 1:], inst, bin_edges=res.bin_edges[1:], seed=1)[0])
    other = ins.measure(res, ins.Instrument(pulse_energy=1e-3, target_range=5e5, channels="stokes"), seed=1)
    with pytest.raises(pprender.Error, match="channels"):
        model.log_prob(truth, other[0])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(free=("rx", "tilt")), "free"),
        (dict(free=("rx",), fixed={"rx": 0.1}), "fixed"),
        (dict(free=("rx",), bounds={"rx": (1.0, -1.0)}), "bounds"),
        (dict(free=("rx",), bounds={"scale": (1.0, 2.0)}), "bounds"),
        (dict(free=("rx",), lidar=pprender.Lidar(polarization=[1, 1, 0, 0])), "polarization"),
        (dict(free=("rx",), lidar=pprender.Lidar(wavelength=532e-9)), "wavelength"),
        (dict(free=("rx",), attitude_frame="sensor"), "attitude_frame"),
        (dict(free=("alpha",), fitted_parts=["wing"]), "fitted_parts"),
    ],
)
def test_model_bad_arguments(kwargs, match):
    inst = ins.Instrument(pulse_energy=1e-3, target_range=5e5)
    with pytest.raises(pprender.Error, match=match):
        fit.ForwardModel(model_mesh(), metal(), inst, [-0.1, 0.0, 0.1], **kwargs)


def test_alpha_bounds_keep_surface_orders_buildable():
    """A fitted material with orders="surface" (pprender.materials' metals by default) exists
    only for alpha in [0.05, 1]: the default bounds are narrowed to it, given bounds outside
    are refused, naming them (a -inf wall inside the prior would be silent), and with
    alpha_step the interpolation near the ends uses only nodes inside (the quadratic through
    the three there) and refuses alpha beyond them."""
    inst = ins.Instrument(pulse_energy=1e-3, target_range=5e5)
    surf = pprender.Material("beckmann", alpha=0.3, eta=1.38 + 10.2j, orders="surface")
    # a face 1.3 deg off the line of sight: at alpha 0.05 its glint is the return
    fixed = {"rx": 0.02, "ry": 0.01, "rz": 0.0}
    edges = [-0.1, 0.0, 0.1]
    m = fit.ForwardModel(model_mesh(), surf, inst, edges, ("alpha",), lidar=LIDAR, fixed=fixed)
    assert m.alpha_step == 0.05
    np.testing.assert_array_equal(m.bounds[0], [0.05, 1.0])
    # between 0.05 and the first node above it (exp(-59 h) = 0.0523) and one node further:
    # only nodes >= 0.05 are built, and the result is the quadratic through the first three
    calls = []
    real = m._rendered
    m._rendered = lambda full: calls.append(full[:, 3].copy()) or real(full)  # type: ignore[method-assign]
    got = m.expected([[0.0505], [0.054]])
    nodes = np.concatenate(calls)
    assert nodes.min() >= 0.05 and np.allclose(np.unique(nodes), np.exp(np.array([-59, -58, -57]) * 0.05))
    # below the materials' range: refused by the bounds, and no value (not an
    # extrapolation) from the interpolation itself
    with pytest.raises(pprender.Error, match="bounds"):
        m.expected([[0.0499]])
    full = m._base[None, :].copy()
    full[:, 3] = 0.0499
    out, ok, _ = m._expected_full(full)
    assert not ok[0] and np.all(np.isnan(out[0]))
    # against exact renders (alpha_step=None): measured 2.0e-5 of the peak bin at 0.0505
    # (the quadratic extrapolated 0.07 of a node below its first node), 4.8e-7 at 0.054,
    # where Catmull-Rom inside the range gives 3.0e-6 at 0.06; the bound is 10x the worst
    exact = fit.ForwardModel(model_mesh(), surf, inst, edges, ("alpha",), lidar=LIDAR, fixed=fixed,
                             alpha_step=None)
    want = exact.expected([[0.0505], [0.054]])
    assert np.all(want.sum(axis=(1, 2)) > 0)
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-4 * want.max())
    for bad in ((0.01, 0.5), (0.1, 1.2)):
        with pytest.raises(pprender.Error, match=r"bounds for 'alpha'.*orders=\"surface\""):
            fit.ForwardModel(model_mesh(), surf, inst, edges, ("alpha",), lidar=LIDAR, fixed=fixed,
                             bounds={"alpha": bad})
    # a material with the seed's orders keeps the default bounds
    seed = fit.ForwardModel(model_mesh(), metal(), inst, edges, ("alpha",), lidar=LIDAR, fixed=fixed)
    np.testing.assert_array_equal(seed.bounds[0], fit.DEFAULT_BOUNDS["alpha"])


# ---------------------------------------------------------------------- Fisher information


def test_fisher_information_equals_the_likelihood_curvature(cube):
    """For data equal to the expectation, -d2 log L / d theta2 = sum (d lam)^2 / lam = F.
    Scale is smooth (the image grid scales with the mesh), so a parabola through log L
    measures the curvature independently of F's formula."""
    model, truth, res, inst = cube
    sub = fit.ForwardModel(model_mesh(), metal(), inst.scaled_to(1e7, res), res.bin_edges, ("scale",),
                           lidar=LIDAR, fixed={"rx": 0.4, "ry": 0.3, "rz": 0.2})
    data = np.round(sub.expected([1.0])).astype(np.int64)  # 1e7 counts: rounding moves log L by < 1e-3
    f = fit.fisher_information(sub, [1.0])[0, 0]  # sd = 1/sqrt(F) = 7.8e-5
    # The renderer accumulates in float32: at 1e7 counts log L is noisy by ~0.3 between
    # nearby scales, so the parabola spans +-1e-3 (+-13 sd, log L falls by ~85); on a
    # symmetric grid the cubic term does not bias the quadratic coefficient.
    x = 1.0 + 1e-3 * np.linspace(-1.0, 1.0, 9)
    ll = sub.log_likelihood(x[:, None], data)
    curvature = -2.0 * np.polyfit(x - 1.0, ll, 2)[0]
    # 1 %: quartic terms over the window and the float32 noise (measured agreement 1e-5)
    assert curvature == pytest.approx(f, rel=0.01)


# ---------------------------------------------------------------------- nlopt


@pytest.mark.parametrize("algorithm", ["BOBYQA", "NELDERMEAD"])
def test_nlopt_recovers_noise_free_parameters(cube, algorithm):
    model, truth, res, inst = cube
    data = np.round(model.expected(truth)).astype(np.int64)
    sd = np.sqrt(np.diag(np.linalg.inv(fit.fisher_information(model, truth))))  # 7e-4 rad, 2e-3
    r = fit.fit_nlopt(model, data, truth + np.array([0.05, -0.05]), algorithm, initial_step=0.02)
    # Noise-free up to rounding the counts to integers (<= 0.5 per bin), which moves the
    # maximum by ~sd / sqrt(12 lam_bin) ~ 0.03 sd (measured 0.02 sd in rx, 0.04 sd in scale,
    # both algorithms); rasterization steps (1e-4 rad apart, below 0.01 in log L at 2e4
    # counts) do not trap the optimizers here. Tolerance 0.1 sd: 7e-5 rad and 2e-4.
    assert np.all(np.abs(r.x - truth) < 0.1 * sd), (r.x - truth) / sd
    assert r.log_likelihood >= model.log_likelihood(truth, data) - 1e-6
    assert r.n_evaluations < 300 and r.names == ("rx", "scale")


def test_nlopt_noisy_fits_fall_within_three_sigma(cube):
    model, truth, res, inst = cube
    z = []
    for seed in (0, 1, 2):
        meas = ins.measure(res, inst, seed=seed)[0]
        r = fit.fit_nlopt(model, meas, truth + np.array([0.03, 0.03]), "BOBYQA", initial_step=0.02)
        sd = np.sqrt(np.diag(np.linalg.inv(fit.fisher_information(model, r.x))))
        z.append((r.x - truth) / sd)
    z = np.array(z)
    # Cramer-Rao standard deviations from the Fisher information at the estimate; each
    # error within 3 sd (measured |z| <= 2.4 over seeds 0-5)
    assert np.all(np.abs(z) < 3.0), z


def test_nlopt_multistart_cobyla_and_bad_inputs(cube):
    model, truth, res, inst = cube
    meas = ins.measure(res, inst, seed=4)[0]
    x0 = truth + np.array([0.05, 0.05])
    r = fit.fit_nlopt(model, meas, x0, "COBYLA", initial_step=0.02, n_starts=2, seed=1, maxeval=60, diagnose=False)
    assert len(r.starts) == 2 and r.n_evaluations <= 120 and not r.diagnosed
    assert np.all((r.x >= model.lower) & (r.x <= model.upper))
    # COBYLA improves on its start (it can stall on this likelihood's ridges: BOBYQA is the default)
    assert r.log_likelihood > model.log_likelihood(x0, meas)
    with pytest.raises(pprender.Error, match="algorithm"):
        fit.fit_nlopt(model, meas, truth, "LBFGS")
    with pytest.raises(pprender.Error, match="x0"):
        fit.fit_nlopt(model, meas, [2.0, 1.0])
    with pytest.raises(pprender.Error, match="x0"):
        fit.fit_nlopt(model, meas, [0.4])


# ---------------------------------------------------------------------- emcee


def test_emcee_posterior_covers_the_truth_and_matches_fisher(cube):
    model, truth, res, inst = cube
    meas = ins.measure(res, inst, seed=11)[0]
    n_walkers, n_steps = 8, 100
    sampler = fit.sample_emcee(model, meas, truth, n_walkers, n_steps, seed=5)
    chain = sampler.get_chain(discard=30, flat=True)
    mean, std = chain.mean(axis=0), chain.std(axis=0)
    # the truth lies within the 3-sigma credible interval (measured z = 2.4 in rx, 1.4 in
    # scale for this data set: the posterior is centred on the ML estimate, not the truth)
    assert np.all(np.abs(mean - truth) < 3.0 * std), (mean - truth) / std
    # the sampler agrees with the maximum-likelihood fit and with the Laplace approximation
    # (autocorrelation ~13 steps: ~40 independent samples, so std estimates good to ~12 %)
    ml = fit.fit_nlopt(model, meas, truth, "BOBYQA", initial_step=0.02).x
    assert np.all(np.abs(mean - ml) < 0.5 * std), (mean - ml) / std
    sd_fisher = np.sqrt(np.diag(np.linalg.inv(fit.fisher_information(model, ml))))
    np.testing.assert_allclose(std, sd_fisher, rtol=0.35)
    # reproducible: the same seed repeats the chain (first steps of a shorter run)
    again = fit.sample_emcee(model, meas, truth, n_walkers, 3, seed=5)
    np.testing.assert_array_equal(again.get_chain(), sampler.get_chain()[:3])
    with pytest.raises(pprender.Error, match="n_walkers"):
        fit.sample_emcee(model, meas, truth, 3, 10, seed=1)
