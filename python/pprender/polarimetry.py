"""Polarimetric quantities of Stokes vectors and Mueller matrices.

Conventions (see ``src/optics/mod.rs``): Stokes ``(I, Q, U, V)`` on a beam basis
``(x, y)`` with ``y = k x x`` and ``V = 2 Im(Ex Ey*)``; Mueller matrices map input Stokes
``j`` to output ``i`` in ``M[..., i, j]``; a flat mirror at normal incidence is
``diag(1, 1, -1, -1)`` (linear states kept, circular handedness flipped).

Every function takes float64-convertible arrays with leading batch dimensions: Stokes
vectors ``(..., 4)``, Mueller matrices ``(..., 4, 4)``. Results keep the leading shape; a
single vector or matrix gives NumPy scalars. The batch loop runs in Rust without the GIL.

Errors (:class:`pprender.Error`, a ``ValueError``): a wrong trailing shape, a non-finite
element, a negative ``I`` or ``M00`` (except :func:`cloude_eigenvalues` and
:func:`is_physical`, which accept any finite matrix). The message names the parameter.

Degenerate inputs never give NaN: ratios to ``I`` or ``M00`` are 0 when ``I = 0`` or
``M00 = 0``; a depolarization ratio whose co-polarized part is 0 is ``inf`` (0 if the
cross-polarized part is 0 too).

References: Lu & Chipman, JOSA A 13, 1106 (1996); Gil & Bernabeu, Optica Acta 33, 185
(1986); Cloude, Optik 75, 26 (1986); Gimmestad, Appl. Opt. 47, 3795 (2008).
"""

from __future__ import annotations

from typing import Any, Tuple

import numpy as np
import numpy.typing as npt

from . import _core

__all__ = [
    "dop",
    "dolp",
    "docp",
    "diattenuation",
    "diattenuation_vector",
    "polarizance",
    "polarizance_vector",
    "depolarization_index",
    "linear_depolarization_ratio",
    "circular_depolarization_ratio",
    "lu_chipman",
    "retardance",
    "linear_retardance",
    "optical_rotation",
    "retardance_vector",
    "cloude_eigenvalues",
    "is_physical",
]

FloatArray = npt.NDArray[np.float64]


def _f64(x: npt.ArrayLike) -> FloatArray:
    return np.asarray(x, dtype=np.float64)


def _out(a: Any) -> Any:
    # 0-d results become NumPy scalars, as NumPy's own reductions do.
    return a[()] if isinstance(a, np.ndarray) and a.ndim == 0 else a


def dop(stokes: npt.ArrayLike) -> Any:
    """Degree of polarization ``sqrt(Q^2 + U^2 + V^2) / I``.

    Parameters
    ----------
    stokes : array_like
        Stokes vectors ``(..., 4)``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``(...)``; 0 where ``I = 0``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``I``.
    """
    return _out(_core.polarimetry_dop(_f64(stokes)))


def dolp(stokes: npt.ArrayLike) -> Any:
    """Degree of linear polarization ``sqrt(Q^2 + U^2) / I``.

    Parameters
    ----------
    stokes : array_like
        Stokes vectors ``(..., 4)``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``(...)``; 0 where ``I = 0``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``I``.
    """
    return _out(_core.polarimetry_dolp(_f64(stokes)))


def docp(stokes: npt.ArrayLike) -> Any:
    """Degree of circular polarization ``|V| / I`` (unsigned; ``sign(V)`` is the handedness).

    Parameters
    ----------
    stokes : array_like
        Stokes vectors ``(..., 4)``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``(...)``; 0 where ``I = 0``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``I``.
    """
    return _out(_core.polarimetry_docp(_f64(stokes)))


def diattenuation(mueller: npt.ArrayLike) -> Any:
    """Diattenuation ``D = sqrt(M01^2 + M02^2 + M03^2) / M00``.

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``(...)``; 0 where ``M00 = 0``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``M00``.
    """
    return _out(_core.polarimetry_diattenuation(_f64(mueller)))


