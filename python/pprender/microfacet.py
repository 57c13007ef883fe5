"""Microfacet masking: exact APS ``<h.k>+`` and the seed's closed-form approximation.

Blinn-Phong distribution ``rho(h) = (m+1)/(2 pi) cos^m(theta_h)`` over solid angle; the APS
masking (seed eq. 7) is ``P(k) = <h.n> cos(theta_k) / <h.k>+`` with
``<h.k>+ = int rho(h) max(0, h.k) d omega`` and ``<h.n> = (m+1)/(m+2)``.

All angles are in **radians**, measured from the macro-surface normal (``theta_k``) or
used as integration limits (``alpha``). Every function accepts scalars or array-likes,
broadcasts them with NumPy's rules and returns a float64 array of the broadcast shape
(a NumPy float for scalar inputs). Invalid inputs (NaN, ``m`` outside [0, 1e10], angles
outside their range) raise :class:`pprender.Error` (a ``ValueError``) naming the parameter.

Exact references: :func:`wallis`, :func:`incomplete_cos_pow`, :func:`hk_plus`,
:func:`hk_plus_eq18`, :func:`aps_masking`, :func:`smith_g1`.
The seed's approximation (docs/seed-approximation.md): :func:`seed_wallis` (eq. 22),
:func:`seed_incomplete_cos_pow` (eq. 19, our reading), :func:`seed_hk_plus` (eq. 23, our
reading), :func:`seed_aps_p`; the printed forms :func:`seed_incomplete_cos_pow_printed`,
:func:`seed_hk_plus_printed`, and :func:`wallis_factorial` (eq. 20 in f64 factorials).
"""

from __future__ import annotations

from typing import Optional, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _core

__all__ = [
    "wallis",
    "wallis_factorial",
    "seed_wallis",
    "incomplete_cos_pow",
    "seed_incomplete_cos_pow",
    "seed_incomplete_cos_pow_printed",
    "hk_plus",
    "hk_plus_eq18",
    "seed_hk_plus",
    "seed_hk_plus_printed",
    "aps_masking",
    "seed_aps_p",
    "smith_g1",
]

FloatOrArray = Union[np.float64, NDArray[np.float64]]


def _out(x: NDArray[np.float64]) -> FloatOrArray:
    """0-d results as NumPy floats, others unchanged."""
    return x[()] if x.ndim == 0 else x


def wallis(m: ArrayLike) -> FloatOrArray:
    """Wallis integral ``A(m) = int_0^{pi/2} cos^m(t) dt`` (seed eq. 20), exact.

    ``A(m) = sqrt(pi)/2 Gamma((m+1)/2) / Gamma(m/2 + 1)`` for real ``m >= 0``, computed
    from a Stirling-series difference of the log-gammas: relative error about 1e-15 for
    ``m`` in [0, 1e10] (``A(0) = pi/2``, ``A(1) = 1``, ``A(m) ~ sqrt(pi/(2m))``).
    """
    return _out(_core.wallis(m))


def wallis_factorial(m: ArrayLike) -> FloatOrArray:
    """Seed eq. 20 evaluated literally in float64: ``(pi/2) m! / (2^m ((m/2)!)^2)``.

    Factorials as ``Gamma(x + 1)``. Accurate while the factorials fit in float64, NaN
    (inf/inf) from ``m = 171`` on: the numerical failure the seed describes. Use
    :func:`wallis` instead.
    """
    return _out(_core.wallis_factorial(m))


def seed_wallis(m: ArrayLike) -> FloatOrArray:
    """Seed eq. 22: ``A(m) ~ (pi/2) sqrt(2 pi m + 1) / (pi m + 1)``.

    From eq. 21, ``m! ~ sqrt(2 pi m + 1) e^-m m^m`` (exact at m = 0). Relative error 0 at
    m = 0, 2.4% at m = 1, about ``0.0113/m`` for large m.
    """
    return _out(_core.seed_wallis(m))


def incomplete_cos_pow(m: ArrayLike, alpha: ArrayLike) -> FloatOrArray:
    """``int_alpha^{pi/2} cos^m(t) dt = A(m) I_{cos^2 alpha}((m+1)/2, 1/2)``, exact.

    ``alpha`` in radians, in [-pi/2, pi/2] (for ``alpha < 0`` this is
    ``2 A(m) - int_{-alpha}^{pi/2} cos^m``). Relative error about 1e-15 (at most ~1e-13
    in deep tails, the conditioning of ``cos^{m+1}(alpha)``) for ``m`` in
    [0, 1e10], including ``alpha`` within 1e-7 of pi/2 (underflowing correctly to 0 for
    large ``m``) and tiny ``alpha``; exactly 0 at ``alpha = pi/2``.
    """
    return _out(_core.incomplete_cos_pow(m, alpha))


def seed_incomplete_cos_pow(m: ArrayLike, alpha: ArrayLike, exact_wallis: bool = False) -> FloatOrArray:
    """Seed eq. 19 as we read it: ``int_alpha^{pi/2} cos^m ~ A(m) cos^{m+1}(alpha)``.

    For ``alpha`` in [0, pi/2]; for ``alpha`` in [-pi/2, 0) the seed's own shape
    ``2 A(m) - A(m) cos^{m+1}(alpha)``. Exact at ``alpha = 0`` and ``+-pi/2`` (with the exact
    ``A``). ``A(m)`` from eq. 22 (:func:`seed_wallis`), or from :func:`wallis` when
    ``exact_wallis`` is true. Radians.
    """
    return _out(_core.seed_incomplete_cos_pow(m, alpha, exact_wallis))


