"""Tumbling targets: torque-free rigid-body motion, per-pulse geometry and spin-state fits.

Conventions (every function in this module):

* Attitudes are unit quaternions ``(w, x, y, z)``, scalar first (:mod:`pprender.inverse.so3`).
  ``q`` rotates the **body** frame into the **inertial** frame, ``p_in = R(q) p_body``; the
  renderer's attitudes rotate the body into the **telescope** frame, ``p_tel = R p_body``
  (``pprender.lidar``), so a render attitude is ``T q`` with ``T`` the inertial-to-telescope
  rotation of :func:`pulse_geometry` (``Z`` the line of sight from the target toward the
  sensor).
* The body frame is the principal-axis frame: the inertia tensor is ``diag(I1, I2, I3)``
  (only ratios matter). A mesh whose principal axes are not its coordinate axes must be
  rotated into them first (``trimesh``'s ``principal_inertia_transform``).
* Angular velocities: ``omega`` in the body frame (rad/s) for the rigid-body state; a
  principal-axis spin is ``rate`` (rad/s, signed) about an inertial unit ``axis``, i.e. the
  inertial angular-velocity vector ``rate * axis``.
* Times are seconds, strictly increasing where a sequence is asked for.

Torque-free motion (:func:`propagate`): Euler's equations ``I w' = (I w) x w`` and the
kinematics ``q' = q (0, w) / 2`` integrated together by scipy's DOP853 (8th order) at
``rtol = 1e-12``; the quaternions returned are renormalized (the integrator keeps
``|q| = 1`` to ~1e-12). Why not the closed form: Jacobi's elliptic functions give ``w(t)``
but the attitude needs an elliptic integral of the third kind (or theta functions) whose
branches are delicate near separatrices and symmetric bodies; the integrator handles
every case (long- and short-axis modes, symmetric tops, pure spins) with one code path,
and the tests check it against the closed forms it did not come from (``tests/test_tumble.py``:
Jacobi ``w(t)``, the symmetric-top precession, pure spin, energy and inertial angular
momentum conserved to 1e-9 over 100 periods).

Per-pulse geometry (:func:`pulse_geometry`): light time and velocity aberration.

* Light time: the pulse sent at ``t_tx`` reaches the target at ``t_r = t_tx + dt`` with
  ``|r + v dt| = c dt``, ``r`` and ``v`` the target's position and velocity relative to
  the sensor at ``t_tx`` (solved exactly; using the relative rather than the target's
  inertial velocity changes ``dt`` by ~``|v_sensor| R / c^2``, 1e-8 s for a ground
  station at 2000 km). The attitude is taken at ``t_r``.
* Aberration: in the target's rest frame the light arrives from the sensor's position at
  ``t_tx`` and must leave toward its position at ``t_tx + 2 dt``, both aberrated: to first
  order in ``v / c`` the transmit and receive directions differ by the point-ahead angle
  ``2 |v_perp| / c`` (``v_perp`` the relative velocity across the line of sight: 5e-5 rad
  in LEO at 7.5 km/s) and their bisector is the geometric line of sight at ``t_r``,
  ``-(r + v dt) / |r + v dt|``. The renderer's monostatic model (``wi = wo = Z``) puts
  ``Z`` on that bisector, which is what this module does; the residual is a bistatic angle
  of ``point_ahead`` (returned per pulse) that ``Lidar(bistatic_angle=...)`` could render
  but that changes a profile far below its noise (5e-5 rad is 0.003 deg of attitude).
* Telescope roll: ``Y`` is ``up`` (default inertial ``+z``) projected across the line of
  sight, ``X = Y x Z``: the polarization reference of an instrument whose analyzers are
  fixed to an alt-az mount with ``up`` the local zenith.

Spin-state fits (:func:`fit_spin`): principal-axis spin, 4 parameters ``(axis polar angle,
axis azimuth, rate, phase)`` (:func:`principal_spin`), and general tumbling, 8 parameters
``(rotation vector of q0 (3), omega0 (3, body), I1/I3, I2/I3)`` (:func:`tumbling_spin`);
the Poisson log-likelihood summed over pulses is maximized by nlopt from a multi-start
grid (the likelihood is very multimodal in the rate).

Example (a tumbling target's renders, one per pulse)::

    from pprender.inverse import tumble
    g = tumble.pulse_geometry(t_tx, rel_position, rel_velocity)   # (T,), (T, 3), (T, 3)
    q, omega = tumble.propagate(q0, omega0, (1.0, 1.4, 2.0), g.reflect_times)
    res = pprender.render(scene, sensor, g.attitudes(q), outputs=("profile",))

What a monostatic profile cannot see (scored by :func:`spin_error`):

* ``q`` and ``-q`` (one rotation);
* a half turn about the line of sight: it rotates every Stokes basis by ``pi``, i.e. the
  Mueller rotation by ``2 pi``, the identity, so the profile is unchanged and a spin about
  ``a`` is indistinguishable from one about ``a`` turned by ``pi`` about the line of sight;
* the axis sign with the rate sign: ``(a, rate)`` and ``(-a, -rate)`` are the same
  angular-velocity vector (the body is turned over, which a target symmetric under that
  turn cannot show); scoring compares angular-velocity vectors, so this is built in;
* the target's own symmetry group ``S`` (``q`` and ``q s``, ``s`` in ``S``): it changes
  the phase, never the angular-velocity vector;
* for profiles that do not depend on the roll about the line of sight (intensity only, or a
  convex single-bounce target, whose monostatic microfacet backscatter is Fresnel at normal
  incidence and so roll-invariant): any rotation about the line of sight, leaving only the
  angle between axis and line of sight (``roll_invariant=True``); a mirror-symmetric
  target seen in intensity also cannot tell ``omega`` from ``-omega``
  (``reversible=True``).

A moving line of sight (a pass: :func:`pulse_geometry` with the positions along it) sees
the rotations about any one line of sight, which no longer map the geometry onto itself.
What remains, when the lines of sight lie in one plane (normal ``n``, e.g. a short pass),
for a target with a mirror plane and a profile that is roll invariant and its own mirror
image (intensity only, or the convex single-bounce ``sigma diag(1, 1, -1, -1)``; a mirror
flips the signs of ``U`` and ``V``): the motion reflected across that plane with the body
reflected across its own mirror plane shows the same body-frame lines of sight and
profiles, and its angular velocity is ``rot(n, pi) omega``: score with
``spin_error(..., line_of_sight=n)`` (``scripts/spin_recovery.py --sweep``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy.integrate import solve_ivp
from scipy.special import gammaln, xlogy

from .._core import Error
from ..lidar import SPEED_OF_LIGHT
from .so3 import _quaternions

__all__ = [
    "PulseGeometry",
    "SpinFit",
    "check_inertia",
    "fit_spin",
    "principal_spin",
    "propagate",
    "pulse_geometry",
    "quaternion_multiply",
    "spin_error",
    "tumbling_spin",
    "tumbling_start",
]


# ---------------------------------------------------------------------- quaternions


def quaternion_multiply(a: Any, b: Any) -> np.ndarray:
    """Hamilton product ``a b`` of ``(w, x, y, z)`` quaternions, broadcast over leading axes.

    ``R(a b) = R(a) R(b)``: apply ``b`` first, then ``a``.

    Parameters
    ----------
    a, b : array_like
        (..., 4) quaternions (any norm; not checked).

    Returns
    -------
    numpy.ndarray
        (..., 4) the product.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def _axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions of rotations by ``angle`` about unit ``axis`` (broadcast)."""
    h = 0.5 * np.asarray(angle, dtype=np.float64)
    return np.concatenate([np.cos(h)[..., None], np.sin(h)[..., None] * axis], axis=-1)


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``R(q) v`` for unit quaternions (broadcast)."""
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _rotvec_to_quat(r: np.ndarray) -> np.ndarray:
    r = np.asarray(r, dtype=np.float64)
    ang = np.linalg.norm(r, axis=-1)
    h = 0.5 * ang
    # sin(h) / ang -> 1/2 as ang -> 0
    s = np.where(ang > 1e-8, np.sin(h) / np.where(ang > 1e-8, ang, 1.0), 0.5 - ang * ang / 48.0)
    return np.concatenate([np.cos(h)[..., None], s[..., None] * r], axis=-1)