def diattenuation_vector(mueller: npt.ArrayLike) -> FloatArray:
    """Diattenuation vector ``(M01, M02, M03) / M00`` (Lu & Chipman eq. 9).

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``.

    Returns
    -------
    numpy.ndarray
        ``(..., 3)``; zero where ``M00 = 0``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``M00``.

    References
    ----------
    Lu & Chipman, JOSA A 13, 1106 (1996).
    """
    return _core.polarimetry_diattenuation_vector(_f64(mueller))


def polarizance(mueller: npt.ArrayLike) -> Any:
    """Polarizance ``P = sqrt(M10^2 + M20^2 + M30^2) / M00``.

    The degree of polarization of the output for unpolarized input.

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``(...)``; 0 where ``M00 = 0``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``M00``.
    """
    return _out(_core.polarimetry_polarizance(_f64(mueller)))


def polarizance_vector(mueller: npt.ArrayLike) -> FloatArray:
    """Polarizance vector ``(M10, M20, M30) / M00`` (Lu & Chipman eq. 10).

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``.

    Returns
    -------
    numpy.ndarray
        ``(..., 3)``; zero where ``M00 = 0``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``M00``.

    References
    ----------
    Lu & Chipman, JOSA A 13, 1106 (1996).
    """
    return _core.polarimetry_polarizance_vector(_f64(mueller))


def depolarization_index(mueller: npt.ArrayLike) -> Any:
    """Gil-Bernabeu depolarization index ``sqrt(sum_ij M_ij^2 - M00^2) / (sqrt(3) M00)``.

    1 for every non-depolarizing matrix (mirror, polarizer, retarder), 0 for the ideal
    depolarizer ``diag(1, 0, 0, 0)``, in ``[0, 1]`` for physical matrices.

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``(...)``; 0 where ``M00 = 0``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``M00``.

    References
    ----------
    Gil & Bernabeu, Optica Acta 33, 185 (1986).
    """
    return _out(_core.polarimetry_depolarization_index(_f64(mueller)))


def linear_depolarization_ratio(mueller: npt.ArrayLike) -> Any:
    """Lidar linear depolarization ratio ``delta_L = (M00 - M11) / (M00 + M11)``.

    Cross- over co-polarized return for linearly polarized input, in the matrix's frame.
    For horizontal input ``(1, 1, 0, 0)`` the co-polarized (horizontal) output intensity is
    ``(M00 + M01 + M10 + M11) / 2`` and the cross-polarized (vertical) one
    ``(M00 + M01 - M10 - M11) / 2``; ``delta_L`` is the ratio of these summed over
    horizontal and vertical input, in which ``M01`` and ``M10`` cancel. Where
    ``M01 = M10 = 0`` (e.g. macroscopically isotropic targets) it is exactly the
    cross/co ratio for horizontal input.

    Mirror ``diag(1, 1, -1, -1)``: 0. Ideal depolarizer ``diag(1, 0, 0, 0)``: 1.

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``(...)``: ``inf`` where ``M00 + M11 = 0`` (no co-polarized return), 0 where
        ``M00 = M11 = 0``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``M00``.
    """
    return _out(_core.polarimetry_linear_depolarization_ratio(_f64(mueller)))


