"""The seed paper's closed forms and literal evaluations, kept to measure how far they are
from the exact functions of :mod:`pprender.microfacet` (docs/seed-approximation.md).

Not for new work: :func:`seed_aps_p` is what ``Material(masking="seed")`` uses, and it is
not energy conserving. Radians throughout; arguments and errors as in
:mod:`pprender.microfacet`.

* :func:`wallis_factorial`: eq. 20 in f64 factorials (fails from m = 171);
* :func:`seed_wallis`: eq. 22;
* :func:`seed_incomplete_cos_pow`: eq. 19 as we read it, :func:`seed_incomplete_cos_pow_printed`
  as printed;
* :func:`seed_hk_plus`: eq. 23 as we read it, :func:`seed_hk_plus_printed` as printed;
* :func:`seed_aps_p`: the seed's APS masking.
"""

from __future__ import annotations

from numpy.typing import ArrayLike

from .. import _core
from .._arrays import FloatOrArray, _out

__all__ = [
    "seed_aps_p",
    "seed_hk_plus",
    "seed_hk_plus_printed",
    "seed_incomplete_cos_pow",
    "seed_incomplete_cos_pow_printed",
    "seed_wallis",
    "wallis_factorial",
]


def wallis_factorial(m: ArrayLike) -> FloatOrArray:
    """Seed eq. 20 evaluated literally in float64: ``(pi/2) m! / (2^m ((m/2)!)^2)``.

    Factorials as ``Gamma(x + 1)``. Accurate while the factorials fit in float64, NaN
    (inf/inf) from ``m = 171`` on: the numerical failure the seed describes.

    Parameters
    ----------
    m : array_like
        Exponent, in [0, 1e10].

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``A(m)``, of the shape of ``m``.

    Raises
    ------
    pprender.Error
        For NaN or arguments outside their ranges (as in :mod:`pprender.microfacet`).

    See Also
    --------
    pprender.microfacet.wallis : The exact Wallis integral; use it instead.
    """
    return _out(_core.wallis_factorial(m))


def seed_wallis(m: ArrayLike) -> FloatOrArray:
    """Seed eq. 22: ``A(m) ~ (pi/2) sqrt(2 pi m + 1) / (pi m + 1)``.

    From eq. 21, ``m! ~ sqrt(2 pi m + 1) e^-m m^m`` (exact at m = 0). Relative error 0 at
    m = 0, 2.4% at m = 1, about ``0.0113/m`` for large m.

    Parameters
    ----------
    m : array_like
        Exponent, in [0, 1e10].

    Returns
    -------
    numpy.ndarray or numpy.float64
        The approximate ``A(m)``, of the shape of ``m``.

    Raises
    ------
    pprender.Error
        For NaN or arguments outside their ranges (as in :mod:`pprender.microfacet`).

    See Also
    --------
    pprender.microfacet.wallis : The exact Wallis integral.
    """
    return _out(_core.seed_wallis(m))


def seed_incomplete_cos_pow(m: ArrayLike, alpha: ArrayLike, exact_wallis: bool = False) -> FloatOrArray:
    """Seed eq. 19 as we read it: ``int_alpha^{pi/2} cos^m ~ A(m) cos^{m+1}(alpha)``.

    For ``alpha`` in [0, pi/2]; for ``alpha`` in [-pi/2, 0) the seed's own shape
    ``2 A(m) - A(m) cos^{m+1}(alpha)``. Exact at ``alpha = 0`` and ``+-pi/2`` (with the exact
    ``A``).

    Parameters
    ----------
    m : array_like
        Exponent, in [0, 1e10].
    alpha : array_like
        Lower limit in radians, in [-pi/2, pi/2]; broadcast against ``m``.
    exact_wallis : bool, optional
        Take ``A(m)`` from :func:`pprender.microfacet.wallis` instead of eq. 22
        (:func:`seed_wallis`, the default).

    Returns
    -------
    numpy.ndarray or numpy.float64
        The approximate integral, of the broadcast shape.

    Raises
    ------
    pprender.Error
        For NaN or arguments outside their ranges (as in :mod:`pprender.microfacet`).

    See Also
    --------
    pprender.microfacet.incomplete_cos_pow : The exact integral.
    """
    return _out(_core.seed_incomplete_cos_pow(m, alpha, exact_wallis))


