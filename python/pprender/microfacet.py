"""Microfacet masking: the exact APS ``<h.k>+``, masking and Smith functions.

Blinn-Phong distribution ``rho(h) = (m+1)/(2 pi) cos^m(theta_h)`` over solid angle; the APS
masking (seed eq. 7) is ``P(k) = <h.n> cos(theta_k) / <h.k>+`` with
``<h.k>+ = int rho(h) max(0, h.k) d omega`` and ``<h.n> = (m+1)/(m+2)``.

All angles are in **radians**, measured from the macro-surface normal (``theta_k``) or
used as integration limits (``alpha``). Every function accepts scalars or array-likes,
broadcasts them with NumPy's rules and returns a float64 array of the broadcast shape
(a NumPy float for scalar inputs). Invalid inputs (NaN, ``m`` outside [0, 1e10], angles
outside their range) raise :class:`pprender.Error` (a ``ValueError``) naming the parameter.

Exact references: :func:`wallis`, :func:`incomplete_cos_pow`, :func:`hk_plus`,
:func:`hk_plus_eq18`, :func:`aps_masking`, :func:`smith_g1`. The seed paper's
approximations are in :mod:`pprender.validation.seed` (also importable from here, as
before, e.g. ``pprender.microfacet.seed_aps_p``).
"""

from __future__ import annotations

from typing import Optional

from numpy.typing import ArrayLike

from . import _core
from ._arrays import FloatOrArray, _out

__all__ = [
    "wallis",
    "incomplete_cos_pow",
    "hk_plus",
    "hk_plus_eq18",
    "aps_masking",
    "smith_g1",
]

def wallis(m: ArrayLike) -> FloatOrArray:
    """Wallis integral ``A(m) = int_0^{pi/2} cos^m(t) dt`` (seed eq. 20), exact.

    ``A(m) = sqrt(pi)/2 Gamma((m+1)/2) / Gamma(m/2 + 1)`` for real ``m >= 0``, computed
    from a Stirling-series difference of the log-gammas: relative error about 1e-15 for
    ``m`` in [0, 1e10] (``A(0) = pi/2``, ``A(1) = 1``, ``A(m) ~ sqrt(pi/(2m))``).

    Parameters
    ----------
    m : array_like
        Exponent, in [0, 1e10].

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``A(m)``, of the shape of ``m`` (a NumPy float for a scalar).

    Raises
    ------
    pprender.Error
        For NaN or ``m`` outside [0, 1e10].
    """
    return _out(_core.wallis(m))


def incomplete_cos_pow(m: ArrayLike, alpha: ArrayLike) -> FloatOrArray:
    """``int_alpha^{pi/2} cos^m(t) dt = A(m) I_{cos^2 alpha}((m+1)/2, 1/2)``, exact.

    For ``alpha < 0`` this is ``2 A(m) - int_{-alpha}^{pi/2} cos^m``. Relative error about
    1e-15 (at most ~1e-13 in deep tails, the conditioning of ``cos^{m+1}(alpha)``) for ``m``
    in [0, 1e10], including ``alpha`` within 1e-7 of pi/2 (underflowing correctly to 0 for
    large ``m``) and tiny ``alpha``; exactly 0 at ``alpha = pi/2``.

    Parameters
    ----------
    m : array_like
        Exponent, in [0, 1e10].
    alpha : array_like
        Lower limit in radians, in [-pi/2, pi/2]; broadcast against ``m``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        The integral, of the broadcast shape (a NumPy float for scalars).

    Raises
    ------
    pprender.Error
        For NaN or arguments outside their ranges.
    """
    return _out(_core.incomplete_cos_pow(m, alpha))


def hk_plus(
    theta_k: ArrayLike,
    distribution: str = "blinn_phong",
    m: Optional[ArrayLike] = None,
    alpha: Optional[ArrayLike] = None,
) -> FloatOrArray:
    """Exact ``<h.k>+ = int rho(h) max(0, h.k) d omega`` (seed eq. 18), any distribution.

    Equals ``<h.n>`` at normal incidence.

    Parameters
    ----------
    theta_k : array_like
        Polar angle of ``k`` in radians, [0, pi/2].
    distribution : {"blinn_phong", "beckmann", "ggx"}, optional
        The microfacet distribution. Default ``"blinn_phong"``.
    m : array_like, optional
        Blinn-Phong exponent; give either ``m`` or ``alpha``.
    alpha : array_like, optional
        Roughness (mapped with ``alpha = sqrt(2/(m+2))``); give either ``m`` or ``alpha``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``<h.k>+``, of the broadcast shape of ``theta_k`` and the roughness.

    Raises
    ------
    pprender.Error
        For NaN, arguments outside their ranges, both or neither of ``m`` and ``alpha``, or an
        unknown ``distribution``.
    """
    return _out(_core.hk_plus(theta_k, distribution, m, alpha))


