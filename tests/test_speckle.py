"""pprender.inverse.speckle against independent oracles: Jones-calculus conventions,
Goodman's moments of gamma speckle (sampled), a directly simulated random-phasor field,
the negative binomial of scipy and a brute-force convolution.

Tolerances of the sampled moments: with ``n`` draws the relative standard error of a
sample variance is ``sqrt((kappa - 1) / n)``, ``kappa`` the kurtosis (``3 + 6 / M`` for a
gamma law; the counts' is smaller, the Poisson part being lighter-tailed). At ``M = 1``,
the worst case, and the issue's 1e5 draws that is 0.9 %, so 2 % would be only 2.2 sigma;
the moment tests draw 2e5 (0.63 %: 2 % is 3.2 sigma, 4.5 sigma at ``M = 10``). A sample
mean's relative standard error is ``1 / sqrt(M n)`` at most, 0.22 %.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate, linalg, stats
from scipy.special import j1, logsumexp

import pprender
from pprender.inverse import speckle as sp
from pprender.inverse.fit import poisson_log_likelihood
from pprender.inverse.instrument import CHANNEL_PRESETS, channel_set

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
from speckle_validation import channel_intensities, m_estimate, random_phasor  # noqa: E402

# Partially polarized received state (degree of polarization 0.54), in counts.
STOKES = np.array([40.0, 12.0, -16.0, 8.0])
SIX = channel_set("stokes")


def _stokes_of_jones(e: np.ndarray) -> np.ndarray:
    """Stokes vectors of Jones vectors (..., 2), V = 2 Im(Ex Ey*): the module docstring of
    pprender.inverse.instrument, written out independently of the code under test."""
    ex, ey = e[..., 0], e[..., 1]
    return np.stack([abs(ex) ** 2 + abs(ey) ** 2, abs(ex) ** 2 - abs(ey) ** 2,
                     2 * (ex * ey.conj()).real, 2 * (ex * ey.conj()).imag], axis=-1)


# ---------------------------------------------------------------------- conventions


def test_coherency_is_the_fields_outer_product(rng) -> None:
    e = rng.standard_normal((50, 2)) + 1j * rng.standard_normal((50, 2))
    j = sp.coherency(_stokes_of_jones(e))
    np.testing.assert_allclose(j, e[:, :, None] * e[:, None, :].conj(), rtol=0, atol=1e-12)


@pytest.mark.parametrize("preset", CHANNEL_PRESETS)
def test_analyzer_matrix_reproduces_every_preset_row(preset, rng) -> None:
    ch = channel_set(preset)
    a = sp.analyzer_matrix(ch.rows)
    # tr(A J) = a . S for fully polarized fields (J = E E^H) and mixtures of them
    e = rng.standard_normal((30, 2)) + 1j * rng.standard_normal((30, 2))
    s = _stokes_of_jones(e)
    got = np.einsum("cij,nji->nc", a, e[:, :, None] * e[:, None, :].conj()).real
    np.testing.assert_allclose(got, s @ ch.rows.T, rtol=1e-12, atol=1e-12)
    mix = s[:10].sum(0)
    np.testing.assert_allclose(np.einsum("cij,ji->c", a, sp.coherency(mix)).real, ch.rows @ mix, rtol=1e-12)
    # a physical analyzer is positive semi-definite
    assert np.all(np.linalg.eigvalsh(a) >= -1e-15)


def test_ideal_polarizers_are_projectors_on_their_jones_vectors() -> None:
    r = np.array([1.0, -1j]) / math.sqrt(2)  # V = 2 Im(Ex Ey*) = +1: "R" in this convention
    np.testing.assert_allclose(_stokes_of_jones(r), [1, 0, 0, 1], atol=1e-15)
    for name, jones in (("R", r), ("H", np.array([1.0, 0])), ("D", np.array([1.0, 1]) / math.sqrt(2))):
        row = SIX.analyzers_array[SIX.names.index(name)]
        np.testing.assert_allclose(sp.analyzer_matrix(row), np.outer(jones, jones.conj()), atol=1e-15)


def test_generator_groups_of_the_mueller_preset() -> None:
    ch = channel_set("mueller")
    unique, index = sp.generator_groups(ch.generators_array)
    assert unique.shape == (4, 4)
    np.testing.assert_array_equal(unique[index], ch.generators_array)
    np.testing.assert_array_equal(index, np.repeat(np.arange(4), 6))


# ---------------------------------------------------------------------- Goodman's moments


def _independent_variance(s: np.ndarray, row: np.ndarray, m: float) -> float:
    """Var tr(A W) = (l1^2 + l2^2) / M, l the eigenvalues of J^(1/2) A J^(1/2) (scipy's
    sqrtm and eigvalsh; J and A written from the Stokes definitions)."""
    j = 0.5 * np.array([[s[0] + s[1], s[2] + 1j * s[3]], [s[2] - 1j * s[3], s[0] - s[1]]])
    a = np.array([[row[0] + row[1], row[2] + 1j * row[3]], [row[2] - 1j * row[3], row[0] - row[1]]])
    root = linalg.sqrtm(j)
    lam = np.linalg.eigvalsh(root @ a @ root)
    return float(np.sum(lam**2) / m)


@pytest.mark.parametrize("m", [1.0, 2.5, 10.0])
def test_sampled_intensity_and_counts_follow_goodmans_moments(m, rng) -> None:
    # six ideal polarizers (one field, split 1/3) plus an open channel and a partial analyzer
    rows = np.vstack([SIX.rows, [0.5, 0, 0, 0], [0.5, 0.2, 0.1, -0.05]])
    gi = np.zeros(len(rows), dtype=int)
    n = 200_000
    s = np.broadcast_to(STOKES, (n, 1, 1, 4))
    i = sp.sample_intensity(s, rows, gi, m, rng)[:, 0, :]
    mean = rows @ STOKES
    var = np.array([_independent_variance(STOKES, r, m) for r in rows])
    # Goodman: an ideal polarizer's integrated intensity has variance mean^2 / M
    np.testing.assert_allclose(var[:6], mean[:6] ** 2 / m, rtol=1e-10)
    np.testing.assert_allclose(i.mean(0), mean, rtol=0.02)
    np.testing.assert_allclose(i.var(0), var, rtol=0.02)
    # one field: H + V = D + A = R + L = tr W / 3 in every draw
    np.testing.assert_allclose(i[:, 0] + i[:, 1], i[:, 2] + i[:, 3], rtol=1e-12)
    np.testing.assert_allclose(i[:, 0] + i[:, 1], i[:, 4] + i[:, 5], rtol=1e-12)
    # the closed-form moments agree with the independent ones
    cmean, ccov = sp.intensity_moments(STOKES[None, None], rows, gi, m)
    np.testing.assert_allclose(cmean[0], mean, rtol=1e-12)
    np.testing.assert_allclose(np.diag(ccov[0]), var, rtol=1e-10)
    # counts: Poisson given the intensity, background 3 counts
    k = sp.sample_counts(s, rows, gi, m, 3.0, rng)[:, 0, :]
    assert k.dtype == np.int64
    np.testing.assert_allclose(k.mean(0), mean + 3.0, rtol=0.02)
    np.testing.assert_allclose(k.var(0), mean + 3.0 + var, rtol=0.02)
    kmean, kcov = sp.count_moments(STOKES[None, None], rows, gi, m, 3.0)
    np.testing.assert_allclose(np.diag(kcov[0]), mean + 3.0 + var, rtol=1e-10)
    # covariances between the channels of one field: z-scores of the sample covariance
    # (standard error from the sampled products) within 4.5
    c = np.cov(i[:, :6].T)
    prod = (i[:, :6, None] - i[:, None, :6].mean(0)) * (i[:, None, :6] - i[:, :6].mean(0)[None, :, None])
    se = prod.std(0) / math.sqrt(n)
    assert np.max(np.abs(c - ccov[0, :6, :6]) / se) < 4.5


def test_generators_are_independent_pulses(rng) -> None:
    ch = channel_set("mueller")
    unique, gi = sp.generator_groups(ch.generators_array)
    m_rand = rng.standard_normal((4, 4)) * 0.1 + np.diag([1.0, 0.6, 0.6, -0.5])
    m_rand[0] = [1.0, 0.1, 0.0, 0.05]
    stokes = sp.received_stokes(100.0 * m_rand[None], unique)  # (1, G, 4)
    n = 50_000
    i = sp.sample_intensity(np.broadcast_to(stokes, (n,) + stokes.shape), ch.rows, gi, 2.0, rng)[:, 0, :]
    corr = np.corrcoef(i.T)
    other = gi[:, None] != gi[None, :]
    # independent: |r| below 4.5 / sqrt(n) = 0.02
    assert np.max(np.abs(corr[other])) < 4.5 / math.sqrt(n)
    np.testing.assert_allclose(i[:, 0] + i[:, 1], i[:, 2] + i[:, 3], rtol=1e-12)
    _, cov = sp.intensity_moments(stokes, ch.rows, gi, 2.0)
    assert np.all(cov[0][other] == 0)


def test_polarized_returns_and_mixed_dof(rng) -> None:
    # a fully polarized (singular J) return: the orthogonal analyzer never sees light, the
    # parallel one is gamma with shape M; bins with dof = inf give the mean exactly
    s = np.array([[[50.0, 50.0, 0, 0]], [[20.0, 0, 0, -20.0]], [[30.0, 0, 0, 0]]])  # (B=3, G=1, 4)
    dof = np.array([[1.5], [math.inf], [4.0]])
    i = sp.sample_intensity(np.broadcast_to(s, (20_000,) + s.shape), SIX.rows, np.zeros(6, int), dof, rng)
    assert np.all(i[:, 0, 1] == 0.0) and np.all(i[:, 0, 0] > 0)
    np.testing.assert_allclose(i[:, 1, :], np.broadcast_to(SIX.rows @ s[1, 0], (20_000, 6)), rtol=1e-12)
    for b, m in ((0, 1.5), (2, 4.0)):
        x = i[:, b, 0] / (SIX.rows[0] @ s[b, 0])
        # Kolmogorov-Smirnov against the gamma law of shape M, mean 1
        assert stats.kstest(x, stats.gamma(m, scale=1 / m).cdf).pvalue > 1e-3


def test_no_speckle_is_todays_poisson_draw() -> None:
    lam = SIX.rows @ STOKES
    got = sp.sample_counts(STOKES[None, None], SIX.rows, np.zeros(6, int), math.inf, 0.5,
                           np.random.default_rng(7))
    np.testing.assert_array_equal(got[0], np.random.default_rng(7).poisson(lam + 0.5))


def test_channel_dof_matches_moments() -> None:
    rows = np.array([[0.5, 0.5, 0, 0], [0.5, 0, 0, 0], [0.5, 0, 0, 0]])
    s = np.array([[[10.0, 0, 0, 0], [10.0, 10.0, 0, 0]]])  # unpolarized, fully H
    m = sp.channel_dof(s, rows, np.array([0, 0, 1]), 3.0)
    # ideal polarizer: M; open channel: 2 M / (1 + P^2) (Goodman's partially polarized speckle)
    np.testing.assert_allclose(m[0], [3.0, 6.0, 3.0], rtol=1e-12)
    assert np.all(sp.channel_dof(s, rows, np.array([0, 0, 1]), math.inf) == math.inf)


# ---------------------------------------------------------------------- degrees of freedom


def test_random_phasor_field_has_the_predicted_dof(rng) -> None:
    """A directly simulated speckle field (random phasors over a uniformly bright disc,
    scripts/speckle_validation.py) against speckle_dof. The configuration's exact M (its
    field is Gaussian: (tr C)^2 / tr C^2) within 1 % (source and aperture discretized by
    200 and 300 points; measured agreement 1e-4, docs/speckle.md); the M sampled from
    3000 draws within 4 standard errors; one field's H + V = D + A in every draw."""
    for d, ds in ((0.5, 2.0), (1.0, 2.0)):
        m_pred = sp.speckle_dof(d, 1e-6, 1e6, math.pi * ds * ds / 4)
        sim = random_phasor(aperture_diameter=d, target_diameter=ds, wavelength=1e-6, target_range=1e6,
                            stokes=STOKES / STOKES[0], n_draws=3000, rng=rng)
        assert sim["m_exact"] == pytest.approx(m_pred, rel=0.01)
        i = channel_intensities(sim["W"], SIX.analyzers_array)
        m_s, se = m_estimate(i[:, 0])
        assert abs(m_s - m_pred) < 4 * se, (d, m_s, se, m_pred)
        np.testing.assert_allclose(i[:, 0] + i[:, 1], i[:, 2] + i[:, 3], rtol=1e-10)
    assert m_pred > 2.5  # the second case is well away from M = 1


