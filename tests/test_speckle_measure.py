"""Speckle wired into the instrument, measure() and the fits (issue 26).

Oracles, independent of the code under test: today's Poisson draw (``rng.poisson`` of the
expected counts with the same seed) for ``speckle=None``; the closed-form count moments of
:func:`pprender.inverse.speckle.count_moments` (law of total covariance, Wishart moments)
and, through the jitter, ``Var k_j = mu_j + sum_i K_ji^2 Var I_i`` written out here; the
geometry of a flat plate for the illuminated area (its area face-on; a tilted plate's
projected strips, integrated on a fine grid with the Gaussian pulse); a save/load round
trip; Monte Carlo spreads of maximum-likelihood estimates for the Cramer-Rao sd.

Sampling tolerances: with ``n`` draws a sample mean's standard error is ``sqrt(var / n)``
and a sample variance's relative standard error ``sqrt((kappa - 1) / n)``, ``kappa`` the
kurtosis (at most ``3 + 6 / M`` for the gamma intensity; the counts' is smaller): the
tests allow 5 standard errors.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import erf

import pprender
from pprender import fit, models
from pprender.inverse import instrument as ins
from pprender.inverse import speckle as sp
from pprender.inverse.speckle import Speckle

pytestmark = pytest.mark.filterwarnings("ignore::pprender.inverse.instrument.PileUpWarning")

# per bin: a mirror-like (polarized) and a depolarizing part, physical (a convex combination)
PROFILE = np.array([0.3, 1.0, 0.1])[:, None, None] * np.diag([1.0, 0.5, -0.5, -0.5])
EDGES = np.array([0.0, 0.1, 0.2, 0.3])


def _inst(**kw):
    base = dict(pulse_energy=0.2, target_range=1e6, n_pulses=4, background_rate=2e9)
    base.update(kw)
    return ins.Instrument(**base)


def metal() -> pprender.Material:
    return pprender.Material("beckmann", alpha=0.3, eta=1.38 + 10.2j, terms=["single"])


def lambertian() -> pprender.Material:
    return pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0j, terms=["diffuse"], diffuse_albedo=0.5)


# ---------------------------------------------------------------------- the option


def test_no_speckle_is_todays_poisson_draw_bit_for_bit() -> None:
    inst = _inst(channels="stokes", jitter=30e-12)
    m = ins.measure(PROFILE, inst, bin_edges=EDGES, seed=7)
    want = np.random.default_rng(7).poisson(ins.expected_counts(PROFILE, inst, bin_edges=EDGES)).astype(np.int64)
    np.testing.assert_array_equal(m.counts, want)
    assert m.speckle_dof is None and inst.speckle is None
    # the saved layout of a speckle-free measurement is unchanged: no speckle variable or key
    ds = m.to_xarray()
    assert "speckle_dof" not in ds.variables and '"speckle"' not in ds.attrs["instrument"]


@pytest.mark.parametrize("channels, jitter", [("stokes", 0.0), ("mueller", 0.0), ("co_cross_linear", 150e-12)])
def test_speckled_counts_follow_the_closed_form_moments(channels, jitter, rng) -> None:
    """Mean, variance and the covariance of channels that share a field, over 20000 draws
    (5000 for the 24 Mueller channels),
    against count_moments; through a jitter blur against sum_i K_ji^2 Var(I_i)."""
    inst = _inst(channels=channels, jitter=jitter, speckle=Speckle(dof=1.5, correlation=0.3))
    ch = inst.channels
    n = 5_000 if channels == "mueller" else 20_000
    m = ins.measure(np.broadcast_to(PROFILE, (n,) + PROFILE.shape), inst, bin_edges=EDGES, rng=rng)
    unique, gi = sp.generator_groups(ch.generators_array)
    stokes = sp.received_stokes(PROFILE * inst.counts_per_cross_section, unique)
    share = np.array([ch.pulse_share[list(gi).index(g)] for g in range(len(unique))])
    dof = sp.accumulated_dof(1.5, inst.n_pulses * share, 0.3) * np.ones((3, 1))
    bg = inst.background_counts(EDGES)
    mean, cov = sp.count_moments(stokes, ch.rows, gi, dof, bg)
    if jitter > 0:
        k = ins.jitter_matrix(EDGES, EDGES, inst.jitter_range)
        i_mean, i_cov = sp.intensity_moments(stokes, ch.rows, gi, dof)
        mean = k @ i_mean + bg
        # bins are independent speckle draws: the blurred intensity's covariance adds K^2-weighted
        cov = np.einsum("ji,icd->jcd", k * k, i_cov) + mean[..., :, None] * np.eye(len(ch))
    np.testing.assert_allclose(m.expected[0], mean, rtol=1e-9)
    var = np.diagonal(cov, axis1=-2, axis2=-1)
    assert np.max(var / mean) > 5  # speckle, not shot noise, dominates
    assert np.max(np.abs(m.counts.mean(0) - mean) / np.sqrt(var / n)) < 5
    assert np.max(np.abs(m.counts.var(0) / var - 1)) < 5 * math.sqrt((2 + 6 / 1.5) / n)
    if channels == "stokes":  # H and V of one field: Cov = tr(A_H J A_V J) / M (0 for a depolarized return)
        c_hv = np.mean((m.counts[:, :, 0] - mean[:, 0]) * (m.counts[:, :, 1] - mean[:, 1]), axis=0)
        sd = np.sqrt(var[:, 0] * var[:, 1] / n) * 3  # the product's sd, kurtosis <= 9
        assert np.all(np.abs(c_hv - cov[:, 0, 1]) < 5 * sd)
        # the recorded marginal dof: ideal polarizers keep the field's
        np.testing.assert_allclose(m.speckle_dof[0], dof[:, gi], rtol=1e-12)
    if jitter > 0:
        i_mean, _ = sp.intensity_moments(stokes, ch.rows, gi, dof)
        np.testing.assert_allclose(m.speckle_dof[0], sp.blurred_dof(k, i_mean, dof[:, gi]), rtol=1e-12)


def test_target_area_gives_goodmans_dof_and_dof_inf_is_poisson(rng) -> None:
    inst = _inst(speckle=Speckle(target_area=[0.5, 2.0, 0.1]), n_pulses=3)
    m = ins.measure(PROFILE, inst, bin_edges=EDGES, rng=rng)
    want = 3 * sp.speckle_dof(inst.aperture_diameter, inst.wavelength, inst.target_range, [0.5, 2.0, 0.1])
    np.testing.assert_allclose(m.speckle_dof, np.repeat(want[:, None], 2, axis=1), rtol=1e-12)
    one = ins.measure(PROFILE, _inst(speckle=Speckle(target_area=0.5), n_pulses=3), bin_edges=EDGES, seed=1)
    np.testing.assert_allclose(one.speckle_dof[0], want[0], rtol=1e-12)
    # dof = inf: the Poisson law (mean = variance), recorded as inf
    m = ins.measure(np.broadcast_to(PROFILE, (4000,) + PROFILE.shape), _inst(speckle=Speckle(dof=math.inf)),
                    bin_edges=EDGES, rng=rng)
    assert np.all(np.isinf(m.speckle_dof))
    lam = m.expected[0]
    assert np.max(np.abs(m.counts.var(0) / lam - 1)) < 5 * math.sqrt(2 / 4000)


def test_measurement_with_speckle_saves_and_loads(tmp_path) -> None:
    inst = _inst(channels="mueller", jitter=40e-12, speckle=Speckle(target_area=(0.5, 2.0, 0.1), correlation=0.2))
    m = ins.measure(np.stack([PROFILE, 0.5 * PROFILE]), inst, bin_edges=EDGES, seed=3)
    m.save(tmp_path / "m.zarr")
    back = ins.Measurement.load(tmp_path / "m.zarr")
    assert back.instrument == inst and back.instrument.speckle == inst.speckle
    np.testing.assert_array_equal(back.counts, m.counts)
    np.testing.assert_array_equal(back.speckle_dof, m.speckle_dof)
    np.testing.assert_array_equal(m[1].speckle_dof, m.speckle_dof[1])
    # inf dof survive JSON and the array store; a scalar area and pulse_fwhm=None too
    inst2 = _inst(speckle=Speckle(dof=math.inf, pulse_fwhm=None))
    m2 = ins.measure(PROFILE, inst2, bin_edges=EDGES, seed=1)
    back2 = ins.Measurement.from_xarray(m2.to_xarray())
    assert back2.instrument == inst2
    np.testing.assert_array_equal(back2.speckle_dof, m2.speckle_dof)


def test_files_with_the_new_fields_are_format_2_and_refused_by_a_version_1_reader() -> None:
    """A measurement with speckle is written as format 2, which a pprender reading up to
    version 1 refuses with "newer pprender" (instead of failing on unknown instrument
    fields); one without speckle, detector or atmosphere stays format 1."""
    from pprender import _io

    plain = ins.measure(PROFILE, _inst(), bin_edges=EDGES, seed=1).to_xarray()
    assert plain.attrs["format"] == "pprender.Measurement/1"
    ds = ins.measure(PROFILE, _inst(speckle=Speckle(dof=3.0)), bin_edges=EDGES, seed=1).to_xarray()
    assert ds.attrs["format"] == "pprender.Measurement/2"
    with pytest.raises(pprender.Error, match="newer pprender"):
        _io.check_format(ds.attrs, "Measurement", 1, "file")
    assert ins.Measurement.from_xarray(ds).instrument.speckle == Speckle(dof=3.0)


# ---------------------------------------------------------------------- illuminated area


@pytest.fixture(scope="module")
def plates():
    """A 1 m x 0.5 m Lambertian plate, face-on and tilted by 0.6 rad about X, rendered with
    images and ranges (64 px, 2x2 supersampling), bins of 2.5 cm and 10 cm."""
    mesh = models.plate(1.0, 0.5, thickness=1e-4)
    scene = pprender.Scene(mesh, lambertian())
    rot = np.stack([np.eye(3), Rotation.from_rotvec([0.6, 0.0, 0.0]).as_matrix()])
    out = {}
    for bw in (0.025, 0.1):
        lid = pprender.Lidar(resolution=64, supersampling=2, bin_width=bw)
        out[bw] = pprender.render(scene, lid, rot, outputs=("profile", "mueller", "range"))
    return out


def _plate_area_oracle(edges, tilt, fwhm_s, width=1.0, height=0.5):
    """Effective area per bin of a uniformly bright tilted plate: strips of the projected
    plate, r = -y' tan(tilt) (y' the projected coordinate), each spread over the bins by the
    Gaussian pulse; integrated on a fine grid in y' (the brightness is uniform, so
    A_j = (int w_j)^2 / int w_j^2 over the projected area)."""
    y = np.linspace(-0.5, 0.5, 20001)[1:-1:2] * height * math.cos(tilt)  # midpoints
    dy = height * math.cos(tilt) / len(y)
    r = -y * math.tan(tilt)
    sigma = pprender.SPEED_OF_LIGHT * fwhm_s / 2 / (2 * math.sqrt(2 * math.log(2)))
    cdf = 0.5 * (1 + erf((edges[:, None] - r[None, :]) / (sigma * math.sqrt(2))))
    w = np.diff(cdf, axis=0)
    num, den = (w.sum(1) * dy * width) ** 2, (w * w).sum(1) * dy * width
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def test_illuminated_area_of_a_flat_plate(plates) -> None:
    for bw, res in plates.items():
        area = sp.illuminated_area(res)  # the default Lidar pulse, 100 ps
        prof = res.profile[..., 0, 0]
        for i, tilt in enumerate((0.0, 0.6)):
            strong = prof[i] > 0.02 * prof[i].max()
            want = _plate_area_oracle(res.bin_edges, tilt, 100e-12)
            # pixelization of the plate's outline (64 px over 1.1 m: ~2 % of its area at the
            # edges, coverage weights keep the error below that)
            np.testing.assert_allclose(area[i][strong], want[strong], rtol=0.02)
        # face-on: the plate's area in every bin its return reaches, the pulse spreading it
        assert np.all(np.abs(area[0][prof[0] > 0.02 * prof[0].max()] / 0.5 - 1) < 0.02)
    # by range only (no pulse): all of a face-on plate's pixels in one bin
    a0 = sp.illuminated_area(plates[0.1], pulse_fwhm=None)[0]
    assert np.count_nonzero(a0) == 1 and a0.max() == pytest.approx(0.5, rel=0.02)


def test_measure_takes_the_area_from_the_render(plates) -> None:
    res = plates[0.1]
    inst = _inst(pulse_energy=1e-3, target_range=2e5, speckle=Speckle(), n_pulses=2)
    m = ins.measure(res, inst, seed=0)
    pulse = inst.speckle.pulse_dof(inst.aperture_diameter, inst.wavelength, inst.target_range,
                                   sp.illuminated_area(res))
    np.testing.assert_allclose(m.speckle_dof, np.repeat(2 * pulse[..., None], 2, axis=-1), rtol=1e-12)
    seen = sp.illuminated_area(res) > 0
    assert np.all(np.isfinite(m.speckle_dof[seen])) and np.all(np.isinf(m.speckle_dof[~seen]))
    # a Stokes render (one transmitted state) gives the same areas from its S0 image
    lid = pprender.Lidar(resolution=64, supersampling=2, bin_width=0.1, polarization=inst.channels.transmit)
    st = pprender.render(pprender.Scene(models.plate(1.0, 0.5, thickness=1e-4), lambertian()), lid, np.eye(3)[None],
                         outputs=("profile", "stokes", "range"))
    np.testing.assert_allclose(sp.illuminated_area(st)[0], sp.illuminated_area(res)[0], rtol=1e-5, atol=1e-12)
    ms = ins.measure(st, inst, seed=0)
    np.testing.assert_allclose(ms.speckle_dof[0], m.speckle_dof[0], rtol=1e-5)
    # a profile-only render with the render's own area output gives the same degrees of
    # freedom (face-on plate: output and image-derived area agree to 5e-8; rtol 1e-5 for
    # the f32 kernel against the f64 image sums)
    lid_m = pprender.Lidar(resolution=64, supersampling=2, bin_width=0.1)
    po = pprender.render(pprender.Scene(models.plate(1.0, 0.5, thickness=1e-4), lambertian()), lid_m,
                         np.eye(3)[None], outputs=("profile", "illuminated_area"))
    assert po.mueller is None and po.illuminated_area is not None
    mp = ins.measure(po, inst, seed=0)
    np.testing.assert_allclose(mp.speckle_dof[0][seen[0]], m.speckle_dof[0][seen[0]], rtol=1e-5)
    # a profile without images, or an array, cannot give the area: the error says what to do
    bare = pprender.RenderResult(cross_section=res.cross_section, bin_edges=res.bin_edges,
                                 pixel_size=res.pixel_size, extent=res.extent, device="", profile=res.profile)
    for profile, kw in ((bare, {}), (res.profile, {"bin_edges": res.bin_edges})):
        with pytest.raises(pprender.Error, match=r'invalid profile.*outputs=\("profile", "illuminated_area"\)'):
            ins.measure(profile, inst, seed=0, **kw)


# ---------------------------------------------------------------------- fits


@pytest.fixture(scope="module")
def plate_fit():
    """A metal plate face-on 0.1 m in front of the body origin, its size ``scale`` free
    (bounds 0.7-1.5: its return stays in the range bin [-0.2, 0] m, > 10 pulse sd from the
    edges), so that the expected signal is ``scale^2`` times that at 1 (checked). 5000
    signal counts, per-pulse dof 5 over 20 pulses (M = 100): the speckle variance s^2 / M
    = 2.5e5 dominates the shot noise s."""
    mesh = models.plate(0.5, 0.5)
    mesh.apply_translation([0.0, 0.0, 0.1])
    lid = pprender.Lidar(resolution=24, bin_width=0.2)
    res = pprender.render(pprender.Scene(mesh, metal()), lid, np.eye(3)[None], outputs=("profile",))

    def make(energy):
        inst = ins.Instrument(pulse_energy=energy, target_range=5e5, background_rate=1e6, n_pulses=20,
                              speckle=Speckle(dof=5.0))
        return fit.ForwardModel(mesh, metal(), inst, res.bin_edges, ("scale",), lidar=lid, bounds={"scale": (0.7, 1.5)})

    model = make(1e-3)
    s1 = (model.expected([1.0]) - model._background).sum()
    model = make(1e-3 * 5000 / s1)
    return model, mesh, lid


def test_fit_likelihood_is_poissons_without_speckle(plate_fit, rng) -> None:
    model, mesh, lid = plate_fit
    edges = model.bin_edges
    inf = fit.ForwardModel(mesh, metal(), ins.Instrument(**{**_fields(model.instrument), "speckle": Speckle(dof=math.inf)}),
                           edges, ("scale",), lidar=lid, bounds={"scale": (0.7, 1.5)})
    none = fit.ForwardModel(mesh, metal(), ins.Instrument(**{**_fields(model.instrument), "speckle": None}),
                            edges, ("scale",), lidar=lid, bounds={"scale": (0.7, 1.5)})
    th = np.array([[0.9], [1.0], [1.2]])
    k = rng.poisson(none.expected([1.0]))
    np.testing.assert_array_equal(inf.log_likelihood(th, k), none.log_likelihood(th, k))
    np.testing.assert_array_equal(inf.log_prob(th, k), none.log_prob(th, k))
    np.testing.assert_allclose(fit.fisher_information(inf, [1.0]), fit.fisher_information(none, [1.0]), rtol=1e-12)
    # finite dof: the speckle likelihood of the model's signal and per-channel dof
    lam = model.expected(th)
    s = lam - model._background
    m = model.speckle_dof(th)
    # ideal polarizers, no jitter: the per-pulse dof times the pulses (the renderer's float32
    # leaves ~1e-6 of the signal where a channel is dark)
    np.testing.assert_allclose(m[s > 1e-3 * s.max()], 100.0, rtol=1e-12)
    np.testing.assert_allclose(model.log_likelihood(th, k), sp.speckle_log_likelihood(k, s, model._background, m),
                               rtol=1e-13)


def _fields(inst):
    return {f: getattr(inst, f) for f in inst.__dataclass_fields__}


def test_speckle_fit_recovers_the_truth_within_its_cramer_rao_sd(plate_fit) -> None:
    """300 speckled measurements at scale 1: the maximum of the speckle likelihood (the
    signal is scale^2 times the model's at 1, checked) spreads as the speckle-aware
    Cramer-Rao sd says; the Poisson Fisher sd is too small by sqrt(1 + s / M) = 7.1 (s =
    5000 counts in one bin and channel, M = 100). One full fit_nlopt with its diagnosis
    lands within 3 sd and is trustworthy."""
    model, mesh, lid = plate_fit
    s1 = model.expected([1.0]) - model._background
    np.testing.assert_allclose(model.expected([1.3]) - model._background, 1.69 * s1, rtol=1e-6, atol=1e-9)
    res = pprender.render(model.scene((None, None, None, None)), model.lidar, model.rotations([1.0]),
                          outputs=("profile",), settings=model.settings)
    n = 300
    meas = ins.measure(np.broadcast_to(res.profile[0], (n,) + res.profile.shape[1:]), model.instrument,
                       bin_edges=res.bin_edges, seed=11)
    np.testing.assert_allclose(meas.expected[0], model.expected([1.0]), rtol=1e-9)
    k, bg, m = meas.counts, model._background, model.speckle_dof([1.0])

    # vectorized golden-section search of the maximum over scale, every draw at once
    def nll(x):
        return -sp.speckle_log_likelihood(k, x[:, None, None] ** 2 * s1, bg, m)

    a, b = np.full(n, 0.7), np.full(n, 1.5)
    g = (math.sqrt(5) - 1) / 2
    for _ in range(45):  # (0.618)^45 * 1.5 ~ 6e-10
        c, d = b - g * (b - a), a + g * (b - a)
        left = nll(c) < nll(d)
        a, b = np.where(left, a, c), np.where(left, d, b)
    est = 0.5 * (a + b)
    sd = 1 / math.sqrt(fit.fisher_information(model, [1.0])[0, 0])
    poisson = fit.ForwardModel(mesh, metal(), ins.Instrument(**{**_fields(model.instrument), "speckle": None}),
                               model.bin_edges, ("scale",), lidar=lid, bounds={"scale": (0.7, 1.5)})
    sd_poisson = 1 / math.sqrt(fit.fisher_information(poisson, [1.0])[0, 0])
    spread = est.std(ddof=1)
    # unbiased within 4 standard errors of the mean; the spread within 15 % of the speckle
    # Cramer-Rao sd (the sd of a sample sd is 4 % at n = 300; fisher_weight's 1 / variance
    # is a lower bound, exact here to 1e-3: no background to speak of)
    assert abs(est.mean() - 1.0) < 4 * spread / math.sqrt(n)
    assert 0.85 < spread / sd < 1.15, (spread, sd)
    assert 6.0 < spread / sd_poisson < 8.5, (spread, sd_poisson)
    r = fit.fit_nlopt(model, meas[0], [1.1], initial_step=0.05)
    assert r.trustworthy, r.problems
    assert abs(r.x[0] - est[0]) < 1e-4 and abs(r.x[0] - 1.0) < 3 * sd
    assert r.sd[0] == pytest.approx(1 / math.sqrt(fit.fisher_information(model, r.x)[0, 0]))


def test_diagnosis_draws_speckled_counts(plate_fit) -> None:
    """At the truth, the speckle model's goodness-of-fit p-values are those of a correct
    model (none below the 1e-3 limit in 8 measurements; measured 0.014-0.99), while the
    Poisson model's deviance rejects most of the same speckled data (the counts spread 7x
    its sd; measured 6 of 8 flagged)."""
    model, mesh, lid = plate_fit
    poisson = fit.ForwardModel(mesh, metal(), ins.Instrument(**{**_fields(model.instrument), "speckle": None}),
                               model.bin_edges, ("scale",), lidar=lid, bounds={"scale": (0.7, 1.5)})
    res = pprender.render(model.scene((None, None, None, None)), model.lidar, model.rotations([1.0]),
                          outputs=("profile",), settings=model.settings)
    meas = ins.measure(np.broadcast_to(res.profile[0], (8,) + res.profile.shape[1:]), model.instrument,
                       bin_edges=res.bin_edges, seed=5)
    p_speckle, p_poisson = [], []
    for i in range(8):
        for mod, out in ((model, p_speckle), (poisson, p_poisson)):
            r = fit.FitResult(x=np.array([1.0]), log_likelihood=float(mod.log_likelihood([1.0], meas[i])),
                              n_evaluations=0, names=("scale",), algorithm="", return_code=0, message="", seconds=0.0)
            out.append(fit.diagnose_fit(mod, meas[i], r, seed=i).deviance_p)
    assert min(p_speckle) > fit.DEVIANCE_P_LIMIT, p_speckle
    assert sum(p < fit.DEVIANCE_P_LIMIT for p in p_poisson) >= 5, p_poisson


def test_per_bin_speckle_fits_take_the_measurements_dof(plate_fit) -> None:
    model, mesh, lid = plate_fit
    inst = ins.Instrument(**{**_fields(model.instrument), "speckle": Speckle(target_area=tuple(np.linspace(0.1, 0.6, len(model.bin_edges) - 1)))})
    per_bin = fit.ForwardModel(mesh, metal(), inst, model.bin_edges, ("scale",), lidar=lid, bounds={"scale": (0.7, 1.5)})
    res = pprender.render(per_bin.scene((None, None, None, None)), per_bin.lidar, per_bin.rotations([1.0]),
                          outputs=("profile",), settings=per_bin.settings)
    meas = ins.measure(res, inst, seed=2)[0]
    np.testing.assert_array_equal(per_bin.speckle_dof([1.0], meas), meas.speckle_dof)
    s = per_bin.expected([1.0]) - per_bin._background
    assert per_bin.log_likelihood([1.0], meas) == pytest.approx(
        sp.speckle_log_likelihood(meas.counts, s, per_bin._background, meas.speckle_dof), rel=1e-13)
    with pytest.raises(pprender.Error, match="invalid data.*Measurement"):
        per_bin.log_likelihood([1.0], meas.counts)


# ---------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: Speckle(dof=0.5), "dof"),
        (lambda: Speckle(dof=math.nan), "dof"),
        (lambda: Speckle(dof="2"), "dof"),
        (lambda: Speckle(dof=True), "dof"),
        (lambda: Speckle(dof=2.0, target_area=1.0), "dof/target_area"),
        (lambda: Speckle(target_area=[1.0, -1.0]), "target_area"),
        (lambda: Speckle(target_area=[[1.0]]), "target_area"),
        (lambda: Speckle(target_area=math.inf), "target_area"),
        (lambda: Speckle(correlation=1.5), "correlation"),
        (lambda: Speckle(correlation=None), "correlation"),
        (lambda: Speckle(pulse_fwhm=0.0), "pulse_fwhm"),
        (lambda: Speckle.from_params({"dof": 2.0, "size": 1}), "speckle settings"),
        (lambda: _inst(speckle={"dof": 2.0}), "speckle"),
        (lambda: ins.measure(PROFILE, _inst(speckle=Speckle(target_area=(1.0, 2.0))), bin_edges=EDGES), "speckle"),
        (lambda: sp.illuminated_area(PROFILE), "result"),
        (lambda: sp.illuminated_area(pprender.RenderResult(np.zeros((1, 4, 4)), EDGES, 0.1, 1.0, "")), "result"),
    ],
)
def test_bad_input_names_the_parameter(call, name) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(pprender.Error, match=f"invalid {name}"):
            call()
