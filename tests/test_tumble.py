"""Tumbling targets (pprender.inverse.tumble): torque-free propagation against closed forms
it did not come from (Jacobi elliptic omega(t), the symmetric top, pure spin) and the
conservation laws; light time and aberration; the symmetry-aware spin error; a tiny
spin-state fit with a cheap synthetic forward model."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import ellipj, ellipk

import pprender
from pprender.inverse import so3, tumble
from pprender.lidar import SPEED_OF_LIGHT


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _matrix(q):
    w, x, y, z = np.moveaxis(np.asarray(q), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _axis_angle(axis, angle):
    axis = _unit(axis)
    h = 0.5 * np.asarray(angle)[..., None]
    return np.concatenate([np.cos(h), np.sin(h) * axis], -1)


Q0 = _unit([0.9, 0.1, 0.3, -0.2])


# ---------------------------------------------------------------------- propagation


def test_energy_and_inertial_momentum_conserved_over_100_periods() -> None:
    # A short-axis-mode tumble (near the I3 spin); tolerance 1e-9 relative (measured ~1e-12).
    inertia = np.array([1.0, 2.0, 3.0])
    w0 = np.array([0.3, 0.2, 1.0])
    t = np.linspace(0.0, 100 * 2 * math.pi / np.linalg.norm(w0), 801)
    q, w = tumble.propagate(Q0, w0, inertia, t)
    energy = 0.5 * np.sum(inertia * w * w, axis=1)
    assert np.max(np.abs(energy / energy[0] - 1)) < 1e-9
    l_in = np.einsum("tij,tj->ti", _matrix(q), inertia * w)
    assert np.max(np.linalg.norm(l_in - l_in[0], axis=1)) / np.linalg.norm(l_in[0]) < 1e-9
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)


@pytest.mark.parametrize("mode", ["short", "long"])
def test_triaxial_omega_matches_jacobi_elliptic(mode) -> None:
    # Landau & Lifshitz, Mechanics, section 37: omega(t) of a free asymmetric top with
    # omega2(0) = 0, in Jacobi's cn, sn, dn. "short": M^2 > 2 E I2 (about I3); "long": about I1
    # (the same formulas with axes 1 and 3 swapped). The sign of sn: omega2'(0) =
    # (I3 - I1) omega3 omega1 / I2 > 0 in both. Tolerance 1e-8 rad/s over 10 periods.
    i1, i2, i3 = 1.0, 1.7, 2.5
    if mode == "short":
        w0 = np.array([0.4, 0.0, 1.1])
        a, b, c = i1, i2, i3
        perm = [0, 1, 2]
    else:
        w0 = np.array([1.1, 0.0, 0.4])
        a, b, c = i3, i2, i1
        perm = [2, 1, 0]
    wp = w0[perm]  # in the (a, b, c) ordering, spinning mostly about c
    e2 = a * wp[0] ** 2 + c * wp[2] ** 2
    m2 = a * a * wp[0] ** 2 + c * c * wp[2] ** 2
    amp1 = math.sqrt((e2 * c - m2) / (a * (c - a)))
    amp2 = math.sqrt((e2 * c - m2) / (b * (c - b)))
    amp3 = math.sqrt((m2 - e2 * a) / (c * (c - a)))
    rate = math.sqrt((c - b) * (m2 - e2 * a) / (a * b * c))
    m = (b - a) * (e2 * c - m2) / ((c - b) * (m2 - e2 * a))
    assert 0 < m < 1
    period = 4 * ellipk(m) / rate
    t = np.linspace(0.0, 10 * period, 501)
    sn, cn, dn, _ = ellipj(rate * t, m)
    expected = np.stack([amp1 * cn, amp2 * sn, amp3 * dn], axis=1)
    _, w = tumble.propagate(Q0, w0, [i1, i2, i3], t)
    assert np.max(np.abs(w[:, perm] - expected)) < 1e-8


def test_symmetric_top_precession() -> None:
    # I1 = I2 = Ip: q(t) = rot(L, |L| t / Ip) q0 rot(e3, -Omega t), Omega = (I3 - Ip) w3 / Ip.
    ip, i3 = 2.0, 3.2
    w0 = np.array([0.3, -0.2, 0.9])
    t = np.linspace(0.0, 60.0, 301)
    q, w = tumble.propagate(Q0, w0, [ip, ip, i3], t)
    l_in = _matrix(Q0) @ (np.array([ip, ip, i3]) * w0)
    big_omega = (i3 - ip) * w0[2] / ip
    expected = tumble.quaternion_multiply(
        tumble.quaternion_multiply(_axis_angle(l_in, np.linalg.norm(l_in) * t / ip), Q0),
        _axis_angle([0, 0, 1], -big_omega * t),
    )
    assert np.max(so3.angular_distance(q, expected)) < 1e-9
    phase = np.arctan2(w[:, 1], w[:, 0])
    ref = np.arctan2(w0[1], w0[0]) + big_omega * t
    assert np.max(np.abs(np.angle(np.exp(1j * (phase - ref))))) < 1e-9


@pytest.mark.parametrize("k", [0, 1, 2])
def test_pure_principal_spin_is_a_rotation_about_a_fixed_axis(k) -> None:
    inertia = [1.0, 1.5, 2.2]
    w0 = np.zeros(3)
    w0[k] = 0.7
    t = np.linspace(-5.0, 20.0, 101)
    q, w = tumble.propagate(Q0, w0, inertia, t)
    expected = tumble.quaternion_multiply(Q0, _axis_angle(np.eye(3)[k], 0.7 * t))
    assert np.max(so3.angular_distance(q, expected)) < 1e-10
    assert np.max(np.abs(w - w0)) < 1e-12


def test_principal_spin_parametrization() -> None:
    # The inertial axis is fixed, the body axis stays on it, and the rate is the turn per s.
    params = np.array([1.1, -2.0, 0.8, 0.3])
    t = np.linspace(0.0, 10.0, 41)
    q = tumble.principal_spin(params, t, body_axis=1)
    axis = np.array([math.sin(1.1) * math.cos(-2.0), math.sin(1.1) * math.sin(-2.0), math.cos(1.1)])
    assert np.allclose(_matrix(q)[:, :, 1], axis, atol=1e-12)
    rel = tumble.quaternion_multiply(q[1:], q[:-1] * np.array([1, -1, -1, -1]))  # q(t+dt) q(t)^-1
    assert np.allclose(so3.angular_distance(rel, np.array([1.0, 0, 0, 0])), 0.8 * 0.25, atol=1e-12)
    assert np.allclose(rel[:, 1:] / np.linalg.norm(rel[:, 1:], axis=1, keepdims=True), axis, atol=1e-12)
    # the same motion from the rigid-body integrator
    qp, _ = tumble.propagate(q[0], [0.0, 0.8, 0.0], [1.0, 2.0, 1.5], t)
    assert np.max(so3.angular_distance(q, qp)) < 1e-10


def test_backward_and_forward_propagation_agree() -> None:
    inertia = [1.0, 2.0, 3.0]
    w0 = np.array([0.5, 0.6, -0.4])
    q, w = tumble.propagate(Q0, w0, inertia, [7.0])
    back_q, back_w = tumble.propagate(q[0], w[0], inertia, [0.0], t0=7.0)
    assert so3.angular_distance(back_q[0], Q0) < 1e-10
    assert np.max(np.abs(back_w[0] - w0)) < 1e-10


def test_tumbling_spin_parameters() -> None:
    rv = np.array([0.2, -0.4, 1.0])
    params = np.concatenate([rv, [0.1, 0.5, 0.2], [0.6, 0.8]])
    t = np.linspace(0.0, 5.0, 11)
    q = tumble.tumbling_spin(params, t)
    from scipy.spatial.transform import Rotation

    q0 = Rotation.from_rotvec(rv).as_quat(scalar_first=True)
    assert so3.angular_distance(q[0], q0) < 1e-12
    qp, _ = tumble.propagate(q0, [0.1, 0.5, 0.2], [0.6, 0.8, 1.0], t)
    assert np.max(so3.angular_distance(q, qp)) < 1e-8


def test_tumbling_start_reproduces_the_principal_spin() -> None:
    # A pure spin about a principal axis is torque-free for any inertia: the integrator,
    # started from tumbling_start, must give principal_spin's closed-form attitudes.
    params = np.array([2.0, 0.4, -0.9, 1.3])
    t = np.linspace(0.0, 12.0, 25)
    start = tumble.tumbling_start(params, (0.5, 0.8), body_axis=0)
    expected = tumble.principal_spin(params, t, body_axis=0)
    assert np.max(so3.angular_distance(tumble.tumbling_spin(start, t), expected)) < 1e-8
    with pytest.raises(pprender.Error, match="inertia_ratios"):
        tumble.tumbling_start(params, (0.1, 0.2))


# ---------------------------------------------------------------------- geometry


def test_light_time_and_point_ahead() -> None:
    # A LEO-like pass: 1000 km range, 7.5 km/s across the line of sight and 1 km/s along it.
    r = np.array([[0.0, 1.0e6, 2.0e5], [1.0e5, 1.1e6, 2.0e5]])
    v = np.array([[7500.0, 0.0, 1000.0 * 0.0], [7400.0, 900.0, 0.0]])
    g = tumble.pulse_geometry([0.0, 0.01], r, v)
    for i in range(2):
        dt = brentq(lambda s: np.linalg.norm(r[i] + v[i] * s) - SPEED_OF_LIGHT * s, 0.0, 1.0, xtol=1e-16)
        assert abs(g.reflect_times[i] - g.transmit_times[i] - dt) < 1e-15
        assert abs(g.range_m[i] - SPEED_OF_LIGHT * dt) < 1e-6
    assert np.allclose(g.line_of_sight, -(r + v * (g.reflect_times - g.transmit_times)[:, None]) / g.range_m[:, None])
    # 2 v_perp / c: ~5e-5 rad at 7.5 km/s
    v_perp = v[0] - (v[0] @ g.line_of_sight[0]) * g.line_of_sight[0]
    assert abs(g.point_ahead[0] - 2 * np.linalg.norm(v_perp) / SPEED_OF_LIGHT) < 1e-15
    assert 4.9e-5 < g.point_ahead[0] < 5.1e-5
    # the telescope frame: Z on the line of sight, Y toward up, right-handed
    m = _matrix(g.telescope)
    assert np.allclose(np.einsum("tij,tj->ti", m, g.line_of_sight), [0, 0, 1], atol=1e-12)
    y_in = m[:, 1, :]  # telescope Y in inertial coordinates
    assert np.all(y_in[:, 2] > 0) and np.allclose(np.sum(y_in * g.line_of_sight, axis=1), 0, atol=1e-12)
    # render attitudes: the body axis the line of sight falls on is seen along Z
    body = tumble.principal_spin([0.4, 0.3, 0.1, 0.0], g.reflect_times)
    att = g.attitudes(body)
    los_body = np.einsum("tji,tj->ti", _matrix(body), g.line_of_sight)
    assert np.allclose(np.einsum("tij,tj->ti", _matrix(att), los_body), [0, 0, 1], atol=1e-12)


def test_static_target_light_time_is_range_over_c() -> None:
    g = tumble.pulse_geometry([0.0, 1.0, 2.0], [3.0e5, 0.0, 4.0e5])
    assert np.allclose(g.reflect_times - g.transmit_times, 5.0e5 / SPEED_OF_LIGHT, rtol=1e-15)
    assert np.all(g.point_ahead == 0)


def test_rendered_flash_comes_when_the_front_faces_the_sensor() -> None:
    # End to end through pprender.render: a plate (front +z: smooth aluminium, alpha 0.05;
    # back: alpha 0.5, a ~100 times dimmer flash) spins about inertial +z with its body y on
    # the axis; the target lies along +x from the sensor, so the line of sight (target to
    # sensor) is -x. By hand: aligning body y with +z is a quarter turn about x (body
    # z -> -y); after a spin angle alpha the front normal is (sin alpha, -cos alpha, 0),
    # which faces the sensor at alpha = 3 pi / 2 (the back at pi / 2). The brightest of 72
    # pulses over a turn must be the one nearest.
    rate = 2 * math.pi / 7.2
    t = np.arange(72) * 0.1
    g = tumble.pulse_geometry(t, [1.0e6, 0.0, 0.0], up=[0.0, 0.0, 1.0])
    q = tumble.principal_spin([0.0, 0.0, rate, 0.0], g.reflect_times, body_axis=1)
    rough = pprender.materials.get("aluminium", alpha=0.5)
    scene = pprender.Scene(pprender.models.plate(0.5, 0.5), {"front": pprender.materials.get("aluminium", alpha=0.05),
                                                              "back": rough, "edge": rough})
    res = pprender.render(scene, pprender.Lidar(resolution=16), g.attitudes(q), outputs=("profile",))
    brightest = int(np.argmax(np.asarray(res.cross_section)[:, 0, 0]))
    assert brightest == round(1.5 * math.pi / rate / 0.1) % 72


# ---------------------------------------------------------------------- scoring


def test_spin_error_symmetries() -> None:
    w = 0.3 * _unit([0.3, -0.5, 0.8])
    los = np.array([0.0, 0.0, 1.0])
    half = 2 * (w @ los) * los - w
    assert tumble.spin_error(w, half)[0] < 1e-6  # the LOS half turn is invisible
    assert tumble.spin_error(w, w * 1.01)[1] == pytest.approx(0.01, rel=1e-9)
    err, _ = tumble.spin_error(w, -w)
    assert err == pytest.approx(180 - math.degrees(2 * math.acos(0.8 / np.linalg.norm([0.3, -0.5, 0.8]))), abs=1e-6)
    assert tumble.spin_error(w, -w, reversible=True)[0] < 1e-6
    # roll-invariant: any rotation about the line of sight; only the angle to it counts
    rolled = _matrix(_axis_angle(los, 1.234)) @ w
    assert tumble.spin_error(w, rolled, roll_invariant=True)[0] < 1e-6
    tilted = _matrix(_axis_angle([1, 0, 0], math.radians(3))) @ np.array([0, 0.3, 0.0])
    assert tumble.spin_error([0, 0.3, 0.0], tilted, roll_invariant=True)[0] == pytest.approx(3.0, abs=1e-9)


# ---------------------------------------------------------------------- fitting


def _synthetic_forward(q, signal=1000.0, background=10.0):
    # Nine "bins" from the render rotation R (body to telescope): the line of sight in the
    # body frame (roll-invariant, like an intensity profile) and the second harmonics of the
    # roll (like linear polarization: invariant under a half turn about Z only).
    r = _matrix(q)
    f = np.concatenate([r[:, 2, :] ** 2, 0.5 * (r[:, 0, :] ** 2 - r[:, 1, :] ** 2), r[:, 0, :] * r[:, 1, :]], axis=1)
    return background + signal * (0.5 + 0.5 * f)[..., None] / 9.0 * 2.0


def test_principal_spin_fit_recovers_axis_and_rate(rng) -> None:
    # 3 random truths, 60 pulses over one period at SNR ~ 50 per pulse (3000 signal, 90
    # background counts): axis within 5 deg (modulo the half turn about the line of sight)
    # and rate within 1 %, and the fit's likelihood at least the truth's (the global mode).
    n_t = 60
    t = np.linspace(0.0, 10.0, n_t, endpoint=False)

    def forward(q):
        return _synthetic_forward(q, signal=3000.0)

    for _ in range(3):
        axis = _unit(rng.normal(size=3))
        rate = 2 * math.pi / 10.0 * rng.uniform(0.9, 1.1)
        truth = [math.acos(axis[2]), math.atan2(axis[1], axis[0]), rate, rng.uniform(0, 2 * math.pi)]
        counts = rng.poisson(forward(tumble.principal_spin(truth, t)))
        fit = tumble.fit_spin(counts, forward, t, rate_bounds=(0.5, 0.8), n_axes=60, n_rates=8,
                              n_phases=8, n_starts=4)
        axis_err, rate_err = tumble.spin_error(rate * axis, fit.omega)
        assert axis_err < 5.0 and rate_err < 0.01, (axis_err, rate_err)
        assert fit.log_likelihood >= tumble._Likelihood(counts.astype(float), forward, None)(
            tumble.principal_spin(truth, t)[None])[0] - 1e-6


def test_fit_with_a_geometry_matches_the_fixed_frame_fit(rng) -> None:
    # A geometry whose telescope frame is the inertial one (line of sight +z, up +y) takes
    # the brute-force grid path; the fixed-frame fit reads its grid off per-axis spin-angle
    # tables. Both must land on the same optimum (1e-6 rad, 1e-8 relative in the rate).
    g = tumble.pulse_geometry(np.linspace(0.0, 10.0, 40, endpoint=False), [0.0, 0.0, -1.0e6], up=[0.0, 1.0, 0.0])
    assert np.allclose(g.telescope, [1.0, 0.0, 0.0, 0.0], atol=1e-12)

    def forward(q):
        return _synthetic_forward(q, signal=3000.0)

    truth = [1.0, 0.7, 0.68, 2.0]
    counts = rng.poisson(forward(tumble.principal_spin(truth, g.reflect_times)))
    kw = dict(rate_bounds=(0.5, 0.8), n_axes=40, n_rates=8, n_phases=8, n_starts=3)
    with_geometry = tumble.fit_spin(counts, forward, g.reflect_times, geometry=g, **kw)
    fixed = tumble.fit_spin(counts, forward, g.reflect_times, **kw)
    assert tumble.spin_error(with_geometry.omega, fixed.omega)[0] < 1e-4
    assert tumble.spin_error(with_geometry.omega, fixed.omega)[1] < 1e-8
    assert tumble.spin_error(0.68 * tumble._axis_from_angles(1.0, 0.7), fixed.omega)[0] < 5.0


def _sweep_geometry(n_t, sweep_deg):
    # A line of sight turning uniformly by sweep_deg about +y (across it) over the pulses,
    # +z at mid-pass; up = +y, so the telescope turns with it.
    beta = math.radians(sweep_deg) * (np.arange(n_t) / (n_t - 1) - 0.5)
    los = np.stack([np.sin(beta), np.zeros(n_t), np.cos(beta)], -1)
    return tumble.pulse_geometry(np.linspace(0.0, 10.0, n_t, endpoint=False), -1.0e6 * los, up=[0.0, 1.0, 0.0])


def test_per_pulse_grid_matches_the_candidate_by_candidate_grid_on_a_pass(rng) -> None:
    # A moving line of sight (60 deg): the grid read off per-pulse spin-angle tables
    # (n_angles 48 < 8 x 8) and the grid evaluating every candidate (n_angles 64 = 8 x 8)
    # must land on the same optimum after BOBYQA (1e-3 deg, 1e-6 relative in the rate), and
    # that optimum on the truth (axis within 2 deg, rate within 1 %, no symmetry allowed:
    # the roll harmonics see the roll and the sweep breaks the half turn about the line of sight).
    g = _sweep_geometry(30, 60.0)

    def forward(q):
        return _synthetic_forward(q, signal=3000.0)

    truth = [1.1, 2.5, 0.66, 1.0]
    omega = 0.66 * tumble._axis_from_angles(1.1, 2.5)
    counts = rng.poisson(forward(g.attitudes(tumble.principal_spin(truth, g.reflect_times))))
    kw = dict(geometry=g, rate_bounds=(0.5, 0.8), n_axes=60, n_rates=8, n_phases=8, n_starts=3)
    tables = tumble.fit_spin(counts, forward, g.reflect_times, n_angles=48, **kw)
    brute = tumble.fit_spin(counts, forward, g.reflect_times, n_angles=64, **kw)
    assert tables.evaluations < brute.evaluations
    assert math.degrees(math.acos(min(1.0, tables.omega @ brute.omega / np.linalg.norm(tables.omega)
                                      / np.linalg.norm(brute.omega)))) < 1e-3
    assert tumble.spin_error(brute.omega, tables.omega)[1] < 1e-6
    axis_err = math.degrees(math.acos(min(1.0, omega @ tables.omega / np.linalg.norm(omega)
                                          / np.linalg.norm(tables.omega))))
    assert axis_err < 2.0 and tumble.spin_error(omega, tables.omega)[1] < 0.01, axis_err


def test_a_moving_line_of_sight_leaves_only_the_half_turn_about_the_sweep_axis(rng) -> None:
    # A roll-invariant forward model (the body-frame line of sight only, like a convex
    # single-bounce target; even in each body axis, like a mirror-symmetric one). Along a
    # fixed line of sight every turn about it gives the same data; along a 60 deg sweep only
    # the reflection across the sweep plane (with a body reflection) does, whose angular
    # velocity is omega turned by a half turn about the sweep axis n = +y. Checked on the
    # expected counts (exact, 1e-9 relative), then the fit (1e5 signal counts per pulse:
    # three roll-invariant bins carry little) recovers the axis modulo that half turn
    # (within 3 deg) and the rate (1 %).
    def forward(q):
        return _synthetic_forward(q, signal=1e5)[:, :3]

    n_t = 30
    g = _sweep_geometry(n_t, 60.0)
    t = g.reflect_times
    truth = [1.1, 2.5, 0.66, 1.0]
    omega = 0.66 * tumble._axis_from_angles(1.1, 2.5)
    q = tumble.principal_spin(truth, t)
    turn = tumble.quaternion_multiply(_axis_angle([0, 0, 1], 1.0), q)  # 57 deg about the mid-pass line of sight
    assert np.allclose(forward(turn), forward(q), rtol=1e-9)  # fixed line of sight: identical
    lam = forward(g.attitudes(q))
    assert np.max(np.abs(forward(g.attitudes(turn)) / lam - 1)) > 0.05  # the sweep sees it
    # the mirror image S R M (S: reflection across the sweep plane y = 0, M: body x -> -x)
    s_mat, m_mat = np.diag([1.0, -1.0, 1.0]), np.diag([-1.0, 1.0, 1.0])
    from scipy.spatial.transform import Rotation

    image = Rotation.from_matrix(s_mat @ _matrix(q) @ m_mat).as_quat(scalar_first=True)
    assert np.allclose(forward(g.attitudes(image)), lam, rtol=1e-9)
    steps = Rotation.from_matrix(_matrix(image[1:]) @ np.swapaxes(_matrix(image[:-1]), -1, -2)).as_rotvec()
    assert np.allclose(steps / np.diff(t)[:, None], [-omega[0], omega[1], -omega[2]], atol=1e-9)  # rot(y, pi) omega
    counts = rng.poisson(lam)
    fit = tumble.fit_spin(counts, forward, t, geometry=g, rate_bounds=(0.5, 0.8), n_axes=60, n_rates=8, n_phases=8,
                          n_angles=48, n_starts=3)
    axis_err, rate_err = tumble.spin_error(omega, fit.omega, line_of_sight=[0.0, 1.0, 0.0])
    assert axis_err < 3.0 and rate_err < 0.01, (axis_err, rate_err)


def test_refining_given_starts_only() -> None:
    # n_starts=0 with starts: no grid, so the evaluations are BOBYQA's alone (<= max_evals
    # per start) and a start at the truth of near noise-free data ends at least as likely and
    # within 1e-3 of its rate.
    t = np.linspace(0.0, 10.0, 20, endpoint=False)
    truth = np.array([1.0, 0.7, 0.68, 2.0])
    counts = np.round(_synthetic_forward(tumble.principal_spin(truth, t), signal=1e6))
    fit = tumble.fit_spin(counts, _synthetic_forward, t, rate_bounds=(0.5, 0.8), n_starts=0, starts=truth,
                          max_evals=50)
    assert fit.starts == 1 and fit.evaluations <= 50
    like = tumble._Likelihood(counts, _synthetic_forward, None)
    assert fit.log_likelihood >= like(tumble.principal_spin(truth, t)[None])[0]
    assert tumble.spin_error(0.68 * tumble._axis_from_angles(1.0, 0.7), fit.omega)[1] < 1e-3
    with pytest.raises(pprender.Error, match="n_starts"):
        tumble.fit_spin(counts, _synthetic_forward, t, rate_bounds=(0.5, 0.8), n_starts=0)


def test_tumbling_fit_refines_from_a_nearby_start(rng) -> None:
    # Near noise-free data (1e6 signal counts per pulse, rounded): from a start 3 % off in
    # every parameter, BOBYQA (400 evaluations) climbs within 1 of the truth's
    # log-likelihood (the start is ~1e3 below) and the initial angular velocity to within
    # 0.2 deg and 0.2 %.
    t = np.linspace(0.0, 5.0, 25)
    truth = np.array([0.3, -0.2, 0.5, 0.2, 0.1, 0.8, 0.55, 0.8])

    def forward(q):
        return _synthetic_forward(q, signal=1e6)

    counts = np.round(forward(tumble.tumbling_spin(truth, t)))
    start = truth * (1 + 0.03 * rng.normal(size=8))
    fit = tumble.fit_spin(counts, forward, t, model="tumbling", starts=start[None], max_evals=400)
    like = tumble._Likelihood(counts, forward, None)
    best = like(tumble.tumbling_spin(truth, t)[None])[0]
    assert like(tumble.tumbling_spin(start, t)[None])[0] < best - 100
    assert fit.log_likelihood >= best - 1.0
    omega_truth = tumble._rotate(tumble._rotvec_to_quat(truth[:3]), truth[3:6])
    axis_err, rate_err = tumble.spin_error(omega_truth, fit.omega)
    assert axis_err < 0.2 and rate_err < 0.002, (axis_err, rate_err)


def test_fit_accepts_a_list_of_measurements() -> None:
    # Measurements from pprender.measure stack into (T, B, C) counts, epoch by epoch.
    inst = pprender.Instrument(pulse_energy=1e-8, target_range=1e5, n_pulses=10000)
    edges = np.linspace(0.0, 0.3, 4)
    prof = np.zeros((3, 4, 4))
    prof[:, 0, 0] = prof[:, 1, 1] = 0.1
    ms = [pprender.measure(prof * (i + 1), inst, bin_edges=edges, seed=i) for i in range(5)]
    assert np.array_equal(tumble._counts(ms), np.stack([m.counts for m in ms]).astype(float))


# ---------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"q0": [1.0, 0.1, 0, 0]}, "q0"),
        ({"inertia": [1.0, -2.0, 2.0]}, "inertia"),
        ({"inertia": [1.0, 1.0, 2.5]}, "inertia"),
        ({"omega0": [0.1, float("nan"), 0.0]}, "omega0"),
        ({"times": [0.0, 1.0, 1.0]}, "times"),
        ({"times": [0.0, float("inf")]}, "times"),
    ],
)
def test_bad_propagation_input_names_the_parameter(kwargs, name) -> None:
    args = {"q0": [1.0, 0, 0, 0], "omega0": [0.1, 0.2, 0.3], "inertia": [1.0, 2.0, 2.5], "times": [0.0, 1.0]}
    args.update(kwargs)
    with pytest.raises(pprender.Error, match=name):
        tumble.propagate(args["q0"], args["omega0"], args["inertia"], args["times"])


def test_bad_geometry_and_fit_input() -> None:
    with pytest.raises(pprender.Error, match="relative_position"):
        tumble.pulse_geometry([0.0], [0.0, 0.0, 0.0])
    with pytest.raises(pprender.Error, match="relative_velocity"):
        tumble.pulse_geometry([0.0], [1e6, 0, 0], [1e8, 0, 0])
    with pytest.raises(pprender.Error, match="up"):
        tumble.pulse_geometry([0.0], [0, 0, 1e6], up=[0, 0, 1])
    with pytest.raises(pprender.Error, match="rate_bounds"):
        tumble.fit_spin(np.ones((2, 3, 1), int), _synthetic_forward, [0.0, 1.0], rate_bounds=(1.0, 0.5))
    with pytest.raises(pprender.Error, match="data/times"):
        tumble.fit_spin(np.ones((2, 3, 1), int), _synthetic_forward, [0.0, 1.0, 2.0], rate_bounds=(0.5, 1.0))
    with pytest.raises(pprender.Error, match="body_axis"):
        tumble.principal_spin([0.0, 0.0, 1.0, 0.0], [0.0], body_axis=3)