def test_speckle_dof_limits_and_quadrature() -> None:
    lam, r = 1e-6, 1e6

    def dof(beta: float) -> float:
        ds = beta * lam * r / math.pi  # aperture 1 m
        return sp.speckle_dof(1.0, lam, r, math.pi * ds * ds / 4)

    # small aperture: M = 1 + beta^2 / 16 + O(beta^4)
    for beta in (0.02, 0.05):
        assert (dof(beta) - 1) / (beta**2 / 16) == pytest.approx(1.0, abs=2e-3)
    # large aperture: M / (A_rx / A_coh) -> 1 from above, like log(beta) / beta
    ratios = [dof(b) / (b * b / 16) for b in (30.0, 100.0, 1000.0, 1e4)]
    assert all(x > y > 1 for x, y in zip(ratios, ratios[1:]))
    assert ratios[2] < 1.01 and ratios[3] < 1.001
    # an adaptive quadrature of Goodman's radial integral (scipy.integrate.quad)
    for beta in (0.7, 5.0, 40.0):
        f = lambda u: (np.arccos(u) - u * np.sqrt(1 - u * u)) * (2 * j1(beta * u) / (beta * u)) ** 2 * u  # noqa: E731
        ref, _ = integrate.quad(f, 1e-12, 1.0, limit=500, epsabs=0, epsrel=1e-12)
        assert dof(beta) == pytest.approx(1.0 / (16 / math.pi * ref), rel=1e-10)
    # it depends on D D_s / (lambda R) only; per-bin areas give an array
    assert sp.speckle_dof(2.0, lam, 2 * r, 0.5) == pytest.approx(sp.speckle_dof(1.0, lam, r, 0.5), rel=1e-12)
    out = sp.speckle_dof(1.0, 1064e-9, 1e6, np.array([1e-4, 0.01, 1.0, 10.0]))
    assert out.shape == (4,) and np.all(np.diff(out) > 0) and out[0] >= 1.0


