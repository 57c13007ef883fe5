"""The detector and the atmosphere in the instrument, the measurement and the fits.

Oracles independent of the code under test: the Poisson draws of earlier versions
(``numpy.random.default_rng(seed).poisson``), Coates' closed form written out here, Kasten
& Young's air-mass formula written out here, the mixed-Poisson variance
``lam + lam^2 sigma_I^2 / n``, the variance of the Monte Carlo score for the Fisher
information, and save/load round trips.

Fit problem: a Lambertian sphere (radius 0.3 m, resolution 24) whose free parameter is its
size ``scale`` (cross-section ~ scale^2), seen by a photon counter with a dead time longer
than the range gate (one event per pulse) at 1.5 expected photo-electrons per pulse and
channel: heavily piled up.
"""

from __future__ import annotations

import functools
import json
import math
import warnings

import numpy as np
import pytest

import pprender
from pprender import fit, models
from pprender import instrument as ins
from pprender.inverse.atmosphere import Atmosphere
from pprender.inverse.detector import Detector, SaturationWarning, record, record_log_likelihood

C = 299_792_458.0
EDGES = np.linspace(-0.3, 0.3, 7)  # 6 bins, gate 4 ns


def stokes_profile(weights, n_lead=None):
    """(..., B, 4) unpolarized-to-partly-polarized Stokes profile, weights per bin (m^2)."""
    w = np.asarray(weights, dtype=np.float64)
    p = w[:, None] * np.array([1.0, 0.4, 0.1, 0.0])
    return p if n_lead is None else np.broadcast_to(p, (n_lead,) + p.shape).copy()


def mueller_profile(weights):
    w = np.asarray(weights, dtype=np.float64)
    return w[:, None, None] * np.diag([1.0, 0.5, -0.5, -0.3])


# ---------------------------------------------------------------------- defaults


@pytest.mark.parametrize("preset", ins.CHANNEL_PRESETS)
def test_defaults_are_todays_poisson_draws_bit_for_bit(preset):
    inst = ins.Instrument(pulse_energy=5e-6, target_range=1e5, channels=preset, n_pulses=400, background_rate=1e6)
    prof = mueller_profile([0.0, 1e-3, 3e-3, 2e-3, 5e-4, 0.0])
    m = ins.measure(prof, inst, bin_edges=EDGES, seed=11)
    assert m.counts.sum() > 20  # up to 0.07 photo-electrons per pulse and bin
    ref = np.random.default_rng(11).poisson(m.expected).astype(np.int64)
    assert m.counts.dtype == np.int64 and np.array_equal(m.counts, ref)
    # an ideal Detector() and a vacuum Atmosphere() are the same model: the same draws
    both = ins.Instrument(pulse_energy=5e-6, target_range=1e5, channels=preset, n_pulses=400, background_rate=1e6,
                          detector=Detector(), atmosphere=Atmosphere())
    m2 = ins.measure(prof, both, bin_edges=EDGES, seed=11)
    assert np.array_equal(m2.counts, ref) and np.array_equal(m2.expected, m.expected)
    # and files without them carry no detector / atmosphere settings
    params = json.loads(m.to_xarray().attrs["instrument"])
    assert "detector" not in params and "atmosphere" not in params


# ---------------------------------------------------------------------- Coates


def coates_p(lam_pulse):
    """Coates (1968) per bin: exp(-sum_{j<b} lam_j) (1 - exp(-lam_b)), written out."""
    out = np.empty_like(lam_pulse)
    before = np.zeros(lam_pulse.shape[1])
    for b in range(lam_pulse.shape[0]):
        out[b] = np.exp(-before) * (1.0 - np.exp(-lam_pulse[b]))
        before = before + lam_pulse[b]
    return out


