"""The detector models (pprender.inverse.detector) against independent oracles: a direct
per-pulse photon simulation for Coates' first-photon probabilities, scipy's multinomial and
normal log-pdfs, McIntyre's limits, and today's Poisson draws bit for bit."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy import stats

import pprender
from pprender.fit import poisson_log_likelihood
from pprender.inverse.atmosphere import Atmosphere
from pprender.inverse.detector import (
    Detector,
    SaturationWarning,
    coates_correction,
    coates_probabilities,
    excess_noise_factor,
    record,
    record_log_likelihood,
)

C_LIGHT = 299_792_458.0
LAM = np.array([0.05, 0.3, 0.8, 0.1, 1.2, 0.4])  # per-pulse photons per bin: deep pile-up


def test_zero_dead_time_is_todays_poisson_bit_for_bit(rng) -> None:
    lam = rng.uniform(0, 50, size=(3, 7, 2))
    det = Detector()
    assert det.is_poisson and det.regime() == "poisson"
    a = det.sample(lam, [10, 10], np.random.default_rng(99))
    b = np.random.default_rng(99).poisson(lam).astype(np.int64)
    assert a.dtype == np.int64 and np.array_equal(a, b)
    assert np.allclose(det.log_likelihood(a, lam, 10), poisson_log_likelihood(a, lam), rtol=0, atol=1e-9)
    assert np.array_equal(det.mean(lam, 10), lam) and np.array_equal(det.variance(lam, 10), lam)


def _direct_first_photon(lam: np.ndarray, n: int, rng: np.random.Generator, scale: np.ndarray | None = None) -> np.ndarray:
    """Bin of the first photon of each of ``n`` pulses (``len(lam)`` = none): Poisson
    arrivals with ``lam_b`` (times the pulse's ``scale``) expected in bin ``b``, uniform in
    time within each bin."""
    total = lam.sum()
    m = rng.poisson(total * (1.0 if scale is None else scale), n)
    width = int(m.max())
    which = rng.choice(len(lam), size=(n, width), p=lam / total)
    t = which + rng.uniform(size=(n, width))  # bin b covers [b, b + 1)
    t[np.arange(width)[None, :] >= m[:, None]] = np.inf
    first = np.min(t, axis=1)
    return np.where(np.isfinite(first), np.floor(np.where(np.isfinite(first), first, 0)), len(lam)).astype(int)


def test_coates_probabilities_match_a_direct_photon_simulation(rng) -> None:
    """2e5 simulated pulses: each bin's first-photon frequency within 4.5 binomial sigmas of
    Coates' probability, and the chi-square over the B + 1 outcomes not rejected at 1e-3."""
    n = 200_000
    first = _direct_first_photon(LAM, n, rng)
    hist = np.bincount(first, minlength=len(LAM) + 1)
    p = coates_probabilities(LAM[:, None])[:, 0]
    assert abs(p.sum() - 1) < 1e-12
    z = (hist - n * p) / np.sqrt(n * p * (1 - p))
    assert np.all(np.abs(z) < 4.5), z
    chi2 = np.sum((hist - n * p) ** 2 / (n * p))
    assert stats.chi2.sf(chi2, len(p) - 1) > 1e-3
    # the naive per-bin answer 1 - exp(-lam) is far off in the later bins (the test can fail)
    assert abs(hist[4] / n - (1 - math.exp(-LAM[4]))) > 0.3


def test_coates_with_scintillation_matches_a_direct_simulation(rng) -> None:
    """Pulses scaled by gamma-gamma factors drawn one per pulse (2e5 pulses, photon by
    photon): the frequencies within 4.5 sigmas of the averaged probabilities (and far from
    the unscintillated ones, so the test can fail); the sampler and likelihood use them."""
    atm = Atmosphere(scintillation="gamma_gamma", rytov_variance=2.0)
    n = 200_000
    first = _direct_first_photon(LAM, n, rng, scale=atm.sample_factor(rng, n))
    hist = np.bincount(first, minlength=len(LAM) + 1)
    p = coates_probabilities(LAM[:, None], atm.laplace)[:, 0]
    assert abs(p.sum() - 1) < 1e-12
    z = (hist - n * p) / np.sqrt(n * p * (1 - p))
    assert np.all(np.abs(z) < 4.5), z
    p0 = coates_probabilities(LAM[:, None])[:, 0]
    assert np.max(np.abs(hist - n * p0) / np.sqrt(n * p0 * (1 - p0))) > 50
    det = Detector(dead_time=math.inf)
    expected = 50 * LAM[:, None]
    assert np.allclose(det.mean(expected, 50, laplace=atm.laplace), 50 * p[:-1, None], rtol=1e-12)
    k = det.sample(expected, 50, rng, laplace=atm.laplace)
    kk = np.append(k[:, 0], 50 - k.sum())
    assert abs(det.log_likelihood(k, expected, 50, laplace=atm.laplace) - stats.multinomial.logpmf(kk, 50, p)) < 1e-9
    with pytest.raises(pprender.Error, match="laplace"):
        Detector().sample(expected, 50, rng, laplace=atm.laplace)


def test_coates_sampler_and_likelihood(rng) -> None:
    """The multinomial sampler's mean over 4000 draws within 5 sigmas of n p, the
    log-likelihood equal to scipy's multinomial logpmf, and it sums to 1 over all outcomes."""
    n = 40
    det = Detector(dead_time=math.inf)
    expected = n * LAM[:, None] * np.array([1.0, 0.5])  # (B, 2)
    k = det.sample(np.broadcast_to(expected, (4000,) + expected.shape), n, rng)
    assert k.dtype == np.int64 and np.all(k.sum(axis=-2) <= n)
    mean = det.mean(expected, n)
    sd = np.sqrt(det.variance(expected, n) / 4000)
    assert np.all(np.abs(k.mean(axis=0) - mean) < 5 * sd)
    p = coates_probabilities(expected / n)
    for c in range(2):
        kk = np.append(k[0, :, c], n - k[0, :, c].sum())
        want = stats.multinomial.logpmf(kk, n, p[:, c])
        got = det.log_likelihood(k[0, :, c : c + 1], expected[:, c : c + 1], n)
        assert abs(got - want) < 1e-9
    # normalization over every outcome of 3 pulses on 2 bins
    lam = np.array([[0.6], [1.3]])
    tot = sum(math.exp(det.log_likelihood(np.array([[a], [b]]), lam, 3)) for a in range(4) for b in range(4 - a))
    assert abs(tot - 1) < 1e-12
    assert det.log_likelihood(np.array([[3], [1]]), lam, 3) == -math.inf  # 4 events in 3 pulses
    assert det.log_likelihood(np.array([[1], [0]]), np.array([[0.0], [1.0]]), 3) == -math.inf


def test_coates_correction_inverts_the_mean_and_recovers_lam(rng) -> None:
    """Exact inverse of the mean (1e-12); on 400 draws of 5000 pulses the estimates'
    z-scores have mean within 0.15 of 0 and standard deviation within 15 % of 1 (the
    standard error is calibrated), every one within 5."""
    n = 5000
    det = Detector(dead_time=1e-6)
    edges = np.linspace(0, 30.0, len(LAM) + 1)  # 30 m gate: 0.2 us < the dead time
    assert det.regime(edges) == "coates"
    expected = n * LAM[:, None]
    est, err = coates_correction(det.mean(expected, n, bin_edges=edges), n)
    assert np.allclose(est, expected, rtol=1e-12, atol=0)
    k = det.sample(np.broadcast_to(expected, (400,) + expected.shape), n, rng, bin_edges=edges)
    est, err = coates_correction(k, n)
    z = (est - expected) / err
    assert np.all(np.abs(z) < 5)
    assert np.all(np.abs(z.mean(axis=0)) < 0.15) and np.all(np.abs(z.std(axis=0) - 1) < 0.15)
    # saturated and dead bins: inf and nan, documented
    e2, _ = coates_correction(np.array([[3], [0]]), 3)
    assert e2[0, 0] == math.inf and math.isnan(e2[1, 0])


def test_dead_time_shorter_than_the_gate_is_refused() -> None:
    edges = np.linspace(0, 30.0, 11)  # gate 2 x 30 m / c = 200 ns
    gate = 2 * 30.0 / C_LIGHT
    det = Detector(dead_time=0.5 * gate)
    with pytest.raises(pprender.Error, match="dead_time.*shorter than the range gate"):
        det.sample(np.ones((10, 1)), 5, np.random.default_rng(0), bin_edges=edges)
    with pytest.raises(pprender.Error, match="bin_edges"):
        det.mean(np.ones((10, 1)), 5)
    assert Detector(dead_time=1.01 * gate).regime(edges) == "coates"
    with pytest.raises(pprender.Error, match="whole number"):
        Detector(dead_time=math.inf).sample(np.ones((10, 1)), 2.5, np.random.default_rng(0))


def test_excess_noise_factor_limits() -> None:
    g = np.array([1.0, 2.0, 10.0, 1e3, 1e6])
    assert np.allclose(excess_noise_factor(g, 1.0), g, rtol=1e-15)  # k = 1: F = G
    assert np.allclose(excess_noise_factor(1.0, np.linspace(0, 1, 5)), 1.0)  # no gain, no excess
    assert abs(excess_noise_factor(1e6, 0.0) - 2.0) < 2e-6  # k = 0: F -> 2
    # hand value: G = 100, k = 0.02: 2 + 0.98 * 1.99
    assert abs(excess_noise_factor(100.0, 0.02) - (2.0 + 0.98 * 1.99)) < 1e-12


@pytest.mark.parametrize("gain,k,noise", [(10.0, 0.02, 0.0), (100.0, 0.02, 300.0), (50.0, 0.5, 0.0), (1.0, 0.3, 2.0)])
def test_apd_moments(gain, k, noise, rng) -> None:
    """Mean and variance of 1e5 draws within 2 % of N and F N + pulses (sigma_a / G)^2
    (N = 200 photo-electrons over 10 pulses: the tolerance is >= 3.8 standard errors of the
    variance estimate for these excess kurtoses)."""
    det = Detector(kind="linear", gain=gain, ionization_ratio=k, amplifier_noise=noise)
    n_pe, pulses = 200.0, 10
    x = det.sample(np.full((100_000, 1, 1), n_pe), pulses, rng)
    assert x.dtype == np.float64
    want_var = excess_noise_factor(gain, k) * n_pe + pulses * (noise / gain) ** 2
    assert float(det.variance(np.full((1, 1), n_pe), pulses)[0, 0]) == pytest.approx(want_var, rel=1e-14)
    assert abs(x.mean() / n_pe - 1) < 0.02
    assert abs(x.var() / want_var - 1) < 0.02


def test_apd_unit_gain_without_noise_is_poisson(rng) -> None:
    lam = rng.uniform(0, 20, size=(5, 3))
    x = Detector(kind="linear").sample(lam, 4, np.random.default_rng(7))
    assert np.array_equal(x, np.random.default_rng(7).poisson(lam).astype(np.float64))


def test_apd_likelihood_is_the_gaussian_of_its_moments(rng) -> None:
    det = Detector(kind="linear", gain=40.0, ionization_ratio=0.1, amplifier_noise=100.0)
    lam = rng.uniform(1, 100, size=(2, 6, 2))
    x = det.sample(lam, 5, rng)
    sd = np.sqrt(det.variance(lam, 5))
    want = stats.norm.logpdf(x, lam, sd).sum(axis=(-2, -1))
    assert np.allclose(det.log_likelihood(x, lam, 5), want, rtol=1e-12)


def test_saturation_warns() -> None:
    det = Detector(kind="linear", gain=100.0, saturation=50.0)
    with pytest.warns(SaturationWarning, match="saturation"):
        det.sample(np.array([[10.0], [600.0]]), 10, np.random.default_rng(0))  # 60 per pulse > 50
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        det.sample(np.array([[10.0], [400.0]]), 10, np.random.default_rng(0))  # 40 per pulse


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"kind": "pmt"}, "kind"),
        ({"dead_time": -1e-9}, "dead_time"),
        ({"dead_time": "1e-9"}, "dead_time"),
        ({"dead_time": True}, "dead_time"),
        ({"dead_time": math.nan}, "dead_time"),
        ({"gain": 100.0}, "gain.*linear"),
        ({"kind": "linear", "gain": 0.5}, "gain"),
        ({"kind": "linear", "ionization_ratio": 1.5}, "ionization_ratio"),
        ({"kind": "linear", "amplifier_noise": -1.0}, "amplifier_noise"),
        ({"kind": "linear", "saturation": 0.0}, "saturation"),
        ({"kind": "linear", "dead_time": 1e-9}, "dead_time.*photon_counting"),
    ],
)
def test_bad_parameters(kwargs, match) -> None:
    with pytest.raises(pprender.Error, match=match):
        Detector(**kwargs)