def test_accumulated_dof() -> None:
    assert sp.accumulated_dof(2.5, 40) == pytest.approx(100.0)
    assert sp.accumulated_dof(2.5, 40, 1.0) == pytest.approx(2.5)
    for rho, n in ((0.5, 10), (0.9, 7), (0.2, 1)):
        i = np.arange(n)
        brute = n * n / np.sum(rho ** np.abs(i[:, None] - i[None, :]))  # n^2 var / var(sum)
        assert sp.accumulated_dof(3.0, n, rho) == pytest.approx(3.0 * brute, rel=1e-12)
    assert sp.accumulated_dof(math.inf, 5) == math.inf


# ---------------------------------------------------------------------- likelihood


@pytest.mark.parametrize("m", [1.0, 2.5, 10.0, 1e3])
def test_log_pmf_is_scipys_negative_binomial_without_background(m) -> None:
    for s in (0.05, 3.0, 200.0, 1e6):
        k = np.unique(np.round(s * np.array([0, 0.1, 0.5, 0.9, 1, 1.2, 2, 3]))).astype(np.int64)
        k = np.union1d(k, np.arange(6))
        ref = stats.nbinom.logpmf(k, m, m / (m + s))
        got = sp.speckle_log_pmf(k, s, 0.0, m)
        ok = ref > -700
        # 1e-9 relative: at 1e6 counts both sides carry the rounding of lgamma(k + 1) ~ 1e7
        np.testing.assert_allclose(got[ok], ref[ok], rtol=1e-9, atol=1e-10)