def test_coates_measurement_matches_the_closed_form_mean():
    n_pulses, n_draws = 5000, 400
    det = Detector(dead_time=1e-6)  # 1 us >= the 4 ns gate: one event per pulse
    base = ins.Instrument(pulse_energy=1e-3, target_range=1e5, n_pulses=n_pulses)
    prof1 = stokes_profile([0.05, 0.3, 0.8, 0.1, 1.2, 0.4])
    # pulse energy giving 0.05 .. 1.2 expected photo-electrons per pulse in the co channel
    base = ins.Instrument(pulse_energy=1e-3 * n_pulses / base.counts_per_cross_section / 0.7, target_range=1e5,
                          n_pulses=n_pulses)
    inst = ins.Instrument(pulse_energy=base.pulse_energy, target_range=1e5, n_pulses=n_pulses, detector=det)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ins.PileUpWarning)  # a dead time models pile-up: no warning
        m = ins.measure(stokes_profile(prof1[:, 0], n_draws), inst, bin_edges=EDGES, seed=3)
    lam_pulse = m.expected[0] / n_pulses
    assert lam_pulse.max() > 1.0  # heavily piled up
    p = coates_p(lam_pulse)
    mean = m.counts.mean(axis=0)
    se = np.sqrt(n_pulses * p * (1 - p) / n_draws)
    z = (mean - n_pulses * p) / se
    # 4 standard errors over 12 bin/channel means (a false alarm ~1e-3)
    assert np.all(np.abs(z) < 4.0), z
    # each draw records at most one event per pulse
    assert np.all(m.counts.sum(axis=-2) <= n_pulses) and m.counts.dtype == np.int64
    # the Poisson model of the same instrument warns about pile-up, and its mean is far off
    with pytest.warns(ins.PileUpWarning):
        mp = ins.measure(stokes_profile(prof1[:, 0]), base, bin_edges=EDGES, seed=3)
    assert mp.expected[2, 0] > 1.5 * n_pulses * p[2, 0]


# ---------------------------------------------------------------------- atmosphere


def test_atmospheric_transmission_enters_the_link_budget():
    tz, h = 0.7, 30.0

    def kasten_young(el):
        return 1.0 / (math.sin(math.radians(el)) + 0.50572 * (el + 6.07995) ** -1.6364)

    t_one_way = tz ** (kasten_young(h) / kasten_young(90.0))
    vac = ins.Instrument(pulse_energy=1e-3, target_range=1e5)
    atm = ins.Instrument(pulse_energy=1e-3, target_range=1e5,
                         atmosphere=Atmosphere(zenith_transmission=tz, elevation_deg=h))
    assert atm.one_way_transmission == pytest.approx(t_one_way, rel=1e-12)
    assert atm.counts_per_cross_section / vac.counts_per_cross_section == pytest.approx(t_one_way**2, rel=1e-12)
    prof = stokes_profile([0.0, 1e-3, 2e-3, 0.0, 0.0, 0.0])
    e_vac = ins.expected_counts(prof, vac, bin_edges=EDGES)
    e_atm = ins.expected_counts(prof, atm, bin_edges=EDGES)
    np.testing.assert_allclose(e_atm, e_vac * t_one_way**2, rtol=1e-12)
    # scintillation only: the instrument's own transmission stays in use
    scint = ins.Instrument(pulse_energy=1e-3, target_range=1e5, transmission=0.8,
                           atmosphere=Atmosphere(scintillation="lognormal", scintillation_index=0.2))
    assert scint.counts_per_cross_section == pytest.approx(0.64 * vac.counts_per_cross_section, rel=1e-12)
    # both transmissions: refused
    with pytest.raises(pprender.Error, match="transmission"):
        ins.Instrument(pulse_energy=1e-3, target_range=1e5, transmission=0.8,
                       atmosphere=Atmosphere(zenith_transmission=tz, elevation_deg=h))


def test_scintillation_raises_the_variance_as_count_moments_says():
    n_pulses, n_draws = 10, 6000
    atm = Atmosphere(scintillation="lognormal", scintillation_index=0.3)
    inst = ins.Instrument(pulse_energy=1e-3, target_range=1e5, n_pulses=n_pulses, atmosphere=atm)
    scale = 100.0 / inst.counts_per_cross_section  # 100 expected counts per bin in the co channel
    prof = stokes_profile(scale * np.array([0.0, 0.5, 1.0, 0.5, 0.0, 0.0]), n_draws)
    # 10 photo-electrons per pulse and bin: a photon counter without dead time still warns
    with pytest.warns(ins.PileUpWarning):
        m = ins.measure(prof, inst, bin_edges=EDGES, seed=5)
    lam = m.expected[0]
    mean_ref, var_ref = atm.count_moments(lam, n_pulses)
    np.testing.assert_allclose(var_ref, lam + lam**2 * 0.3 / n_pulses, rtol=1e-12)  # the closed form
    # the total over the bins of the co channel: one factor per pulse for all of them
    k = m.counts[:, :, 0].sum(axis=1).astype(np.float64)
    lam_tot = lam[:, 0].sum()
    var_tot = lam_tot + lam_tot**2 * 0.3 / n_pulses  # 7.2x the Poisson variance here
    d2 = (k - k.mean()) ** 2
    se_var = d2.std() / math.sqrt(n_draws)
    assert abs(k.mean() - lam_tot) < 4.0 * math.sqrt(var_tot / n_draws)
    assert abs(d2.mean() - var_tot) < 4.0 * se_var, (d2.mean(), var_tot, se_var)
    # per bin, as count_moments says (4 standard errors of the sample variance)
    kb = m.counts.astype(np.float64)
    d2b = (kb - kb.mean(axis=0)) ** 2
    live = lam > 0
    z = (d2b.mean(axis=0) - var_ref) / (d2b.std(axis=0) / math.sqrt(n_draws) + 1e-300)
    assert np.all(np.abs(z[live]) < 4.0), z
    # channels that see the same pulses are correlated through the factor
    cov = np.cov(m.counts[:, 2, 0], m.counts[:, 2, 1])[0, 1]
    assert cov > 0.5 * lam[2, 0] * lam[2, 1] * 0.3 / n_pulses


