"""Laser speckle in what a PPR receiver records: degrees of freedom, sampling, likelihood.

A short pulse off an unresolved, optically rough target makes a speckle pattern at the
receiver aperture. This module gives its statistics per range bin and polarization
channel, standalone: arrays in, arrays out, no :class:`~pprender.inverse.instrument.Instrument`
needed (the instrument and the fits call it).

Conventions (every function in this module):

* Stokes ``(I, Q, U, V)`` in the received basis ``(X, Y)`` of :mod:`pprender.lidar`,
  ``V = 2 Im(Ex Ey*)`` (:mod:`pprender.inverse.instrument`). The coherency matrix of a
  field ``E = (Ex, Ey)`` is ``J = <E E^H>``, ``J[0, 1] = <Ex Ey*>``, so that
  ``S0 = J00 + J11``, ``S1 = J00 - J11``, ``S2 = 2 Re J01``, ``S3 = 2 Im J01``, and

  ``J = 1/2 [[S0 + S1, S2 + i S3], [S2 - i S3, S0 - S1]]`` (:func:`coherency`).

* An analyzer row ``a = (a0, a1, a2, a3)`` (what :class:`~pprender.inverse.instrument.Channels`
  calls ``rows``: intensity ``a . S``) is the Hermitian matrix ``A = 2 coherency(a)``
  (:func:`analyzer_matrix`), with ``tr(A J) = a . S`` for every ``J``. An ideal polarizer
  passing the unit state ``s`` (``a = 1/2 (1, s)``) is the projector ``e e^H`` on that
  state's Jones vector. A physical analyzer (``a0 >= |(a1, a2, a3)|``) is positive
  semi-definite.
* Arrays: received Stokes vectors are ``(..., B, G, 4)`` (range bins, transmitted
  generator states), in counts (the expected counts a channel of row ``(1, 0, 0, 0)``
  would record: the instrument's ``counts_per_cross_section`` times the Mueller
  cross-section times the generator, :func:`received_stokes`). Channels ``C`` have rows
  ``(C, 4)`` and the index of their generator ``(C,)``; counts arrays are ``(..., B, C)``.

Model (J. W. Goodman, *Speckle Phenomena in Optics*, ch. 3-4: polarization and integrated
speckle; *Statistical Optics*, ch. 6: the integrated intensity). Per pulse and range bin
the received field is a circular complex Gaussian Jones vector of coherency ``J``. Integrated over the aperture
(and the pulse), the coherency matrix ``W`` the detectors see is approximated by a scaled
complex Wishart matrix with ``M`` degrees of freedom and mean ``J``: ``W = J^(1/2) Omega
J^(1/2) / M`` with ``Omega ~ CW_2(M, I)``. ``M >= 1`` is Goodman's number of speckle
"cells" the aperture averages (:func:`speckle_dof`); it is matched to the exact variance
of the integrated intensity, which is how Goodman defines it. A channel's intensity is
``I_c = tr(A_c W)``: for an ideal polarizer a gamma variable of shape ``M`` and mean
``a_c . S``; for a partial analyzer the sum ``(l1 g1 + l2 g2) / M`` of two independent
gammas of shape ``M``, ``l1, l2`` the eigenvalues of ``J^(1/2) A_c J^(1/2)``. Channels
that share a generator see the same ``W`` (for one field ``H + V = D + A = R + L =
tr W`` exactly); channels of different generators are different pulses (independent).

Over ``n`` pulses of one generator with independent speckle the Wishart matrices add:
``M n`` degrees of freedom. Speckle that does not change from pulse to pulse (a target
that does not move) is counted with :func:`accumulated_dof`'s ``correlation``.

Counts given the intensities are Poisson with mean ``I_c + background_c``, independent
between channels (shot noise). So an ideal-polarizer channel's counts are negative
binomial (Mandel's formula: Poisson mixed over a gamma) convolved with the Poisson
background; ``M -> inf`` is today's Poisson model.

Exact and approximate: the Wishart law of ``W`` is exact for integer ``M`` cells of
equal weight; for a real aperture Goodman's moment-matched ``M`` makes the intensity's
mean and variance exact and its law approximately gamma (the tests and ``docs/speckle.md``
compare it with a directly simulated random-phasor field: the exact law of an aperture
integral is a weighted sum of exponentials, whose skewness exceeds the gamma law's
``2 / sqrt(M)`` by up to ~25 % near ``M = 2-4``: the far upper tail is a little heavier).

Range bins: each bin's speckle is an independent draw (different parts of the target).
That holds for bins at least a pulse length (``c pulse_fwhm / 2``) wide; the renderer's
default bins are a quarter of it, and neighbouring bins that see the same surface within
one pulse have correlated speckle, which is left out (sums over such bins, and the jitter
blur, fluctuate less here than in reality).

In an instrument: :class:`Speckle` is the option of
:class:`~pprender.inverse.instrument.Instrument` (``speckle=``) that
:func:`~pprender.inverse.instrument.measure` and :mod:`pprender.inverse.fit` follow;
:func:`illuminated_area` gives each range bin's effective illuminated area from a render.

Likelihood: :func:`speckle_log_likelihood` multiplies the channels' exact marginal laws
(a composite likelihood; channels sharing a field are correlated, ``docs/speckle.md``
measures by how much), :func:`channel_dof` gives each channel's marginal shape,
:func:`blurred_dof` carries it through a timing-jitter blur and :func:`fisher_weight`
replaces the Poisson ``1 / lambda`` of a Fisher information.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.special import erf, gammaln, j1, xlogy

from .._core import Error
from ..lidar import SPEED_OF_LIGHT, RenderResult

__all__ = [
    "Speckle",
    "accumulated_dof",
    "analyzer_matrix",
    "blurred_dof",
    "channel_dof",
    "coherency",
    "count_moments",
    "fisher_weight",
    "generator_groups",
    "illuminated_area",
    "intensity_moments",
    "received_stokes",
    "sample_counts",
    "sample_intensity",
    "speckle_dof",
    "speckle_log_likelihood",
    "speckle_log_pmf",
]

# Relative tolerance on physical Stokes vectors / analyzer rows (the renderer accumulates
# in float32: a fully polarized return comes out at ~1e-7 of its intensity beyond |s| = S0).
_TOL = 1e-5

# Trapezoid nodes of the likelihood's quadrature over the log speckle intensity, and how
# far (in natural log units) the integrand falls at the ends of its interval.
_N_QUAD = 97
_DROP = 46.0  # exp(-46) = 1e-20 of the peak
# Elements per block of the quadrature (memory: _BLOCK * _N_QUAD floats).
_BLOCK = 4096

# speckle_dof: Gauss-Legendre nodes per sub-interval of the aperture integral, and the
# largest aperture-over-speckle parameter integrated numerically (above it: A_rx / A_coh).
_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)
_BETA_MAX = 2.0e4
# fisher_weight: most terms of its exact sum over the counts.
_FISHER_TERMS = 4000


# ---------------------------------------------------------------------- validation


def _array(value: Any, name: str, what: str) -> np.ndarray:
    """``value`` as float64; :class:`Error` naming ``name`` for text, None, complex."""
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError):
        raise Error(f"invalid {name}: {what}, got {type(value).__name__}") from None
    ok = raw.dtype.kind in "biuf"
    if raw.dtype.kind == "O":
        ok = all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) for v in raw.flat)
    if not ok:
        shown = repr(value) if raw.size <= 8 else f"an array of dtype {raw.dtype}"
        raise Error(f"invalid {name} = {shown}: {what} (not text, None or complex)")
    return raw.astype(np.float64)


def _positive(value: Any, name: str, unit: str, hi: float = math.inf) -> np.ndarray:
    a = _array(value, name, f"finite numbers > 0 ({unit})")
    if not np.all(np.isfinite(a)) or np.any(a <= 0) or np.any(a > hi):
        raise Error(f"invalid {name} = {value!r}: finite numbers in (0, {hi:g}] ({unit})")
    return a


def _stokes(value: Any, name: str = "stokes") -> np.ndarray:
    """(..., 4) physical Stokes vectors (S0 >= |s| within _TOL), with |s| clipped to S0."""
    s = _array(value, name, "Stokes vectors (..., 4)")
    if s.ndim < 1 or s.shape[-1] != 4:
        raise Error(f"invalid {name}: shape {s.shape}, expected (..., 4) Stokes vectors")
    if not np.all(np.isfinite(s)):
        raise Error(f"invalid {name}: not finite")
    scale = float(np.max(np.abs(s[..., 0]), initial=0.0))
    p = np.linalg.norm(s[..., 1:], axis=-1)
    if np.any(s[..., 0] < -_TOL * scale) or np.any(p > s[..., 0] + _TOL * scale):
        raise Error(
            f"invalid {name}: not physical Stokes vectors (need S0 >= |(S1, S2, S3)|, within {_TOL:g} "
            "of the largest S0)"
        )
    s0 = np.clip(s[..., 0], 0.0, None)
    shrink = np.where(p > s0, s0 / np.where(p > 0, p, 1.0), 1.0)
    return np.concatenate([s0[..., None], s[..., 1:] * shrink[..., None]], axis=-1)


def _rows(value: Any, name: str = "rows") -> np.ndarray:
    r = _array(value, name, "analyzer rows (C, 4)")
    if r.ndim != 2 or r.shape[1] != 4 or r.shape[0] < 1:
        raise Error(f"invalid {name}: shape {r.shape}, expected (C, 4) analyzer rows with C >= 1")
    if not np.all(np.isfinite(r)):
        raise Error(f"invalid {name}: not finite")
    if np.any(r[:, 0] < 0) or np.any(np.linalg.norm(r[:, 1:], axis=1) > r[:, 0] * (1 + 1e-12)):
        raise Error(f"invalid {name}: each row (a0, a1, a2, a3) needs a0 >= |(a1, a2, a3)| (a physical analyzer)")
    return r


def _generator_index(value: Any, n_channels: int, n_generators: int) -> np.ndarray:
    try:
        g = np.asarray(value)
    except (TypeError, ValueError):
        raise Error("invalid generator_index: not an array of integers") from None
    if g.dtype.kind not in "iu" or g.shape != (n_channels,):
        raise Error(
            f"invalid generator_index: integers of shape ({n_channels},) (one per channel), got dtype "
            f"{g.dtype} shape {g.shape}"
        )
    if np.any(g < 0) or np.any(g >= n_generators):
        raise Error(f"invalid generator_index: values in [0, {n_generators - 1}] (stokes has G = {n_generators})")
    return g.astype(np.intp)


def _dof(value: Any, shape: tuple[int, ...], name: str = "dof", last: str = "G") -> np.ndarray:
    """Degrees of freedom in [1, inf] broadcast to ``shape``."""
    d = _array(value, name, "degrees of freedom in [1, inf]")
    if np.any(np.isnan(d)) or np.any(d < 1):
        raise Error(f"invalid {name}: degrees of freedom in [1, inf] (inf: no speckle)")
    if d.ndim >= 1 and d.shape[-1] not in (1, shape[-1]):
        raise Error(
            f"invalid {name}: shape {d.shape} does not broadcast to {shape} (..., B, {last}); a per-bin "
            f"array (..., B) needs a trailing axis: {name}[..., None]"
        )
    try:
        return np.broadcast_to(d, shape)
    except ValueError:
        raise Error(f"invalid {name}: shape {d.shape} does not broadcast to {shape} (..., B, {last})") from None


def _check_rng(rng: Any) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise Error(f"invalid rng of type {type(rng).__name__}: expected numpy.random.Generator")
    return rng


# ---------------------------------------------------------------------- matrices


def coherency(stokes: Any) -> np.ndarray:
    """The 2x2 coherency matrix ``J = <E E^H>`` of Stokes vectors (module docstring).

    Parameters
    ----------
    stokes : array_like
        (..., 4) Stokes vectors ``(S0, S1, S2, S3)``, ``V = S3 = 2 Im(Ex Ey*)``. Any real
        4-vector is converted (the map is linear); physical ones give positive
        semi-definite ``J``.

    Returns
    -------
    numpy.ndarray
        (..., 2, 2) complex Hermitian ``1/2 [[S0 + S1, S2 + i S3], [S2 - i S3, S0 - S1]]``.

    Raises
    ------
    pprender.Error
        For an array that is not (..., 4) real numbers or not finite.
    """
    s = _array(stokes, "stokes", "Stokes vectors (..., 4)")
    if s.ndim < 1 or s.shape[-1] != 4:
        raise Error(f"invalid stokes: shape {s.shape}, expected (..., 4) Stokes vectors")
    if not np.all(np.isfinite(s)):
        raise Error("invalid stokes: not finite")
    return _coherency(s)


def _coherency(s: np.ndarray) -> np.ndarray:
    j = np.empty(s.shape[:-1] + (2, 2), dtype=np.complex128)
    j[..., 0, 0] = 0.5 * (s[..., 0] + s[..., 1])
    j[..., 1, 1] = 0.5 * (s[..., 0] - s[..., 1])
    j[..., 0, 1] = 0.5 * (s[..., 2] + 1j * s[..., 3])
    j[..., 1, 0] = 0.5 * (s[..., 2] - 1j * s[..., 3])
    return j


def analyzer_matrix(rows: Any) -> np.ndarray:
    """The Hermitian 2x2 matrices ``A`` of analyzer rows: ``tr(A J) = a . S`` for every field.

    Parameters
    ----------
    rows : array_like
        (..., 4) analyzer rows ``(a0, a1, a2, a3)`` (intensity ``a . S``), e.g.
        ``Channels.rows``; an ideal polarizer passing the unit state ``s`` is
        ``1/2 (1, s)``.

    Returns
    -------
    numpy.ndarray
        (..., 2, 2) complex ``A = [[a0 + a1, a2 + i a3], [a2 - i a3, a0 - a1]]``
        (``2 coherency(a)``): the projector on the passed state's Jones vector for an
        ideal polarizer.

    Raises
    ------
    pprender.Error
        For an array that is not (..., 4) finite real numbers.
    """
    a = _array(rows, "rows", "analyzer rows (..., 4)")
    if a.ndim < 1 or a.shape[-1] != 4:
        raise Error(f"invalid rows: shape {a.shape}, expected (..., 4) analyzer rows")
    if not np.all(np.isfinite(a)):
        raise Error("invalid rows: not finite")
    return 2.0 * _coherency(a)


def _sqrtm_psd(j: np.ndarray) -> np.ndarray:
    """Hermitian square root of 2x2 positive semi-definite matrices, closed form:
    ``(J + sqrt(det J) I) / sqrt(tr J + 2 sqrt(det J))`` (0 for J = 0)."""
    det = np.clip((j[..., 0, 0] * j[..., 1, 1] - j[..., 0, 1] * j[..., 1, 0]).real, 0.0, None)
    sd = np.sqrt(det)
    t = np.sqrt(np.clip(j[..., 0, 0].real + j[..., 1, 1].real + 2.0 * sd, 0.0, None))
    out = j.copy()
    out[..., 0, 0] += sd
    out[..., 1, 1] += sd
    safe = np.where(t > 0, t, 1.0)
    return np.where((t > 0)[..., None, None], out / safe[..., None, None], 0.0)


def received_stokes(mueller: Any, generators: Any) -> np.ndarray:
    """Received Stokes vectors ``M g`` for each transmitted generator state.

    Parameters
    ----------
    mueller : array_like
        (..., B, 4, 4) Mueller profile (cross-sections in m^2, or already times the
        instrument's ``counts_per_cross_section`` for counts).
    generators : array_like
        (G, 4) transmitted Stokes states (e.g. the unique rows of
        ``Channels.generators_array``, :func:`generator_groups`).

    Returns
    -------
    numpy.ndarray
        (..., B, G, 4) received Stokes vectors, in the units of ``mueller``.

    Raises
    ------
    pprender.Error
        For shapes other than these or values that are not finite.
    """
    m = _array(mueller, "mueller", "a Mueller profile (..., B, 4, 4)")
    g = _array(generators, "generators", "generator states (G, 4)")
    if m.ndim < 3 or m.shape[-2:] != (4, 4):
        raise Error(f"invalid mueller: shape {m.shape}, expected (..., B, 4, 4)")
    if g.ndim != 2 or g.shape[1] != 4 or g.shape[0] < 1:
        raise Error(f"invalid generators: shape {g.shape}, expected (G, 4)")
    if not (np.all(np.isfinite(m)) and np.all(np.isfinite(g))):
        raise Error("invalid mueller/generators: not finite")
    return np.einsum("...ij,gj->...gi", m, g)


def generator_groups(generators: Any) -> tuple[np.ndarray, np.ndarray]:
    """The distinct transmitted states of a channel set and each channel's index among them.

    Channels with the same generator state see the same received field (one speckle
    draw); a Mueller polarimeter's channels of different generators are different pulses.

    Parameters
    ----------
    generators : array_like
        (C, 4) the channels' generator states (``Channels.generators_array``).

    Returns
    -------
    unique : numpy.ndarray
        (G, 4) the distinct states, in order of first appearance.
    generator_index : numpy.ndarray
        (C,) int: ``unique[generator_index[c]]`` is channel ``c``'s state.

    Raises
    ------
    pprender.Error
        For an array that is not (C, 4) finite numbers.
    """
    g = _array(generators, "generators", "generator states (C, 4)")
    if g.ndim != 2 or g.shape[1] != 4 or g.shape[0] < 1 or not np.all(np.isfinite(g)):
        raise Error(f"invalid generators: shape {g.shape}, expected (C, 4) finite generator states")
    unique: list[np.ndarray] = []
    index = np.empty(len(g), dtype=np.intp)
    for c, row in enumerate(g):
        for u, known in enumerate(unique):
            if np.array_equal(known, row):
                index[c] = u
                break
        else:
            index[c] = len(unique)
            unique.append(row)
    return np.array(unique), index


# ---------------------------------------------------------------------- degrees of freedom


def _inverse_dof(beta: float) -> float:
    """Goodman's ``1/M = (16/pi) int_0^1 [acos u - u sqrt(1 - u^2)] |mu(beta u)|^2 u du``
    for a circular aperture and a uniformly bright circular source, ``|mu(q)| =
    |2 J1(q) / q|``. With ``u = cos(theta)`` the integrand is analytic on ``[0, pi/2]``
    (no square-root end point); Gauss-Legendre on sub-intervals a quarter oscillation of
    ``J1^2`` long."""
    n_sub = max(8, int(math.ceil(4.0 * beta / math.pi)))
    edges = np.linspace(0.0, 0.5 * math.pi, n_sub + 1)
    half = 0.5 * np.diff(edges)
    theta = (0.5 * (edges[1:] + edges[:-1]))[:, None] + half[:, None] * _GL_X[None, :]
    w = half[:, None] * _GL_W[None, :]
    u, sin_t = np.cos(theta), np.sin(theta)
    q = beta * u
    mu = np.where(q > 1e-8, 2.0 * j1(q) / np.where(q > 1e-8, q, 1.0), 1.0 - q * q / 8.0)
    kernel = theta - u * sin_t
    return float(16.0 / math.pi * np.sum(w * kernel * mu * mu * u * sin_t))


def speckle_dof(aperture_diameter: Any, wavelength: Any, target_range: Any, target_area: Any) -> Any:
    """Goodman's number of speckle degrees of freedom ``M`` one pulse's aperture integral averages.

    The aperture is a disc of diameter ``D``; the target's illuminated, optically rough
    part (the part in one range bin) is treated as an incoherent, uniformly bright disc of
    area ``A_s`` (diameter ``D_s``) at range ``R``, normal to the line of sight. With the
    Van Cittert-Zernike coherence ``|mu(r)| = |2 J1(q) / q|``, ``q = pi D_s r /
    (lambda R)``, Goodman's integral for the integrated intensity (*Statistical Optics*
    ch. 6, *Speckle Phenomena in Optics* ch. 4)

    ``1/M = (1/A_rx^2) int K(r) |mu(r)|^2 d^2r``

    (``K`` the aperture's autocorrelation, the overlap area of two discs ``r`` apart) is
    evaluated as a radial integral in ``beta = pi D_s D / (lambda R)`` by Gauss-Legendre
    quadrature (relative error below 1e-10 against an adaptive quadrature, tests). Limits:
    ``M -> 1`` when the aperture is much smaller than the speckle ``lambda R / D_s``
    (``M = 1 + beta^2 / 16 + ...``), and ``M -> A_rx / A_coh = A_rx A_s / (lambda R)^2 =
    beta^2 / 16`` for a large one, the ratio converging like ``1 + O(log(beta) / beta)``
    (``docs/speckle.md``). Above ``beta = 2e4`` (``M > 2.5e7``, where speckle is
    negligible next to shot noise anyway) the large-aperture limit is returned, within
    1e-3 relative of the integral.

    A target of non-uniform brightness ``I(xi)``: pass the effective area
    ``(int I)^2 / int I^2``, which makes the large-aperture limit exact (Goodman,
    the coherence area of an incoherent source is ``A_coh = (lambda R)^2 int I^2 / (int I)^2``) and
    keeps ``M -> 1`` exact. One pulse's time integral adds degrees of freedom when the
    target's depth within a bin exceeds the pulse length; that is not included (pass
    ``M`` times a temporal factor if you have one).

    Parameters
    ----------
    aperture_diameter : float or array_like
        Receiver aperture diameter ``D`` (m), > 0.
    wavelength : float or array_like
        Wavelength (m), > 0.
    target_range : float or array_like
        Range ``R`` (m), > 0.
    target_area : float or array_like
        Projected area ``A_s`` (m^2, > 0) of the illuminated, rough part of the target in
        each range bin, e.g. (B,): the effective area above.

    Returns
    -------
    float or numpy.ndarray
        ``M >= 1`` broadcast over the inputs (a float for scalars).

    Raises
    ------
    pprender.Error
        For values that are not finite and > 0, or shapes that do not broadcast.
    """
    d = _positive(aperture_diameter, "aperture_diameter", "m")
    lam = _positive(wavelength, "wavelength", "m")
    r = _positive(target_range, "target_range", "m")
    a = _positive(target_area, "target_area", "m^2")
    try:
        d, lam, r, a = np.broadcast_arrays(d, lam, r, a)
    except ValueError:
        raise Error("invalid aperture_diameter/wavelength/target_range/target_area: shapes do not broadcast") from None
    beta = math.pi * np.sqrt(4.0 * a / math.pi) * d / (lam * r)
    out = np.empty(beta.shape)
    cache: dict[float, float] = {}
    for i, b in np.ndenumerate(beta):
        b = float(b)
        if b > _BETA_MAX:
            out[i] = b * b / 16.0
            continue
        if b not in cache:
            cache[b] = 1.0 / _inverse_dof(b)
        out[i] = max(1.0, cache[b])
    return float(out) if out.ndim == 0 else out


def accumulated_dof(dof: Any, n_pulses: Any, correlation: Any = 0.0) -> Any:
    """Degrees of freedom of the speckle summed over ``n`` pulses: ``M n_eff``.

    Independent speckle in each pulse adds the pulses' Wishart matrices: ``M n`` degrees of
    freedom. A target that moves little between pulses keeps its speckle: with ``rho``
    the correlation coefficient of one channel's integrated intensity between consecutive
    pulses (of the same generator), decaying geometrically (``rho^k`` at ``k`` pulses
    apart: the speckle pattern drifting across the aperture as the target turns), the
    variance of the sum is ``n var [1 + 2 sum_k (1 - k/n) rho^k]``; the number of
    independent pulses that gives the same variance (Goodman's own moment matching of
    ``M``) is

    ``n_eff = n / [1 + 2 rho / (1 - rho) - 2 rho (1 - rho^n) / (n (1 - rho)^2)]``,

    ``n`` at ``rho = 0``, 1 at ``rho = 1`` (a frozen speckle pattern: every pulse sees the
    same field). The result's mean and variance are exact; its gamma law is the usual
    moment-matched approximation.

    Parameters
    ----------
    dof : float or array_like
        Per-pulse degrees of freedom ``M`` (:func:`speckle_dof`), in [1, inf].
    n_pulses : float or array_like
        Pulses of one generator state (``n_pulses * pulse_share`` of an instrument),
        >= 1.
    correlation : float or array_like, optional
        ``rho`` in [0, 1]. Default 0 (independent speckle in every pulse).

    Returns
    -------
    float or numpy.ndarray
        ``M n_eff``, broadcast over the inputs (a float for scalars).

    Raises
    ------
    pprender.Error
        For values outside these ranges, or shapes that do not broadcast.
    """
    m = _array(dof, "dof", "degrees of freedom in [1, inf]")
    if np.any(np.isnan(m)) or np.any(m < 1):
        raise Error(f"invalid dof = {dof!r}: degrees of freedom in [1, inf]")
    n = _array(n_pulses, "n_pulses", "a number of pulses >= 1")
    if not np.all(np.isfinite(n)) or np.any(n < 1):
        raise Error(f"invalid n_pulses = {n_pulses!r}: a finite number of pulses >= 1")
    rho = _array(correlation, "correlation", "a correlation coefficient in [0, 1]")
    if not np.all(np.isfinite(rho)) or np.any(rho < 0) or np.any(rho > 1):
        raise Error(f"invalid correlation = {correlation!r}: a correlation coefficient in [0, 1]")
    try:
        m, n, rho = np.broadcast_arrays(m, n, rho)
    except ValueError:
        raise Error("invalid dof/n_pulses/correlation: shapes do not broadcast") from None
    one = rho >= 1.0
    r = np.where(one, 0.0, rho)
    factor = 1.0 + 2.0 * r / (1.0 - r) - 2.0 * r * (1.0 - r**n) / (n * (1.0 - r) ** 2)
    n_eff = np.where(one, 1.0, n / factor)
    out = m * np.maximum(n_eff, 1.0)
    return float(out) if out.ndim == 0 else out


# ---------------------------------------------------------------------- moments


def _setup(stokes: Any, rows: Any, generator_index: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    s = _stokes(stokes)
    if s.ndim < 3:
        raise Error(f"invalid stokes: shape {s.shape}, expected (..., B, G, 4)")
    r = _rows(rows)
    g = _generator_index(generator_index, r.shape[0], s.shape[-2])
    return s, r, g


def intensity_moments(stokes: Any, rows: Any, generator_index: Any, dof: Any) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of the channels' speckle intensities, in closed form.

    ``E[I_c] = a_c . S_g``; ``Cov(I_c, I_d) = tr(A_c J A_d J) / M`` for channels of the
    same generator (one Wishart matrix ``W``: ``Cov(tr(A W), tr(B W)) = tr(A J B J) / M``),
    0 between generators. For an ideal polarizer ``Var I_c = E[I_c]^2 / M`` (Goodman's
    gamma law); for ``H + V`` of one field, ``Var = tr(J^2) / M = (S0^2 + |s|^2) / (2 M)``.

    Parameters
    ----------
    stokes : array_like
        (..., B, G, 4) received Stokes vectors per generator, in counts (module docstring).
    rows : array_like
        (C, 4) channel analyzer rows (split and pulse share included: ``Channels.rows``).
    generator_index : array_like
        (C,) int: each channel's generator in ``stokes``.
    dof : float or array_like
        Degrees of freedom in [1, inf], broadcast to (..., B, G) (a per-bin array
        ``(..., B)`` as ``dof[..., None]``); inf: no speckle.

    Returns
    -------
    mean : numpy.ndarray
        (..., B, C) mean intensities (counts).
    cov : numpy.ndarray
        (..., B, C, C) their covariance (counts^2).

    Raises
    ------
    pprender.Error
        For shapes other than these, unphysical Stokes vectors or analyzer rows, generator
        indices out of range, or ``dof`` outside [1, inf].
    """
    s, r, g = _setup(stokes, rows, generator_index)
    m = _dof(dof, s.shape[:-1])
    j = _coherency(s)[..., g, :, :]  # (..., B, C, 2, 2)
    a = 2.0 * _coherency(r)  # (C, 2, 2)
    mean = np.einsum("ci,...ci->...c", r, s[..., g, :])
    aj = np.einsum("cij,...cjk->...cik", a, j)  # A_c J_c
    cov = np.einsum("...cij,...dji->...cd", aj, aj).real
    same = g[:, None] == g[None, :]
    inv_m = 1.0 / m[..., g]  # (..., B, C)
    cov = cov * same * np.sqrt(inv_m[..., :, None] * inv_m[..., None, :])
    return mean, cov