def test_log_pmf_is_the_convolution_with_the_background(rng) -> None:
    worst = 0.0
    for _ in range(60):
        m = 1 + rng.exponential(4.0) * (rng.random() < 0.7)
        s = 10 ** rng.uniform(-3, 2.3)
        b = 10 ** rng.uniform(-4, 2.3)
        k = int(rng.poisson(rng.gamma(m, s / m) + b)) if rng.random() < 0.8 else int(rng.integers(0, 250))
        j = np.arange(k + 1)
        ref = logsumexp(stats.nbinom.logpmf(j, m, m / (m + s)) + stats.poisson.logpmf(k - j, b))
        worst = max(worst, abs(float(sp.speckle_log_pmf(k, s, b, m)) - ref))
    assert worst < 1e-10
    # k = 0 in closed form: exp(-b) (1 + s / M)^-M
    assert float(sp.speckle_log_pmf(0, 7.0, 0.3, 1.5)) == pytest.approx(-0.3 - 1.5 * math.log1p(7.0 / 1.5), rel=1e-13)


def test_log_pmf_is_a_normalized_law_with_goodmans_moments() -> None:
    s, b, m = 30.0, 4.0, 2.5
    k = np.arange(0, 1500)
    p = np.exp(sp.speckle_log_pmf(k, s, b, m))
    assert p.sum() == pytest.approx(1.0, abs=1e-11)
    mean = np.sum(k * p)
    assert mean == pytest.approx(s + b, rel=1e-11)
    assert np.sum((k - mean) ** 2 * p) == pytest.approx(s + b + s * s / m, rel=1e-10)


