"""pprender.instrument: link budget, polarization channels, jitter, background, shot noise.

Every reference here is computed independently of the module: photon numbers and beam
areas written out from their definitions, Mueller and Stokes algebra done by hand or with
pprender.polarimetry (Rust), the jitter blur by brute-force numerical convolution, Poisson
statistics by their moments.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import dblquad
from scipy.stats import norm

import pprender
from pprender import instrument as ins
from pprender import materials, models, polarimetry

C_LIGHT = 299_792_458.0
H_PLANCK = 6.62607015e-34
IDENTITY = np.array([[1.0, 0.0, 0.0, 0.0]])


def lambertian(rho: float) -> pprender.Material:
    # eta = 1: no specular layer, so the BRDF is exactly rho / pi (see tests/test_render.py)
    return pprender.Material("beckmann", alpha=0.3, eta=1.0 + 0j, terms=["diffuse"], diffuse_albedo=rho)


def random_mueller(rng: np.random.Generator, n: int = 3) -> np.ndarray:
    """A physical, depolarizing Mueller matrix: a sum of n non-depolarizing ones built from
    random Jones matrices with M = A (J x J*) A^-1 (the textbook formula, independent of
    the package)."""
    a = np.array([[1, 0, 0, 1], [1, 0, 0, -1], [0, 1, 1, 0], [0, 1j, -1j, 0]])
    m = np.zeros((4, 4))
    for _ in range(n):
        j = rng.normal(size=(2, 2)) + 1j * rng.normal(size=(2, 2))
        m += np.real(a @ np.kron(j, j.conj()) @ np.linalg.inv(a))
    return m


def instrument(**kw) -> ins.Instrument:
    base = dict(pulse_energy=1e-3, target_range=500e3)
    base.update(kw)
    return ins.Instrument(**base)


# ---------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    "field, value",
    [
        ("pulse_energy", 0.0),
        ("pulse_energy", -1e-3),
        ("pulse_energy", math.nan),
        ("target_range", 0.0),
        ("wavelength", -1.0),
        ("divergence", 0.0),
        ("divergence", 4.0),
        ("beam", "square"),
        ("aperture_diameter", 0.0),
        ("efficiency", 1.5),
        ("efficiency", 0.0),
        ("transmission", 1.01),
        ("jitter", -1e-12),
        ("background_rate", -1.0),
        ("background_rate", [1.0, 2.0, 3.0]),  # 3 values for 2 channels
        ("channels", "quarter_wave"),
        ("n_pulses", 0),
        ("n_pulses", 1.5),
    ],
)
def test_bad_instrument_fields_name_the_field(field, value):
    with pytest.raises(pprender.Error, match=field):
        instrument(**{field: value})


def test_instrument_is_frozen_and_hashable():
    a = instrument()
    with pytest.raises(AttributeError):
        a.pulse_energy = 2.0  # type: ignore[misc]
    assert hash(a) == hash(instrument()) and a == instrument()


# ---------------------------------------------------------------------- link budget


def test_link_budget_lambertian_sphere_against_hand_computation():
    """sigma = 8/3 pi a^2 rho for a Lambertian sphere, and a photon budget written out."""
    a, rho = 0.2, 0.5
    scene = pprender.Scene(models.sphere(radius=a, subdivisions=4), lambertian(rho), smooth=True)
    res = pprender.render(scene, pprender.Lidar(resolution=64), IDENTITY, outputs=("profile",))
    e_pulse, lam, r_m, theta, d_rx, eff, t_atm, n_p = 2e-3, 1064e-9, 800e3, 30e-6, 0.75, 0.4, 0.7, 1000
    inst = ins.Instrument(pulse_energy=e_pulse, target_range=r_m, wavelength=lam, divergence=theta,
                          aperture_diameter=d_rx, efficiency=eff, transmission=t_atm, n_pulses=n_p)
    photons = e_pulse / (H_PLANCK * C_LIGHT / lam)  # E / (h nu)
    assert photons == pytest.approx(1.0713e16, rel=1e-4)  # 2 mJ at 1064 nm: 1.07e16 photons
    w = r_m * theta / 2  # 1/e^2 radius, 12 m; tan(theta/2) = theta/2 to 1e-10 here
    peak_fraction_per_m2 = 2.0 / (math.pi * w**2)  # Gaussian peak irradiance over power
    sigma = 8.0 / 3.0 * math.pi * a * a * rho
    hand = n_p * photons * peak_fraction_per_m2 * sigma * (math.pi * d_rx**2 / 4) / (4 * math.pi * r_m**2) * eff * t_atm**2
    counts = ins.expected_counts(res, inst)
    # a Lambertian surface depolarizes fully: co = cross = sigma / 2, summing to sigma.
    # 3e-3: the rendered icosphere's sigma is 1.4e-3 low (facets inside the sphere, area
    # 0.12 % short; measured at resolutions 48-96 alike)
    assert counts.sum() == pytest.approx(hand, rel=3e-3)
    np.testing.assert_allclose(counts[..., 0].sum(), counts[..., 1].sum(), rtol=1e-6)
    # the top-hat beam spreads the same power over twice the area of the Gaussian's peak
    flat = ins.expected_counts(res, replace(inst, beam="tophat"))
    np.testing.assert_allclose(flat, counts / 2, rtol=1e-12)
    # scaling laws: counts ~ E D^2 eff T^2 / (R^4 theta^2) (R^2 from the beam, R^2 from the return)
    far = replace(inst, target_range=2 * r_m, aperture_diameter=2 * d_rx)
    np.testing.assert_allclose(ins.expected_counts(res, far), counts * 4 / 16, rtol=1e-9)


def test_background_is_rate_times_gate_time():
    inst = instrument(background_rate=[2e5, 5e4], n_pulses=100)
    edges = np.array([0.0, 0.003, 0.006, 0.012])  # 3 mm bins = 20 ps round trip
    bg = inst.background_counts(edges)
    # 2e5/s * (2 * 0.003 m / c = 20.0138 ps) * 100 pulses = 4.00277e-4 counts; the 6 mm bin twice that
    np.testing.assert_allclose(bg[:, 0], [4.002769e-4, 4.002769e-4, 8.005538e-4], rtol=1e-6)
    np.testing.assert_allclose(bg[:, 1], bg[:, 0] / 4, rtol=1e-12)
    # with no signal the expected counts are the background
    zero = np.zeros((3, 4, 4))
    np.testing.assert_allclose(ins.expected_counts(zero, inst, bin_edges=edges), bg, rtol=1e-15)
    # a Mueller polarimeter's channel only opens its gate for its generator's quarter of the pulses
    mu = instrument(background_rate=1e5, n_pulses=100, channels="mueller")
    np.testing.assert_allclose(mu.background_counts(edges), 0.25 * 0.5 * np.repeat(bg[:, :1], 24, axis=1), rtol=1e-12)


# ---------------------------------------------------------------------- channels


def channel_signal(mueller: np.ndarray, channels: str) -> np.ndarray:
    """Counts per channel for a one-bin profile, in units of the link budget."""
    inst = instrument(channels=channels)
    c = ins.expected_counts(mueller[None], inst, bin_edges=[0.0, 1.0], background=False)
    return c[0] / inst.counts_per_cross_section


def test_co_cross_linear_mirror_depolarizer_and_depolarization_ratio():
    np.testing.assert_allclose(channel_signal(np.diag([1.0, 1, -1, -1]), "co_cross_linear"), [1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(channel_signal(np.diag([1.0, 0, 0, 0]), "co_cross_linear"), [0.5, 0.5], atol=1e-15)
    # randomly oriented particles: diag(M00, M11, -M11, M00 - 2 M11) (Mishchenko & Hovenier)
    m = np.diag([1.0, 0.6, -0.6, -0.2])
    co, cross = channel_signal(m, "co_cross_linear")
    assert cross / co == pytest.approx(polarimetry.linear_depolarization_ratio(m), rel=1e-12)


def test_co_cross_circular_mirror_and_depolarization_ratio():
    # a mirror flips V: the circular "co" channel catches all of it
    np.testing.assert_allclose(channel_signal(np.diag([1.0, 1, -1, -1]), "co_cross_circular"), [1.0, 0.0], atol=1e-15)
    m = np.diag([1.0, 0.6, -0.6, -0.2])
    co, cross = channel_signal(m, "co_cross_circular")
    assert cross / co == pytest.approx(polarimetry.circular_depolarization_ratio(m), rel=1e-12)


def test_stokes_channels_reconstruct_the_returned_stokes_vector(rng):
    m = random_mueller(rng)
    h, v, d, a, r, l = channel_signal(m, "stokes")
    s_out = m @ np.array([1.0, 1.0, 0.0, 0.0])  # transmitted H
    # each analyzer sees a third of the light: S = 3 (H + V, H - V, D - A, R - L)
    np.testing.assert_allclose(3 * np.array([h + v, h - v, d - a, r - l]), s_out, rtol=1e-12, atol=1e-12)
    # the three arms each pass a third of the intensity
    np.testing.assert_allclose([h + v, d + a, r + l], [s_out[0] / 3] * 3, rtol=1e-12)


def test_mueller_channels_reconstruct_the_mueller_matrix(rng):
    m = random_mueller(rng)
    counts = channel_signal(m, "mueller")
    states = {"H": [1, 1, 0, 0], "V": [1, -1, 0, 0], "D": [1, 0, 1, 0], "A": [1, 0, -1, 0],
              "R": [1, 0, 0, 1], "L": [1, 0, 0, -1]}
    rows = []  # the measurement matrix from the documented states, built here from scratch
    for g in "HVDR":
        for an in "HVDARL":
            rows.append(np.outer(0.5 * np.array(states[an]), states[g]).ravel() / 12.0)
    w = np.array(rows)
    assert np.linalg.matrix_rank(w) == 16
    m_hat = np.linalg.lstsq(w, counts, rcond=None)[0].reshape(4, 4)
    np.testing.assert_allclose(m_hat, m, atol=1e-12 * np.abs(m).max())


def test_stokes_input_equals_mueller_input_and_mueller_channels_need_mueller(rng):
    prof = np.stack([random_mueller(rng) for _ in range(5)])
    edges = np.linspace(-0.1, 0.15, 6)
    inst = instrument(jitter=30e-12, background_rate=1e4)
    stokes = prof @ inst.channels.transmit
    np.testing.assert_allclose(
        ins.expected_counts(stokes, inst, bin_edges=edges), ins.expected_counts(prof, inst, bin_edges=edges),
        rtol=1e-12,
    )
    with pytest.raises(pprender.Error, match="Mueller profile"):
        ins.expected_counts(stokes, instrument(channels="mueller"), bin_edges=edges)


def test_custom_channels_validate():
    with pytest.raises(pprender.Error, match="analyzers"):
        ins.Channels(("a",), ((0.5, 0.9, 0.0, 0.0),), ((1.0, 1.0, 0.0, 0.0),), (1.0,), (1.0,))
    with pytest.raises(pprender.Error, match="generators"):
        ins.Channels(("a",), ((0.5, 0.5, 0.0, 0.0),), ((2.0, 1.0, 0.0, 0.0),), (1.0,), (1.0,))
    with pytest.raises(pprender.Error, match="split"):
        ins.Channels(("a",), ((0.5, 0.5, 0.0, 0.0),), ((1.0, 1.0, 0.0, 0.0),), (0.0,), (1.0,))
    with pytest.raises(pprender.Error, match="unique"):
        ins.Channels(("a", "a"), ((0.5, 0.5, 0, 0),) * 2, ((1.0, 1.0, 0, 0),) * 2, (1.0, 1.0), (1.0, 1.0))


# ---------------------------------------------------------------------- jitter


def test_jitter_matrix_against_quadrature_and_fine_convolution():
    sigma = 0.004
    src = np.array([-0.01, -0.005, 0.0, 0.007, 0.01])  # unequal bins on purpose
    dst = np.linspace(-0.03, 0.03, 13)
    k = ins.jitter_matrix(src, dst, sigma)
    # (1) one entry by 2-D quadrature of the definition: int_dst int_src g(x - y) dy dx / w
    i, j = 2, 7
    ref, _ = dblquad(lambda y, x: norm.pdf(x - y, scale=sigma), dst[j], dst[j + 1], src[i], src[i + 1])
    assert k[j, i] == pytest.approx(ref / (src[i + 1] - src[i]), rel=1e-7, abs=1e-12)
    # (2) the whole matrix by brute force: 2000 point masses per source bin, Gaussian CDF
    # differences per output bin. Its error is ~ (w/2000)^2 / sigma^2 ~ 1e-7.
    brute = np.zeros_like(k)
    for i in range(len(src) - 1):
        y = np.linspace(src[i], src[i + 1], 2001)
        y = 0.5 * (y[1:] + y[:-1])
        cdf = norm.cdf((dst[:, None] - y[None, :]) / sigma)
        brute[:, i] = np.diff(cdf, axis=0).mean(axis=1)
    np.testing.assert_allclose(k, brute, atol=1e-6)
    # (3) the window covers +-5 sigma beyond the source: columns sum to 1 within 1e-6
    np.testing.assert_allclose(k.sum(axis=0), 1.0, atol=1e-6)
    # (4) no blur and equal edges: the identity; half-offset edges: halves
    np.testing.assert_array_equal(ins.jitter_matrix(dst, dst, 0.0), np.eye(len(dst) - 1))
    half = ins.jitter_matrix([0.0, 1.0], [-0.5, 0.5, 1.5], 0.0)
    np.testing.assert_allclose(half[:, 0], [0.5, 0.5])


def test_jitter_keeps_the_sum_and_adds_its_variance():
    inst = instrument(jitter=100e-12)  # 15 mm of range RMS
    s_j = C_LIGHT * 100e-12 / 2
    w = 0.002
    edges = np.arange(-0.2, 0.2 + w / 2, w)
    centres = 0.5 * (edges[1:] + edges[:-1])
    prof = np.zeros((len(centres), 4, 4))
    prof[:, 0, 0] = np.exp(-0.5 * (centres / 0.01) ** 2)  # a Gaussian return, sigma 10 mm
    blurred = ins.expected_counts(prof, inst, bin_edges=edges)[:, 0]
    sharp = ins.expected_counts(prof, instrument(), bin_edges=edges)[:, 0]
    assert blurred.sum() == pytest.approx(sharp.sum(), rel=1e-12)  # +-13 sigma window
    # variances add. The input is a Gaussian (sigma 10 mm) sampled at the bin centres: its
    # variance is 0.01^2 to ~1e-300. Spreading each bin uniformly adds w^2/12, the blur
    # s_j^2, and re-binning to centres adds Sheppard's w^2/12 (exact for a Gaussian up to
    # exp(-2 pi^2 (sigma/w)^2) terms). 1e-6 relative separates this from the w^2/12 a
    # point-sampled kernel would give (3e-7 of 3.2e-4, i.e. 1e-3 relative).
    var = lambda p: float((p * centres**2).sum() / p.sum())  # noqa: E731
    assert var(sharp) == pytest.approx(0.01**2, rel=1e-12)
    assert var(blurred) == pytest.approx(0.01**2 + s_j**2 + w**2 / 6, rel=1e-6)


# ---------------------------------------------------------------------- measure


@pytest.fixture(scope="module")
def plate_result():
    scene = pprender.Scene(models.plate(width=0.3, height=0.2), materials.get("aluminium", alpha=0.3))
    att = np.array([[math.cos(0.15), math.sin(0.15), 0.0, 0.0]])  # tilted 0.3 rad about X
    return pprender.render(scene, pprender.Lidar(resolution=48), att, outputs=("profile",))


def test_measure_is_poisson_and_reproducible(plate_result):
    inst = instrument(jitter=20e-12, background_rate=10.0, n_pulses=10**5).scaled_to(500.0, plate_result)
    m = ins.measure(plate_result, inst, seed=7)
    assert m.counts.dtype == np.int64 and m.counts.shape == m.expected.shape == (1, len(plate_result.bin_edges) - 1, 2)
    assert m.channel_names == ("co", "cross")
    np.testing.assert_array_equal(m.counts, ins.measure(plate_result, inst, seed=7).counts)
    np.testing.assert_array_equal(m.counts, ins.measure(plate_result, inst, rng=np.random.default_rng(7)).counts)
    assert not np.array_equal(m.counts, ins.measure(plate_result, inst, seed=8).counts)
    np.testing.assert_allclose(m.expected, m.signal + m.background, rtol=1e-15)
    # scaled_to: the expected signal is the requested total
    assert m.signal.sum() == pytest.approx(500.0, rel=1e-12)
    # Poisson moments over 4000 repeats of the same profile: mean and variance of the total
    # both equal the expected total (tolerance 5 standard errors of each estimate)
    big = np.repeat(plate_result.profile, 4000, axis=0)
    tot = ins.measure(big, inst, bin_edges=plate_result.bin_edges, seed=1).counts.sum(axis=(1, 2))
    lam = m.expected.sum()
    assert abs(tot.mean() - lam) < 5 * math.sqrt(lam / 4000)
    assert abs(tot.var() - lam) < 5 * lam * math.sqrt(2 / 4000)
    # SNR = S / sqrt(S + B)
    s, b = m.signal.sum(), m.background.sum()
    assert m.snr == pytest.approx(s / math.sqrt(s + b), rel=1e-12)
    assert ins.snr(m.signal, m.background) == pytest.approx(m.snr, rel=1e-12)


def test_measure_bad_inputs(plate_result):
    inst = instrument()
    p, e = plate_result.profile, plate_result.bin_edges
    with pytest.raises(pprender.Error, match="bin_edges"):
        ins.measure(p, inst)  # an array needs edges
    with pytest.raises(pprender.Error, match="shape"):
        ins.measure(p, inst, bin_edges=e[:-1])  # one bin too few
    with pytest.raises(pprender.Error, match="bin_edges"):
        ins.measure(plate_result, inst, bin_edges=e + 0.001)  # edges that contradict the result
    with pytest.raises(pprender.Error, match="increasing"):
        ins.measure(p, inst, bin_edges=e[::-1])
    bad = p.copy()
    bad[0, 3, 0, 0] = np.nan
    with pytest.raises(pprender.Error, match="finite"):
        ins.measure(bad, inst, bin_edges=e)
    neg = np.zeros_like(p)
    neg[0, 3, 0, 0] = -1.0  # negative intensity: not physical
    with pytest.raises(pprender.Error, match="negative"):
        ins.measure(neg, inst, bin_edges=e)
    with pytest.raises(pprender.Error, match="shape"):
        ins.measure(p[..., :3], inst, bin_edges=e)
    with pytest.raises(pprender.Error, match="seed"):
        ins.measure(plate_result, inst, seed=1, rng=np.random.default_rng(1))
    with pytest.raises(pprender.Error, match="instrument"):
        ins.measure(plate_result, "lidar")
    with pytest.raises(pprender.Error, match="total_signal_counts"):
        inst.scaled_to(-5.0, plate_result)