def test_bad_arrays() -> None:
    det = Detector()
    rng = np.random.default_rng(0)
    with pytest.raises(pprender.Error, match="expected"):
        det.sample(np.array([1.0, 2.0]), 1, rng)  # not (..., B, C)
    with pytest.raises(pprender.Error, match="expected"):
        det.sample(np.array([[-1.0]]), 1, rng)
    with pytest.raises(pprender.Error, match="pulses"):
        det.sample(np.ones((3, 2)), [1, 2, 3], rng)
    with pytest.raises(pprender.Error, match="rng"):
        det.sample(np.ones((3, 2)), 1, 5)  # type: ignore[arg-type]
    with pytest.raises(pprender.Error, match="data"):
        det.log_likelihood(np.full((3, 2), 0.5), np.ones((3, 2)), 1)
    with pytest.raises(pprender.Error, match="counts"):
        coates_correction(np.array([[3.0], [2.0]]), 4)  # 5 events in 4 pulses
    with pytest.raises(pprender.Error, match="gain"):
        excess_noise_factor(0.5, 0.1)


def test_record_without_scintillation_is_the_detector() -> None:
    lam = np.random.default_rng(1).uniform(0, 20, size=(3, 5, 2))
    a = record(lam, 10, np.random.default_rng(4))
    assert np.array_equal(a, np.random.default_rng(4).poisson(lam).astype(np.int64))
    assert np.array_equal(record(lam, 10, np.random.default_rng(4), atmosphere=Atmosphere(zenith_transmission=0.5)), a)
    assert record_log_likelihood(a, lam, 10) == pytest.approx(poisson_log_likelihood(a, lam), abs=1e-9)


