"""The atmosphere between the lidar and the target: transmission by elevation and scintillation.

Transmission: the one-way transmission at elevation ``h`` is
``T(h) = T_zenith ** (X(h) / X(90 deg))`` with ``X`` the relative optical air mass of
Kasten & Young (1989), ``X(h) = 1 / (sin h + 0.50572 (h + 6.07995)^-1.6364)`` (``h`` in
degrees; :func:`airmass`). Dividing by ``X(90) = 0.99971`` makes ``T(90) = T_zenith``
exactly. The round trip is ``T(h)^2`` (the instrument's ``transmission`` is the one-way
``T(h)``: :meth:`Atmosphere.transmission`). Elevations in [``MIN_ELEVATION_DEG``, 90] deg
are accepted; the formula, fitted to Kasten & Young's ray-traced table over the whole
range 0-90 deg, stays within 0.5 % of it, but a lidar does not range through the
horizon's 38 air masses.

Scintillation: turbulence modulates the received power of each pulse by a factor ``I``
of mean 1, the same on every bin and channel of that pulse (the aperture-averaged
irradiance fluctuation of the return, which depends on the pulse, not on the range bin
within a few metres of target), independent between pulses (pulse periods >> the
atmospheric coherence time, ~ms, are assumed). Laws (:class:`Atmosphere`):

* ``"none"``: ``I = 1``;
* ``"lognormal"`` (weak turbulence): ``ln I ~ N(-s^2 / 2, s^2)``, ``s^2 = ln(1 + sigma_I^2)``,
  ``sigma_I^2`` the scintillation index;
* ``"gamma_gamma"`` (Andrews & Phillips, moderate to strong turbulence): ``I = X Y``,
  ``X ~ Gamma(alpha, 1/alpha)``, ``Y ~ Gamma(beta, 1/beta)``, pdf
  ``2 (alpha beta)^((alpha+beta)/2) / (Gamma(alpha) Gamma(beta)) I^((alpha+beta)/2 - 1)
  K_{alpha-beta}(2 sqrt(alpha beta I))``, scintillation index
  ``1/alpha + 1/beta + 1/(alpha beta)``. From the Rytov variance ``sigma_R^2`` (plane
  wave, zero inner scale; Andrews & Phillips, *Laser Beam Propagation through Random
  Media*, 2nd ed., eqs. 9.9 and 9.32):
  ``alpha = 1 / (exp(0.49 sigma_R^2 / (1 + 1.11 sigma_R^(12/5))^(7/6)) - 1)``,
  ``beta = 1 / (exp(0.51 sigma_R^2 / (1 + 0.69 sigma_R^(12/5))^(5/6)) - 1)``.

Accumulated counts: a bin expecting ``lam`` counts over ``n`` pulses (``lam / n`` per pulse,
Poisson given the factors) records ``K ~ Poisson(lam S)``, ``S = (I_1 + ... + I_n) / n``,
a mixed Poisson with the exact moments ``E K = lam``,
``Var K = lam + lam^2 sigma_I^2 / n``, and ``Cov(K_b, K_b') = lam_b lam_b' sigma_I^2 / n``
between bins and channels that share the pulses (the common factor correlates them).
:meth:`Atmosphere.sample_counts` draws this exactly (the ``n`` factors of each pulse
group) up to ``n_exact`` pulses; above it, it draws ``S`` from the law of the factor's
family with mean 1 and variance ``sigma_I^2 / n`` (below).

Likelihood (:meth:`Atmosphere.log_likelihood`). Given ``S`` the counts are independent
Poisson, so the counts of one pulse group (every bin and channel seeing the same pulses)
have ``log L = sum_b [k_b log lam_b - log k_b!] + log E[S^K exp(-Lam S)]``, ``K`` and
``Lam`` the group's total counts and expectation: a one-dimensional integral, which keeps
the correlation between bins and channels. ``approximation="auto"`` (default) evaluates
it for ``S`` of the factor's family with mean 1 and variance ``sigma_I^2 / n``: the exact
law for ``n = 1``; for ``n > 1`` a lognormal of index ``sigma_I^2 / n`` (Fenton-Wilkinson)
or a gamma-gamma with both shapes scaled by the ``c`` giving that variance. The integrand
is log-concave in ``ln S``: its mode by safeguarded Newton, then 48-node Gauss-Hermite quadrature
scaled to the mode's curvature (gamma-gamma: the smaller-shape gamma integrated in closed
form). Its error against adaptive quadrature is below 1e-7 in ``log L`` for the lognormal
and for gamma-gamma with ``max(alpha, beta) >= 1.5`` (every Rytov-derived pair), 4e-5 at
``alpha = 0.8, beta = 0.6``. ``approximation="gamma"``: ``S`` gamma with shape
``r = n / sigma_I^2``, the negative multinomial in closed form,
``... + log Gamma(r + K) - log Gamma(r) + r log r - (r + K) log(r + Lam)``, each bin's
marginal the negative binomial matched in the first two moments (faster, coarser at few
pulses). Both have the exact mean and variance and are the Poisson likelihood without
scintillation. Their errors against direct simulation (total variation distance for
n = 1, 2, 10, 100) are in docs/detector-atmosphere.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.special import betaln, gammaln, kve, xlogy

from .._core import Error
from .detector import _array, _number, _pulses

__all__ = [
    "MIN_ELEVATION_DEG",
    "SCINTILLATION_LAWS",
    "Atmosphere",
    "airmass",
    "gamma_gamma_parameters",
    "pulse_groups",
]

#: Lowest elevation (deg) :func:`airmass` and :class:`Atmosphere` accept.
MIN_ELEVATION_DEG = 1.0

#: The scintillation laws :class:`Atmosphere` accepts.
SCINTILLATION_LAWS = ("none", "lognormal", "gamma_gamma")

_N_EXACT = 100_000


def airmass(elevation_deg: Any) -> Any:
    """Kasten & Young's (1989) relative optical air mass at an elevation.

    ``X(h) = 1 / (sin h + 0.50572 (h + 6.07995)^-1.6364)``, ``h`` in degrees (Appl. Opt.
    28, 4735, eq. 3); ``X(90) = 0.99971`` (the formula's value, not renormalized here).

    Parameters
    ----------
    elevation_deg : float or array_like
        Elevation above the horizon (deg) in [``MIN_ELEVATION_DEG``, 90].

    Returns
    -------
    float or numpy.ndarray
        The relative air mass.

    Raises
    ------
    pprender.Error
        For elevations outside [``MIN_ELEVATION_DEG``, 90] deg or that are not numbers.
    """
    h = _array(elevation_deg, "elevation_deg")
    if not np.all(np.isfinite(h)) or np.any(h < MIN_ELEVATION_DEG) or np.any(h > 90.0):
        raise Error(f"invalid elevation_deg: values in [{MIN_ELEVATION_DEG:g}, 90] deg")
    x = 1.0 / (np.sin(np.radians(h)) + 0.50572 * (h + 6.07995) ** -1.6364)
    return float(x) if np.ndim(x) == 0 else x


def gamma_gamma_parameters(rytov_variance: float) -> tuple[float, float]:
    """Andrews & Phillips' gamma-gamma ``(alpha, beta)`` for a plane wave of Rytov variance ``sigma_R^2``.

    Zero inner scale (module docstring): ``alpha = 1 / (exp(0.49 sigma_R^2 / (1 + 1.11
    sigma_R^(12/5))^(7/6)) - 1)``, ``beta = 1 / (exp(0.51 sigma_R^2 / (1 + 0.69
    sigma_R^(12/5))^(5/6)) - 1)``. Weak turbulence: the scintillation index tends to
    ``sigma_R^2``; strong: ``alpha -> inf``, ``beta -> 1`` (index -> 1, exponential
    statistics).

    Parameters
    ----------
    rytov_variance : float
        ``sigma_R^2`` in (0, 1e4].

    Returns
    -------
    tuple of float
        ``(alpha, beta)``.

    Raises
    ------
    pprender.Error
        For ``rytov_variance`` outside (0, 1e4].
    """
    s2 = _number("rytov_variance", rytov_variance, 0.0, 1e4, True, False, "Rytov variance")
    s125 = s2 ** 1.2
    a = 1.0 / math.expm1(0.49 * s2 / (1.0 + 1.11 * s125) ** (7.0 / 6.0))
    b = 1.0 / math.expm1(0.51 * s2 / (1.0 + 0.69 * s125) ** (5.0 / 6.0))
    return a, b


def pulse_groups(generators: Any) -> np.ndarray:
    """Labels of the channels that see the same pulses (one transmitted state, one group).

    Parameters
    ----------
    generators : array_like
        (C, 4) transmitted Stokes state of each channel (``Channels.generators``).

    Returns
    -------
    numpy.ndarray
        (C,) int labels ``0 .. G-1``, equal for channels with equal generators.

    Raises
    ------
    pprender.Error
        For an array that is not (C, 4) finite numbers.
    """
    g = _array(generators, "generators")
    if g.ndim != 2 or g.shape[1] != 4 or len(g) == 0 or not np.all(np.isfinite(g)):
        raise Error(f"invalid generators: shape {g.shape}, expected (C, 4) finite Stokes states")
    _, labels = np.unique(g, axis=0, return_inverse=True)
    return np.asarray(labels, dtype=np.int64).reshape(-1)


@dataclass(frozen=True)
class Atmosphere:
    """Atmospheric transmission by elevation and per-pulse scintillation (module docstring).

    ``Atmosphere()`` is vacuum: transmission 1 and no scintillation.

    Parameters
    ----------
    zenith_transmission : float, optional
        One-way transmission towards the zenith, in (0, 1]. Default 1.
    elevation_deg : float, optional
        Elevation of the target (deg) in [``MIN_ELEVATION_DEG``, 90]. Default 90.
    scintillation : {"none", "lognormal", "gamma_gamma"}, optional
        The law of the per-pulse factor. Default ``"none"``.
    scintillation_index : float, optional
        ``sigma_I^2``, in [0, 100]: the lognormal's parameter (required there); for
        ``"gamma_gamma"`` it is computed from ``alpha`` and ``beta`` (leave it 0). Default 0.
    alpha : float, optional
        Gamma-gamma large-scale parameter, in (0, 1e8]; with ``beta``, or neither and
        ``rytov_variance`` instead.
    beta : float, optional
        Gamma-gamma small-scale parameter, in (0, 1e8].
    rytov_variance : float, optional
        Gamma-gamma: the plane-wave Rytov variance, in (0, 1e4], giving ``alpha`` and
        ``beta`` (:func:`gamma_gamma_parameters`).

    Raises
    ------
    pprender.Error
        For a value outside its range, an unknown law, parameters of another law, both
        ``(alpha, beta)`` and ``rytov_variance``, or a lognormal without a positive index.
    """

    zenith_transmission: float = 1.0
    elevation_deg: float = 90.0
    scintillation: str = "none"
    scintillation_index: float = 0.0
    alpha: float | None = None
    beta: float | None = None
    rytov_variance: float | None = None

    def __post_init__(self) -> None:
        _number("zenith_transmission", self.zenith_transmission, 0.0, 1.0, True, False, "one-way")
        object.__setattr__(self, "zenith_transmission", float(self.zenith_transmission))
        _number("elevation_deg", self.elevation_deg, MIN_ELEVATION_DEG, 90.0, False, False, "deg")
        object.__setattr__(self, "elevation_deg", float(self.elevation_deg))
        if self.scintillation not in SCINTILLATION_LAWS:
            raise Error(f"invalid scintillation = {self.scintillation!r}: one of {SCINTILLATION_LAWS}")
        idx = _number("scintillation_index", self.scintillation_index, 0.0, 100.0, False, False, "sigma_I^2")
        gg = (self.alpha, self.beta, self.rytov_variance)
        if self.scintillation != "gamma_gamma" and any(v is not None for v in gg):
            raise Error(
                f"invalid alpha/beta/rytov_variance for scintillation={self.scintillation!r}: they apply to "
                "'gamma_gamma' only"
            )
        if self.scintillation == "none":
            if idx != 0:
                raise Error(
                    f"invalid scintillation_index = {idx!r} with scintillation='none': choose 'lognormal' or "
                    "'gamma_gamma'"
                )
        elif self.scintillation == "lognormal":
            if not idx > 0:
                raise Error("invalid scintillation_index = 0 for 'lognormal': a value in (0, 100] (sigma_I^2)")
        else:
            if idx != 0:
                raise Error(
                    "invalid scintillation_index for 'gamma_gamma': it follows from alpha and beta "
                    "(1/alpha + 1/beta + 1/(alpha beta)); give alpha and beta or rytov_variance"
                )
            if self.rytov_variance is not None:
                if self.alpha is not None or self.beta is not None:
                    raise Error("invalid alpha/beta with rytov_variance: give (alpha, beta) or rytov_variance, not both")
                r = _number("rytov_variance", self.rytov_variance, 0.0, 1e4, True, False, "Rytov variance")
                a, b = gamma_gamma_parameters(r)
                object.__setattr__(self, "rytov_variance", r)
            else:
                if self.alpha is None or self.beta is None:
                    raise Error("invalid alpha/beta: 'gamma_gamma' needs both alpha and beta, or rytov_variance")
                a = _number("alpha", self.alpha, 0.0, 1e8, True, False, "gamma-gamma shape")
                b = _number("beta", self.beta, 0.0, 1e8, True, False, "gamma-gamma shape")
            object.__setattr__(self, "alpha", a)
            object.__setattr__(self, "beta", b)
            idx = 1.0 / a + 1.0 / b + 1.0 / (a * b)
        object.__setattr__(self, "scintillation_index", float(idx))

    # ------------------------------------------------------------------ transmission

    def transmission(self) -> float:
        """One-way transmission at the elevation, ``T_zenith ** (X(h) / X(90))`` (:func:`airmass`).

        Returns
        -------
        float
            In (0, 1]; the instrument's one-way transmission (the round trip is its square):
            ``Instrument(atmosphere=...)`` uses it in the link budget
            (:attr:`pprender.inverse.instrument.Instrument.one_way_transmission`).
        """
        return float(self.zenith_transmission ** (airmass(self.elevation_deg) / airmass(90.0)))

    # ------------------------------------------------------------------ per-pulse factor

    @property
    def index(self) -> float:
        """The scintillation index ``sigma_I^2`` (the factor's variance; 0 without scintillation)."""
        return float(self.scintillation_index)

    def moments(self) -> tuple[float, float]:
        """Mean and variance of the per-pulse factor: ``(1, sigma_I^2)``.

        Returns
        -------
        tuple of float
            ``(1.0, sigma_I^2)``.
        """
        return 1.0, self.index

    def sample_factor(self, rng: np.random.Generator, size: Any = None) -> Any:
        """Draw per-pulse scintillation factors (mean 1).

        Parameters
        ----------
        rng : numpy.random.Generator
            The generator.
        size : int or tuple of int, optional
            Output shape (None: one float).

        Returns
        -------
        float or numpy.ndarray
            The factors, ``> 0`` (all 1 without scintillation).

        Raises
        ------
        pprender.Error
            For an ``rng`` that is not a numpy Generator.
        """
        if not isinstance(rng, np.random.Generator):
            raise Error(f"invalid rng of type {type(rng).__name__}: expected numpy.random.Generator")
        if self.scintillation == "none":
            out: Any = np.ones(size) if size is not None else 1.0
        elif self.scintillation == "lognormal":
            s2 = math.log1p(self.index)
            out = np.exp(rng.normal(-0.5 * s2, math.sqrt(s2), size))
        else:
            a, b = float(self.alpha), float(self.beta)  # type: ignore[arg-type]
            out = rng.gamma(a, 1.0 / a, size) * rng.gamma(b, 1.0 / b, size)
        return float(out) if size is None else np.asarray(out, dtype=np.float64)

    def laplace(self, t: Any) -> Any:
        """The factor's Laplace transform ``L(t) = E[exp(-t I)]``.

        A photon counter recording the first photon of each pulse sees Coates' probabilities
        averaged over the factor through it
        (:func:`pprender.inverse.detector.coates_probabilities`). Computed as the one-pulse
        likelihood's integral (module docstring) with no count: within ~1e-9 of adaptive
        quadrature.

        Parameters
        ----------
        t : float or array_like
            Values ``t >= 0`` (expected photo-electrons of a pulse before a bin, without
            scintillation).

        Returns
        -------
        float or numpy.ndarray
            ``L(t)`` in (0, 1], ``exp(-t)`` without scintillation.

        Raises
        ------
        pprender.Error
            For negative or non-finite values.
        """
        x = _array(t, "t")
        if not np.all(np.isfinite(x)) or np.any(x < 0):
            raise Error("invalid t: finite values >= 0")
        if self.scintillation == "none":
            out = np.exp(-x)
        else:
            out = np.exp(self._log_single_pulse(np.zeros_like(x), x))
        return float(out) if np.ndim(out) == 0 else out

    def pdf(self, intensity: Any) -> Any:
        """Probability density of the per-pulse factor.

        Parameters
        ----------
        intensity : float or array_like
            Values ``I >= 0``.

        Returns
        -------
        float or numpy.ndarray
            The density (``0`` is returned at ``I = 0`` itself).

        Raises
        ------
        pprender.Error
            Without scintillation (a point mass at 1 has no density), or for negative or
            non-finite values.
        """
        x = _array(intensity, "intensity")
        if not np.all(np.isfinite(x)) or np.any(x < 0):
            raise Error("invalid intensity: finite values >= 0")
        if self.scintillation == "none":
            raise Error("invalid scintillation='none' for pdf: the factor is exactly 1 (no density)")
        pos = x > 0
        xs = np.where(pos, x, 1.0)
        if self.scintillation == "lognormal":
            s2 = math.log1p(self.index)
            logp = -((np.log(xs) + 0.5 * s2) ** 2) / (2 * s2) - np.log(xs * math.sqrt(2 * math.pi * s2))
        else:
            a, b = float(self.alpha), float(self.beta)  # type: ignore[arg-type]
            z = 2.0 * np.sqrt(a * b * xs)
            v = abs(a - b)
            with np.errstate(divide="ignore", over="ignore"):
                logk = np.log(kve(v, z)) - z  # K_v(z) = kve(v, z) exp(-z), no overflow at large z
            if v > 0:
                # small z, large v: K_v(z) ~ Gamma(v) / 2 (2 / z)^v (kve overflows there)
                small = gammaln(v) - math.log(2.0) + v * np.log(2.0 / z)
                logk = np.where(np.isfinite(logk), logk, small)
            logp = (math.log(2.0) + 0.5 * (a + b) * math.log(a * b) - gammaln(a) - gammaln(b)
                    + (0.5 * (a + b) - 1.0) * np.log(xs) + logk)
        out = np.where(pos, np.exp(logp), 0.0)
        return float(out) if np.ndim(out) == 0 else out

    # ------------------------------------------------------------------ accumulated counts

    def _mean_law(self, n: float) -> "Atmosphere":
        """The law of the same family as the factor with mean 1 and variance ``sigma_I^2 / n``:
        the law used for the mean ``S`` of ``n`` factors (itself at ``n = 1``). Lognormal:
        index ``sigma_I^2 / n`` (Fenton-Wilkinson); gamma-gamma: ``(c alpha, c beta)`` with
        ``1/(c alpha) + 1/(c beta) + 1/(c^2 alpha beta) = sigma_I^2 / n``."""
        if n == 1.0 or self.scintillation == "none":
            return self
        v = self.index / n
        if self.scintillation == "lognormal":
            return Atmosphere(scintillation="lognormal", scintillation_index=v)
        a, b = float(self.alpha), float(self.beta)  # type: ignore[arg-type]
        # y = 1 / c solves y (1/a + 1/b) + y^2 / (a b) = v (the positive root, without cancellation)
        p1 = 1.0 / a + 1.0 / b
        y = 2.0 * v / (p1 + math.sqrt(p1 * p1 + 4.0 * v / (a * b)))
        return Atmosphere(scintillation="gamma_gamma", alpha=min(a / y, 1e8), beta=min(b / y, 1e8))

    def _log_single_pulse(self, ktot: Any, ltot: Any) -> np.ndarray:
        """``log E[S^K exp(-Lam S)]`` for one pulse, ``S`` the factor (arrays ``K``, ``Lam``)."""
        kk = np.asarray(ktot, dtype=np.float64)
        lt = np.asarray(ltot, dtype=np.float64)
        shape = np.broadcast_shapes(kk.shape, lt.shape)
        kk, lt = np.broadcast_to(kk, shape), np.broadcast_to(lt, shape)
        zero = lt <= 0
        lt = np.where(zero, 1.0, lt)
        K, L = kk[..., None], lt[..., None]
        if self.scintillation == "lognormal":
            s2 = math.log1p(self.index)
            c = -0.5 * math.log(2.0 * math.pi * s2)

            def g(u: Any) -> Any:
                return K * u - L * np.exp(u) - (u + 0.5 * s2) ** 2 / (2.0 * s2) + c

            def dg(u: Any) -> Any:
                return kk - lt * np.exp(u) - (u + 0.5 * s2) / s2

            def d2g(u: Any) -> Any:
                return -lt * np.exp(u) - 1.0 / s2
        else:
            a, b = float(self.alpha), float(self.beta)  # type: ignore[arg-type]
            # X ~ Gamma(a, 1/a) over u = ln x, E_Y[(x Y)^K exp(-Lam x Y)] in closed form; the
            # larger shape goes to the quadrature (its left tail in u decays like exp((a + K) u))
            a, b = max(a, b), min(a, b)
            c0 = a * math.log(a) - gammaln(a) + b * math.log(b) - gammaln(b)
            cK = gammaln(b + K)

            def g(u: Any) -> Any:
                return c0 + cK + (a + K) * u - a * np.exp(u) - (b + K) * np.log(b + L * np.exp(u))

            def dg(u: Any) -> Any:
                e = np.exp(u)
                return a + kk - a * e - (b + kk) * lt * e / (b + lt * e)

            def d2g(u: Any) -> Any:
                e = np.exp(u)
                return -a * e - (b + kk) * b * lt * e / (b + lt * e) ** 2
        with np.errstate(over="ignore", under="ignore", divide="ignore", invalid="ignore"):
            out = _log_laplace_gh(g, dg, d2g, shape)
        # Lam = 0: E[S^K] is 1 for K = 0; a count where nothing is expected is impossible
        return np.where(zero, np.where(kk > 0, -np.inf, 0.0), out)

    def _groups(self, c: int, pulses: Any, groups: Any) -> tuple[np.ndarray, np.ndarray]:
        p = _pulses(pulses, c, self.scintillation != "none",
                    "scintillation acts pulse by pulse, so each channel needs a whole number (>= 1) of pulses")
        if groups is None:
            g = np.zeros(c, dtype=np.int64)
        else:
            g = np.asarray(groups)
            if g.shape != (c,) or g.dtype.kind not in "iu":
                raise Error(f"invalid groups: ({c},) integer labels of the channels sharing pulses")
            _, g = np.unique(g, return_inverse=True)
            g = g.reshape(-1)
        for k in range(int(g.max()) + 1):
            pk = p[g == k]
            if np.any(np.abs(pk - pk[0]) > 1e-9 * pk[0]):
                raise Error(f"invalid pulses/groups: channels of group {k} see different numbers of pulses {pk}")
        return p, g

    def count_moments(self, expected: Any, pulses: Any) -> tuple[np.ndarray, np.ndarray]:
        """Exact mean and variance of the accumulated counts under scintillation.

        Parameters
        ----------
        expected : array_like
            (..., B, C) expected counts over the pulses, without scintillation.
        pulses : float or array_like
            Pulses per channel, one value or ``(C,)``.

        Returns
        -------
        mean : numpy.ndarray
            ``expected``.
        variance : numpy.ndarray
            ``expected + expected^2 sigma_I^2 / pulses``.

        Raises
        ------
        pprender.Error
            For expected counts that are not finite and ``>= 0`` or invalid pulses.
        """
        lam = _expected(expected)
        p, _ = self._groups(lam.shape[-1], pulses, None)
        return lam.copy(), lam + lam**2 * self.index / p

    def sample_counts(
        self, expected: Any, pulses: Any, rng: np.random.Generator, *, groups: Any = None, n_exact: int = _N_EXACT
    ) -> np.ndarray:
        """Draw accumulated counts ``Poisson(expected S)``, one ``S`` per pulse group (module docstring).

        Without scintillation this is one ``rng.poisson(expected)`` call (as
        :func:`pprender.measure`, bit for bit).

        Parameters
        ----------
        expected : array_like
            (..., B, C) expected counts over the pulses, without scintillation.
        pulses : float or array_like
            Pulses per channel, one value or ``(C,)``; whole numbers (>= 1) with
            scintillation.
        rng : numpy.random.Generator
            The generator.
        groups : array_like, optional
            (C,) int labels of the channels that see the same pulses (:func:`pulse_groups`);
            default: all channels see the same pulses.
        n_exact : int, optional
            Up to this many pulses the factors are drawn pulse by pulse; above, their mean
            ``S`` is drawn from the factor's family with mean 1 and variance
            ``sigma_I^2 / n`` (module docstring).
            Default 100000.

        Returns
        -------
        numpy.ndarray
            (..., B, C) int64 counts.

        Raises
        ------
        pprender.Error
            For invalid arrays, pulses, groups, ``rng`` or ``n_exact``.
        """
        if not isinstance(rng, np.random.Generator):
            raise Error(f"invalid rng of type {type(rng).__name__}: expected numpy.random.Generator")
        if isinstance(n_exact, (bool, np.bool_)) or not isinstance(n_exact, (int, np.integer)) or not (
            1 <= n_exact <= 10**8
        ):
            raise Error(f"invalid n_exact = {n_exact!r}: an integer in [1, 1e8]")
        lam = _expected(expected)
        p, g = self._groups(lam.shape[-1], pulses, groups)
        if self.scintillation == "none":
            return rng.poisson(lam).astype(np.int64)
        lead = lam.shape[:-2]
        s = np.empty(lead + (lam.shape[-1],))
        for k in range(int(g.max()) + 1):
            cols = np.flatnonzero(g == k)
            n = int(p[cols[0]])
            if n <= n_exact:
                # per-pulse draws, in blocks so that memory stays bounded
                total = np.zeros(lead)
                left = n
                block = max(1, 2_000_000 // max(1, int(np.prod(lead, dtype=np.int64))))
                while left > 0:
                    m = min(left, block)
                    total = total + np.sum(self.sample_factor(rng, lead + (m,)), axis=-1)
                    left -= m
                sk = total / n
            else:
                sk = self._mean_law(float(n)).sample_factor(rng, lead)
            s[..., cols] = np.asarray(sk)[..., None]
        return rng.poisson(lam * s[..., None, :]).astype(np.int64)

    def log_likelihood(
        self, counts: Any, expected: Any, pulses: Any, *, groups: Any = None, approximation: str = "auto"
    ) -> Any:
        """Log-likelihood of accumulated counts under scintillation, per pulse group (module docstring).

        The exact Poisson log-likelihood without scintillation. Otherwise, per group,
        ``sum_b [k_b log lam_b - log k_b!] + log E[S^K exp(-Lam S)]``, ``S`` the mean factor
        of the group's ``n`` pulses: exact for ``n = 1``, ``S`` moment-matched within the
        factor's family above (``"auto"``), or gamma (``"gamma"``: the negative multinomial,
        ``log Gamma(r + K) - log Gamma(r) + r log r - (r + K) log(r + Lam)``,
        ``r = n / sigma_I^2``).

        Parameters
        ----------
        counts : array_like
            (..., B, C) non-negative integer counts.
        expected : array_like
            (..., B, C) expected counts over the pulses, without scintillation; broadcast
            against ``counts``.
        pulses : float or array_like
            Pulses per channel, one value or ``(C,)``.
        groups : array_like, optional
            (C,) int labels of the channels that see the same pulses (:func:`pulse_groups`);
            default: all channels see the same pulses.
        approximation : {"auto", "gamma"}, optional
            ``"auto"`` (default): ``S`` of the factor's family with mean 1 and variance
            ``sigma_I^2 / n`` (exact for one pulse), by quadrature; ``"gamma"``: ``S``
            gamma, the closed-form negative multinomial.

        Returns
        -------
        float or numpy.ndarray
            Over the leading axes (a float for 2-D inputs); ``-inf`` for a count where
            nothing is expected, never NaN.

        Raises
        ------
        pprender.Error
            For counts that are not non-negative integers, invalid expected counts, pulses
            or groups, or shapes that do not broadcast.
        """
        k = _array(counts, "counts")
        if k.ndim < 2 or not np.all(np.isfinite(k)) or np.any(k < 0) or np.any(k != np.round(k)):
            raise Error(f"invalid counts: non-negative integers of shape (..., B, C), got shape {k.shape}")
        lam = _expected(expected)
        try:
            np.broadcast_shapes(k.shape, lam.shape)
        except ValueError:
            raise Error(f"invalid counts/expected: shapes {k.shape} and {lam.shape} do not broadcast") from None
        if approximation not in ("auto", "gamma"):
            raise Error(f'invalid approximation = {approximation!r}: "auto" or "gamma"')
        p, g = self._groups(lam.shape[-1], pulses, groups)
        poisson = np.sum(xlogy(k, lam) - gammaln(k + 1.0), axis=-2)  # (..., C), without -lam
        if self.scintillation == "none":
            out = np.sum(poisson - np.sum(lam, axis=-2), axis=-1)
            return float(out) if np.ndim(out) == 0 else out
        kk, ll = np.broadcast_arrays(k, lam)
        out = np.sum(poisson, axis=-1)
        for j in range(int(g.max()) + 1):
            cols = g == j
            n = float(p[cols][0])
            ktot = np.sum(kk[..., cols], axis=(-2, -1))
            ltot = np.sum(ll[..., cols], axis=(-2, -1))
            if approximation == "auto":
                out = out + self._mean_law(n)._log_single_pulse(ktot, ltot)
                continue
            r = n / self.index
            # log Gamma(r + K) - log Gamma(r) - K log r - (r + K) log(1 + Lam / r): the Poisson
            # limit (-Lam) without cancellation at large r (betaln keeps the Gamma ratio exact)
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.where(ktot > 0, gammaln(np.maximum(ktot, 1.0)) - betaln(r, np.maximum(ktot, 1.0)), 0.0)
            out = out + ratio - ktot * math.log(r) - (r + ktot) * np.log1p(ltot / r)
        out = np.where(np.isnan(out), -np.inf, out)
        return float(out) if np.ndim(out) == 0 else out


_GH_X, _GH_W = np.polynomial.hermite.hermgauss(48)


def _log_laplace_gh(g: Any, dg: Any, d2g: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``log int exp(g(u)) du`` for concave ``g`` (arrays of ``shape``): the mode by Newton
    on ``g'`` safeguarded by bisection (bracket grown by doubling), Gauss-Hermite nodes scaled by ``1 / sqrt(-g'')``."""
    lo = np.full(shape, -1.0)
    hi = np.full(shape, 1.0)
    for _ in range(12):
        lo = np.where(dg(lo) > 0, lo, 2.0 * lo)
        hi = np.where(dg(hi) < 0, hi, 2.0 * hi)
    lo, hi = np.maximum(lo, -700.0), np.minimum(hi, 700.0)
    # safeguarded Newton: a Newton step where it stays inside the bracket, else bisection
    u0 = 0.5 * (lo + hi)
    for _ in range(100):
        d = dg(u0)
        lo, hi = np.where(d > 0, u0, lo), np.where(d > 0, hi, u0)
        step = d / d2g(u0)
        un = u0 - step
        inside = np.isfinite(un) & (un > lo) & (un < hi)
        u0 = np.where(inside, un, 0.5 * (lo + hi))
        tol = 1e-12 * (1.0 + np.abs(u0))
        if np.all((inside & (np.abs(step) <= tol)) | (hi - lo <= tol)):
            break
    sd = 1.0 / np.sqrt(-d2g(u0))
    u = u0[..., None] + math.sqrt(2.0) * sd[..., None] * _GH_X
    terms = g(u) + (_GH_X**2 + np.log(_GH_W))
    top = np.max(terms, axis=-1)
    return top + np.log(np.sum(np.exp(terms - top[..., None]), axis=-1)) + np.log(math.sqrt(2.0) * sd)


def _expected(value: Any) -> np.ndarray:
    lam = _array(value, "expected")
    if lam.ndim < 2:
        raise Error(f"invalid expected: shape {lam.shape}, expected (..., B, C)")
    if not np.all(np.isfinite(lam)) or np.any(lam < 0):
        raise Error("invalid expected: must be finite and >= 0 (counts)")
    return lam