def circular_depolarization_ratio(mueller: npt.ArrayLike) -> Any:
    """Lidar circular depolarization ratio ``delta_C = (M00 + M33) / (M00 - M33)``.

    Cross- over co-polarized return for circularly polarized input. As in lidar usage, the
    co-polarized channel is the one a mirror returns. A mirror at normal incidence is
    ``diag(1, 1, -1, -1)`` here: it flips the sign of ``V``. So for input
    ``(1, 0, 0, +-1)`` the co-polarized intensity is the opposite-``V`` part
    ``(I_out -+ V_out) / 2`` and the cross-polarized one ``(I_out +- V_out) / 2``; summed
    over both handednesses they are ``M00 - M33`` and ``M00 + M33`` (``M03`` and ``M30``
    cancel; where they are 0 the ratio is the same for either handedness).

    Mirror: 0. Ideal depolarizer ``diag(1, 0, 0, 0)``: 1. For backscattering by randomly
    oriented particles, ``M = diag(M00, M11, -M11, M00 - 2 M11)``, it equals
    ``2 delta_L / (1 - delta_L)`` (Mishchenko & Hovenier 1995).

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``(...)``: ``inf`` where ``M00 - M33 = 0`` (e.g. the identity: no co-polarized
        return), 0 where ``M00 = M33 = 0``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``M00``.

    See Also
    --------
    linear_depolarization_ratio : ``delta_L``.

    References
    ----------
    Mishchenko & Hovenier (1995).
    """
    return _out(_core.polarimetry_circular_depolarization_ratio(_f64(mueller)))


def lu_chipman(mueller: npt.ArrayLike) -> Tuple[FloatArray, FloatArray, FloatArray]:
    """Lu-Chipman polar decomposition ``M = M_delta @ M_R @ M_D``.

    ``m_delta = sign(det m') sqrt(m' m'^T)`` (Lu & Chipman's sign rule) from an SVD of
    ``m' = m_delta m_R``; this reconstructs any finite ``M`` with ``D < 1``. Where ``m'`` is
    rank deficient (total or partial depolarizers) ``m_R`` is not unique: for rank 2 we take
    the unique proper rotation, for rank 1 the smallest rotation taking the right singular
    vector to the left one, for rank 0 the identity.

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``.

    Returns
    -------
    M_delta : numpy.ndarray
        ``(..., 4, 4)`` ``[[1, 0], [P_delta, m_delta]]`` with symmetric ``m_delta``: the
        depolarizer.
    M_R : numpy.ndarray
        ``(..., 4, 4)`` ``[[1, 0], [0, m_R]]`` with ``m_R`` a proper rotation: the retarder.
    M_D : numpy.ndarray
        ``(..., 4, 4)`` ``M00 [[1, D^T], [D, m_D]]``,
        ``m_D = sqrt(1 - D^2) I + (1 - sqrt(1 - D^2)) D^ D^^T``: the diattenuator, carrying
        the transmittance ``M00``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``M00``.

    Notes
    -----
    Limits: ``M00 = 0`` gives ``(I, I, 0)``. ``D >= 1 - 1e-11`` (ideal polarizer, ``M_D``
    singular) uses ``M_D``'s ``D -> 1`` limit ``M00 (1, D^)(1, D^)^T``, ``M_R`` the smallest
    rotation taking ``D^`` to ``P^`` (the polarizance direction; identity if ``P = 0``),
    and ``M_delta = diag(1, |P|, |P|, |P|)``; this reconstructs every physical such ``M``.
    Very close to ``D = 1`` the decomposition is ill-conditioned: the reconstruction error
    grows to about ``1e-6`` near ``1 - D = 1e-11``.

    References
    ----------
    Lu & Chipman, JOSA A 13, 1106 (1996).
    """
    d, r, dd = _core.polarimetry_lu_chipman(_f64(mueller))
    return d, r, dd


def retardance(mueller: npt.ArrayLike) -> Any:
    """Total retardance ``R = arccos(tr(M_R) / 2 - 1)`` in ``[0, pi]`` radians.

    ``M_R`` is the retarder of :func:`lu_chipman`. A mirror ``diag(1, 1, -1, -1)`` has
    ``R = pi``.

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``(...)``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``M00``.
    """
    return _out(_core.polarimetry_retardance(_f64(mueller))[0])