# ---------------------------------------------------------------------- save / load, APD


def test_apd_records_save_and_load(tmp_path):
    det = Detector(kind="linear", gain=50.0, ionization_ratio=0.02, amplifier_noise=200.0, saturation=1e4)
    atm = Atmosphere(zenith_transmission=0.9, elevation_deg=45.0, scintillation="gamma_gamma", rytov_variance=0.5)
    inst = ins.Instrument(pulse_energy=1e-3, target_range=1e5, n_pulses=20, detector=det, atmosphere=atm)
    prof = stokes_profile([0.0, 1e-3, 3e-3, 1e-3, 0.0, 0.0], 3)
    m = ins.measure(prof, inst, bin_edges=EDGES, seed=7)
    assert m.counts.dtype == np.float64 and np.any(m.counts != np.round(m.counts))
    for name in ("m.zarr", "m.nc"):
        m.save(tmp_path / name)
        back = ins.Measurement.load(tmp_path / name)
        assert back.instrument == inst and back.instrument.detector == det and back.instrument.atmosphere == atm
        assert back.counts.dtype == np.float64 and np.array_equal(back.counts, m.counts)
    # Coates and a lognormal atmosphere, and alpha/beta given directly
    for d, a in ((Detector(dead_time=math.inf), Atmosphere(scintillation="lognormal", scintillation_index=0.1)),
                 (Detector(dead_time=1e-6), Atmosphere(scintillation="gamma_gamma", alpha=4.0, beta=2.5))):
        i2 = ins.Instrument(pulse_energy=1e-6, target_range=1e5, n_pulses=20, detector=d, atmosphere=a)
        m2 = ins.measure(prof, i2, bin_edges=EDGES, seed=1)
        back = ins.Measurement.from_xarray(m2.to_xarray())
        assert back.instrument == i2 and np.array_equal(back.counts, m2.counts)
    # the APD warns above its saturation level
    hot = ins.Instrument(pulse_energy=1.0, target_range=1e5, n_pulses=20, detector=det)
    assert ins.expected_counts(prof, hot, bin_edges=EDGES).max() / 20 > 1e4
    with pytest.warns(SaturationWarning):
        ins.measure(prof, hot, bin_edges=EDGES, seed=1)


# ---------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"detector": "spad"}, "detector"),
        ({"atmosphere": 0.8}, "atmosphere"),
        ({"channels": "mueller", "n_pulses": 6, "detector": Detector(dead_time=1e-6)}, "n_pulses"),
        ({"channels": "mueller", "n_pulses": 2,
          "atmosphere": Atmosphere(scintillation="lognormal", scintillation_index=0.1)}, "n_pulses"),
    ],
)
def test_bad_receivers_are_refused(kwargs, match):
    with pytest.raises(pprender.Error, match=match):
        ins.Instrument(pulse_energy=1e-3, target_range=1e5, **kwargs)


def test_dead_time_inside_the_gate_is_refused():
    inst = ins.Instrument(pulse_energy=1e-3, target_range=1e5, detector=Detector(dead_time=1e-9))  # gate 4 ns
    with pytest.raises(pprender.Error, match="dead_time"):
        ins.measure(stokes_profile([0.0, 1e-3, 0.0, 0.0, 0.0, 0.0]), inst, bin_edges=EDGES, seed=0)
    # whole pulses: a mueller receiver cycling 4 generators needs n_pulses a multiple of 4
    ok = ins.Instrument(pulse_energy=1e-3, target_range=1e5, channels="mueller", n_pulses=8,
                        detector=Detector(dead_time=1e-6))
    assert np.array_equal(ok.pulses, np.full(24, 2.0))


# ---------------------------------------------------------------------- fits


