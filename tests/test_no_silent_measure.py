"""No silent wrong answers in instrument, fit and classify (issue 21).

Each test feeds the public API an input that used to give a plausible but wrong result
without a word, and checks that it now raises :class:`pprender.Error` (naming the
parameter) or warns:

* an instrument applied to a render made at another wavelength (counts off by the
  wavelength ratio);
* nlopt returning ``x0`` with "xtol reached" when the log-likelihood is -inf everywhere,
  and emcee's refusal of such a start not saying why;
* the classifier "matching" measurements with no positive signal, all-zero candidates,
  and presenting a best score of 0 as a match;
* shot-noise measurements far beyond the photon-counting (no pile-up) regime;
* scipy ``Rotation`` objects as attitudes (their quaternions are (x, y, z, w), pprender's
  (w, x, y, z));
* numbers passed as strings (or None) reaching a raw TypeError or being converted
  silently.

Everything is tiny: one render of a 1 m square plate at resolution 16 (well under a
second), synthetic arrays otherwise.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import pprender
from pprender import classify, fit
from pprender import instrument as ins

PLATE = (
    np.array([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]]),
    np.array([[0, 1, 2], [0, 2, 3]]),
)


def metal() -> pprender.Material:
    return pprender.Material("beckmann", alpha=0.3, eta=1.38 + 10.2j, terms=["single"])


def instrument(**kw) -> ins.Instrument:
    base = dict(pulse_energy=1e-3, target_range=1e5)
    base.update(kw)
    return ins.Instrument(**base)


@pytest.fixture(scope="module")
def plate_render() -> pprender.RenderResult:
    """A 1064 nm Stokes render (co/cross linear transmit state) of the plate facing the sensor."""
    sensor = pprender.Lidar(resolution=16, polarization=instrument().channels.transmit)
    return pprender.render(pprender.Scene(PLATE, metal()), sensor, np.eye(3)[None], outputs=("profile",))


def plate_model(bin_edges, **kw) -> fit.ForwardModel:
    kw.setdefault("bounds", {"rx": (-0.1, 0.1)})
    return fit.ForwardModel(PLATE, metal(), instrument(), bin_edges, ("rx",), lidar=pprender.Lidar(resolution=16), **kw)


# ---------------------------------------------------------------------- 4. wavelength


def test_render_wavelength_must_match_the_instrument(plate_render):
    assert plate_render.wavelength == pytest.approx(1064e-9)
    green = instrument(wavelength=532e-9)
    calls = {
        "expected_counts": lambda: ins.expected_counts(plate_render, green),
        "measure": lambda: ins.measure(plate_render, green, seed=1),
        "signal_counts": lambda: green.signal_counts(plate_render),
        "scaled_to": lambda: green.scaled_to(100.0, plate_render),
    }
    for name, call in calls.items():
        with pytest.raises(pprender.Error, match=r"\bwavelength\b") as err:
            call()
        assert "1.064e-06" in str(err.value) and "5.32e-07" in str(err.value), (name, str(err.value))


def test_wavelength_check_tolerance_and_unchecked_inputs(plate_render):
    ref = ins.expected_counts(plate_render, instrument())
    # within 1e-6 relative: accepted, same counts to that precision
    close = instrument(wavelength=1064e-9 * (1 + 5e-7))
    np.testing.assert_allclose(ins.expected_counts(plate_render, close), ref, rtol=1e-6)
    with pytest.raises(pprender.Error, match="wavelength"):
        ins.expected_counts(plate_render, instrument(wavelength=1064e-9 * (1 + 2e-6)))
    # a hand-assembled result (wavelength None) and raw arrays cannot be checked
    green = instrument(wavelength=532e-9)
    by_hand = dataclasses.replace(plate_render, wavelength=None)
    np.testing.assert_allclose(ins.expected_counts(by_hand, green), 0.5 * ref, rtol=1e-12)
    ins.expected_counts(plate_render.profile, green, bin_edges=plate_render.bin_edges)


# ---------------------------------------------------------------------- 5. -inf likelihood


def test_fit_nlopt_refuses_a_likelihood_that_is_minus_inf_everywhere():
    # bins 5 m behind the plate: the model expects 0 counts there, the data has 1 per bin,
    # so log L = -inf at every attitude (no background to explain them)
    model = plate_model([5.0, 5.1, 5.2])
    data = np.ones((2, 2), dtype=np.int64)
    assert model.log_likelihood([0.0], data) == -math.inf
    with pytest.raises(pprender.Error, match=r"log-likelihood is -inf at every") as err:
        fit.fit_nlopt(model, data, [0.0], n_starts=2, seed=0, maxeval=20)
    assert "bin_edges" in str(err.value) and "background" in str(err.value)


def test_fit_nlopt_still_fits_when_some_points_are_finite(plate_render):
    model = plate_model(plate_render.bin_edges)
    data = np.round(model.expected([0.02])).astype(np.int64)
    r = fit.fit_nlopt(model, data, [0.05], maxeval=40)
    assert math.isfinite(r.log_likelihood) and r.return_code > 0


def test_sample_emcee_says_why_the_start_is_refused():
    model = plate_model([5.0, 5.1, 5.2])
    data = np.ones((2, 2), dtype=np.int64)
    with pytest.raises(pprender.Error, match=r"log-likelihood is -inf"):
        fit.sample_emcee(model, data, [0.0], n_walkers=4, n_steps=2, seed=1)


# ---------------------------------------------------------------------- 6. classifier


def candidates() -> np.ndarray:
    """(3, 4, 2): three non-negative profiles with signal in bins 0-1 only."""
    c = np.zeros((3, 4, 2))
    c[:, :2] = np.random.default_rng(0).uniform(0.1, 1.0, size=(3, 2, 2))
    return c


@pytest.mark.parametrize("method", ["scores", "top_k"])
@pytest.mark.parametrize(
    "measurement",
    [-np.ones((4, 2)), -candidates()[0], np.zeros((4, 2)), np.stack([candidates()[1], -candidates()[0]])],
    ids=["negative", "negated-candidate", "zeros", "second-of-two-negative"],
)
def test_classifier_refuses_measurements_without_positive_signal(method, measurement):
    clf = classify.Classifier(candidates())
    call = clf.scores if method == "scores" else lambda x: clf.top_k(x, 1)
    with pytest.raises(pprender.Error, match=r"\bmeasurements\b"):
        call(measurement)


def test_classifier_refuses_measurements_the_weights_cannot_see():
    c = candidates()
    clf = classify.Classifier(c, weights=np.array([1.0, 0.0]))  # channel 1 ignored
    x = np.zeros((4, 2))
    x[:2, 1] = 1.0  # signal only in the ignored channel
    with pytest.raises(pprender.Error, match=r"\bmeasurements\b.*\bweights\b"):
        clf.scores(x)


def test_classifier_refuses_candidates_that_are_all_zero():
    with pytest.raises(pprender.Error, match=r"\bcandidates\b.*zero"):
        classify.Classifier(np.zeros((3, 4, 2)))
    c = candidates()
    c[..., 0] = 0.0
    with pytest.raises(pprender.Error, match=r"\bcandidates\b.*\bweights\b"):
        classify.Classifier(c, weights=np.array([1.0, 0.0]))  # W y = 0 for every candidate


def test_top_k_does_not_present_a_zero_score_as_a_match():
    clf = classify.Classifier(candidates())
    x = np.zeros((2, 4, 2))
    x[0] = candidates()[2]  # a true match
    x[1, 3] = 1.0  # signal only where no candidate has any: every score is 0
    with pytest.warns(classify.NoMatchWarning, match=r"measurement\(s\) \[1\]"):
        top = clf.top_k(x, 2)
    assert issubclass(classify.NoMatchWarning, UserWarning)
    np.testing.assert_array_equal(top.matched, [True, False])
    assert top.score[1, 0] == 0.0 and top.score[0, 0] == pytest.approx(1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert clf.top_k(x[:1], 1).matched.tolist() == [True]


# ---------------------------------------------------------------------- 7. pile-up


def _stokes(b: int = 2) -> tuple[np.ndarray, np.ndarray]:
    p = np.zeros((b, 4))
    p[:, 0] = p[:, 1] = 1.0  # unit cross-section, co-polarized
    return p, np.linspace(0.0, 0.1 * b, b + 1)


def test_measure_warns_beyond_the_photon_counting_regime():
    p, e = _stokes()
    assert issubclass(ins.PileUpWarning, UserWarning)
    assert ins.PILE_UP_THRESHOLD == 0.1
    # 5e17 expected counts per bin in one pulse: far past one photon per pulse
    close = instrument(pulse_energy=1e3, target_range=1.0, divergence=1e-3, aperture_diameter=100.0)
    big = close.scaled_to(1e18, p, bin_edges=e)
    with pytest.warns(ins.PileUpWarning, match=r"5e\+17 expected counts per bin per pulse.*pile-up"):
        m = ins.measure(p, big, bin_edges=e, seed=0)
    assert m.counts[0, 0] == pytest.approx(5e17, rel=1e-6)
    # beyond what a Poisson draw can hold (int64): refused, not a raw ValueError
    assert ins.expected_counts(p, close, bin_edges=e).max() > 1e30
    with pytest.raises(pprender.Error, match="pulse energy"):
        ins.measure(p, close, bin_edges=e, seed=0)
    # 0.2 per bin per pulse (2 counts over 10 pulses): warns, with the value
    inst = instrument(n_pulses=10).scaled_to(4.0, p, bin_edges=e)
    with pytest.warns(ins.PileUpWarning, match=r"0\.2 expected counts per bin per pulse"):
        ins.measure(p, inst, bin_edges=e, seed=0)
    # background alone: 1e9 counts/s over a 0.1 m bin is 0.67 per bin per pulse
    with pytest.warns(ins.PileUpWarning):
        ins.measure(p * 0.0, instrument(background_rate=1e9), bin_edges=e, seed=0)
    # a Mueller polarimeter's channel sees a quarter of the pulses: 5 counts per bin over
    # 100 pulses is 0.05 per pulse overall but 0.2 per pulse of that channel's generator
    mu = np.zeros((2, 4, 4))
    mu[:, 0, 0] = 1.0
    inst = instrument(n_pulses=100, channels="mueller").scaled_to(24 * 2 * 5.0, mu, bin_edges=e)
    with pytest.warns(ins.PileUpWarning, match=r"0\.2 expected counts per bin per pulse"):
        ins.measure(mu, inst, bin_edges=e, seed=0)


def test_measure_is_quiet_in_the_photon_counting_regime():
    p, e = _stokes()
    # 0.05 per bin per pulse in each of a Mueller polarimeter's channels (a quarter of the
    # pulses each): counts are divided by the pulses that channel sees
    mu = np.zeros((2, 4, 4))
    mu[:, 0, 0] = 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ins.measure(p, instrument(n_pulses=1000).scaled_to(100.0, p, bin_edges=e), bin_edges=e, seed=0)
        m = ins.measure(mu, instrument(n_pulses=400, channels="mueller").scaled_to(24 * 2 * 5.0, mu, bin_edges=e),
                        bin_edges=e, seed=0)
    per_pulse = m.expected / (400 * np.asarray(m.instrument.channels.pulse_share))
    assert per_pulse.max() == pytest.approx(0.05)


# ---------------------------------------------------------------------- Rotation objects


def test_scipy_rotations_are_accepted_as_attitudes():
    r = Rotation.from_rotvec([0.3, -0.5, 1.1])
    q_wxyz = r.as_quat()[[3, 0, 1, 2]]
    assert fit.attitude_error(r, q_wxyz) == pytest.approx(0.0, abs=1e-7)
    assert fit.attitude_error(r, Rotation.identity()) == pytest.approx(r.magnitude(), abs=1e-12)
    assert fit.attitude_error(r.as_matrix(), Rotation.identity()) == pytest.approx(r.magnitude(), abs=1e-12)
    stack = Rotation.from_rotvec([[0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.3]])
    np.testing.assert_allclose(fit.attitude_error(stack, stack.as_quat()[:, [3, 0, 1, 2]]), 0.0, atol=1e-7)
    np.testing.assert_allclose(fit.attitude_error(stack, Rotation.identity()), [0.1, 0.2, 0.3], atol=1e-12)
    # the pitfall this avoids: scipy's (x, y, z, w) array read as (w, x, y, z)
    assert fit.attitude_error(r, r.as_quat()) > 0.1
    e = [-0.1, 0.1]
    theta = np.array([[0.02, 0.0, -0.03], [0.0, 0.0, 0.0]])
    free = ("rx", "ry", "rz")
    for frame in ("telescope", "body"):
        kw = dict(free=free, attitude_frame=frame)
        by_rot = fit.ForwardModel(PLATE, metal(), instrument(), e, reference_attitude=r, **kw)
        by_quat = fit.ForwardModel(PLATE, metal(), instrument(), e, reference_attitude=q_wxyz, **kw)
        np.testing.assert_allclose(by_rot.rotations(theta), by_quat.rotations(theta), atol=1e-7)
        np.testing.assert_allclose(by_rot.rotations(theta[1])[0], r.as_matrix(), atol=1e-15)
    with pytest.raises(pprender.Error, match="reference_attitude"):
        fit.ForwardModel(PLATE, metal(), instrument(), e, free, reference_attitude=stack)
    with pytest.raises(pprender.Error, match="reference_attitude"):
        fit.ForwardModel(PLATE, metal(), instrument(), e, free, reference_attitude=np.ones((3, 3)))


# ---------------------------------------------------------------------- numbers as strings


_E = np.linspace(-0.1, 0.1, 5)
_DATA = np.ones((4, 2), dtype=np.int64)


def _model(**kw) -> fit.ForwardModel:
    return plate_model(_E, **kw)


BAD_NUMBERS = [
    # instrument.py
    ("pulse_energy", lambda: instrument(pulse_energy="1e-3")),
    ("n_pulses", lambda: instrument(n_pulses="10")),
    ("background_rate", lambda: instrument(background_rate="1e5")),
    ("background_rate", lambda: instrument(background_rate=["1e5", "2e5"])),
    ("sigma", lambda: ins.jitter_matrix(_E, _E, None)),
    ("sigma", lambda: ins.jitter_matrix(_E, _E, "1e-3")),
    ("bin_edges", lambda: ins.expected_counts(np.ones((4, 4)), instrument(), bin_edges=[str(x) for x in _E])),
    ("profile", lambda: ins.expected_counts(np.ones((4, 4)).astype(str), instrument(), bin_edges=_E)),
    ("total_signal_counts", lambda: instrument().scaled_to("10", np.ones((4, 4)), bin_edges=_E)),
    ("signal", lambda: ins.snr("1", 0.0)),
    ("signal", lambda: ins.snr(None, 0.0)),
    # fit.py
    ("bin_edges", lambda: fit.ForwardModel(PLATE, metal(), instrument(), [str(x) for x in _E], ("rx",))),
    ("bounds", lambda: _model(bounds={"rx": ("-1", "1")})),
    ("cache_size", lambda: _model(cache_size="64")),
    ("cache_size", lambda: _model(cache_size=None)),
    ("cache_size", lambda: _model(cache_size=2.5)),
    ("reference_attitude", lambda: _model(reference_attitude=["1", "0", "0", "0"])),
    ("fixed", lambda: fit.ForwardModel(PLATE, metal(), instrument(), _E, ("rx",), fixed={"ry": "0.1"})),
    ("ftol_abs", lambda: fit.fit_nlopt(_model(), _DATA, [0.0], ftol_abs="1e-6")),
    ("ftol_abs", lambda: fit.fit_nlopt(_model(), _DATA, [0.0], ftol_abs=None)),
    ("xtol_abs", lambda: fit.fit_nlopt(_model(), _DATA, [0.0], xtol_abs="1e-8")),
    ("initial_step", lambda: fit.fit_nlopt(_model(), _DATA, [0.0], initial_step="0.01")),
    ("seed", lambda: fit.fit_nlopt(_model(), _DATA, [0.0], seed="1")),
    ("seed", lambda: fit.fit_nlopt(_model(), _DATA, [0.0], seed=1.5)),
    ("maxeval", lambda: fit.fit_nlopt(_model(), _DATA, [0.0], maxeval="10")),
    ("x0", lambda: fit.fit_nlopt(_model(), _DATA, ["0.0"])),
    ("spread", lambda: fit.sample_emcee(_model(), _DATA, [0.0], 4, 1, 1, spread="1e-3")),
    ("step", lambda: fit.fisher_information(_model(), [0.0], step="1e-3")),
    ("theta", lambda: _model().log_prob(["0.0"], _DATA)),
    ("expected", lambda: fit.poisson_log_likelihood(_DATA, _DATA.astype(str))),
    ("attitude", lambda: fit.attitude_error(["1", "0", "0", "0"], [1.0, 0.0, 0.0, 0.0])),
    # classify.py
    ("candidates", lambda: classify.Classifier(candidates().astype(str))),
    ("weights", lambda: classify.Classifier(candidates(), weights=["1", "2"])),
    ("regularization", lambda: classify.Classifier(candidates(), regularization="0.01")),
    ("n_components", lambda: classify.Classifier(candidates(), labels={"material": list("aab")}, weights="lda",
                                                 n_components="1")),
    ("n_components", lambda: classify.Classifier(candidates(), n_components=1)),
    ("measurements", lambda: classify.Classifier(candidates()).scores(candidates()[0].astype(str))),
    ("k", lambda: classify.Classifier(candidates()).top_k(candidates()[0], "1")),
    ("stokes_in", lambda: classify.stokes_projection(["1", "0", "0", "0"])),
]


@pytest.mark.parametrize("name, call", BAD_NUMBERS, ids=[f"{i}-{n}" for i, (n, _) in enumerate(BAD_NUMBERS)])
def test_numbers_as_strings_or_none_raise_an_error_naming_the_parameter(name, call):
    with pytest.raises(pprender.Error, match=rf"\b{name}\b"):
        call()