def linear_retardance(mueller: npt.ArrayLike) -> Any:
    """Linear retardance ``delta = arccos(sqrt((R11 + R22)^2 + (R21 - R12)^2) - 1)``, radians.

    In ``[0, pi]``, with ``R = M_R`` of :func:`lu_chipman` (Lu & Chipman eq. 25).
    ``M_R = M_LR(delta) @ M_rot(psi)``: a linear retarder after an optical rotator
    (:func:`optical_rotation`).

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``(...)``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``M00``.

    References
    ----------
    Lu & Chipman, JOSA A 13, 1106 (1996).
    """
    return _out(_core.polarimetry_retardance(_f64(mueller))[1])


def optical_rotation(mueller: npt.ArrayLike) -> Any:
    """Optical rotation ``psi = arctan2(R21 - R12, R11 + R22) / 2`` in ``(-pi/2, pi/2]`` radians.

    ``R = M_R`` of :func:`lu_chipman` and ``M_R = M_LR(delta) @ M_rot(psi)``. ``psi > 0``
    turns the polarization ellipse from ``x`` toward ``y`` (Q toward U), so ``M_rot(psi)`` is
    the frame rotator of angle ``-psi``. 0 where ``delta = pi`` (undefined there).

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``.

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``(...)``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``M00``.
    """
    return _out(_core.polarimetry_retardance(_f64(mueller))[2])


def retardance_vector(mueller: npt.ArrayLike) -> FloatArray:
    """Retardance vector ``R a`` of ``M_R`` (Lu & Chipman eq. 20).

    ``a`` is the fast axis on the Poincare sphere, ``(1, 0, 0)`` for a linear retarder with
    its fast axis along ``x``, ``(cos 2t, sin 2t, 0)`` for fast axis at angle ``t``. At
    ``R = pi`` the axis sign is ambiguous; its first non-zero component is made positive.

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``.

    Returns
    -------
    numpy.ndarray
        ``(..., 3)``, radians.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape, a non-finite element or a negative ``M00``.

    References
    ----------
    Lu & Chipman, JOSA A 13, 1106 (1996).
    """
    return _core.polarimetry_retardance(_f64(mueller))[3]


def cloude_eigenvalues(mueller: npt.ArrayLike) -> FloatArray:
    """Eigenvalues, in descending order, of the Cloude coherency matrix.

    ``H = 1/4 sum_ij M_ij kron(sigma_i, conj(sigma_j))``, in the Pauli basis of this package:
    ``sigma_0 = I``, ``sigma_1 = diag(1, -1)``, ``sigma_2 = [[0, 1], [1, 0]]``,
    ``sigma_3 = [[0, 1j], [-1j, 0]]``. For a non-depolarizing matrix from Jones ``J``,
    ``H = vec(J) vec(J)^H / 2`` (row-major ``vec``); the eigenvalues sum to ``M00``. All
    ``>= 0`` means ``M`` is a convex sum of non-depolarizing Mueller matrices (physically
    realizable).

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``, any finite values.

    Returns
    -------
    numpy.ndarray
        ``(..., 4)``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape or a non-finite element.

    References
    ----------
    Cloude, Optik 75, 26 (1986).
    """
    return _core.polarimetry_cloude_eigenvalues(_f64(mueller))


def is_physical(mueller: npt.ArrayLike, tol: float = 1e-9) -> Any:
    """Physical realizability: ``M00 >= 0`` and every Cloude eigenvalue ``>= -tol * M00``.

    The eigenvalues are those of :func:`cloude_eigenvalues`.

    Parameters
    ----------
    mueller : array_like
        Mueller matrices ``(..., 4, 4)``, any finite values.
    tol : float, optional
        Tolerance, finite and ``>= 0``. Default 1e-9.

    Returns
    -------
    numpy.ndarray or numpy.bool_
        bool ``(...)``.

    Raises
    ------
    pprender.Error
        For a wrong trailing shape or a non-finite element.
    """
    return _out(_core.polarimetry_is_physical(_f64(mueller), float(tol)))