def _quat_to_rotvec(q: np.ndarray) -> np.ndarray:
    q = np.where(q[..., :1] < 0, -q, q)
    s = np.linalg.norm(q[..., 1:], axis=-1)
    ang = 2.0 * np.arctan2(s, q[..., 0])
    f = np.where(s > 1e-12, ang / np.where(s > 1e-12, s, 1.0), 2.0)
    return f[..., None] * q[..., 1:]


def _align(e: np.ndarray, a: np.ndarray) -> np.ndarray:
    """(..., 4) the smallest rotation taking unit ``e`` to unit ``a``; a half turn about an
    axis perpendicular to ``e`` (the first of x, y farther from ``e``) when ``a = -e``."""
    a = np.asarray(a, dtype=np.float64)
    e = np.broadcast_to(np.asarray(e, dtype=np.float64), a.shape)
    d = np.sum(e * a, axis=-1)
    c = np.cross(e, a)
    q = np.concatenate([(1.0 + d)[..., None], c], axis=-1)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    anti = n[..., 0] < 1e-9
    if np.any(anti):
        ref = np.where(np.abs(e[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
        perp = np.cross(e, ref)
        perp /= np.linalg.norm(perp, axis=-1, keepdims=True)
        half = np.concatenate([np.zeros(a.shape[:-1] + (1,)), perp], axis=-1)
        q = np.where(anti[..., None], half, q)
        n = np.where(anti[..., None], 1.0, n)
    return q / n


# ---------------------------------------------------------------------- validation


def _vector3(value: Any, name: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise Error(f"invalid {name}: not a 3-vector of numbers") from None
    if v.shape != (3,):
        raise Error(f"invalid {name}: shape {v.shape}, expected (3,)")
    if not np.all(np.isfinite(v)):
        raise Error(f"invalid {name}: non-finite components, expected finite numbers")
    return v


def _times(value: Any, name: str = "times") -> np.ndarray:
    try:
        t = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise Error(f"invalid {name}: not an array of numbers (s)") from None
    if t.ndim != 1 or t.size == 0:
        raise Error(f"invalid {name}: shape {t.shape}, expected a non-empty 1-D array (s)")
    if not np.all(np.isfinite(t)):
        raise Error(f"invalid {name}: non-finite values, expected finite seconds")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise Error(f"invalid {name}: must be strictly increasing (s)")
    return t


def check_inertia(inertia: Any) -> np.ndarray:
    """Validate principal moments of inertia; only their ratios matter.

    Parameters
    ----------
    inertia : array_like
        ``(I1, I2, I3)``: finite, > 0, and each at most the sum of the other two (the
        triangle inequality every physical body satisfies; equality is a flat plate),
        within 1e-12 relative.

    Returns
    -------
    numpy.ndarray
        (3,) float64 moments, as given.

    Raises
    ------
    pprender.Error
        Naming ``inertia`` and the violated range.
    """
    i = _vector3(inertia, "inertia")
    if np.any(i <= 0):
        raise Error(f"invalid inertia = {i.tolist()}: principal moments must be > 0")
    s = float(np.sum(i))
    for k in range(3):
        if i[k] > s - i[k] + 1e-12 * s:
            raise Error(
                f"invalid inertia = {i.tolist()}: I{k + 1} exceeds the sum of the other two (the triangle "
                f"inequality I1 + I2 >= I3, for every order, holds for every physical body)"
            )
    return i


def _unit_quaternion(q: Any, name: str) -> np.ndarray:
    a = _quaternions(q, name)
    if a.shape != (4,):
        raise Error(f"invalid {name}: shape {a.shape}, expected one quaternion (4,) (w, x, y, z)")
    return a


# ---------------------------------------------------------------------- propagation


def _euler_rhs(inertia: np.ndarray) -> Callable[[float, np.ndarray], np.ndarray]:
    i1, i2, i3 = inertia
    c1, c2, c3 = (i2 - i3) / i1, (i3 - i1) / i2, (i1 - i2) / i3

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        qw, qx, qy, qz, w1, w2, w3 = y
        return np.array(
            [
                0.5 * (-qx * w1 - qy * w2 - qz * w3),
                0.5 * (qw * w1 + qy * w3 - qz * w2),
                0.5 * (qw * w2 - qx * w3 + qz * w1),
                0.5 * (qw * w3 + qx * w2 - qy * w1),
                c1 * w2 * w3,
                c2 * w3 * w1,
                c3 * w1 * w2,
            ]
        )

    return rhs


def propagate(
    q0: Any,
    omega0: Any,
    inertia: Any,
    times: Any,
    *,
    t0: float = 0.0,
    rtol: float = 1e-12,
    atol: float = 1e-14,
) -> tuple[np.ndarray, np.ndarray]:
    """Torque-free rigid-body attitude and angular velocity at ``times``.

    Euler's equations and the quaternion kinematics integrated by DOP853 (module
    docstring); every regime (pure spin, symmetric precession, long- and short-axis
    tumbling) goes through the same integrator. Times before ``t0`` are integrated
    backward.

    Parameters
    ----------
    q0 : array_like or scipy.spatial.transform.Rotation
        (4,) unit quaternion ``(w, x, y, z)`` at ``t0``: body to inertial.
    omega0 : array_like
        (3,) angular velocity at ``t0`` in the body (principal) frame, rad/s; finite.
    inertia : array_like
        (3,) principal moments (any unit; :func:`check_inertia`).
    times : array_like
        (T,) strictly increasing times (s).
    t0 : float, optional
        The epoch of ``q0`` and ``omega0`` (s). Default 0.
    rtol, atol : float, optional
        DOP853 tolerances (default 1e-12 and 1e-14); ``rtol`` in [1e-14, 1e-3].

    Returns
    -------
    q : numpy.ndarray
        (T, 4) unit quaternions (body to inertial), renormalized.
    omega : numpy.ndarray
        (T, 3) body-frame angular velocities (rad/s).

    Raises
    ------
    pprender.Error
        For a non-unit ``q0``, a non-finite ``omega0``, an invalid ``inertia``, times that
        are not finite and strictly increasing, a non-finite ``t0`` or tolerances out of range.
    """
    q = _unit_quaternion(q0, "q0")
    w = _vector3(omega0, "omega0")
    inert = check_inertia(inertia)
    t = _times(times)
    if not math.isfinite(float(t0)):
        raise Error(f"invalid t0 = {t0!r}: a finite time (s)")
    if not (1e-14 <= float(rtol) <= 1e-3) or not (0 < float(atol) <= 1e-3):
        raise Error(f"invalid rtol/atol = {rtol!r}/{atol!r}: rtol in [1e-14, 1e-3], atol in (0, 1e-3]")
    y0 = np.concatenate([q, w])
    rhs = _euler_rhs(inert)
    out = np.empty((t.size, 7))
    for mask in (t >= t0, t < t0):
        ts = t[mask]
        if ts.size == 0:
            continue
        order = np.argsort(np.abs(ts - t0))
        ts_sorted = ts[order]
        if np.all(ts_sorted == t0):
            res_y = np.repeat(y0[:, None], ts.size, axis=1)
        else:
            end = float(ts_sorted[-1])
            sol = solve_ivp(rhs, (float(t0), end), y0, method="DOP853", t_eval=ts_sorted, rtol=rtol, atol=atol)
            if not sol.success:  # pragma: no cover - DOP853 on a smooth bounded system
                raise Error(f"propagation failed: {sol.message}")
            res_y = sol.y
        block = np.empty((ts.size, 7))
        block[order] = res_y.T
        out[mask] = block
    qs = out[:, :4]
    qs /= np.linalg.norm(qs, axis=-1, keepdims=True)
    return qs, out[:, 4:]


# ---------------------------------------------------------------------- spin models


def _axis_from_angles(polar: Any, azimuth: Any) -> np.ndarray:
    polar = np.asarray(polar, dtype=np.float64)
    azimuth = np.asarray(azimuth, dtype=np.float64)
    s = np.sin(polar)
    return np.stack([s * np.cos(azimuth), s * np.sin(azimuth), np.cos(polar)], axis=-1)


def principal_spin(params: Any, times: Any, *, body_axis: int = 2) -> np.ndarray:
    """Attitudes of a principal-axis spin: 4 parameters ``(polar, azimuth, rate, phase)``.

    The body's principal axis ``body_axis`` lies along the inertial unit axis ``a`` (polar
    angle from inertial ``+z``, azimuth from ``+x`` toward ``+y``, rad) and the body turns
    about it at ``rate`` (rad/s, signed): ``q(t) = rot(a, phase + rate t) align(e, a)``,
    ``align`` the smallest rotation taking the body axis ``e`` onto ``a``. A spin about a
    principal axis is torque-free motion (:func:`propagate` with ``omega0`` along that
    axis gives the same attitudes); physically stable about the largest or smallest moment.

    Parameters
    ----------
    params : array_like
        (..., 4) ``(polar, azimuth, rate, phase)``; a leading batch broadcasts.
    times : array_like
        (T,) strictly increasing times (s).
    body_axis : int, optional
        0, 1 or 2: the principal axis the body spins about. Default 2 (``z``).

    Returns
    -------
    numpy.ndarray
        (..., T, 4) unit quaternions, body to inertial.

    Raises
    ------
    pprender.Error
        For non-finite parameters, a last axis not of length 4, invalid times or
        ``body_axis``.
    """
    p = np.asarray(params, dtype=np.float64)
    if p.ndim == 0 or p.shape[-1] != 4 or not np.all(np.isfinite(p)):
        raise Error(f"invalid params: shape {p.shape}, expected finite (..., 4) (polar, azimuth, rate, phase)")
    if body_axis not in (0, 1, 2) or isinstance(body_axis, bool):
        raise Error(f"invalid body_axis = {body_axis!r}: 0, 1 or 2")
    t = _times(times)
    return _principal(p, t, body_axis)


def _principal(p: np.ndarray, t: np.ndarray, body_axis: int) -> np.ndarray:
    a = _axis_from_angles(p[..., 0], p[..., 1])
    e = np.zeros(3)
    e[body_axis] = 1.0
    q_align = _align(e, a)  # (..., 4)
    ang = p[..., 3, None] + p[..., 2, None] * t  # (..., T)
    q_spin = _axis_angle(a[..., None, :], ang)  # (..., T, 4)
    return quaternion_multiply(q_spin, q_align[..., None, :])


def tumbling_spin(params: Any, times: Any, *, t0: float = 0.0, rtol: float = 1e-10) -> np.ndarray:
    """Attitudes of general torque-free tumbling: 8 parameters.

    ``params = (r1, r2, r3, w1, w2, w3, k1, k2)``: the rotation vector of ``q0`` (rad,
    body to inertial at ``t0``), the body-frame angular velocity ``omega0`` (rad/s) and the
    inertia ratios ``k1 = I1 / I3``, ``k2 = I2 / I3`` (:func:`propagate`).

    Parameters
    ----------
    params : array_like
        (8,) the parameters.
    times : array_like
        (T,) strictly increasing times (s).
    t0 : float, optional
        Epoch of ``q0`` and ``omega0`` (s). Default 0.
    rtol : float, optional
        Integration tolerance (default 1e-10: ample for fitting).

    Returns
    -------
    numpy.ndarray
        (T, 4) unit quaternions, body to inertial.

    Raises
    ------
    pprender.Error
        For a shape other than (8,), non-finite values, inertia ratios that are not > 0 or
        violate the triangle inequality, or invalid times.
    """
    p = np.asarray(params, dtype=np.float64)
    if p.shape != (8,) or not np.all(np.isfinite(p)):
        raise Error(f"invalid params: shape {p.shape}, expected 8 finite numbers (rotvec, omega0, I1/I3, I2/I3)")
    q0 = _rotvec_to_quat(p[:3])
    q, _ = propagate(q0, p[3:6], (p[6], p[7], 1.0), times, t0=t0, rtol=rtol, atol=rtol * 1e-2)
    return q


def tumbling_start(principal_params: Any, inertia_ratios: Any, *, body_axis: int = 2) -> np.ndarray:
    """The 8 tumbling parameters of a principal-axis spin: a start for a tumbling fit.

    A spin about a principal axis is torque-free motion for any inertia, so
    :func:`tumbling_spin` of the result gives the attitudes of :func:`principal_spin`
    ``(principal_params, times)`` (for ``t0 = 0``); a tumbling fit started there (with a
    few ``inertia_ratios``, or ``omega0`` nudged off the axis) explores tumbles near a
    principal-axis fit.

    Parameters
    ----------
    principal_params : array_like
        (4,) ``(polar, azimuth, rate, phase)`` (:func:`principal_spin`).
    inertia_ratios : array_like
        (2,) ``(I1 / I3, I2 / I3)``, > 0, satisfying the triangle inequality.
    body_axis : int, optional
        The spin's principal axis (0, 1, 2). Default 2.

    Returns
    -------
    numpy.ndarray
        (8,) ``(rotation vector of q0, omega0, I1 / I3, I2 / I3)``.

    Raises
    ------
    pprender.Error
        For parameters that are not finite (4,), invalid ratios or ``body_axis``.
    """
    p = np.asarray(principal_params, dtype=np.float64)
    if p.shape != (4,) or not np.all(np.isfinite(p)):
        raise Error(f"invalid principal_params: shape {p.shape}, expected 4 finite numbers")
    k = np.asarray(inertia_ratios, dtype=np.float64)
    if k.shape != (2,):
        raise Error(f"invalid inertia_ratios: shape {k.shape}, expected (I1 / I3, I2 / I3)")
    try:
        check_inertia([k[0], k[1], 1.0])
    except Error as e:
        raise Error(f"invalid inertia_ratios = {k.tolist()}: {str(e).split(': ', 1)[-1]}") from None
    q0 = principal_spin(p, [0.0], body_axis=body_axis)[0]
    omega0 = np.zeros(3)
    omega0[body_axis] = p[2]
    return np.concatenate([_quat_to_rotvec(q0), omega0, k])


# ---------------------------------------------------------------------- geometry


@dataclass
class PulseGeometry:
    """Per-pulse observation geometry made by :func:`pulse_geometry`.

    Attributes
    ----------
    transmit_times : numpy.ndarray
        (T,) pulse transmit times (s).
    reflect_times : numpy.ndarray
        (T,) times the pulses reach the target (s): the attitudes to render are at these.
    range_m : numpy.ndarray
        (T,) sensor-to-target distance at ``reflect_times`` (m).
    line_of_sight : numpy.ndarray
        (T, 3) inertial unit vectors from the target toward the sensor at ``reflect_times``
        (the monostatic bisector; module docstring).
    telescope : numpy.ndarray
        (T, 4) quaternions rotating inertial into telescope coordinates (``Z`` the line of
        sight, ``Y`` along ``up`` projected).
    point_ahead : numpy.ndarray
        (T,) angle between the transmit and receive directions in the target's frame,
        ``2 |v_perp| / c`` (rad), not rendered (module docstring).
    """

    transmit_times: np.ndarray
    reflect_times: np.ndarray
    range_m: np.ndarray
    line_of_sight: np.ndarray
    telescope: np.ndarray
    point_ahead: np.ndarray

    def attitudes(self, q_inertial: Any) -> np.ndarray:
        """Render attitudes (body to telescope) from body-to-inertial attitudes at ``reflect_times``.

        Parameters
        ----------
        q_inertial : array_like
            (..., T, 4) unit quaternions, body to inertial, one per pulse.

        Returns
        -------
        numpy.ndarray
            (..., T, 4) quaternions for ``pprender.render(..., attitudes=...)``.
        """
        return quaternion_multiply(self.telescope, np.asarray(q_inertial, dtype=np.float64))


def _telescope(los: np.ndarray, up: np.ndarray) -> np.ndarray:
    y = up - np.sum(up * los, axis=-1, keepdims=True) * los
    n = np.linalg.norm(y, axis=-1, keepdims=True)
    if np.any(n < 1e-6):
        raise Error("invalid up: parallel to the line of sight (within 1e-6 rad); choose another reference")
    y = y / n
    x = np.cross(y, los)
    # rows of the inertial -> telescope matrix are X, Y, Z in inertial coordinates
    m = np.stack([x, y, los], axis=-2)
    from scipy.spatial.transform import Rotation

    return np.asarray(Rotation.from_matrix(m).as_quat(scalar_first=True))


def pulse_geometry(
    transmit_times: Any,
    relative_position: Any,
    relative_velocity: Any = None,
    *,
    up: Any = (0.0, 0.0, 1.0),
) -> PulseGeometry:
    """Light time, line of sight and telescope frame per pulse (module docstring).

    Parameters
    ----------
    transmit_times : array_like
        (T,) strictly increasing pulse transmit times (s).
    relative_position : array_like
        (T, 3) or (3,) position of the target relative to the sensor at each transmit time,
        inertial (m); a norm in (0, 1e10] m.
    relative_velocity : array_like, optional
        (T, 3) or (3,) velocity of the target relative to the sensor (m/s), each below
        ``c / 10``; default zero.
    up : array_like, optional
        (3,) inertial reference for the telescope's ``Y`` axis (default ``+z``).

    Returns
    -------
    PulseGeometry
        Reflection times, ranges, lines of sight, telescope rotations and point-ahead angles.

    Raises
    ------
    pprender.Error
        For invalid times, positions or velocities of the wrong shape or out of range, or
        ``up`` along a line of sight.
    """
    t = _times(transmit_times, "transmit_times")
    n = t.size

    def per_pulse(value: Any, name: str) -> np.ndarray:
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise Error(f"invalid {name}: not an array of numbers") from None
        if a.shape == (3,):
            a = np.broadcast_to(a, (n, 3))
        if a.shape != (n, 3) or not np.all(np.isfinite(a)):
            raise Error(f"invalid {name}: shape {a.shape}, expected finite (3,) or ({n}, 3)")
        return a

    r = per_pulse(relative_position, "relative_position")
    v = np.zeros((n, 3)) if relative_velocity is None else per_pulse(relative_velocity, "relative_velocity")
    u = _vector3(up, "up")
    rn = np.linalg.norm(r, axis=-1)
    if np.any(rn <= 0) or np.any(rn > 1e10):
        raise Error("invalid relative_position: distances must be in (0, 1e10] m")
    c = SPEED_OF_LIGHT
    vv = np.sum(v * v, axis=-1)
    if np.any(vv >= (0.1 * c) ** 2):
        raise Error("invalid relative_velocity: speeds must be below c / 10")
    # |r + v dt| = c dt: (c^2 - v^2) dt^2 - 2 (r.v) dt - |r|^2 = 0, positive root
    rv = np.sum(r * v, axis=-1)
    a2 = c * c - vv
    dt = (rv + np.sqrt(rv * rv + a2 * rn * rn)) / a2
    p = r + v * dt[:, None]
    rng = np.linalg.norm(p, axis=-1)
    los = -p / rng[:, None]
    v_perp = v - np.sum(v * los, axis=-1, keepdims=True) * los
    return PulseGeometry(
        transmit_times=t.copy(),
        reflect_times=t + dt,
        range_m=rng,
        line_of_sight=los,
        telescope=_telescope(los, np.broadcast_to(u, (n, 3))),
        point_ahead=2.0 * np.linalg.norm(v_perp, axis=-1) / c,
    )


# ---------------------------------------------------------------------- scoring


def spin_error(
    omega_true: Any,
    omega_fit: Any,
    *,
    line_of_sight: Any = (0.0, 0.0, 1.0),
    roll_invariant: bool = False,
    reversible: bool = False,
) -> tuple[float, float]:
    """Axis error (deg) and relative rate error of a spin, modulo what a monostatic profile cannot see.

    Spins are compared as inertial angular-velocity vectors ``rate * axis`` (so ``(a, rate)``
    and ``(-a, -rate)`` are one spin; a target's own symmetries only shift the phase).
    The axis error is the smallest angle between ``omega_fit`` and an image of
    ``omega_true`` under the invisible symmetries (module docstring): a half turn about
    ``line_of_sight`` always; every rotation about it when ``roll_invariant`` (then only
    the angles to the line of sight are compared); and ``omega -> -omega`` when
    ``reversible``.

    Parameters
    ----------
    omega_true, omega_fit : array_like
        (3,) inertial angular-velocity vectors (rad/s), non-zero.
    line_of_sight : array_like, optional
        (3,) inertial line of sight (any norm > 0); default ``+z`` (inertial = telescope).
    roll_invariant : bool, optional
        The profile does not depend on the roll about the line of sight. Default False.
    reversible : bool, optional
        ``omega`` and ``-omega`` give the same profiles. Default False.

    Returns
    -------
    tuple of float
        ``(axis_error_deg, |rate_fit - rate_true| / rate_true)`` with rates the norms.

    Raises
    ------
    pprender.Error
        For vectors that are not finite (3,) and non-zero.
    """
    wt = _vector3(omega_true, "omega_true")
    wf = _vector3(omega_fit, "omega_fit")
    los = _vector3(line_of_sight, "line_of_sight")
    nt, nf, nl = (float(np.linalg.norm(x)) for x in (wt, wf, los))
    if nt == 0 or nf == 0 or nl == 0:
        raise Error("invalid omega_true/omega_fit/line_of_sight: must be non-zero vectors")
    at, af, z = wt / nt, wf / nf, los / nl
    signs = (1.0, -1.0) if reversible else (1.0,)
    best = math.pi
    for s in signs:
        a = s * at
        if roll_invariant:
            d = abs(math.acos(np.clip(a @ z, -1, 1)) - math.acos(np.clip(af @ z, -1, 1)))
        else:
            half = 2.0 * (a @ z) * z - a  # rot(z, pi) a
            d = min(math.acos(np.clip(b @ af, -1, 1)) for b in (a, half))
        best = min(best, d)
    return math.degrees(best), abs(nf - nt) / nt


# ---------------------------------------------------------------------- fitting


@dataclass
class SpinFit:
    """What :func:`fit_spin` returns.

    Attributes
    ----------
    model : str
        ``"principal"`` or ``"tumbling"``.
    params : numpy.ndarray
        The best parameters (4 or 8; :func:`principal_spin`, :func:`tumbling_spin`).
    log_likelihood : float
        The Poisson log-likelihood at ``params``, summed over pulses.
    omega : numpy.ndarray
        (3,) inertial angular velocity ``rate * axis`` (principal) or the initial one,
        ``R(q0) omega0`` (tumbling), rad/s: what :func:`spin_error` compares.
    starts : int
        Local optimizations run.
    evaluations : int
        Likelihood evaluations (grid and local).
    seconds : float
        Wall time.
    candidates : numpy.ndarray
        (K, P) the local optima, best first.
    candidate_log_likelihoods : numpy.ndarray
        (K,) their log-likelihoods.
    """

    model: str
    params: np.ndarray
    log_likelihood: float
    omega: np.ndarray
    starts: int
    evaluations: int
    seconds: float
    candidates: np.ndarray = field(repr=False)
    candidate_log_likelihoods: np.ndarray = field(repr=False)


def _counts(data: Any) -> np.ndarray:
    if isinstance(data, (list, tuple)) and data and all(hasattr(m, "counts") for m in data):
        data = np.stack([np.asarray(m.counts) for m in data])
    elif hasattr(data, "counts"):
        data = data.counts
    try:
        k = np.asarray(data)
    except (TypeError, ValueError):
        raise Error("invalid counts: not an array of numbers") from None
    if k.dtype == object or not (np.issubdtype(k.dtype, np.integer) or np.issubdtype(k.dtype, np.floating)):
        raise Error(f"invalid counts: dtype {k.dtype}, expected integers")
    k = k.astype(np.float64)
    if k.ndim < 2 or not np.all(np.isfinite(k)) or np.any(k < 0) or np.any(k != np.round(k)):
        raise Error(f"invalid counts: shape {k.shape}; expected (T, ...) finite non-negative integers")
    return k


class _Likelihood:
    def __init__(self, counts: np.ndarray, forward: Callable[[np.ndarray], Any], geometry: PulseGeometry | None):
        self.k = counts
        self.lgk = float(np.sum(gammaln(counts + 1.0)))
        self.forward = forward
        self.geometry = geometry
        self.evaluations = 0

    def __call__(self, q_inertial: np.ndarray) -> np.ndarray:
        """(K,) log-likelihoods of K candidate attitude sequences (K, T, 4)."""
        kq = q_inertial if self.geometry is None else self.geometry.attitudes(q_inertial)
        k_count, t_count = kq.shape[0], kq.shape[1]
        lam = np.asarray(self.forward(kq.reshape(-1, 4)), dtype=np.float64)
        if lam.shape[0] != k_count * t_count:
            raise Error(f"invalid forward: returned shape {lam.shape} for {k_count * t_count} attitudes")
        lam = lam.reshape((k_count,) + self.k.shape)
        if not np.all(np.isfinite(lam)) or np.any(lam < 0):
            raise Error("invalid forward: expected counts must be finite and >= 0")
        self.evaluations += k_count
        axes = tuple(range(1, lam.ndim))
        return np.sum(xlogy(self.k, lam) - lam, axis=axes) - self.lgk


def _fibonacci_sphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = math.pi * (3.0 - math.sqrt(5.0)) * i
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=-1)


def _positive_int(value: Any, name: str, lo: int = 1, hi: int = 10_000_000) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= int(value) <= hi:
        raise Error(f"invalid {name} = {value!r}: an integer in [{lo}, {hi}]")
    return int(value)


def _spin_angle_grid(
    like: "_Likelihood",
    polar: np.ndarray,
    azim: np.ndarray,
    rates: np.ndarray,
    phases: np.ndarray,
    t: np.ndarray,
    body_axis: int,
    n_angles: int,
    n_starts: int,
    batch: int,
    telescope: np.ndarray | None = None,
) -> np.ndarray:
    """Best (rate, phase) grid point of each of the ``n_starts`` best axes, (S, 4).

    For axis ``a`` the attitude at pulse ``t`` depends on the spin angle
    ``alpha = phase + rate t`` only (and, with a ``telescope`` rotation per pulse, on the
    pulse): the expected counts ``lam[t, alpha]`` are tabulated once at ``n_angles``
    angles (once for all pulses without a telescope, per pulse with one); a candidate's
    pulse ``t`` reads the angle nearest ``phase + rate t``, so its log-likelihood is
    ``sum_t G[t, i_t]`` with ``G[t, i] = k_t . log(lam[t, i]) - sum lam[t, i]``.
    """
    alpha = np.arange(n_angles) * 2.0 * math.pi / n_angles
    k = like.k.reshape(t.size, -1)
    ang = phases[None, :, None] + rates[:, None, None] * t[None, None, :]  # (R, P, T)
    idx = np.rint(ang / (2.0 * math.pi / n_angles)).astype(np.int64) % n_angles
    rows = np.arange(t.size)
    # about batch * T forward evaluations per call, as the candidate-by-candidate grid
    per_call = batch * t.size
    n_pulse = 1 if telescope is None else t.size
    per_axis = max(1, per_call // (n_angles * n_pulse))
    best = []
    for i0 in range(0, polar.size, per_axis):
        p = np.column_stack([polar[i0 : i0 + per_axis], azim[i0 : i0 + per_axis]])
        p = np.column_stack([p, np.ones(len(p)), np.zeros(len(p))])
        q = _principal(p, alpha, body_axis)  # (A, n_angles, 4)
        if telescope is not None:
            q = quaternion_multiply(telescope[None, None, :, :], q[:, :, None, :])  # (A, n_angles, T, 4)
        q = q.reshape(-1, 4)
        lam = np.concatenate(
            [np.asarray(like.forward(q[i : i + per_call]), dtype=np.float64) for i in range(0, q.shape[0], per_call)]
        )
        lam = lam.reshape(len(p), n_angles, n_pulse, -1)
        if lam.shape[-1] != k.shape[1] or not np.all(np.isfinite(lam)) or np.any(lam < 0):
            raise Error("invalid forward: expected counts of the wrong shape, non-finite or < 0")
        like.evaluations += len(p) * n_angles  # per pulse: one candidate's worth of T attitudes per angle
        for j in range(len(p)):
            log_lam = xlogy(1.0, np.maximum(lam[j], 1e-300))  # (n_angles, n_pulse, C); log(0) guarded
            if telescope is None:
                g = k @ log_lam[:, 0, :].T  # (T, n_angles)
            else:
                g = np.einsum("tc,atc->ta", k, log_lam)
            g = np.where(np.isfinite(g), g, -1e300) - lam[j].sum(axis=-1).T  # (T, n_angles)
            ll = g[rows, idx].sum(axis=-1)  # (R, P)
            r, ph = np.unravel_index(int(np.argmax(ll)), ll.shape)
            best.append((float(ll[r, ph]) - like.lgk, p[j, 0], p[j, 1], rates[r], phases[ph]))
    best.sort(key=lambda b: -b[0])
    return np.array([b[1:] for b in best[:n_starts]])


def fit_spin(
    data: Any,
    forward: Callable[[np.ndarray], Any],
    times: Any,
    *,
    model: str = "principal",
    geometry: PulseGeometry | None = None,
    rate_bounds: tuple[float, float] | None = None,
    body_axis: int = 2,
    n_axes: int = 200,
    axes: Any = None,
    n_rates: int = 32,
    n_phases: int = 12,
    n_angles: int = 360,
    n_starts: int = 8,
    starts: Any = None,
    max_evals: int = 2000,
    batch: int = 256,
) -> SpinFit:
    """Fit a spin state to a sequence of noisy pulse measurements by maximum likelihood.

    The Poisson log-likelihood ``sum_t sum [k log(lam) - lam - log(k!)]`` of the counts of
    every pulse is maximized over the spin parameters. Principal-axis spin: every point of
    a grid of ``n_axes`` axes (a Fibonacci sphere) x ``n_rates`` rates (uniform in
    ``rate_bounds``) x ``n_phases`` phases is evaluated, then nlopt's BOBYQA refines the
    best grid point of each of the ``n_starts`` best axes; the grid spacing in rate should
    keep the phase error at the last pulse below ~1 rad
    (``(rate_max - rate_min) * duration / n_rates <~ 1``). For one axis the attitude of a
    principal-axis spin at a pulse depends on ``phase + rate t`` only, so the grid stage
    tabulates each axis's expected counts at ``n_angles`` spin angles and reads every
    (rate, phase) candidate's pulses off that table (nearest angle). Without a
    ``geometry`` (a fixed telescope frame) one table serves every pulse: the cost is
    ``n_axes * n_angles`` forward evaluations, whatever ``n_rates`` and ``n_phases``. With
    a geometry (a moving line of sight) the table is per pulse, ``n_axes * n_angles * T``,
    used when ``n_angles < n_rates * n_phases``; otherwise every candidate is evaluated
    (``n_axes * n_rates * n_phases * T``). ``n_starts=0`` with ``starts`` skips the grid
    and refines the given starts only (e.g. candidates from a cheaper fixed-frame fit).
    General tumbling (8 parameters) is refined from ``starts`` (e.g. a principal fit's
    attitude and ``rate * e`` with a few inertia ratios).

    Parameters
    ----------
    data : array_like or sequence of Measurement
        (T, ...) counts per pulse (T epochs, e.g. (T, B, C)), or T measurements whose
        ``counts`` are stacked.
    forward : callable
        ``forward(attitudes)``: (N, 4) render attitudes (body to telescope, or body to
        inertial when ``geometry`` is None) to (N, ...) expected counts, the shape of one
        epoch of ``data`` (a renderer with :func:`pprender.inverse.instrument.expected_counts`,
        or an interpolator over a database of profiles).
    times : array_like
        (T,) strictly increasing times of the attitudes (s): ``geometry.reflect_times``
        when a geometry is given.
    model : {"principal", "tumbling"}, optional
        The spin model. Default "principal".
    geometry : PulseGeometry, optional
        Telescope rotations per pulse; None: the inertial frame is the telescope frame.
    rate_bounds : tuple of float, optional
        ``(min, max)`` rate magnitude (rad/s, 0 < min < max); required for "principal".
    body_axis : int, optional
        The principal axis of a principal-axis spin (0, 1, 2). Default 2.
    n_axes, n_rates, n_phases : int, optional
        Grid sizes (principal). Defaults 200, 32, 12.
    axes : array_like, optional
        (A, 3) candidate inertial axes (any norm > 0) replacing the ``n_axes`` Fibonacci
        sphere (principal): e.g. a hemisphere when a symmetry maps it onto the other half
        (a half turn about the line of sight does, :func:`spin_error`).
    n_angles : int, optional
        Spin-angle samples per axis (and per pulse with a geometry) of the grid stage (principal), in
        [8, 1e5]. Default 360.
    n_starts : int, optional
        Local refinements from the best grid points (principal), in [0, 1e4]; 0 (with
        ``starts``): no grid, only the given starts are refined. Default 8.
    starts : array_like, optional
        (S, 8) starting parameters (tumbling; required there: :func:`tumbling_start`) or (S, 4) extra starts
        (principal).
    max_evals : int, optional
        Likelihood evaluations per local refinement. Default 2000.
    batch : int, optional
        Grid candidates per ``forward`` call. Default 256.

    Returns
    -------
    SpinFit
        The best parameters, likelihood, inertial angular velocity and bookkeeping.

    Raises
    ------
    pprender.Error
        For invalid counts or times (their lengths must agree), an unknown model, missing or
        invalid ``rate_bounds`` or ``starts``, invalid grid sizes, or a forward model
        returning the wrong shape or invalid expected counts.
    """
    import nlopt

    t0 = time.perf_counter()
    k = _counts(data)
    t = _times(times)
    if k.shape[0] != t.size:
        raise Error(f"invalid data/times: {k.shape[0]} epochs of counts for {t.size} times")
    if geometry is not None and (not isinstance(geometry, PulseGeometry) or geometry.telescope.shape[0] != t.size):
        raise Error("invalid geometry: expected a PulseGeometry with one pulse per time")
    if model not in ("principal", "tumbling"):
        raise Error(f"invalid model = {model!r}: 'principal' or 'tumbling'")
    if body_axis not in (0, 1, 2) or isinstance(body_axis, bool):
        raise Error(f"invalid body_axis = {body_axis!r}: 0, 1 or 2")
    n_starts = _positive_int(n_starts, "n_starts", 0, 10_000)
    max_evals = _positive_int(max_evals, "max_evals", 1, 10_000_000)
    batch = _positive_int(batch, "batch", 1, 1_000_000)
    like = _Likelihood(k.reshape((t.size, -1)), lambda q: np.asarray(forward(q)).reshape(q.shape[0], -1), geometry)

    npar = 4 if model == "principal" else 8
    extra = None
    if starts is not None:
        extra = np.asarray(starts, dtype=np.float64)
        if extra.ndim == 1:
            extra = extra[None]
        if extra.ndim != 2 or extra.shape[1] != npar or not np.all(np.isfinite(extra)):
            raise Error(f"invalid starts: shape {extra.shape}, expected finite (S, {npar})")

    if model == "principal":
        if rate_bounds is None:
            raise Error("invalid rate_bounds = None: give (min, max) rad/s for a principal-axis fit")
        rb = np.asarray(rate_bounds, dtype=np.float64)
        if rb.shape != (2,) or not np.all(np.isfinite(rb)) or not 0 < rb[0] < rb[1]:
            raise Error(f"invalid rate_bounds = {rate_bounds!r}: (min, max) with 0 < min < max (rad/s)")
        n_rates = _positive_int(n_rates, "n_rates")
        n_phases = _positive_int(n_phases, "n_phases")
        n_angles = _positive_int(n_angles, "n_angles", 8, 100_000)
        if n_starts == 0 and extra is None:
            raise Error("invalid n_starts = 0: give starts to refine, or n_starts >= 1 for the grid")
        if axes is None:
            axes = _fibonacci_sphere(_positive_int(n_axes, "n_axes"))
        else:
            try:
                axes = np.asarray(axes, dtype=np.float64)
            except (TypeError, ValueError):
                raise Error("invalid axes: not an (A, 3) array of numbers") from None
            norms = np.linalg.norm(axes, axis=-1, keepdims=True) if axes.ndim == 2 else np.zeros(1)
            if axes.ndim != 2 or axes.shape[1] != 3 or not np.all(np.isfinite(axes)) or np.any(norms == 0):
                raise Error(f"invalid axes: shape {axes.shape}, expected finite non-zero (A, 3) vectors")
            axes = axes / norms
        n_axes = axes.shape[0]
        polar = np.arccos(np.clip(axes[:, 2], -1, 1))
        azim = np.arctan2(axes[:, 1], axes[:, 0])
        rates = rb[0] + (np.arange(n_rates) + 0.5) * (rb[1] - rb[0]) / n_rates
        phases = np.arange(n_phases) * 2.0 * math.pi / n_phases
        telescope = None if geometry is None else np.asarray(geometry.telescope, dtype=np.float64)
        if n_starts == 0:
            top = np.empty((0, 4))
        elif telescope is None or n_angles < n_rates * n_phases:
            top = _spin_angle_grid(like, polar, azim, rates, phases, t, body_axis, n_angles, n_starts, batch,
                                   telescope)
        else:
            grid = np.stack(np.meshgrid(np.arange(n_axes), rates, phases, indexing="ij"), axis=-1).reshape(-1, 3)
            idx = grid[:, 0].astype(int)
            cand = np.column_stack([polar[idx], azim[idx], grid[:, 1], grid[:, 2]])
            ll = np.concatenate(
                [like(_principal(cand[i : i + batch], t, body_axis)) for i in range(0, cand.shape[0], batch)]
            )
            top = cand[np.argsort(-ll)[:n_starts]]
        x0s = top if extra is None else np.vstack([extra, top])
        lower = np.array([-0.5, -4 * math.pi, rb[0] * 0.9, -1e3])
        upper = np.array([math.pi + 0.5, 4 * math.pi, rb[1] * 1.1, 1e3])

        def attitudes(x: np.ndarray) -> np.ndarray:
            return _principal(x[None], t, body_axis)

        dx = np.array([0.05, 0.05, (rb[1] - rb[0]) / n_rates / 4, 0.1])
    else:
        if extra is None:
            raise Error("invalid starts = None: a tumbling fit needs (S, 8) starting parameters")
        x0s = extra
        lower = np.array([-4 * math.pi] * 3 + [-1e3] * 3 + [1e-3, 1e-3])
        upper = np.array([4 * math.pi] * 3 + [1e3] * 3 + [1e3, 1e3])

        def attitudes(x: np.ndarray) -> np.ndarray:
            return tumbling_spin(x, t)[None]

        dx = None

    def objective(x: np.ndarray, grad: np.ndarray) -> float:
        if model == "tumbling":
            i = np.array([x[6], x[7], 1.0])
            if np.any(i <= 0) or np.max(i) > np.sum(i) - np.max(i):
                return -1e300
        return float(like(attitudes(np.asarray(x)))[0])

    results = []
    for x0 in x0s:
        x0 = np.clip(x0, lower, upper)
        opt = nlopt.opt(nlopt.LN_BOBYQA, npar)
        opt.set_lower_bounds(lower)
        opt.set_upper_bounds(upper)
        opt.set_max_objective(objective)
        opt.set_maxeval(max_evals)
        opt.set_xtol_rel(1e-10)
        opt.set_ftol_abs(1e-9)
        if dx is not None:
            opt.set_initial_step(dx)
        else:
            opt.set_initial_step(np.maximum(1e-3, 0.02 * np.abs(x0)))
        try:
            x = opt.optimize(x0)
            f = opt.last_optimum_value()
        except (nlopt.RoundoffLimited, RuntimeError):  # pragma: no cover - keep the start's value
            x, f = x0, float(like(attitudes(x0))[0])
        results.append((f, np.asarray(x)))
    results.sort(key=lambda r: -r[0])
    best_f, best = results[0]
    if model == "principal":
        omega = best[2] * _axis_from_angles(best[0], best[1])
    else:
        omega = _rotate(_rotvec_to_quat(best[:3]), best[3:6])
    return SpinFit(
        model=model,
        params=best,
        log_likelihood=float(best_f),
        omega=np.asarray(omega),
        starts=len(results),
        evaluations=like.evaluations,
        seconds=time.perf_counter() - t0,
        candidates=np.array([r[1] for r in results]),
        candidate_log_likelihoods=np.array([r[0] for r in results]),
    )