@functools.lru_cache(maxsize=1)
def lambertian():
    """Built once (a few seconds on a loaded machine)."""
    return pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0j, terms=["diffuse"], diffuse_albedo=0.6)


@pytest.fixture(scope="module")
def sphere():
    """Coates data of the fit problem (module docstring) and models with and without the
    detector, on 4 range bins (edges every 55 rendered bins): the size shows in the total
    counts more than in the shape. Recorded on the rendered bins, then summed: the first
    photon of a pulse in a coarse bin is the first in one of its fine bins, so the sums are
    the coarse bins' Coates records exactly."""
    mesh = models.sphere(radius=0.3, subdivisions=3)
    n_pulses = 2000
    det = Detector(dead_time=math.inf)
    base = ins.Instrument(pulse_energy=1e-3, target_range=2e5, n_pulses=n_pulses)
    lid = pprender.Lidar(resolution=24)
    res = pprender.render(pprender.Scene(mesh, lambertian(), smooth=True),
                          pprender.Lidar(resolution=24, polarization=base.channels.transmit), np.eye(3)[None],
                          outputs=("profile",))
    plain = base.scaled_to(1.5 * n_pulses * 2, res)  # 1.5 photo-electrons per pulse and channel
    coates = ins.Instrument(pulse_energy=plain.pulse_energy, target_range=2e5, n_pulses=n_pulses, detector=det)
    cut = np.array([0, 55, 109, 164, len(res.bin_edges) - 1])
    edges = res.bin_edges[cut]
    kw = dict(lidar=lid, smooth=True, bounds={"scale": (0.5, 1.5)}, fitted_parts=())  # no material rebuilt
    m_coates = fit.ForwardModel(mesh, lambertian(), coates, edges, ("scale",), **kw)
    m_plain = fit.ForwardModel(mesh, lambertian(), plain, edges, ("scale",), **kw)
    fine = ins.measure(res, coates, seed=4)[0].counts
    data = np.add.reduceat(fine, cut[:-1], axis=0)
    return m_coates, m_plain, data


def test_coates_fit_recovers_the_size_where_poisson_is_biased(sphere):
    m_coates, m_plain, data = sphere
    r_c = fit.fit_nlopt(m_coates, data, [1.1], "BOBYQA", initial_step=0.05)
    sd = 1.0 / math.sqrt(fit.fisher_information(m_coates, r_c.x)[0, 0])
    with pytest.warns(fit.FitWarning, match="does not fit"):  # the diagnosis sees the wrong model
        r_p = fit.fit_nlopt(m_plain, data, [1.1], "BOBYQA", initial_step=0.05)
    print(f"scale: Coates fit {r_c.x[0]:.4f} +- {sd:.4f}, Poisson fit {r_p.x[0]:.4f} (truth 1)")
    # the Coates fit within 3 Cramer-Rao sd of the truth; the Poisson fit of the same
    # piled-up data is biased by many sd (it sees (1 - e^-1.5) / 1.5 = 0.52 of the photons,
    # partly made up by the shape of the 4 bins)
    assert abs(r_c.x[0] - 1.0) < 3.0 * sd
    assert r_p.x[0] < 1.0 - 8.0 * sd  # measured 0.9145 against sd 0.0062: -14 sd
    # the diagnosis: curvature agrees with the Fisher information, the bootstrap accepts it
    d = fit.diagnose_fit(m_coates, data, r_c)
    assert d.curvature_ratio is not None and 0.7 < d.curvature_ratio[0] <= d.curvature_ratio[1] < 1.4
    assert d.deviance_p is not None and d.deviance_p > 1e-3