def count_moments(
    stokes: Any, rows: Any, generator_index: Any, dof: Any, background: Any
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of the counts: speckle intensity plus Poisson shot noise.

    ``E[k_c] = I_c + b_c`` and ``Cov(k_c, k_d) = Cov(I_c, I_d) + delta_cd (E[I_c] + b_c)``
    (law of total covariance; given the intensities the counts are independent Poisson).
    For an ideal polarizer ``Var k = mu + s^2 / M`` (``s`` the signal, ``mu = s + b``):
    the negative binomial's variance plus the background's.

    Parameters
    ----------
    stokes : array_like
        (..., B, G, 4) received Stokes vectors per generator, in counts.
    rows : array_like
        (C, 4) channel analyzer rows.
    generator_index : array_like
        (C,) int: each channel's generator.
    dof : float or array_like
        Degrees of freedom in [1, inf], broadcast to (..., B, G).
    background : array_like
        Background counts >= 0, broadcast to (..., B, C).

    Returns
    -------
    mean : numpy.ndarray
        (..., B, C) mean counts.
    cov : numpy.ndarray
        (..., B, C, C) their covariance.

    Raises
    ------
    pprender.Error
        As :func:`intensity_moments`, and for a background that is not finite and >= 0 or
        does not broadcast.
    """
    mean, cov = intensity_moments(stokes, rows, generator_index, dof)
    b = _background(background, mean.shape)
    mu = mean + b
    c = mean.shape[-1]
    return mu, cov + mu[..., :, None] * np.eye(c)


def channel_dof(stokes: Any, rows: Any, generator_index: Any, dof: Any) -> np.ndarray:
    """Each channel's marginal degrees of freedom, for :func:`speckle_log_likelihood`.

    The gamma law with the channel intensity's exact mean and variance:
    ``M_c = M (a_c . S)^2 / tr(A_c J A_c J)``. For an ideal polarizer (rank-one ``A_c``,
    every channel of :func:`~pprender.inverse.instrument.channel_set`'s presets) that is
    ``M`` exactly and the marginal law is exactly gamma; for a partial analyzer the
    intensity is a sum of two gammas (module docstring) and ``M <= M_c <= 2 M``
    (``2 M / (1 + P^2)`` for an open channel, ``P`` the degree of polarization, Goodman's
    partially polarized speckle) is its moment-matched approximation.

    Parameters
    ----------
    stokes : array_like
        (..., B, G, 4) received Stokes vectors per generator, in counts.
    rows : array_like
        (C, 4) channel analyzer rows.
    generator_index : array_like
        (C,) int: each channel's generator.
    dof : float or array_like
        Degrees of freedom in [1, inf], broadcast to (..., B, G).

    Returns
    -------
    numpy.ndarray
        (..., B, C) marginal degrees of freedom (``dof`` itself where a channel has no
        signal).

    Raises
    ------
    pprender.Error
        As :func:`intensity_moments`.
    """
    s, r, g = _setup(stokes, rows, generator_index)
    m = _dof(dof, s.shape[:-1])[..., g]
    mean, cov = intensity_moments(s, r, g, 1.0)
    var1 = np.diagonal(cov, axis1=-2, axis2=-1)  # tr(A J A J)
    ok = var1 > 0
    ratio = np.where(ok, mean * mean / np.where(ok, var1, 1.0), 1.0)
    return np.where(np.isinf(m), np.inf, m * np.clip(ratio, 1.0, 2.0))


def blurred_dof(kernel: Any, signal: Any, dof: Any) -> np.ndarray:
    """Each output bin's degrees of freedom after a linear blur of the bins (timing jitter).

    A blur (``jitter_matrix`` of :mod:`pprender.inverse.instrument`) moves detected
    photons between range bins: output bin ``j`` collects ``sum_i K_ji I_i`` of the
    rendered bins' intensities, whose speckle is independent between bins (different
    parts of the target). The gamma law with that sum's exact mean and variance has
    ``M_j = (sum_i K_ji s_i)^2 / sum_i K_ji^2 s_i^2 / M_i``, what
    :func:`speckle_log_likelihood` needs for blurred counts. (Sampling needs none of this:
    blur the drawn intensities, :func:`sample_intensity`.)

    Parameters
    ----------
    kernel : array_like
        (B_out, B) blur matrix, entries >= 0.
    signal : array_like
        (..., B, C) mean intensities before the blur (counts), >= 0.
    dof : float or array_like
        (..., B, C) each channel's marginal degrees of freedom before the blur
        (:func:`channel_dof`), in [1, inf], broadcast against ``signal``.

    Returns
    -------
    numpy.ndarray
        (..., B_out, C) degrees of freedom (inf where the blurred signal has no speckle
        variance: no signal, or inf ``dof`` throughout).

    Raises
    ------
    pprender.Error
        For a kernel that is not a 2-D array of finite values >= 0, a signal that is not
        finite and >= 0, ``dof`` outside [1, inf], or shapes that do not agree.
    """
    k = _array(kernel, "kernel", "a (B_out, B) blur matrix")
    if k.ndim != 2 or not np.all(np.isfinite(k)) or np.any(k < 0):
        raise Error(f"invalid kernel: shape {k.shape}; a (B_out, B) matrix of finite values >= 0")
    s = _array(signal, "signal", "mean signal counts >= 0")
    if s.ndim < 2 or s.shape[-2] != k.shape[1] or not np.all(np.isfinite(s)) or np.any(s < 0):
        raise Error(f"invalid signal: shape {s.shape}, expected (..., {k.shape[1]}, C) finite counts >= 0")
    m = _array(dof, "dof", "degrees of freedom in [1, inf]")
    if np.any(np.isnan(m)) or np.any(m < 1):
        raise Error("invalid dof: degrees of freedom in [1, inf] (inf: no speckle)")
    try:
        s, m = np.broadcast_arrays(s, m)
    except ValueError:
        raise Error(f"invalid dof: shape {m.shape} does not broadcast to the signal's {s.shape}") from None
    mean = np.einsum("ji,...ic->...jc", k, s)
    var = np.einsum("ji,...ic->...jc", k * k, s * s / m)
    ok = var > 0
    return np.where(ok, mean * mean / np.where(ok, var, 1.0), np.inf)


def fisher_weight(signal: Any, background: Any, dof: Any, *, exact: bool = False) -> np.ndarray:
    """Fisher information of one count about its mean signal ``s`` (shape ``M`` held fixed).

    What replaces the Poisson ``1 / (s + b)`` in a Fisher information ``F_ij = sum (d s /
    d theta_i)(d s / d theta_j) w`` when the counts carry speckle. By default the inverse
    variance ``1 / v``, ``v = s + b + s^2 / M``: exact for the negative binomial (``b =
    0``, ``M / (s (M + s))``) and for Poisson (``M = inf``), and otherwise a lower bound
    (Cramer-Rao for the unbiased estimate ``k - b`` of ``s``), so the standard errors it
    gives are conservative; ``docs/speckle.md`` tabulates the exact information over
    ``1 / v``: at most 1.15 (M = 1, signal ~ background / 10 to background), 1.07 at
    ``M = 3``, 1.012 at ``M = 10``.

    With ``exact=True``, ``E[(d log P(k) / ds)^2]`` summed over the counts within 14
    standard deviations of the mean (plus the gamma tail: 40 for ``M < 3``), using
    ``dP(k)/ds = Q(k - 1) - Q(k)``, ``Q`` the law of :func:`speckle_log_pmf` with shape
    ``M + 1`` and mean ``s (M + 1) / M`` (the gamma density times ``x / s`` is that
    gamma). Where that sum would exceed 4000 terms, ``1 / v`` is kept.

    Parameters
    ----------
    signal : array_like
        Mean speckle intensities ``s`` (counts), > 0.
    background : array_like
        Background counts ``b >= 0``, broadcast against ``signal``.
    dof : float or array_like
        Each count's degrees of freedom in [1, inf] (:func:`channel_dof`), broadcast
        against ``signal``.
    exact : bool, optional
        Sum the exact information (default False: ``1 / v``).

    Returns
    -------
    numpy.ndarray
        The information per count (1 / counts^2), the broadcast shape.

    Raises
    ------
    pprender.Error
        For a signal that is not finite and > 0, a background not finite and >= 0, ``dof``
        outside [1, inf], or shapes that do not broadcast.
    """
    s = _array(signal, "signal", "mean signal counts > 0")
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise Error("invalid signal: must be finite and > 0 (counts)")
    b = _array(background, "background", "background counts >= 0")
    if not np.all(np.isfinite(b)) or np.any(b < 0):
        raise Error("invalid background: must be finite and >= 0 (counts)")
    m = _array(dof, "dof", "degrees of freedom in [1, inf]")
    if np.any(np.isnan(m)) or np.any(m < 1):
        raise Error("invalid dof: degrees of freedom in [1, inf] (inf: no speckle)")
    try:
        s, b, m = np.broadcast_arrays(s, b, m)
    except ValueError:
        raise Error("invalid signal/background/dof: shapes do not broadcast") from None
    inv_m = np.where(np.isinf(m), 0.0, 1.0 / m)
    out = np.array(1.0 / (s + b + s * s * inv_m), dtype=np.float64)
    if not exact:
        return out
    sd = np.sqrt(s + b + s * s * inv_m)
    reach = np.where(m < 3, 40.0, 14.0) * sd
    lo = np.floor(np.clip(s + b - reach, 0.0, None))
    hi = np.ceil(s + b + reach) + 1.0
    todo = np.isfinite(m) & (b > 0) & (hi - lo <= _FISHER_TERMS)
    if not np.any(todo):
        return out
    lo_t, hi_t = lo[todo].astype(np.int64), hi[todo].astype(np.int64)
    n = hi_t - lo_t + 1
    elem = np.repeat(np.arange(n.size), n)
    k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n) + lo_t[elem]
    ss, bb, mm = s[todo][elem], b[todo][elem], m[todo][elem]
    p = np.exp(speckle_log_pmf(k, ss, bb, mm))
    q_k = np.exp(speckle_log_pmf(k, ss * (mm + 1) / mm, bb, mm + 1))
    q_km1 = np.where(k > 0, np.exp(speckle_log_pmf(np.maximum(k - 1, 0), ss * (mm + 1) / mm, bb, mm + 1)), 0.0)
    terms = np.where(p > 0, (q_km1 - q_k) ** 2 / np.where(p > 0, p, 1.0), 0.0)
    out[todo] = np.add.reduceat(terms, np.cumsum(n) - n)
    return out


# ---------------------------------------------------------------------- sampling


def _background(value: Any, shape: tuple[int, ...]) -> np.ndarray:
    b = _array(value, "background", "counts >= 0")
    if not np.all(np.isfinite(b)) or np.any(b < 0):
        raise Error("invalid background: finite counts >= 0")
    try:
        return np.broadcast_to(b, shape)
    except ValueError:
        raise Error(f"invalid background: shape {b.shape} does not broadcast to {shape} (..., B, C)") from None


def sample_intensity(stokes: Any, rows: Any, generator_index: Any, dof: Any, rng: Any) -> np.ndarray:
    """Draw the channels' speckle intensities: one Wishart coherency per bin and generator.

    ``W = J^(1/2) Omega J^(1/2) / M`` with ``Omega ~ CW_2(M, I)`` drawn by the complex
    Bartlett decomposition ``Omega = T T^H``, ``T = [[t11, 0], [t21, t22]]``, ``t11^2 ~
    Gamma(M)``, ``t22^2 ~ Gamma(M - 1)``, ``t21 ~ CN(0, 1)``, all independent: exact for
    real ``M >= 1`` (``M = 1`` gives a rank-one ``W``, one fully developed speckle),
    ``J^(1/2)`` the closed-form Hermitian square root (singular ``J`` included). Channel
    ``c`` gets ``tr(A_c W)``: channels of one generator share ``W`` (``H + V = D + A``
    holds draw by draw). Where ``dof`` is inf the mean ``a_c . S`` is returned and,
    where it is inf everywhere, nothing is drawn from ``rng``.

    The result is the signal before the detector: apply a jitter blur to it (it moves
    photons between bins) before adding background and Poisson noise (as
    :func:`sample_counts` does without jitter).

    Parameters
    ----------
    stokes : array_like
        (..., B, G, 4) received Stokes vectors per generator, in counts.
    rows : array_like
        (C, 4) channel analyzer rows (``Channels.rows``).
    generator_index : array_like
        (C,) int: each channel's generator in ``stokes``.
    dof : float or array_like
        Degrees of freedom in [1, inf] over all the pulses accumulated
        (:func:`accumulated_dof`), broadcast to (..., B, G) (per bin: ``dof[..., None]``).
    rng : numpy.random.Generator
        The generator to draw with.

    Returns
    -------
    numpy.ndarray
        (..., B, C) intensities (counts, float64, >= 0); their mean is ``a_c . S``.

    Raises
    ------
    pprender.Error
        For shapes other than these, unphysical Stokes vectors or analyzer rows, generator
        indices out of range, ``dof`` outside [1, inf], or ``rng`` not a Generator.
    """
    s, r, g = _setup(stokes, rows, generator_index)
    m = _dof(dof, s.shape[:-1])
    rng = _check_rng(rng)
    inf = np.isinf(m)
    if np.all(inf):
        return np.einsum("ci,...ci->...c", r, s[..., g, :])
    shape = m.shape
    mf = np.where(inf, 1.0, m)
    t11 = np.sqrt(rng.standard_gamma(mf, size=shape))
    t22sq = rng.standard_gamma(mf - 1.0, size=shape)
    z = rng.standard_normal(shape + (2,)) * math.sqrt(0.5)
    t21 = z[..., 0] + 1j * z[..., 1]
    omega = np.empty(shape + (2, 2), dtype=np.complex128)
    omega[..., 0, 0] = t11 * t11
    omega[..., 0, 1] = t11 * np.conj(t21)
    omega[..., 1, 0] = t11 * t21
    omega[..., 1, 1] = (t21 * np.conj(t21)).real + t22sq
    omega /= mf[..., None, None]
    omega[inf] = np.eye(2)
    root = _sqrtm_psd(_coherency(s))
    w = root @ omega @ root  # (..., B, G, 2, 2)
    a = 2.0 * _coherency(r)
    out = np.einsum("cij,...cji->...c", a, w[..., g, :, :]).real
    return np.clip(out, 0.0, None)


def sample_counts(
    stokes: Any, rows: Any, generator_index: Any, dof: Any, background: Any, rng: Any
) -> np.ndarray:
    """Draw counts: Poisson with mean speckle intensity (:func:`sample_intensity`) plus background.

    Parameters
    ----------
    stokes : array_like
        (..., B, G, 4) received Stokes vectors per generator, in counts.
    rows : array_like
        (C, 4) channel analyzer rows.
    generator_index : array_like
        (C,) int: each channel's generator.
    dof : float or array_like
        Degrees of freedom in [1, inf], broadcast to (..., B, G); inf everywhere gives
        ``rng.poisson(a_c . S + background)``, the speckle-free model.
    background : array_like
        Background counts >= 0, broadcast to (..., B, C).
    rng : numpy.random.Generator
        The generator to draw with.

    Returns
    -------
    numpy.ndarray
        (..., B, C) int64 counts.

    Raises
    ------
    pprender.Error
        As :func:`sample_intensity`, and for a background that is not finite and >= 0 or
        does not broadcast.
    """
    i = sample_intensity(stokes, rows, generator_index, dof, rng)
    b = _background(background, i.shape)
    return rng.poisson(i + b).astype(np.int64)


# ---------------------------------------------------------------------- likelihood


def _v_minus_expm1(v: np.ndarray, e: np.ndarray) -> np.ndarray:
    """``v - expm1(v)`` (``e = expm1(v)``) without cancellation near 0 (Taylor series for
    |v| < 0.1)."""
    out = v - e
    small = np.abs(v) < 0.1
    if np.any(small):
        vs = v[small]
        # -(v^2/2! + v^3/3! + ... + v^13/13!) by Horner
        acc = np.full(vs.shape, 1.0 / math.factorial(13))
        for n in range(12, 1, -1):
            acc = acc * vs + 1.0 / math.factorial(n)
        out[small] = -acc * vs * vs
    return out


def _gamma_log_norm(m: np.ndarray) -> np.ndarray:
    """``M log M - M - lgamma(M)``, the log normalisation of the gamma density of
    ``v = log(x / mean)``; by Stirling's series above M = 10 (no cancellation)."""
    big = m >= 10.0
    mb = np.where(big, m, 10.0)
    inv = 1.0 / mb
    inv2 = inv * inv
    stirling = inv * (1.0 / 12 - inv2 * (1.0 / 360 - inv2 * (1.0 / 1260 - inv2 * (1.0 / 1680 - inv2 / 1188))))
    large = 0.5 * np.log(mb / (2.0 * math.pi)) - stirling
    ms = np.where(big, 1.0, m)
    small = ms * np.log(ms) - ms - gammaln(ms)
    return np.where(big, large, small)


def _phi(v: np.ndarray, v0: np.ndarray, k: np.ndarray, x0: np.ndarray, g: np.ndarray, m: np.ndarray) -> np.ndarray:
    # log of [gamma density of v = log(x / s)] x [Poisson(k; x + b) / Poisson(k; x0 + b)],
    # x0 = s e^v0, less the gamma normalisation: with w = v - v0 and g = x0 / (x0 + b),
    # M (v - expm1 v) + k log(1 - g + g e^w) - x0 expm1(w)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        vc = np.minimum(v, 700.0)
        w = np.minimum(v - v0, 700.0)
        e = np.expm1(w)
        ge = g * e
        # log(1 - g + g e^w): log1p where accurate, else log-add-exp (exact at g = 1, far left)
        far = ge < -0.5
        lg = np.where(far, np.logaddexp(np.log1p(-g), np.log(g) + w), np.log1p(np.where(far, 0.0, ge)))
        out = m * _v_minus_expm1(vc, np.expm1(vc)) + np.where(k > 0, k * lg, 0.0) - x0 * e
    return np.where(np.isnan(out), -np.inf, out)


def _log_pmf_gamma(k: np.ndarray, s: np.ndarray, b: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``log p(k)`` for 1-D arrays (s > 0, finite m >= 1), p the Poisson law mixed over a
    gamma intensity of mean s and shape m, plus background b.

    ``p(k) = Poisson(k; x0 + b) int exp(c(m) + phi(v)) dv`` over ``v = log(x / s)``, with
    ``x0`` the integrand's mode (so that no large terms cancel, even for counts far below
    the mean). The integrand is unimodal (``phi'`` has one zero: in ``y = e^v`` it is
    concave, positive at 0 and -> -inf). Its mode is found by Newton's method, the
    interval where it is within exp(-_DROP) of the peak by doubling steps from the
    curvature width, and the integral by the trapezoid rule on _N_QUAD nodes of a sinh
    map (spectrally accurate for a smooth, rapidly decaying integrand)."""
    f = s / (s + b)
    # mode: the zero of phi' = g(y), y = e^v, g(y) = M - (M + s) y + k f y / (1 - f + f y),
    # concave with g(0) = M > 0; Newton from y = (M + k) / (M + s), where g <= 0, descends
    # monotonically onto the one root (the tangents of a concave function lie above it)
    y = (m + k) / (m + s)
    for _ in range(100):
        den = 1.0 - f + f * y
        gy = m - (m + s) * y + k * f * y / den
        dg = -(m + s) + k * f * (1.0 - f) / (den * den)
        y_new = np.where(gy < 0, y - gy / dg, y)
        done = np.all(np.abs(y_new - y) <= 1e-15 * y)
        y = y_new
        if done:
            break
    v0 = np.log(y)
    x0 = s * y
    c = x0 + b
    g = x0 / c
    p0 = _phi(v0, v0, k, x0, g, m)
    curv = y * (m + s - k * f * (1.0 - f) / (1.0 - f + f * y) ** 2)
    width = np.clip(1.0 / np.sqrt(np.clip(curv, 1e-300, None)), 1e-12, 1e3)
    ends = []
    for sign in (-1.0, 1.0):
        d = width.copy()
        for _ in range(80):
            low = ~(_phi(v0 + sign * d, v0, k, x0, g, m) > p0 - _DROP)
            if np.all(low):
                break
            d = np.where(low, d, 2.0 * d)
        ends.append(v0 + sign * d)
    # v = v0 + width sinh(t): fine steps at the peak, wide ones in the (possibly long)
    # tails; the trapezoid rule in t over [asinh(-d_left / width), asinh(d_right / width)]
    t_lo = np.arcsinh((ends[0] - v0) / width)
    t_hi = np.arcsinh((ends[1] - v0) / width)
    u = np.linspace(0.0, 1.0, _N_QUAD)
    t = t_lo[:, None] + (t_hi - t_lo)[:, None] * u[None, :]
    et = np.exp(t)
    v = v0[:, None] + width[:, None] * (0.5 * (et - 1.0 / et))  # sinh
    h = (t_hi - t_lo) / (_N_QUAD - 1)
    ph = _phi(v, v0[:, None], k[:, None], x0[:, None], g[:, None], m[:, None]) - p0[:, None]
    wts = np.full(_N_QUAD, 1.0)
    wts[[0, -1]] = 0.5
    total = (np.exp(ph) * (0.5 * (et + 1.0 / et))) @ wts  # cosh
    poisson = xlogy(k, c) - c - gammaln(k + 1.0)
    return poisson + p0 + np.log(h * width * total) + _gamma_log_norm(m)


def speckle_log_pmf(counts: Any, signal: Any, background: Any, dof: Any) -> np.ndarray:
    """Log-probability of each count: Poisson mixed over a gamma speckle intensity, plus background.

    ``log P(k) = log int Poisson(k; x + b) Gamma(x; M, s / M) dx``: for ``b = 0`` the
    negative binomial of Mandel's formula (``n = M``, ``p = M / (M + s)``), in general
    that negative binomial convolved with the Poisson background. ``M = inf`` or
    ``s = 0`` gives the Poisson log-pmf ``k log(mu) - mu - log(k!)`` exactly (the same
    floating-point operations as :func:`pprender.fit.poisson_log_likelihood`).

    Evaluation: a Poisson log-pmf at the integrand's mode ``x0`` plus ``log int
    exp(phi(v)) dv`` over the log intensity ``v = log(x / s)``, every term written without
    cancellation (``expm1``, ``log1p``, Stirling's series for ``lgamma``), by the
    trapezoid rule on 97 nodes of a sinh map over the interval where the (unimodal)
    integrand is within 1e-20 of its peak: within 1e-10 of a brute-force convolution in
    the log for counts below ~1e3, and at large counts (tested to 1e9, ``M`` from 1 to
    1e15) as accurate as the Poisson log-pmf itself (the rounding of ``lgamma(k + 1)``,
    1e-9 relative at 1e6 counts), deep fades (counts far below a huge mean) included
    (tests: brute-force convolution, :class:`scipy.stats.nbinom`, the closed form at
    ``k = 0``), with a cost independent of the counts (no sum over ``k``).

    Parameters
    ----------
    counts : array_like
        (..., B, C) non-negative integers.
    signal : array_like
        Mean speckle intensities ``s >= 0`` (counts), broadcast against ``counts``.
    background : array_like
        Background counts ``b >= 0``, broadcast against ``counts``.
    dof : float or array_like
        Gamma shape ``M`` in [1, inf] per channel (:func:`channel_dof`), broadcast
        against ``counts``; inf: no speckle.

    Returns
    -------
    numpy.ndarray
        The log-pmf of each count, the broadcast shape; ``-inf`` for a count that cannot
        occur (``k > 0`` with ``s + b = 0``).

    Raises
    ------
    pprender.Error
        For counts that are not finite non-negative integers, signal or background not
        finite and >= 0, ``dof`` outside [1, inf], or shapes that do not broadcast.
    """
    try:
        k = np.asarray(counts)
    except (TypeError, ValueError):
        raise Error("invalid counts: not an array of numbers") from None
    if k.dtype == object or not (np.issubdtype(k.dtype, np.integer) or np.issubdtype(k.dtype, np.floating)):
        raise Error(f"invalid counts: dtype {k.dtype}, expected integers")
    k = k.astype(np.float64)
    if not np.all(np.isfinite(k)) or np.any(k < 0) or np.any(k != np.round(k)):
        raise Error("invalid counts: must be finite non-negative integers")
    s = _array(signal, "signal", "mean signal counts >= 0")
    if not np.all(np.isfinite(s)) or np.any(s < 0):
        raise Error("invalid signal: must be finite and >= 0 (counts)")
    b = _array(background, "background", "background counts >= 0")
    if not np.all(np.isfinite(b)) or np.any(b < 0):
        raise Error("invalid background: must be finite and >= 0 (counts)")
    m = _array(dof, "dof", "degrees of freedom in [1, inf]")
    if np.any(np.isnan(m)) or np.any(m < 1):
        raise Error("invalid dof: degrees of freedom in [1, inf] (inf: no speckle)")
    try:
        k, s, b, m = np.broadcast_arrays(k, s, b, m)
    except ValueError:
        raise Error(
            f"invalid counts/signal/background/dof: shapes {np.shape(counts)}, {np.shape(signal)}, "
            f"{np.shape(background)}, {np.shape(dof)} do not broadcast"
        ) from None
    lam = s + b
    out = np.asarray(xlogy(k, lam) - lam - gammaln(k + 1.0))
    todo = np.isfinite(m) & (s > 0)
    if np.any(todo):
        kk, ss, bb, mm = k[todo], s[todo], b[todo], m[todo]
        logp = np.empty(kk.shape)
        for i in range(0, kk.size, _BLOCK):
            sl = slice(i, i + _BLOCK)
            logp[sl] = _log_pmf_gamma(kk[sl], ss[sl], bb[sl], mm[sl])
        out[todo] = logp
    return out


def speckle_log_likelihood(counts: Any, signal: Any, background: Any, dof: Any) -> Any:
    """Speckle log-likelihood ``sum log P(k)`` over the last two axes (range bins, channels).

    Each count's marginal law (:func:`speckle_log_pmf`: negative binomial convolved with
    the Poisson background) summed over bins and channels. With ``dof = inf`` it is the
    Poisson log-likelihood of :func:`pprender.fit.poisson_log_likelihood` with
    ``expected = signal + background``, bit for bit.

    Channels are treated as independent: a composite (marginal) likelihood. Channels that
    share a generator see the same speckle field (``H + V = D + A`` for one field), so
    their intensities are correlated (:func:`intensity_moments`) and this is not the joint
    likelihood: each marginal is exact (for ideal polarizers), the correlations are left
    out. Estimates stay consistent, but where speckle dominates the noise their spread is
    larger than this likelihood's Fisher information says: ``docs/speckle.md`` measures
    it (sandwich formula, jointly simulated counts): with ``M = 2`` and 1000 counts in a
    bin, the error bar of a signal scale is too small by up to 1.4x for the co/cross
    receivers (a return polarized across the analyzers) and 1.7-2.2x for the six-channel
    ``"stokes"`` polarimeter (its three arms see one field); it is right for co/cross
    with an unpolarized or co-polarized return, and every ratio tends to 1 as shot noise
    takes over (``M n`` large).

    Parameters
    ----------
    counts : array_like
        (..., B, C) non-negative integers.
    signal : array_like
        (..., B, C) expected signal counts (the mean speckle intensity), >= 0;
        broadcast against ``counts``.
    background : array_like
        Background counts >= 0, broadcast against ``counts``.
    dof : float or array_like
        Each channel's marginal degrees of freedom in [1, inf] (:func:`channel_dof`),
        broadcast against ``counts``; inf: no speckle (Poisson).

    Returns
    -------
    float or numpy.ndarray
        The log-likelihood over the leading axes, which are kept (a float for 2-D inputs).

    Raises
    ------
    pprender.Error
        As :func:`speckle_log_pmf`, and for counts that are not (..., B, C).
    """
    if np.ndim(counts) < 2:
        raise Error(f"invalid counts: shape {np.shape(counts)}, expected (..., B, C)")
    out = np.sum(speckle_log_pmf(counts, signal, background, dof), axis=(-2, -1))
    return float(out) if np.ndim(out) == 0 else out



# ---------------------------------------------------------------------- the instrument's option


def _real(value: Any, name: str, what: str) -> float:
    """A real scalar (not bool, text, None or complex) as float; :class:`Error` naming ``name``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise Error(f"invalid {name} = {value!r}: {what}")
    return float(value)


@dataclass(frozen=True)
class Speckle:
    """Laser speckle in an :class:`~pprender.inverse.instrument.Instrument`'s measurements.

    ``Instrument(..., speckle=Speckle(...))`` makes :func:`~pprender.inverse.instrument.measure`
    draw speckled counts (module docstring: one Wishart coherency per range bin and
    transmitted state, accumulated over the pulses) and :mod:`pprender.inverse.fit` use the
    speckle likelihood. The per-pulse degrees of freedom ``M`` of each range bin come from
    one of:

    * ``dof``: a fixed ``M`` for every bin (``inf``: no speckle, the Poisson model in
      distribution, though not the same random draws as ``speckle=None``);
    * ``target_area``: the illuminated, rough part of the target in each bin (m^2,
      projected on the plane normal to the line of sight), one value or one per range bin
      of the profile: ``M = speckle_dof(aperture_diameter, wavelength, target_range,
      target_area)`` with the instrument's aperture, wavelength and range;
    * neither (default): the per-bin effective area :func:`illuminated_area` of the
      :class:`~pprender.RenderResult` given to ``measure``, which must then be rendered
      with ``outputs=("profile", "illuminated_area")`` (the render's own per-bin area) or
      with images and ranges, ``outputs=("profile", "mueller", "range")`` (or
      ``"stokes"`` for a single transmitted state); bins without any seen pixel get no
      speckle (they have no signal).

    Over the ``n_pulses * pulse_share`` pulses of each transmitted state the degrees of
    freedom add, with ``correlation`` the pulse-to-pulse correlation
    (:func:`accumulated_dof`). Range bins are independent draws (module docstring: right
    for bins at least a pulse length wide).

    Parameters
    ----------
    dof : float, optional
        Per-pulse degrees of freedom in [1, inf]. Not with ``target_area``.
    target_area : float or sequence of float, optional
        Projected illuminated area (m^2, finite, > 0): one value, or one per range bin of
        the profiles measured (B,). Not with ``dof``.
    correlation : float, optional
        Pulse-to-pulse correlation of the speckle in [0, 1] (0, the default: independent
        pulses; 1: a frozen pattern).
    pulse_fwhm : float or None, optional
        Only for the area from the render: the pulse's FWHM (s, in (0, 1e-6]) the result was
        rendered with (``Lidar.pulse_fwhm``; default 100e-12, the Lidar's default), which
        spreads each pixel over the range bins its pulse covers (:func:`illuminated_area`).
        None: each pixel counts in the bin of its range only (bins much wider than the
        pulse).

    Raises
    ------
    pprender.Error
        For both ``dof`` and ``target_area``, or a value outside the ranges above (naming
        the parameter).
    """

    dof: float | None = None
    target_area: float | tuple[float, ...] | None = None
    correlation: float = 0.0
    pulse_fwhm: float | None = 100e-12

    def __post_init__(self) -> None:
        if self.dof is not None and self.target_area is not None:
            raise Error(
                "invalid dof/target_area: give one of them (or neither: the area comes from the render), not both"
            )
        if self.dof is not None:
            d = _real(self.dof, "dof", "degrees of freedom per pulse in [1, inf] (a number)")
            if not d >= 1:
                raise Error(f"invalid dof = {self.dof!r}: degrees of freedom per pulse in [1, inf]")
            object.__setattr__(self, "dof", d)
        if self.target_area is not None:
            a = _array(self.target_area, "target_area", "areas in m^2, one or one per range bin")
            if a.ndim > 1 or a.size == 0 or not np.all(np.isfinite(a)) or np.any(a <= 0):
                raise Error(
                    f"invalid target_area = {self.target_area!r}: finite areas > 0 (m^2), one value or a 1-D "
                    "sequence with one per range bin"
                )
            object.__setattr__(self, "target_area", float(a) if a.ndim == 0 else tuple(float(x) for x in a))
        rho = _real(self.correlation, "correlation", "a correlation coefficient in [0, 1]")
        if not 0.0 <= rho <= 1.0:
            raise Error(f"invalid correlation = {self.correlation!r}: a correlation coefficient in [0, 1]")
        object.__setattr__(self, "correlation", rho)
        if self.pulse_fwhm is not None:
            f = _real(self.pulse_fwhm, "pulse_fwhm", "a pulse FWHM in (0, 1e-6] s, or None")
            if not 0.0 < f <= 1e-6:
                raise Error(f"invalid pulse_fwhm = {self.pulse_fwhm!r}: a pulse FWHM in (0, 1e-6] s, or None")
            object.__setattr__(self, "pulse_fwhm", f)

    @property
    def source(self) -> str:
        """Where the per-pulse dof come from: ``"dof"``, ``"target_area"`` or ``"render"``."""
        if self.dof is not None:
            return "dof"
        return "target_area" if self.target_area is not None else "render"

    @property
    def per_bin(self) -> bool:
        """Whether the per-pulse dof differ from bin to bin (a per-bin ``target_area`` or the
        render's areas): a fit then takes them from the measurement."""
        return self.source == "render" or isinstance(self.target_area, tuple)

    def pulse_dof(self, aperture_diameter: float, wavelength: float, target_range: float, area: Any = None) -> Any:
        """The per-pulse degrees of freedom: ``dof``, or :func:`speckle_dof` of the area.

        Parameters
        ----------
        aperture_diameter, wavelength, target_range : float
            The instrument's (m).
        area : array_like, optional
            (..., B) projected areas (m^2, >= 0; 0: no speckle, inf dof) for the render
            source (:func:`illuminated_area`); ignored otherwise.

        Returns
        -------
        float or numpy.ndarray
            ``M`` in [1, inf]: a float, (B,) for a per-bin ``target_area``, or the shape of
            ``area``.

        Raises
        ------
        pprender.Error
            For the render source without ``area``, or areas that are not finite and >= 0.
        """
        if self.dof is not None:
            return self.dof
        if self.target_area is not None:
            return speckle_dof(aperture_diameter, wavelength, target_range, np.asarray(self.target_area))
        if area is None:
            raise Error(
                "invalid profile: Speckle() takes the illuminated area from the render: pass a RenderResult "
                'rendered with outputs=("profile", "illuminated_area") or outputs=("profile", "mueller", "range") '
                '(or "stokes" for one transmitted state), or give Speckle(target_area=...) or Speckle(dof=...)'
            )
        a = _array(area, "area", "projected areas in m^2")
        if not np.all(np.isfinite(a)) or np.any(a < 0):
            raise Error("invalid area: finite projected areas >= 0 (m^2)")
        out = np.full(a.shape, np.inf)
        seen = a > 0
        if np.any(seen):
            out[seen] = speckle_dof(aperture_diameter, wavelength, target_range, a[seen])
        return out

    def to_params(self) -> dict[str, Any]:
        """The settings as JSON values (:meth:`from_params` rebuilds an equal Speckle).

        Returns
        -------
        dict
            ``dof``, ``target_area`` (a float, a list or None), ``correlation``, ``pulse_fwhm``.
        """
        area = self.target_area
        return {
            "dof": self.dof,
            "target_area": list(area) if isinstance(area, tuple) else area,
            "correlation": self.correlation,
            "pulse_fwhm": self.pulse_fwhm,
        }

    @classmethod
    def from_params(cls, params: Any) -> "Speckle":
        """The Speckle of :meth:`to_params`' values.

        Parameters
        ----------
        params : mapping
            As :meth:`to_params` returns.

        Returns
        -------
        Speckle
            The settings.

        Raises
        ------
        pprender.Error
            For values the constructor refuses, or a mapping with other keys.
        """
        try:
            return cls(**dict(params))
        except TypeError as e:
            raise Error(f"invalid speckle settings {params!r}: {e}") from None


def illuminated_area(result: Any, pulse_fwhm: Any = 100e-12) -> np.ndarray:
    """Per range bin, the effective projected area of the target that returns light in it.

    A :class:`~pprender.RenderResult` rendered with the ``"illuminated_area"`` output
    (``outputs=("profile", "illuminated_area")``: accumulated beside the profile, no images
    needed) carries it: :attr:`~pprender.RenderResult.illuminated_area` is returned (a
    copy), computed with the render's own pulse and the pixels' range footprints (then
    ``pulse_fwhm`` is not used unless it is None). Otherwise it is computed from the
    images, as follows. From a :class:`~pprender.RenderResult` rendered with images and ranges
    (``outputs=("profile", "mueller", "range")``, or ``"stokes"``/``"intensity"`` for a
    transmitted state): pixel ``p`` has the projected area ``a_p = coverage_p
    pixel_size^2`` (on the plane normal to the line of sight), the cross-section ``I_p``
    (``S0``: ``M00`` of a Mueller image, the unpolarized transmitter's return) and the
    range ``r_p``. Its share of range bin ``j`` is ``w_jp``: the fraction of a Gaussian
    pulse of range FWHM ``c pulse_fwhm / 2`` about ``r_p`` that falls in the bin (with
    ``pulse_fwhm=None``, 1 for the bin containing ``r_p`` and 0 elsewhere). Bin ``j``'s
    effective area is

    ``A_j = (sum_p w_jp I_p)^2 / sum_p (w_jp I_p)^2 / a_p``,

    Goodman's effective area ``(int I)^2 / int I^2`` of a non-uniformly bright source
    (:func:`speckle_dof`): the area of a uniformly bright region when the brightness is
    uniform (a flat plate seen face-on: its area, in every bin its return reaches), and
    smaller where a few pixels dominate. The pulse's time integral is not counted as extra
    degrees of freedom (a target deeper than the pulse has more; :func:`speckle_dof`).

    Parameters
    ----------
    result : RenderResult
        Rendered with ``"illuminated_area"``, or with ``"range"`` (which also sets
        ``coverage``) and an image output.
    pulse_fwhm : float or None, optional
        For the image computation: the rendering Lidar's ``pulse_fwhm`` (s, in (0, 1e-6];
        default 100e-12, the Lidar's default). A Lidar with ``pulse_samples``: the FWHM of
        the Gaussian of the same variance. None: bin by the pixel's range only (from the
        images, even when the result carries the render output).

    Returns
    -------
    numpy.ndarray
        (N, B) areas (m^2) per attitude and range bin; 0 where no seen pixel returns light.

    Raises
    ------
    pprender.Error
        For something that is not a RenderResult, one without the ``"illuminated_area"``
        output and without ``range``/``coverage`` or an image output, or a ``pulse_fwhm``
        outside (0, 1e-6].
    """
    if not isinstance(result, RenderResult):
        raise Error(f"invalid result of type {type(result).__name__}: expected a pprender.RenderResult")
    if pulse_fwhm is not None:
        f = _real(pulse_fwhm, "pulse_fwhm", "a pulse FWHM in (0, 1e-6] s, or None")
        if not 0.0 < f <= 1e-6:
            raise Error(f"invalid pulse_fwhm = {pulse_fwhm!r}: a pulse FWHM in (0, 1e-6] s, or None")
        if result.illuminated_area is not None:
            return np.array(result.illuminated_area, dtype=np.float64)
    if result.range is None or result.coverage is None:
        raise Error(
            'invalid result: no "illuminated_area" output and no "range" image: render with '
            'outputs=("profile", "illuminated_area") (or ("profile", "mueller", "range")) to get the '
            "illuminated area per range bin"
        )
    if result.mueller is not None:
        inten = np.asarray(result.mueller)[..., 0, 0]
    elif result.stokes is not None:
        inten = np.asarray(result.stokes)[..., 0]
    elif result.intensity is not None:
        inten = np.asarray(result.intensity)
    else:
        raise Error(
            'invalid result: no image output: render with outputs=("profile", "mueller", "range") (or "stokes" / '
            '"intensity" with a transmitted polarization)'
        )
    edges = np.asarray(result.bin_edges, dtype=np.float64)
    n_bins = len(edges) - 1
    cov = np.asarray(result.coverage, dtype=np.float64)
    rng_img = np.asarray(result.range, dtype=np.float64)
    inten = np.clip(inten.astype(np.float64), 0.0, None)
    n = cov.shape[0]
    out = np.zeros((n, n_bins))
    pix = float(result.pixel_size) ** 2
    for i in range(n):
        seen = (cov[i] > 0) & np.isfinite(rng_img[i]) & (inten[i] > 0)
        a = cov[i][seen] * pix
        ip = inten[i][seen]
        r = rng_img[i][seen]
        if a.size == 0:
            continue
        if pulse_fwhm is None:
            j = np.searchsorted(edges, r, side="right") - 1
            inside = (j >= 0) & (j < n_bins)
            num = np.bincount(j[inside], ip[inside], minlength=n_bins)
            den = np.bincount(j[inside], ip[inside] ** 2 / a[inside], minlength=n_bins)
        else:
            # share of each pixel's Gaussian pulse in each bin: differences of its CDF at the edges
            sigma = SPEED_OF_LIGHT * float(pulse_fwhm) / 2.0 / (2.0 * math.sqrt(2.0 * math.log(2.0)))
            cdf = 0.5 * (1.0 + erf((edges[:, None] - r[None, :]) / (sigma * math.sqrt(2.0))))  # (B + 1, P)
            w = np.diff(cdf, axis=0) * ip[None, :]  # (B, P)
            num = w.sum(axis=1)
            den = (w * w / a[None, :]).sum(axis=1)
        ok = den > 0
        out[i, ok] = num[ok] ** 2 / den[ok]
    return out