def test_record_coates_with_scintillation_per_pulse(rng) -> None:
    """Two channels sharing 400 pulses (gamma-gamma factors), 3000 records simulated pulse by
    pulse: each channel's mean within 5 sigmas of Coates' averaged probabilities, and the
    covariance between the channels' total recorded counts (``n`` minus the pulses without
    an event) within 5 standard errors of the joint law's ``n (L(A_B + A'_B) - L(A_B)
    L(A'_B))``, clearly positive (the shared factor; independent channels would give 0)."""
    atm = Atmosphere(scintillation="gamma_gamma", rytov_variance=2.0)
    det = Detector(dead_time=math.inf)
    n, reps = 400, 3000
    per_pulse = np.stack([LAM, LAM[::-1] * 0.5], axis=-1)  # (B, 2)
    expected = n * per_pulse
    k = record(np.broadcast_to(expected, (reps,) + expected.shape), n, rng, detector=det, atmosphere=atm)
    mean = det.mean(expected, n, laplace=atm.laplace)
    sd = np.sqrt(det.variance(expected, n, laplace=atm.laplace) / reps)
    assert np.all(np.abs(k.mean(axis=0) - mean) < 5 * sd)
    a0, a1 = per_pulse.sum(axis=0)
    cov = n * (atm.laplace(a0 + a1) - atm.laplace(a0) * atm.laplace(a1))
    x, y = k[:, :, 0].sum(axis=1).astype(float), k[:, :, 1].sum(axis=1).astype(float)
    prod = (x - x.mean()) * (y - y.mean())
    se = np.std(prod) / math.sqrt(reps)
    assert cov > 10 * se and abs(prod.mean() - cov) < 5 * se, (prod.mean(), cov, se)
    # above n_exact: channels independent, marginally the same multinomial
    k2 = record(np.broadcast_to(expected, (reps,) + expected.shape), n, rng, detector=det, atmosphere=atm, n_exact=10)
    assert np.all(np.abs(k2.mean(axis=0) - mean) < 5 * sd)
    ll = record_log_likelihood(k[0], expected, n, detector=det, atmosphere=atm)
    assert ll == pytest.approx(det.log_likelihood(k[0], expected, n, laplace=atm.laplace), rel=1e-14)