def test_log_likelihood_without_speckle_is_poissons_bit_for_bit(rng) -> None:
    sig = rng.uniform(0, 50, (3, 20, 6))
    sig[0, :3] = 0.0
    bg = rng.uniform(0, 2, (20, 6))
    k = rng.poisson(sig + bg)
    ref = poisson_log_likelihood(k, sig + bg)
    got = sp.speckle_log_likelihood(k, sig, bg, math.inf)
    assert np.array_equal(got, ref)
    # zero signal is Poisson at any M; a huge M approaches it
    assert sp.speckle_log_likelihood(k[0, :3], 0.0, bg[:3], 2.0) == poisson_log_likelihood(k[0, :3], bg[:3])
    np.testing.assert_allclose(sp.speckle_log_likelihood(k, sig, bg, 1e12), ref, rtol=0, atol=1e-6)
    # speckle widens the law: data far from the mean are likelier than under Poisson
    assert sp.speckle_log_pmf(300, 100.0, 0.0, 2.0) > stats.poisson.logpmf(300, 100.0)


def test_log_pmf_large_counts_and_edge_cases() -> None:
    # huge counts: finite, no O(k) work (a brute-force log-sum-exp over 2e6 terms as oracle)
    k, s, b, m = 2_000_000, 1.9e6, 1e5, 4.0
    j = np.arange(0, k + 1, dtype=float)
    ref = logsumexp(stats.nbinom.logpmf(j, m, m / (m + s)) + stats.poisson.logpmf(k - j, b))
    assert float(sp.speckle_log_pmf(k, s, b, m)) == pytest.approx(ref, rel=1e-9)
    big = sp.speckle_log_pmf(np.array([10**9, 0, 10**12]), np.array([1e9, 1e9, 1e12]), 1e3, np.array([1.0, 7.0, 1e15]))
    assert np.all(np.isfinite(big))
    # deep fades: counts far below a huge mean (no cancellation against the Poisson term)
    for k, s, m in ((1, 1e18, 2.0), (3, 1e15, 1.0), (0, 1e12, 50.0)):
        assert float(sp.speckle_log_pmf(k, s, 0.0, m)) == pytest.approx(stats.nbinom.logpmf(k, m, m / (m + s)),
                                                                        rel=1e-12)
    # impossible data: counts with no signal nor background
    assert sp.speckle_log_pmf(3, 0.0, 0.0, 2.0) == -math.inf
    assert sp.speckle_log_pmf(0, 0.0, 0.0, 2.0) == 0.0