def seed_incomplete_cos_pow_printed(m: ArrayLike, alpha: ArrayLike) -> FloatOrArray:
    """Seed eq. 19 as printed: ``2 A(m) - A(m) (1 - A(m) cos(alpha))^{m+1}`` (exact ``A``).

    Kept to show how it fails: it equals ``A(m)`` at ``alpha = pi/2`` and not ``A(m)`` at
    ``alpha = 0``; NaN where the base is negative and ``m + 1`` is not an integer. Radians.
    """
    return _out(_core.seed_incomplete_cos_pow_printed(m, alpha))


def hk_plus(
    theta_k: ArrayLike,
    distribution: str = "blinn_phong",
    m: Optional[ArrayLike] = None,
    alpha: Optional[ArrayLike] = None,
) -> FloatOrArray:
    """Exact ``<h.k>+ = int rho(h) max(0, h.k) d omega`` (seed eq. 18), any distribution.

    ``theta_k``: polar angle of ``k`` in radians, [0, pi/2]. ``distribution``:
    ``"blinn_phong"``, ``"beckmann"`` or ``"ggx"``, with either ``m`` (Blinn-Phong exponent)
    or ``alpha`` (roughness; mapped with ``alpha = sqrt(2/(m+2))``). Equals ``<h.n>`` at
    normal incidence.
    """
    return _out(_core.hk_plus(theta_k, distribution, m, alpha))


def hk_plus_eq18(m: ArrayLike, theta_k: ArrayLike) -> FloatOrArray:
    """Exact Blinn-Phong ``<h.k>+`` from the exact reduction of seed eq. 18 (radians).

    ``(m+1)/pi A(m+2) [cos(theta_k) (2 A(m+1) - F_{m+1}(pi/2 - theta_k)) + sin^{m+2}(theta_k)/(m+1)]``
    with ``F_m(a) = int_a^{pi/2} cos^m``: an independent route to :func:`hk_plus`.
    """
    return _out(_core.hk_plus_eq18(m, theta_k))


def seed_hk_plus(m: ArrayLike, theta_k: ArrayLike, exact_wallis: bool = False) -> FloatOrArray:
    """The seed's closed-form ``<h.k>+`` (eq. 23 as we read it), Blinn-Phong, radians.

    ``(m+1)/pi A(m+2) [cos(theta_k) A(m+1) (2 - sin^{m+2}(theta_k)) + sin^{m+2}(theta_k)/(m+1)]``
    with ``A`` from eq. 22 (or exact if ``exact_wallis``). Same normalization as
    :func:`hk_plus`; positive and finite for ``m`` in [0, 1e10].
    """
    return _out(_core.seed_hk_plus(m, theta_k, exact_wallis))


def seed_hk_plus_printed(m: ArrayLike, theta_k: ArrayLike) -> FloatOrArray:
    """Seed eq. 23 as printed (``cos(alpha)^{m+2}`` with ``alpha = theta_k``), radians.

    Kept to show how it fails: half the exact value at normal incidence.
    """
    return _out(_core.seed_hk_plus_printed(m, theta_k))


def aps_masking(
    theta_k: ArrayLike,
    distribution: str = "blinn_phong",
    m: Optional[ArrayLike] = None,
    alpha: Optional[ArrayLike] = None,
) -> FloatOrArray:
    """Exact APS masking ``P(k) = <h.n> cos(theta_k) / <h.k>+`` (seed eq. 7), radians.

    1 at normal incidence, 0 at grazing. Arguments as in :func:`hk_plus`.
    """
    return _out(_core.aps_masking(theta_k, distribution, m, alpha))


def seed_aps_p(m: ArrayLike, theta_k: ArrayLike, exact_wallis: bool = False) -> FloatOrArray:
    """The seed's APS masking ``<h.n> cos(theta_k) / seed_hk_plus``, clamped to [0, 1].

    What ``masking="seed"`` uses. Blinn-Phong exponent ``m`` in [0, 1e10], ``theta_k`` in
    radians, [0, pi/2]. Error vs :func:`aps_masking`: docs/seed-approximation.md.
    """
    return _out(_core.seed_aps_p(m, theta_k, exact_wallis))


def smith_g1(
    theta_k: ArrayLike,
    distribution: str,
    m: Optional[ArrayLike] = None,
    alpha: Optional[ArrayLike] = None,
    variant: str = "exact",
) -> FloatOrArray:
    """Smith masking ``G1 = 1 / (1 + Lambda)`` (Walter et al. 2007), radians.

    ``distribution`` ``"beckmann"`` or ``"ggx"`` with ``alpha``, or ``"blinn_phong"`` with
    ``m``. ``variant``: ``"exact"`` (Beckmann: the erfc form; Blinn-Phong: the Smith
    function of the Blinn-Phong distribution itself, ``Lambda = N_D / cos``, equal to
    :func:`aps_masking`) or ``"walter"`` (the rational approximation Mitsuba 3 uses;
    Blinn-Phong through Beckmann with ``alpha = sqrt(2/(m+2))``); GGX is exact either way.
    """
    return _out(_core.smith_g1(theta_k, distribution, m, alpha, variant))