def seed_incomplete_cos_pow_printed(m: ArrayLike, alpha: ArrayLike) -> FloatOrArray:
    """Seed eq. 19 as printed: ``2 A(m) - A(m) (1 - A(m) cos(alpha))^{m+1}`` (exact ``A``).

    Kept to show how it fails: it equals ``A(m)`` at ``alpha = pi/2`` and not ``A(m)`` at
    ``alpha = 0``; NaN where the base is negative and ``m + 1`` is not an integer.

    Parameters
    ----------
    m : array_like
        Exponent, in [0, 1e10].
    alpha : array_like
        Radians, in [-pi/2, pi/2]; broadcast against ``m``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        Of the broadcast shape.

    Raises
    ------
    pprender.Error
        For NaN or arguments outside their ranges (as in :mod:`pprender.microfacet`).
    """
    return _out(_core.seed_incomplete_cos_pow_printed(m, alpha))


def seed_hk_plus(m: ArrayLike, theta_k: ArrayLike, exact_wallis: bool = False) -> FloatOrArray:
    """The seed's closed-form ``<h.k>+`` (eq. 23 as we read it), Blinn-Phong, radians.

    ``(m+1)/pi A(m+2) [cos(theta_k) A(m+1) (2 - sin^{m+2}(theta_k)) + sin^{m+2}(theta_k)/(m+1)]``
    with ``A`` from eq. 22 (or exact if ``exact_wallis``). Same normalization as
    :func:`pprender.microfacet.hk_plus`; positive and finite for ``m`` in [0, 1e10].

    Parameters
    ----------
    m : array_like
        Blinn-Phong exponent, in [0, 1e10].
    theta_k : array_like
        Polar angle of ``k`` in radians, [0, pi/2]; broadcast against ``m``.
    exact_wallis : bool, optional
        Use the exact ``A`` (:func:`pprender.microfacet.wallis`) instead of eq. 22. Default
        False.

    Returns
    -------
    numpy.ndarray or numpy.float64
        The approximate ``<h.k>+``, of the broadcast shape.

    Raises
    ------
    pprender.Error
        For NaN or arguments outside their ranges (as in :mod:`pprender.microfacet`).
    """
    return _out(_core.seed_hk_plus(m, theta_k, exact_wallis))


def seed_hk_plus_printed(m: ArrayLike, theta_k: ArrayLike) -> FloatOrArray:
    """Seed eq. 23 as printed (``cos(alpha)^{m+2}`` with ``alpha = theta_k``), radians.

    Kept to show how it fails: half the exact value at normal incidence.

    Parameters
    ----------
    m : array_like
        Blinn-Phong exponent, in [0, 1e10].
    theta_k : array_like
        Polar angle of ``k`` in radians, [0, pi/2]; broadcast against ``m``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        Of the broadcast shape.

    Raises
    ------
    pprender.Error
        For NaN or arguments outside their ranges (as in :mod:`pprender.microfacet`).
    """
    return _out(_core.seed_hk_plus_printed(m, theta_k))


def seed_aps_p(m: ArrayLike, theta_k: ArrayLike, exact_wallis: bool = False) -> FloatOrArray:
    """The seed's APS masking ``<h.n> cos(theta_k) / seed_hk_plus``, clamped to [0, 1].

    What ``masking="seed"`` uses.

    Parameters
    ----------
    m : array_like
        Blinn-Phong exponent, in [0, 1e10].
    theta_k : array_like
        Polar angle of ``k`` in radians, [0, pi/2]; broadcast against ``m``.
    exact_wallis : bool, optional
        Use the exact ``A`` (:func:`pprender.microfacet.wallis`) in :func:`seed_hk_plus`
        instead of eq. 22. Default False.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``P(k)`` in [0, 1], of the broadcast shape.

    Raises
    ------
    pprender.Error
        For NaN or arguments outside their ranges (as in :mod:`pprender.microfacet`).

    See Also
    --------
    pprender.microfacet.aps_masking : The exact masking; the error against it is in
        docs/seed-approximation.md.
    """
    return _out(_core.seed_aps_p(m, theta_k, exact_wallis))