def test_fisher_weight() -> None:
    s = np.array([0.3, 3.0, 40.0])
    # negative binomial (no background): M / (s (M + s)); Poisson without speckle
    np.testing.assert_allclose(sp.fisher_weight(s, 0.0, 2.5), 2.5 / (s * (2.5 + s)), rtol=1e-14)
    np.testing.assert_allclose(sp.fisher_weight(s, 1e-12, 2.5, exact=True), 2.5 / (s * (2.5 + s)), rtol=1e-8)
    np.testing.assert_allclose(sp.fisher_weight(s, 2.0, math.inf, exact=True), 1 / (s + 2.0), rtol=1e-14)
    # with background: E[(d log P / ds)^2] by central differences of the log-pmf, and the
    # Cramer-Rao bound 1 / var below it
    for si, b, m in ((1.0, 10.0, 1.0), (10.0, 3.0, 2.5), (10.0, 100.0, 1.0)):
        k = np.arange(0, 2000)
        h = 1e-5 * si
        d = (sp.speckle_log_pmf(k, si + h, b, m) - sp.speckle_log_pmf(k, si - h, b, m)) / (2 * h)
        ref = np.sum(np.exp(sp.speckle_log_pmf(k, si, b, m)) * d * d)
        got = float(sp.fisher_weight(si, b, m, exact=True))
        assert got == pytest.approx(ref, rel=1e-6)
        assert got >= float(sp.fisher_weight(si, b, m)) == pytest.approx(1 / (si + b + si * si / m))


def test_blurred_dof() -> None:
    s = np.array([[10.0, 4.0], [10.0, 0.0], [5.0, 2.0]])  # (B = 3, C = 2)
    m = np.array([[2.0, 3.0], [2.0, 3.0], [4.0, math.inf]])
    np.testing.assert_array_equal(sp.blurred_dof(np.eye(3), s, m)[:, 0], m[:, 0])
    # two independent gammas of equal mean and shape add to shape 2 M (exactly a gamma)
    out = sp.blurred_dof([[1.0, 1.0, 0.0]], s, m)
    assert out[0, 0] == pytest.approx(4.0) and out[0, 1] == pytest.approx(3.0)
    # moment matching: M_out = mean^2 / var, var = sum K^2 s^2 / M
    k = np.array([[0.2, 0.5, 0.3]])
    ref = (k @ s[:, 0]) ** 2 / (k**2 @ (s[:, 0] ** 2 / m[:, 0]))
    assert sp.blurred_dof(k, s, m)[0, 0] == pytest.approx(ref[0], rel=1e-14)
    assert sp.blurred_dof([[0.0, 1.0, 1.0]], s, m)[0, 1] == math.inf  # no speckle variance


def test_with_an_instrument_as_measure_would_call_it(rng) -> None:
    """The integration path: an Instrument's Mueller polarimeter, a Mueller profile in
    counts per generator, per-bin dof accumulated over each generator's pulses. The
    speckle-free intensities are expected_counts' signal; the sampled counts average to
    expected_counts with the background, within 5 standard errors (count_moments)."""
    from pprender.inverse.instrument import Instrument, expected_counts

    inst = Instrument(pulse_energy=0.1, target_range=1e6, channels="mueller", n_pulses=40, background_rate=2e9)
    ch = inst.channels
    edges = np.array([0.0, 0.1, 0.2, 0.3])
    # per bin: half mirror, half ideal depolarizer (physical: a convex combination)
    profile = np.array([0.3, 1.0, 0.1])[:, None, None] * np.diag([1.0, 0.5, -0.5, -0.5])
    signal = expected_counts(profile, inst, bin_edges=edges, background=False)
    bg = inst.background_counts(edges)
    unique, gi = sp.generator_groups(ch.generators_array)
    stokes = sp.received_stokes(profile * inst.counts_per_cross_section, unique)  # (B, G, 4)
    np.testing.assert_allclose(sp.sample_intensity(stokes, ch.rows, gi, math.inf, rng), signal, rtol=1e-12)
    m_pulse = sp.speckle_dof(inst.aperture_diameter, inst.wavelength, inst.target_range, [0.01, 0.5, 0.05])
    share = np.array([ch.pulse_share[list(gi).index(g)] for g in range(len(unique))])
    dof = sp.accumulated_dof(m_pulse[:, None], inst.n_pulses * share[None, :], 0.5)  # (B, G)
    n = 20_000
    k = sp.sample_counts(np.broadcast_to(stokes, (n,) + stokes.shape), ch.rows, gi, dof, bg, rng)
    mean, cov = sp.count_moments(stokes, ch.rows, gi, dof, bg)
    np.testing.assert_allclose(mean, signal + bg, rtol=1e-12)
    var = np.diagonal(cov, axis1=-2, axis2=-1)
    assert np.max(signal) > 100 and np.max(var / mean) > 10  # speckle, not shot noise, dominates somewhere
    se = np.sqrt(var / n)
    assert np.max(np.abs(k.mean(0) - mean) / se) < 5
    # variances within 5 of their standard errors (sqrt((kurtosis - 1) / n), kurtosis <= 9)
    assert np.max(np.abs(k.var(0) / var - 1)) < 5 * math.sqrt(8 / n)
    # the likelihood's per-channel dof; inf gives Poisson
    m_c = sp.channel_dof(stokes, ch.rows, gi, dof)
    np.testing.assert_allclose(m_c, dof[:, gi], rtol=1e-12)  # ideal polarizers
    assert np.isfinite(sp.speckle_log_likelihood(k[:5], signal, bg, m_c)).all()