def hk_plus_eq18(m: ArrayLike, theta_k: ArrayLike) -> FloatOrArray:
    """Exact Blinn-Phong ``<h.k>+`` from the exact reduction of seed eq. 18 (radians).

    ``(m+1)/pi A(m+2) [cos(theta_k) (2 A(m+1) - F_{m+1}(pi/2 - theta_k)) + sin^{m+2}(theta_k)/(m+1)]``
    with ``F_m(a) = int_a^{pi/2} cos^m``: an independent route to :func:`hk_plus`.

    Parameters
    ----------
    m : array_like
        Blinn-Phong exponent, in [0, 1e10].
    theta_k : array_like
        Polar angle of ``k`` in radians, [0, pi/2]; broadcast against ``m``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``<h.k>+``, of the broadcast shape.

    Raises
    ------
    pprender.Error
        For NaN or arguments outside their ranges.
    """
    return _out(_core.hk_plus_eq18(m, theta_k))


def aps_masking(
    theta_k: ArrayLike,
    distribution: str = "blinn_phong",
    m: Optional[ArrayLike] = None,
    alpha: Optional[ArrayLike] = None,
) -> FloatOrArray:
    """Exact APS masking ``P(k) = <h.n> cos(theta_k) / <h.k>+`` (seed eq. 7), radians.

    1 at normal incidence, 0 at grazing.

    Parameters
    ----------
    theta_k : array_like
        As in :func:`hk_plus`.
    distribution : {"blinn_phong", "beckmann", "ggx"}, optional
        As in :func:`hk_plus`. Default ``"blinn_phong"``.
    m : array_like, optional
        As in :func:`hk_plus`.
    alpha : array_like, optional
        As in :func:`hk_plus`.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``P(k)``, of the broadcast shape.

    Raises
    ------
    pprender.Error
        As :func:`hk_plus`.
    """
    return _out(_core.aps_masking(theta_k, distribution, m, alpha))


def smith_g1(
    theta_k: ArrayLike,
    distribution: str,
    m: Optional[ArrayLike] = None,
    alpha: Optional[ArrayLike] = None,
    variant: str = "exact",
) -> FloatOrArray:
    """Smith masking ``G1 = 1 / (1 + Lambda)`` (Walter et al. 2007), radians.

    Parameters
    ----------
    theta_k : array_like
        Polar angle of ``k`` in radians, [0, pi/2].
    distribution : {"beckmann", "ggx", "blinn_phong"}
        ``"beckmann"`` or ``"ggx"`` with ``alpha``, or ``"blinn_phong"`` with ``m``.
    m : array_like, optional
        Blinn-Phong exponent.
    alpha : array_like, optional
        Beckmann or GGX roughness.
    variant : {"exact", "walter"}, optional
        ``"exact"`` (default; Beckmann: the erfc form; Blinn-Phong: the Smith function of the
        Blinn-Phong distribution itself, ``Lambda = N_D / cos``, equal to
        :func:`aps_masking`) or ``"walter"`` (the rational approximation Mitsuba 3 uses;
        Blinn-Phong through Beckmann with ``alpha = sqrt(2/(m+2))``); GGX is exact either way.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``G1``, of the broadcast shape.

    Raises
    ------
    pprender.Error
        For NaN, arguments outside their ranges, both or neither of ``m`` and ``alpha``, an
        unknown ``distribution`` or ``variant``.

    References
    ----------
    Walter et al. (2007).
    """
    return _out(_core.smith_g1(theta_k, distribution, m, alpha, variant))


# The seed's approximations, at their earlier paths (pprender.validation.seed)
from .validation.seed import (  # noqa: E402
    seed_aps_p,
    seed_hk_plus,
    seed_hk_plus_printed,
    seed_incomplete_cos_pow,
    seed_incomplete_cos_pow_printed,
    seed_wallis,
    wallis_factorial,
)