@pytest.mark.parametrize("receiver", ["coates", "apd", "scintillation"])
def test_fisher_information_is_the_expected_curvature(sphere, receiver):
    """F = E[-d2 log L / d scale2] (= Var(d log L / d scale) where the likelihood is the
    records' law) over 2000 draws of what the receiver records, by central differences of
    the likelihood (step 0.01 of the scale; a relative standard error of a few % on both)."""
    m_coates, _, _ = sphere
    inst = m_coates.instrument
    if receiver == "apd":
        inst = ins.Instrument(pulse_energy=inst.pulse_energy, target_range=2e5, n_pulses=2000,
                              detector=Detector(kind="linear", gain=30.0, ionization_ratio=0.1, amplifier_noise=50.0))
    elif receiver == "scintillation":  # 1500 photo-electrons per channel over 10 pulses, index 0.35
        inst = ins.Instrument(pulse_energy=inst.pulse_energy * 100.0, target_range=2e5, n_pulses=10,
                              atmosphere=Atmosphere(scintillation="gamma_gamma", alpha=8.0, beta=5.0))
    model = fit.ForwardModel(models.sphere(radius=0.3, subdivisions=3), lambertian(), inst, m_coates.bin_edges,
                             ("scale",), lidar=pprender.Lidar(resolution=24), smooth=True, bounds={"scale": (0.5, 1.5)},
                             fitted_parts=())
    h = 0.01
    lam = model.expected(np.array([[1.0], [1.0 + h], [1.0 - h]]))
    f = fit.fisher_information(model, [1.0], step=h)[0, 0]
    rng = np.random.default_rng(8)
    kw = dict(detector=inst.detector, atmosphere=inst.atmosphere, bin_edges=model.bin_edges,
              groups=np.zeros(2, dtype=np.int64))
    draws = record(np.broadcast_to(lam[0], (2000,) + lam[0].shape), inst.pulses, rng, **kw)
    ll = [np.asarray(record_log_likelihood(draws, lam[i], inst.pulses, **kw)) for i in range(3)]
    score = (ll[1] - ll[2]) / (2 * h)
    curv = -(ll[1] - 2 * ll[0] + ll[2]) / h**2
    var, mean_curv = float(np.var(score)), float(np.mean(curv))
    print(f"{receiver}: Fisher {f:.5g}, E[-H] {mean_curv:.5g} +- {np.std(curv) / math.sqrt(2000):.2g}, "
          f"Var(score) {var:.5g}")
    if receiver == "scintillation":
        # the moment-based information: a lower bound on the likelihood's, close to it here
        assert 0.85 * mean_curv < f < 1.03 * mean_curv
    else:
        assert f == pytest.approx(mean_curv, rel=0.03)
        assert f == pytest.approx(var, rel=0.15)


def test_models_take_apd_records_and_refuse_what_they_cannot_model(sphere):
    m_coates, m_plain, _ = sphere
    apd = ins.Instrument(pulse_energy=m_plain.instrument.pulse_energy, target_range=2e5, n_pulses=2000,
                         detector=Detector(kind="linear", gain=30.0, ionization_ratio=0.1))
    kw = dict(lidar=pprender.Lidar(resolution=24), smooth=True, bounds={"scale": (0.5, 1.5)}, fitted_parts=())
    model = fit.ForwardModel(models.sphere(radius=0.3, subdivisions=3), lambertian(), apd, m_plain.bin_edges,
                             ("scale",), **kw)
    lam = model.expected([1.0])
    x = record(lam, apd.pulses, np.random.default_rng(2), detector=apd.detector)
    assert x.dtype == np.float64
    # the APD model's likelihood is the Gaussian of detector.record_log_likelihood, highest near the truth
    ll = model.log_likelihood(np.array([[0.9], [1.0], [1.1]]), x)
    assert ll[1] == pytest.approx(record_log_likelihood(x, lam, apd.pulses, detector=apd.detector), rel=1e-12)
    assert ll[1] > max(ll[0], ll[2])
    # a photon-counting model refuses real-valued records
    with pytest.raises(pprender.Error, match="integers"):
        m_plain.log_likelihood([1.0], x)
    # a dead time inside the range gate (5.4 ns here) is refused when the model is made
    short = ins.Instrument(pulse_energy=1e-3, target_range=2e5, detector=Detector(dead_time=1e-9))
    with pytest.raises(pprender.Error, match="dead_time"):
        fit.ForwardModel(models.sphere(radius=0.3, subdivisions=3), lambertian(), short, m_plain.bin_edges,
                         ("scale",), **kw)


def test_speckle_with_a_dead_time_an_apd_or_scintillation_is_refused() -> None:
    """Their joint statistics are not modelled: the Instrument refuses the combination,
    naming speckle; an atmosphere's transmission and an ideal Detector() work with it."""
    from pprender.inverse.speckle import Speckle

    base = dict(pulse_energy=1e-3, target_range=500e3, n_pulses=100, speckle=Speckle(dof=4.0))
    for kw in (dict(detector=Detector(dead_time=1e-6)),
               dict(detector=Detector(kind="linear", gain=50.0)),
               dict(atmosphere=Atmosphere(scintillation="lognormal", scintillation_index=0.2))):
        with pytest.raises(pprender.Error, match="speckle"):
            ins.Instrument(**base, **kw)
    ok = ins.Instrument(**base, detector=Detector(), atmosphere=Atmosphere(zenith_transmission=0.8, elevation_deg=40.0))
    assert ok.speckle is not None and ok.one_way_transmission < 0.8