# ---------------------------------------------------------------------- errors

S1 = STOKES[None, None]
R1 = SIX.rows
G1 = np.zeros(6, dtype=int)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: sp.speckle_dof(0.0, 1e-6, 1e6, 1.0), "aperture_diameter"),
        (lambda: sp.speckle_dof(1.0, -1e-6, 1e6, 1.0), "wavelength"),
        (lambda: sp.speckle_dof(1.0, 1e-6, math.inf, 1.0), "target_range"),
        (lambda: sp.speckle_dof(1.0, 1e-6, 1e6, [1.0, math.nan]), "target_area"),
        (lambda: sp.speckle_dof(1.0, 1e-6, 1e6, "1"), "target_area"),
        (lambda: sp.accumulated_dof(0.5, 10), "dof"),
        (lambda: sp.accumulated_dof(2.0, 0.5), "n_pulses"),
        (lambda: sp.accumulated_dof(2.0, 10, 1.5), "correlation"),
        (lambda: sp.coherency([1.0, 0.0, 0.0]), "stokes"),
        (lambda: sp.analyzer_matrix([[1, 0, 0, 1j]]), "rows"),
        (lambda: sp.sample_intensity(np.array([[[1.0, 2.0, 0, 0]]]), R1, G1, 2.0, np.random.default_rng()), "stokes"),
        (lambda: sp.sample_intensity(S1, [[0.5, 0.6, 0, 0]], [0], 2.0, np.random.default_rng()), "rows"),
        (lambda: sp.sample_intensity(S1, R1, G1 + 1, 2.0, np.random.default_rng()), "generator_index"),
        (lambda: sp.sample_intensity(S1, R1, G1.astype(float), 2.0, np.random.default_rng()), "generator_index"),
        (lambda: sp.sample_intensity(S1, R1, G1, 0.9, np.random.default_rng()), "dof"),
        (lambda: sp.sample_intensity(S1, R1, G1, np.ones(3), np.random.default_rng()), "dof"),
        (lambda: sp.sample_intensity(S1, R1, G1, 2.0, 42), "rng"),
        (lambda: sp.sample_counts(S1, R1, G1, 2.0, -1.0, np.random.default_rng()), "background"),
        (lambda: sp.speckle_log_pmf(1.5, 1.0, 0.0, 2.0), "counts"),
        (lambda: sp.speckle_log_pmf(1, -1.0, 0.0, 2.0), "signal"),
        (lambda: sp.speckle_log_pmf(1, 1.0, math.nan, 2.0), "background"),
        (lambda: sp.speckle_log_pmf(1, 1.0, 0.0, math.nan), "dof"),
        (lambda: sp.speckle_log_likelihood([1, 2], 1.0, 0.0, 2.0), "counts"),
        (lambda: sp.speckle_log_likelihood(np.ones((2, 3), int), np.ones(4), 0.0, 2.0), "counts/signal"),
        (lambda: sp.generator_groups([[1.0, 0, 0]]), "generators"),
        (lambda: sp.received_stokes(np.ones((2, 4, 3)), np.ones((1, 4))), "mueller"),
        (lambda: sp.fisher_weight(0.0, 1.0, 2.0), "signal"),
        (lambda: sp.fisher_weight(1.0, 1.0, 0.5), "dof"),
        (lambda: sp.blurred_dof(-np.eye(2), np.ones((2, 1)), 2.0), "kernel"),
        (lambda: sp.blurred_dof(np.eye(2), np.ones((3, 1)), 2.0), "signal"),
    ],
)
def test_bad_input_names_the_parameter(call, name) -> None:
    with pytest.raises(pprender.Error, match=f"invalid {name}"):
        call()