def test_record_linear_with_scintillation(rng) -> None:
    """APD behind a lognormal atmosphere: 1e5 records' mean within 1 % and variance within 3 %
    of N and F N + N^2 sigma_I^2 / n + pulses (sigma_a / G)^2; the likelihood is that Gaussian."""
    atm = Atmosphere(scintillation="lognormal", scintillation_index=0.5)
    det = Detector(kind="linear", gain=50.0, ionization_ratio=0.02, amplifier_noise=200.0)
    n_pe, n = 300.0, 5
    x = record(np.full((100_000, 1, 1), n_pe), n, rng, detector=det, atmosphere=atm)
    var = det.excess_noise * n_pe + n_pe**2 * 0.5 / n + n * (200.0 / 50.0) ** 2
    assert abs(x.mean() / n_pe - 1) < 0.01 and abs(x.var() / var - 1) < 0.03
    ll = record_log_likelihood(x[:3], np.full((1, 1), n_pe), n, detector=det, atmosphere=atm)
    assert np.allclose(ll, stats.norm.logpdf(x[:3, 0, 0], n_pe, math.sqrt(var)), rtol=1e-12)
    with pytest.raises(pprender.Error, match="atmosphere"):
        record(np.ones((2, 1)), 1, rng, atmosphere="vacuum")  # type: ignore[arg-type]
