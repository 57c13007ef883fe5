"""What the detector records: photon counting with dead time (pile-up) or a linear-mode APD.

Conventions (those of :mod:`pprender.inverse.instrument`): arrays are ``(..., B, C)``,
range bins then polarization channels; ``expected`` holds the expected photo-electrons
(signal + background) of each bin and channel accumulated over that channel's pulses,
``pulses`` (``(C,)``, ``n_pulses * pulse_share``) the number of pulses each channel sees.
The per-pulse expectation is ``lam = expected / pulses``. Each channel has its own
detector; pulses, channels and leading (attitude) axes are independent.

Kinds (:class:`Detector`):

* ``"photon_counting"`` (SPAD, PMT in counting mode) with dead time ``dead_time`` (s):

  - ``dead_time = 0``: no dead time; the counts are Poisson with mean ``expected``
    (:func:`pprender.measure`'s model, drawn by the same ``rng.poisson`` call, bit for bit).
  - ``dead_time >= gate``, the gate being the span of the bins, ``2 (e[-1] - e[0]) / c``
    (the classic case: one event per pulse, the first photon). Photons arrive as a Poisson
    process, ``lam_b`` expected in bin ``b`` of a pulse; the detector records the first
    one, in bin ``b`` with Coates' (1968) probability
    ``p_b = exp(-sum_{j<b} lam_j) (1 - exp(-lam_b))``, or nothing with
    ``p_0 = exp(-sum_j lam_j)``. Over ``n`` pulses the recorded counts are multinomial
    ``(n; p_1..p_B, p_0)``: :meth:`Detector.sample` draws them and
    :meth:`Detector.log_likelihood` is their exact log-pmf. :func:`coates_correction`
    inverts the mean (the maximum-likelihood estimate of ``lam``,
    ``lam_b = -ln(1 - k_b / (n - sum_{j<b} k_j))``), with its delta-method standard error.
    The gate is taken to open at the first bin edge (the background before it is not
    counted) and the detector to recover between pulses (dead time shorter than the pulse
    period). Scintillation (a per-pulse factor ``I`` on the whole return,
    :mod:`pprender.inverse.atmosphere`) keeps the pulses i.i.d., so the counts stay
    multinomial with Coates' probabilities averaged over ``I`` through its Laplace
    transform (``laplace=atmosphere.laplace``; :func:`coates_probabilities`), exactly; the
    differences of the transform carry an absolute error ~1e-11 per probability (the
    quadrature's), i.e. relative ~1e-11 / lam_b for a bin of ``lam_b`` per pulse.
  - ``0 < dead_time < gate``: refused (:class:`pprender.Error`). A detector recovering
    within the gate records several events per pulse; the recorded counts of the bins of a
    pulse are then a dependent (non-multinomial) vector whose likelihood over ``n`` pulses
    has no closed form (it needs the per-pulse joint law of a renewal process with a
    piecewise-constant rate), and an approximate one would be a silent wrong answer in the
    fits. Model such a detector as ``dead_time = 0`` only where it stays well below one
    count per dead time (:data:`pprender.inverse.instrument.PILE_UP_THRESHOLD`).

* ``"linear"`` (linear-mode APD): gain ``G``, ionization ratio ``k`` (hole-to-electron
  for an electron-injected APD, ``k <= 1``), McIntyre's (1966) excess noise factor
  ``F = k G + (1 - k) (2 - 1/G)``, amplifier noise ``sigma_a`` (electrons RMS per bin and
  pulse at the amplifier input, i.e. ``sigma_a / G`` photo-electrons) and a saturation
  level (photo-electrons per bin and pulse) above which a :class:`SaturationWarning` is
  given. The record is an analog photo-electron estimate (float) per bin with mean
  ``N = expected`` and variance ``F N + pulses (sigma_a / G)^2``.

  The sampler draws the primary photo-electrons ``m ~ Poisson(N)`` and their multiplied
  charge as a sum of ``m`` independent gains, each a gamma variable of mean ``G`` and
  variance ``(F - 1) G^2`` (the two-moment gamma approximation of McIntyre's
  single-electron gain distribution; sums of gammas are gamma, so the bin's output over
  all its pulses is ``Gamma(m / (F - 1), (F - 1))`` photo-electrons), then adds Gaussian
  amplifier noise. Its mean and variance are exactly ``N`` and ``F N + pulses (sigma_a /
  G)^2``, it keeps McIntyre's positive skew and the no-electron atom at 0, and ``G = 1``
  (``F = 1``) gives the Poisson count ``m``. :meth:`Detector.log_likelihood` for this kind
  is the Gaussian with the same two moments (the sampler's law, a Poisson mixture of
  gammas convolved with a Gaussian, has no closed form). Its error falls like the
  skewness ``~ (1 + 2 (F - 1)) / sqrt(F N)`` (docs/detector-atmosphere.md gives the
  measured distance between the two laws).

Detector and atmosphere together: :func:`record` draws what the receiver records (the
detector's records of the counts, scintillation included, channels sharing pulses
correlated through the factor) and :func:`record_log_likelihood` is the matching
log-likelihood (exact without scintillation and for one channel per pulse group; a
composite likelihood otherwise, said there).

References: Coates, J. Phys. E 1, 878 (1968); McIntyre, IEEE Trans. Electron Devices 13,
164 (1966); Conradi, IEEE Trans. Electron Devices 19, 713 (1972).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.special import gammaln, xlogy

from .._core import Error

if TYPE_CHECKING:  # the atmosphere imports this module's helpers; no import at run time
    from .atmosphere import Atmosphere

__all__ = [
    "DETECTOR_KINDS",
    "Detector",
    "SaturationWarning",
    "coates_correction",
    "coates_probabilities",
    "excess_noise_factor",
    "record",
    "record_log_likelihood",
]

#: The kinds :class:`Detector` accepts.
DETECTOR_KINDS = ("photon_counting", "linear")

_C = 299_792_458.0


class SaturationWarning(UserWarning):
    """A linear-mode detector was asked for more photo-electrons per bin and pulse than its saturation level.

    The recorded values assume a linear response; above saturation a real detector's
    output is compressed (:class:`Detector`).
    """


def _number(name: str, value: Any, lo: float, hi: float, lo_open: bool, hi_open: bool, unit: str) -> float:
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    v = float(value) if ok else math.nan
    ok = ok and not math.isnan(v) and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not ok:
        rng = ("(" if lo_open else "[") + f"{lo:g}, {hi:g}" + (")" if hi_open else "]")
        raise Error(f"invalid {name} = {value!r}: a number in {rng} ({unit})")
    return v


def _array(value: Any, name: str) -> np.ndarray:
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError):
        raise Error(f"invalid {name}: not an array of numbers") from None
    if raw.dtype.kind not in "biuf":
        raise Error(f"invalid {name}: dtype {raw.dtype}, an array of real numbers (not text, None or complex)")
    return raw.astype(np.float64)


def excess_noise_factor(gain: Any, ionization_ratio: Any) -> Any:
    """McIntyre's excess noise factor ``F = k G + (1 - k) (2 - 1/G)`` of an APD.

    Parameters
    ----------
    gain : float or array_like
        Mean gain ``G >= 1``.
    ionization_ratio : float or array_like
        Ionization coefficient ratio ``k`` in [0, 1] (the carrier injected is the more
        ionizing one).

    Returns
    -------
    float or numpy.ndarray
        ``F >= 1`` (``F = 1`` at ``G = 1``; ``F = G`` at ``k = 1``; ``F -> 2`` as
        ``G -> inf`` at ``k = 0``), broadcast over the inputs.

    Raises
    ------
    pprender.Error
        For ``G < 1``, ``k`` outside [0, 1], or values that are not finite numbers.
    """
    g = _array(gain, "gain")
    k = _array(ionization_ratio, "ionization_ratio")
    if not np.all(np.isfinite(g)) or np.any(g < 1):
        raise Error("invalid gain: finite values >= 1")
    if not np.all(np.isfinite(k)) or np.any(k < 0) or np.any(k > 1):
        raise Error("invalid ionization_ratio: values in [0, 1]")
    f = k * g + (1.0 - k) * (2.0 - 1.0 / g)
    return float(f) if np.ndim(f) == 0 else f


def coates_probabilities(lam: Any, laplace: Any = None) -> np.ndarray:
    """Coates' per-pulse probabilities of the first recorded photon, per bin and "none".

    With a per-pulse scintillation factor ``I`` (mean 1, the same on every bin of the
    pulse; :class:`pprender.inverse.atmosphere.Atmosphere`), the pulses stay independent
    and identically distributed, so the recorded counts stay multinomial, with the
    probabilities averaged over ``I``: ``p_b = L(A_b) - L(A_{b+1})`` and ``p_0 = L(A_B)``,
    ``A_b = sum_{j<b} lam_j`` and ``L(t) = E[exp(-t I)]`` the factor's Laplace transform
    (:meth:`~pprender.inverse.atmosphere.Atmosphere.laplace`). ``L(t) = exp(-t)`` gives
    Coates' formula.

    Parameters
    ----------
    lam : array_like
        (..., B, C) expected photo-electrons per bin and pulse (signal + background), finite
        and ``>= 0``.
    laplace : callable, optional
        ``L(t)``, elementwise on an array of ``t >= 0`` (e.g. ``atmosphere.laplace``);
        default none (no scintillation: Coates' closed form).

    Returns
    -------
    numpy.ndarray
        (..., B + 1, C): ``p_b = exp(-sum_{j<b} lam_j) (1 - exp(-lam_b))`` for the bins, then
        ``exp(-sum_j lam_j)`` (no event); each column sums to 1.

    Raises
    ------
    pprender.Error
        For values that are not finite and ``>= 0``, an array that is not (..., B, C), or a
        ``laplace`` that does not return values in [0, 1] of the shape it was given.
    """
    lam = _lam_array(lam, "lam")
    if laplace is None:
        before = np.cumsum(lam, axis=-2) - lam  # sum_{j<b}
        p = np.exp(-before) * -np.expm1(-lam)
        none = np.exp(-np.sum(lam, axis=-2, keepdims=True))
        return np.concatenate([p, none], axis=-2)
    cum = np.concatenate([np.zeros_like(lam[..., :1, :]), np.cumsum(lam, axis=-2)], axis=-2)  # A_0 .. A_B
    if not callable(laplace):
        raise Error(f"invalid laplace of type {type(laplace).__name__}: a callable L(t) = E[exp(-t I)]")
    big_l = np.asarray(laplace(cum), dtype=np.float64)
    if big_l.shape != cum.shape or not np.all((big_l >= 0) & (big_l <= 1)):
        raise Error("invalid laplace: L(t) must return values in [0, 1] of the shape of t")
    big_l = np.minimum.accumulate(big_l, axis=-2)  # non-increasing in t, whatever the rounding
    return np.concatenate([big_l[..., :-1, :] - big_l[..., 1:, :], big_l[..., -1:, :]], axis=-2)


def _lam_array(value: Any, name: str) -> np.ndarray:
    a = _array(value, name)
    if a.ndim < 2:
        raise Error(f"invalid {name}: shape {a.shape}, expected (..., B, C)")
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise Error(f"invalid {name}: must be finite and >= 0 (photo-electrons)")
    return a


def _pulses(pulses: Any, c: int, whole: bool,
            why: str = "a dead-time detector needs a whole number (>= 1) of pulses per channel") -> np.ndarray:
    """Pulses per channel (C,), finite and > 0; with ``whole``, whole numbers (``why`` says
    why in the error)."""
    p = _array(pulses, "pulses")
    if p.ndim == 0:
        p = np.full(c, float(p))
    if p.shape != (c,) or not np.all(np.isfinite(p)) or np.any(p <= 0):
        raise Error(f"invalid pulses: {c} finite values > 0 (pulses per channel), got shape {p.shape}")
    if whole:
        r = np.round(p)
        if np.any(np.abs(p - r) > 1e-9 * np.maximum(r, 1.0)) or np.any(r < 1):
            raise Error(
                f"invalid pulses = {p.tolist()}: {why} (n_pulses * pulse_share)"
            )
        p = r
    return p


def coates_correction(counts: Any, pulses: Any) -> tuple[np.ndarray, np.ndarray]:
    """Coates' pile-up correction: the expected counts per bin that recorded first-photon counts imply.

    For a detector recording at most one event per pulse (:class:`Detector` with
    ``dead_time >= gate``): ``lam_b = -ln(1 - k_b / (n - sum_{j<b} k_j))`` per pulse, the
    maximum-likelihood estimate (each bin's recorded count is binomial over the pulses
    still live at it), returned over all ``n`` pulses (``n lam_b``) as ``expected`` is.
    Its standard error (delta method, evaluated at the estimate) is
    ``n sqrt((exp(lam_b) - 1) / m_b)``, ``m_b = n - sum_{j<b} k_j`` the live pulses.

    Parameters
    ----------
    counts : array_like
        (..., B, C) recorded counts, non-negative integers (real numbers are accepted, e.g.
        :meth:`Detector.mean`'s expected recorded counts, the exact inverse).
    pulses : float or array_like
        Pulses per channel, one value or ``(C,)``.

    Returns
    -------
    estimate : numpy.ndarray
        (..., B, C) corrected expected counts over the pulses. ``inf`` where every live
        pulse recorded an event in the bin (no upper bound: more pulses or less light are
        needed); ``nan`` where no pulse was live at the bin (earlier bins took them all: the
        data say nothing about it).
    std_error : numpy.ndarray
        (..., B, C) standard errors (same conventions; ``0`` where the estimate is 0).

    Raises
    ------
    pprender.Error
        For negative or non-finite counts, counts whose sum over bins exceeds the pulses,
        or invalid ``pulses``.
    """
    k = _lam_array(counts, "counts")
    n = _pulses(pulses, k.shape[-1], whole=False)
    if np.any(np.sum(k, axis=-2) > n * (1 + 1e-12)):
        raise Error("invalid counts: more recorded events over the bins than pulses (at most one per pulse)")
    live = n - (np.cumsum(k, axis=-2) - k)
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(live > 0, k / np.where(live > 0, live, 1.0), np.nan)
        frac = np.clip(frac, 0.0, 1.0)
        lam = -np.log1p(-frac)
        err = np.sqrt(np.expm1(lam) / np.where(live > 0, live, np.nan))
    return n * lam, n * err


@dataclass(frozen=True)
class Detector:
    """A detector: photon counting with dead time, or a linear-mode APD (module docstring).

    ``Detector()`` is the ideal photon counter (Poisson counts, as :func:`pprender.measure`).

    Parameters
    ----------
    kind : {"photon_counting", "linear"}, optional
        Default ``"photon_counting"``.
    dead_time : float, optional
        Photon counting: dead time (s), ``0`` (none: Poisson counts) or at least the range
        gate (one event per pulse: Coates' multinomial), ``inf`` allowed; in [0, inf].
        Default 0. Dead times between 0 and the gate are refused where the gate is known
        (:meth:`sample` etc.; module docstring).
    gain : float, optional
        Linear: mean APD gain ``G`` in [1, 1e6]. Default 1.
    ionization_ratio : float, optional
        Linear: ionization coefficient ratio ``k`` in [0, 1]. Default 0.
    amplifier_noise : float, optional
        Linear: amplifier noise, electrons RMS per bin and pulse at the amplifier input,
        in [0, 1e12]. Default 0.
    saturation : float, optional
        Linear: photo-electrons per bin and pulse above which the response is not linear
        (:class:`SaturationWarning`), in (0, inf]. Default inf.

    Raises
    ------
    pprender.Error
        For a value outside its range, an unknown kind, or a parameter of the other kind
        set away from its default (e.g. a gain for a photon counter).
    """

    kind: str = "photon_counting"
    dead_time: float = 0.0
    gain: float = 1.0
    ionization_ratio: float = 0.0
    amplifier_noise: float = 0.0
    saturation: float = math.inf

    def __post_init__(self) -> None:
        if self.kind not in DETECTOR_KINDS:
            raise Error(f"invalid kind = {self.kind!r}: one of {DETECTOR_KINDS}")
        vals = {
            "dead_time": _number("dead_time", self.dead_time, 0.0, math.inf, False, False, "s"),
            "gain": _number("gain", self.gain, 1.0, 1e6, False, False, "mean APD gain"),
            "ionization_ratio": _number("ionization_ratio", self.ionization_ratio, 0.0, 1.0, False, False, "k"),
            "amplifier_noise": _number(
                "amplifier_noise", self.amplifier_noise, 0.0, 1e12, False, False, "electrons RMS per bin and pulse"
            ),
            "saturation": _number(
                "saturation", self.saturation, 0.0, math.inf, True, False, "photo-electrons per bin and pulse"
            ),
        }
        other = ("gain", "ionization_ratio", "amplifier_noise", "saturation") if self.kind == "photon_counting" else (
            "dead_time",
        )
        defaults = {"dead_time": 0.0, "gain": 1.0, "ionization_ratio": 0.0, "amplifier_noise": 0.0,
                    "saturation": math.inf}
        for name in other:
            if vals[name] != defaults[name]:
                raise Error(
                    f"invalid {name} = {vals[name]!r} for kind={self.kind!r}: it applies to kind="
                    f"{'linear' if self.kind == 'photon_counting' else 'photon_counting'!r} only"
                )
        for name, v in vals.items():
            object.__setattr__(self, name, v)

    # ------------------------------------------------------------------ regime

    @property
    def excess_noise(self) -> float:
        """McIntyre's excess noise factor ``F`` (:func:`excess_noise_factor`; 1 for a photon counter)."""
        if self.kind != "linear":
            return 1.0
        return float(excess_noise_factor(self.gain, self.ionization_ratio))

    @property
    def is_poisson(self) -> bool:
        """Whether the records are Poisson counts with mean ``expected`` (a photon counter
        without dead time: :func:`pprender.measure`'s model)."""
        return self.kind == "photon_counting" and self.dead_time == 0.0

    def regime(self, bin_edges: Any = None) -> str:
        """The statistical model used on these bins: ``"poisson"``, ``"coates"`` or ``"linear"``.

        Parameters
        ----------
        bin_edges : array_like, optional
            (B + 1,) range bin edges (m), increasing; needed for a finite dead time > 0
            (to compare it with the gate ``2 (e[-1] - e[0]) / c``).

        Returns
        -------
        str
            ``"poisson"`` (no dead time), ``"coates"`` (dead time at least the gate) or
            ``"linear"`` (an APD).

        Raises
        ------
        pprender.Error
            For a dead time in (0, gate) (not modelled, module docstring), a finite dead
            time > 0 without ``bin_edges``, or invalid ``bin_edges``.
        """
        if self.kind == "linear":
            return "linear"
        if self.dead_time == 0.0:
            return "poisson"
        if math.isinf(self.dead_time):
            return "coates"
        if bin_edges is None:
            raise Error(
                "invalid bin_edges = None: a detector with a finite dead time needs the bin edges to compare "
                "the dead time with the range gate"
            )
        e = _array(bin_edges, "bin_edges")
        if e.ndim != 1 or len(e) < 2 or not np.all(np.isfinite(e)) or not np.all(np.diff(e) > 0):
            raise Error("invalid bin_edges: (B + 1,) finite, strictly increasing range edges (m)")
        gate = 2.0 * float(e[-1] - e[0]) / _C
        if self.dead_time >= gate:
            return "coates"
        raise Error(
            f"invalid dead_time = {self.dead_time:g} s: shorter than the range gate ({gate:.4g} s, 2 x "
            f"{float(e[-1] - e[0]):.4g} m / c). Modelled: dead_time = 0 (Poisson) or >= the gate (one event "
            "per pulse, Coates); a detector recovering within the gate is not (pprender.inverse.detector)"
        )

    # ------------------------------------------------------------------ statistics

    def _check(self, expected: Any, pulses: Any, bin_edges: Any, laplace: Any) -> tuple[np.ndarray, np.ndarray, str]:
        lam = _lam_array(expected, "expected")
        mode = self.regime(bin_edges)
        n = _pulses(pulses, lam.shape[-1], whole=mode == "coates")
        if laplace is not None and mode != "coates":
            raise Error(
                f"invalid laplace for a {mode!r} detector: scintillation enters here only for a dead time at "
                "least the gate; without dead time use Atmosphere.sample_counts / log_likelihood"
            )
        return lam, n, mode

    def mean(self, expected: Any, pulses: Any, *, bin_edges: Any = None, laplace: Any = None) -> np.ndarray:
        """The expected recorded value per bin and channel.

        Parameters
        ----------
        expected : array_like
            (..., B, C) expected photo-electrons over each channel's pulses (signal +
            background).
        pulses : float or array_like
            Pulses per channel (``n_pulses * pulse_share``), one value or ``(C,)``; whole
            numbers for a dead-time detector.
        bin_edges : array_like, optional
            (B + 1,) range bin edges (m), needed for a finite dead time (:meth:`regime`).
        laplace : callable, optional
            Dead time at least the gate: the scintillation factor's Laplace transform
            ``L(t) = E[exp(-t I)]`` (``atmosphere.laplace``), which averages Coates'
            probabilities over the per-pulse factor (:func:`coates_probabilities`); refused
            for the other regimes. Default none.

        Returns
        -------
        numpy.ndarray
            (..., B, C): ``expected`` itself (Poisson, linear), or ``n p_b`` (Coates'
            probabilities, :func:`coates_probabilities`, of ``expected / n``).

        Raises
        ------
        pprender.Error
            For invalid arrays or pulses, or a dead time that is not modelled.
        """
        lam, n, mode = self._check(expected, pulses, bin_edges, laplace)
        if mode != "coates":
            return lam.copy()
        return n * coates_probabilities(lam / n, laplace)[..., :-1, :]

    def variance(self, expected: Any, pulses: Any, *, bin_edges: Any = None, laplace: Any = None) -> np.ndarray:
        """The variance of the recorded value per bin and channel.

        Parameters
        ----------
        expected : array_like
            (..., B, C) expected photo-electrons over each channel's pulses.
        pulses : float or array_like
            Pulses per channel, one value or ``(C,)``.
        bin_edges : array_like, optional
            (B + 1,) range bin edges (m), needed for a finite dead time.
        laplace : callable, optional
            Dead time at least the gate: the scintillation factor's Laplace transform
            ``L(t) = E[exp(-t I)]`` (``atmosphere.laplace``), which averages Coates'
            probabilities over the per-pulse factor (:func:`coates_probabilities`); refused
            for the other regimes. Default none.

        Returns
        -------
        numpy.ndarray
            (..., B, C): ``expected`` (Poisson), ``n p_b (1 - p_b)`` (Coates, multinomial),
            ``F expected + pulses (sigma_a / G)^2`` (linear).

        Raises
        ------
        pprender.Error
            As :meth:`mean`.
        """
        lam, n, mode = self._check(expected, pulses, bin_edges, laplace)
        if mode == "poisson":
            return lam.copy()
        if mode == "coates":
            p = coates_probabilities(lam / n, laplace)[..., :-1, :]
            return n * p * (1.0 - p)
        return self.excess_noise * lam + n * (self.amplifier_noise / self.gain) ** 2

    def sample(
        self, expected: Any, pulses: Any, rng: np.random.Generator, *, bin_edges: Any = None, laplace: Any = None
    ) -> np.ndarray:
        """Draw what the detector records.

        Parameters
        ----------
        expected : array_like
            (..., B, C) expected photo-electrons over each channel's pulses (signal +
            background).
        pulses : float or array_like
            Pulses per channel (``n_pulses * pulse_share``), one value or ``(C,)``; whole
            numbers for a dead-time detector.
        rng : numpy.random.Generator
            The generator. Poisson: one ``rng.poisson(expected)`` call (as
            :func:`pprender.measure`, bit for bit).
        bin_edges : array_like, optional
            (B + 1,) range bin edges (m), needed for a finite dead time.
        laplace : callable, optional
            Dead time at least the gate: the scintillation factor's Laplace transform
            ``L(t) = E[exp(-t I)]`` (``atmosphere.laplace``), which averages Coates'
            probabilities over the per-pulse factor (:func:`coates_probabilities`); refused
            for the other regimes. Default none.

        Returns
        -------
        numpy.ndarray
            (..., B, C): int64 counts (photon counting) or float64 photo-electron estimates
            (linear).

        Raises
        ------
        pprender.Error
            For invalid arrays, pulses or ``rng``, or a dead time that is not modelled.

        Warns
        -----
        SaturationWarning
            Linear: where ``expected / pulses`` exceeds the saturation level (the values
            are still drawn, linearly).
        """
        if not isinstance(rng, np.random.Generator):
            raise Error(f"invalid rng of type {type(rng).__name__}: expected numpy.random.Generator")
        lam, n, mode = self._check(expected, pulses, bin_edges, laplace)
        if mode == "poisson":
            return rng.poisson(lam).astype(np.int64)
        if mode == "coates":
            p = coates_probabilities(lam / n, laplace)
            pm = np.moveaxis(p, -2, -1)  # (..., C, B + 1)
            pm = pm / np.sum(pm, axis=-1, keepdims=True)
            nn = np.broadcast_to(n.astype(np.int64), pm.shape[:-1])
            k = rng.multinomial(nn, pm)
            return np.moveaxis(k[..., :-1], -1, -2).astype(np.int64)
        self._warn_saturation(lam, n)
        return self._amplify(rng.poisson(lam), n, rng)

    def _amplify(self, m: np.ndarray, n: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The linear record of ``m`` primary photo-electrons (module docstring)."""
        f = self.excess_noise
        if f > 1.0:
            x = rng.gamma(m / (f - 1.0), f - 1.0)
        else:
            x = m.astype(np.float64)
        if self.amplifier_noise > 0:
            x = x + rng.normal(0.0, 1.0, size=x.shape) * np.sqrt(n) * (self.amplifier_noise / self.gain)
        return np.asarray(x, dtype=np.float64)

    def log_likelihood(
        self, data: Any, expected: Any, pulses: Any, *, bin_edges: Any = None, laplace: Any = None,
        _extra_variance: Any = 0.0,
    ) -> Any:
        """Log-likelihood of recorded ``data`` given ``expected``, summed over bins and channels.

        Poisson: ``sum [k log(lam) - lam - log(k!)]`` (:func:`pprender.fit.poisson_log_likelihood`).
        Coates: the exact multinomial log-pmf per channel, ``log n! - sum_b log k_b! -
        log k_0! + sum_b k_b log p_b + k_0 log p_0``, ``k_0 = n - sum_b k_b`` the pulses
        without an event. Linear: the Gaussian with the detector's mean and variance (module
        docstring).

        Parameters
        ----------
        data : array_like
            (..., B, C) records (counts: non-negative integers; linear: real numbers).
        expected : array_like
            (..., B, C) expected photo-electrons over each channel's pulses; broadcast
            against ``data``.
        pulses : float or array_like
            Pulses per channel, one value or ``(C,)``.
        bin_edges : array_like, optional
            (B + 1,) range bin edges (m), needed for a finite dead time.
        laplace : callable, optional
            Dead time at least the gate: the scintillation factor's Laplace transform
            ``L(t) = E[exp(-t I)]`` (``atmosphere.laplace``), which averages Coates'
            probabilities over the per-pulse factor (:func:`coates_probabilities`); refused
            for the other regimes. Default none.

        Returns
        -------
        float or numpy.ndarray
            Over the leading axes (a float for 2-D inputs); ``-inf`` for impossible data
            (a count where nothing is expected, more events than pulses), never NaN.

        Raises
        ------
        pprender.Error
            For counts that are not non-negative integers, shapes that do not broadcast,
            invalid ``expected`` or pulses, or a dead time that is not modelled.
        """
        lam, n, mode = self._check(expected, pulses, bin_edges, laplace)
        x = _array(data, "data")
        if x.ndim < 2 or not np.all(np.isfinite(x)):
            raise Error(f"invalid data: finite values of shape (..., B, C), got shape {x.shape}")
        try:
            shape = np.broadcast_shapes(x.shape, lam.shape)
        except ValueError:
            raise Error(f"invalid data/expected: shapes {x.shape} and {lam.shape} do not broadcast") from None
        if shape[-2:] != lam.shape[-2:]:
            raise Error(f"invalid data: shape {x.shape}, its bins and channels differ from expected's {lam.shape}")
        if mode != "linear" and (np.any(x < 0) or np.any(x != np.round(x))):
            raise Error("invalid data: counts must be non-negative integers")
        if mode == "poisson":
            out = np.sum(xlogy(x, lam) - lam - gammaln(x + 1.0), axis=(-2, -1))
        elif mode == "coates":
            x, lam = np.broadcast_arrays(x, lam)
            k0 = n - np.sum(x, axis=-2)
            bad = np.any(k0 < 0, axis=-1)
            k0 = np.maximum(k0, 0.0)
            kk = np.concatenate([x, k0[..., None, :]], axis=-2)
            # log p_b = -sum_{j<b} lam_j + log(1 - exp(-lam_b)): kept in logs for small lam_b
            ll = lam / n
            with np.errstate(divide="ignore"):
                if laplace is None:
                    before = np.cumsum(ll, axis=-2) - ll
                    logp = np.concatenate(
                        [-before + np.log(-np.expm1(-ll)), -np.sum(ll, axis=-2, keepdims=True)], axis=-2
                    )
                else:
                    logp = np.log(coates_probabilities(ll, laplace))
            possible = np.isfinite(logp)
            terms = kk * np.where(possible, logp, 0.0)
            terms = np.where((kk > 0) & ~possible, -np.inf, terms)
            out = np.sum(gammaln(n + 1.0) - np.sum(gammaln(kk + 1.0), axis=-2) + np.sum(terms, axis=-2), axis=-1)
            out = np.where(bad, -np.inf, out)
        else:
            v = self.excess_noise * lam + n * (self.amplifier_noise / self.gain) ** 2 + _extra_variance
            v = np.broadcast_to(v, shape)
            xb, mb = np.broadcast_arrays(x, lam)
            with np.errstate(divide="ignore", invalid="ignore"):
                z = np.where(v > 0, -0.5 * ((xb - mb) ** 2 / np.where(v > 0, v, 1.0) + np.log(2 * np.pi * v)), 0.0)
            z = np.where((v <= 0) & (xb != mb), -np.inf, z)
            out = np.sum(z, axis=(-2, -1))
        return float(out) if np.ndim(out) == 0 else out

    def _warn_saturation(self, lam: np.ndarray, n: np.ndarray) -> None:
        per_pulse = lam / n
        worst = float(np.max(per_pulse, initial=0.0))
        if not worst > self.saturation:
            return
        n_over = int(np.sum(per_pulse > self.saturation))
        warnings.warn(
            f"detector: up to {worst:.3g} photo-electrons per bin and pulse expected, above the saturation "
            f"level {self.saturation:g} ({n_over} bin/channel value(s)); the records assume a linear response "
            "(lower the pulse energy or the gain).",
            SaturationWarning,
            stacklevel=3,
        )


# ---------------------------------------------------------------------- detector + atmosphere


def _setup(detector: Any, atmosphere: Any, bin_edges: Any) -> tuple[Detector, Any, str]:
    det = Detector() if detector is None else detector
    if not isinstance(det, Detector):
        raise Error(f"invalid detector of type {type(det).__name__}: expected a Detector")
    if atmosphere is not None and not all(hasattr(atmosphere, a) for a in ("laplace", "sample_counts", "index")):
        raise Error(f"invalid atmosphere of type {type(atmosphere).__name__}: expected an Atmosphere")
    atm = atmosphere if atmosphere is not None and atmosphere.scintillation != "none" else None
    return det, atm, det.regime(bin_edges)


def record(
    expected: Any,
    pulses: Any,
    rng: np.random.Generator,
    *,
    detector: Detector | None = None,
    atmosphere: "Atmosphere | None" = None,
    bin_edges: Any = None,
    groups: Any = None,
    n_exact: int = 100_000,
) -> np.ndarray:
    """What the receiver records: the detector's records of the counts, scintillation included.

    Without scintillation this is :meth:`Detector.sample` (a photon counter without dead
    time: one ``rng.poisson(expected)`` call, :func:`pprender.measure`'s, bit for bit). With
    scintillation (:class:`~pprender.inverse.atmosphere.Atmosphere`; its transmission is the
    caller's, in ``expected``):

    * no dead time: :meth:`Atmosphere.sample_counts` (exact up to ``n_exact`` pulses);
    * dead time at least the gate: each pulse simulated (up to ``n_exact`` pulses per
      channel): one factor ``I`` per pulse and group, and in each channel the first photon
      at the bin where ``I A(t)`` (``A`` the cumulative expected photo-electrons of the
      pulse) first exceeds an ``Exp(1)`` draw, exactly the first arrival of the Poisson
      process; channels sharing pulses are correlated through ``I``. Above ``n_exact``,
      each channel is drawn from its multinomial with Coates' probabilities averaged over
      ``I`` (exact per channel, without the correlation between channels);
    * linear APD: the primary photo-electrons from :meth:`Atmosphere.sample_counts`, then
      the gain and amplifier noise.

    Parameters
    ----------
    expected : array_like
        (..., B, C) expected photo-electrons over each channel's pulses, without
        scintillation (signal + background).
    pulses : float or array_like
        Pulses per channel (``n_pulses * pulse_share``), one value or ``(C,)``.
    rng : numpy.random.Generator
        The generator.
    detector : Detector, optional
        Default ``Detector()`` (Poisson counts).
    atmosphere : Atmosphere, optional
        Its scintillation is used (none by default).
    bin_edges : array_like, optional
        (B + 1,) range bin edges (m), needed for a finite dead time.
    groups : array_like, optional
        (C,) labels of the channels that see the same pulses
        (:func:`pprender.inverse.atmosphere.pulse_groups`); default all alike.
    n_exact : int, optional
        Largest number of pulses simulated one by one (default 100000).

    Returns
    -------
    numpy.ndarray
        (..., B, C) int64 counts or float64 linear records.

    Raises
    ------
    pprender.Error
        For invalid arrays, pulses, groups, detector, atmosphere or ``rng``, or a dead time
        that is not modelled.

    Warns
    -----
    SaturationWarning
        As :meth:`Detector.sample`.
    """
    det, atm, mode = _setup(detector, atmosphere, bin_edges)
    if atm is None:
        return det.sample(expected, pulses, rng, bin_edges=bin_edges)
    if not isinstance(rng, np.random.Generator):
        raise Error(f"invalid rng of type {type(rng).__name__}: expected numpy.random.Generator")
    if mode == "poisson":
        return np.asarray(atm.sample_counts(expected, pulses, rng, groups=groups, n_exact=n_exact))
    lam, n, _ = det._check(expected, pulses, bin_edges, None)
    if mode == "linear":
        det._warn_saturation(lam, n)
        m = atm.sample_counts(lam, n, rng, groups=groups, n_exact=n_exact)
        return det._amplify(np.asarray(m), n, rng)
    # Coates: validate the groups with the atmosphere's own check
    _, g = atm._groups(lam.shape[-1], n, groups)
    lead, b_count, c_count = lam.shape[:-2], lam.shape[-2], lam.shape[-1]
    out = np.zeros(lam.shape, dtype=np.int64)
    cum = np.cumsum(lam / n, axis=-2)  # (..., B, C): A_{b+1}, per pulse
    n_lead = int(np.prod(lead, dtype=np.int64))
    for k in range(int(g.max()) + 1):
        cols = np.flatnonzero(g == k)
        n_k = int(n[cols[0]])
        if n_k > n_exact:
            out[..., cols] = det.sample(lam[..., cols], n[cols], rng, laplace=atm.laplace)
            continue
        left = n_k
        block = max(1, 4_000_000 // max(1, n_lead * b_count * len(cols)))
        while left > 0:
            m = min(left, block)
            i_factor = np.asarray(atm.sample_factor(rng, lead + (m,)))  # (..., m)
            for c in cols:
                x = rng.exponential(1.0, lead + (m,)) / i_factor  # first arrival in units of A
                first = np.sum(cum[..., None, :, c] < x[..., None], axis=-1)  # (..., m): bin, B = none
                out[..., c] += np.sum(first[..., :, None] == np.arange(b_count), axis=-2)
            left -= m
    return out


def record_log_likelihood(
    data: Any,
    expected: Any,
    pulses: Any,
    *,
    detector: Detector | None = None,
    atmosphere: "Atmosphere | None" = None,
    bin_edges: Any = None,
    groups: Any = None,
) -> Any:
    """Log-likelihood of what :func:`record` draws, summed over bins and channels.

    Without scintillation, :meth:`Detector.log_likelihood` (exact Poisson or Coates;
    Gaussian for the APD). With scintillation: no dead time,
    :meth:`Atmosphere.log_likelihood` (per pulse group); dead time at least the gate, the
    product over channels of the exact multinomial with Coates' probabilities averaged over
    the factor (exact per channel; the correlation between channels sharing pulses, which
    the sampler keeps, is left out: a composite likelihood); linear APD, the Gaussian with
    variance ``F N + N^2 sigma_I^2 / n + pulses (sigma_a / G)^2`` per bin (the correlation
    between bins left out).

    Parameters
    ----------
    data : array_like
        (..., B, C) records.
    expected : array_like
        (..., B, C) expected photo-electrons over each channel's pulses, without
        scintillation.
    pulses : float or array_like
        Pulses per channel, one value or ``(C,)``.
    detector : Detector, optional
        Default ``Detector()``.
    atmosphere : Atmosphere, optional
        Its scintillation is used (none by default).
    bin_edges : array_like, optional
        (B + 1,) range bin edges (m), needed for a finite dead time.
    groups : array_like, optional
        (C,) labels of the channels that see the same pulses; default all alike.

    Returns
    -------
    float or numpy.ndarray
        Over the leading axes (a float for 2-D inputs); ``-inf`` for impossible data.

    Raises
    ------
    pprender.Error
        As :meth:`Detector.log_likelihood` and :meth:`Atmosphere.log_likelihood`.
    """
    det, atm, mode = _setup(detector, atmosphere, bin_edges)
    if atm is None:
        return det.log_likelihood(data, expected, pulses, bin_edges=bin_edges)
    if mode == "poisson":
        return atm.log_likelihood(data, expected, pulses, groups=groups)
    if mode == "coates":
        return det.log_likelihood(data, expected, pulses, bin_edges=bin_edges, laplace=atm.laplace)
    lam, n, _ = det._check(expected, pulses, bin_edges, None)
    return det.log_likelihood(data, lam, n, _extra_variance=lam**2 * atm.index / n)
