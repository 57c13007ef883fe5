"""Spin-state recovery study for principal-axis spin: writes docs/spin-recovery.md.

Issue 26's target: at SNR 30 per pulse and 100 pulses over a period, >= 90 % of 30 random
principal-axis truths recover the axis within 5 deg and the rate within 1 %.

Target: the 3U CubeSat of :func:`pprender.models.cubesat` (deployed panels, no antenna,
``detail=0``), aluminium (alpha 0.3), rendered with two bounces: the panel-bus dihedrals
are what makes the polarization depend on the roll about the line of sight (a convex
single-bounce target's monostatic Mueller profile is ``sigma diag(1, 1, -1, -1)``, roll
invariant, and cannot show the axis's azimuth about the line of sight at all).

Forward model: a table of Mueller profiles over the line-of-sight direction in the body
frame ``(theta, phi)`` (a regular grid, ``--step`` degrees) at a reference roll, bilinear
in ``(theta, phi)``; the roll ``psi`` about the line of sight is applied exactly,
``M(rot_z(psi) R0) = L(-psi) M(R0) L(-psi)`` (``L`` the Stokes rotation; checked here
against direct renders). Attitudes decompose as ``R = rot_z(psi) rot_y(-theta) rot_z(-phi)``.
Profiles are summed into bins of ``--bin`` metres. The table's error against direct
renders is measured on random attitudes and reported.

Truths: axis uniform on the sphere, rate ``2 pi / T`` times U(0.8, 1.25) with ``T`` the
observation span (100 pulses over ``T``), phase uniform, spin about the body's ``y`` axis
(the largest moment: the panels extend along ``x``). Their counts are drawn from direct
renders (``--truth render``, default) or from the table (``--truth table``); the fit
(:func:`pprender.inverse.tumble.fit_spin`) always uses the table. The instrument is the
``"stokes"`` preset (transmit H; six analyzers), scaled so that the mean signal per pulse
over the table's directions is ``S`` with ``S / sqrt(S + B) = --snr`` and background ``B``
= 10 % of ``S``. Scoring, as the issue asks, modulo the symmetries a monostatic profile
cannot see: :func:`pprender.inverse.tumble.spin_error` modulo the half turn about the line
of sight for truths whose roll about the line of sight is observable (the noise-free
log-likelihood ratio against the motion turned about the line of sight exceeds 5), and
modulo any roll (the angle between axis and line of sight only) for the others, whose
profiles are roll invariant throughout (both scores are also reported for every truth).

Moving line of sight (``--sweep DEG``, writes docs/spin-recovery-pass.md): the line of
sight turns uniformly by ``DEG`` about inertial ``+y`` over the observation (``+z`` at
mid-pass, telescope ``up = +y``; :func:`sweep_geometry`), the same truths (the fixed study's
random stream is kept). The fit has three stages: the fixed-line-of-sight fit above at the
mid-pass line of sight (angle between axis and line of sight, rate); that fit's optima
turned about the mid-pass line of sight (``--n-rolls``), tilted (``--tilts``) and corrected
for the sweep, scored with the pass geometry; BOBYQA with the pass geometry from the best
``--n-refine`` (``fit_spin(geometry=..., n_starts=0, starts=...)``). Scored without any
symmetry and modulo the half turn about the sweep axis (what a roll-invariant profile of
a mirror-symmetric target still cannot see: the page explains). About 30 s per truth::

    python scripts/spin_recovery.py --sweep 45 --truths 30

Full run (about 25 min on 2 loaded cores: the table 5 min, 30 s per truth)::

    python scripts/spin_recovery.py --truths 30

Quick look::

    python scripts/spin_recovery.py --truths 4 --out /tmp/spin.md
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("NODEVICE_SELECT", "1")

import pprender  # noqa: E402
from pprender import materials, models  # noqa: E402
from pprender.inverse import so3, tumble  # noqa: E402
from pprender.inverse.instrument import Instrument, expected_counts  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def stokes_rotation(theta: np.ndarray) -> np.ndarray:
    """(..., 4, 4) ``L(theta)``: rotation of the linear Stokes components by ``2 theta``."""
    c, s = np.cos(2 * theta), np.sin(2 * theta)
    out = np.zeros(np.shape(theta) + (4, 4))
    out[..., 0, 0] = out[..., 3, 3] = 1.0
    out[..., 1, 1] = out[..., 2, 2] = c
    out[..., 1, 2] = s
    out[..., 2, 1] = -s
    return out


def q_axis(axis: int, angle: np.ndarray) -> np.ndarray:
    angle = np.asarray(angle, dtype=float)
    q = np.zeros(angle.shape + (4,))
    q[..., 0] = np.cos(angle / 2)
    q[..., 1 + axis] = np.sin(angle / 2)
    return q


def matrices(q: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(q.reshape(-1, 4), scalar_first=True).as_matrix().reshape(q.shape[:-1] + (3, 3))


class Target:
    def __init__(self, resolution: int, bin_m: float) -> None:
        mesh = models.cubesat("3U", antenna=False, detail=0)
        self.scene = pprender.Scene(mesh, materials.get("aluminium", alpha=0.3))
        self.sensor = pprender.Lidar(wavelength=1064e-9, pulse_fwhm=100e-12, resolution=resolution, bounces=2)
        self.bin_m = bin_m
        self.edges: np.ndarray | None = None
        self.factor = 0

    def render(self, q: np.ndarray) -> np.ndarray:
        """(N, B, 4, 4) Mueller profiles, summed into bins of about ``bin_m``."""
        res = pprender.render(self.scene, self.sensor, q, outputs=("profile",))
        p = np.asarray(res.profile, dtype=np.float64)
        e = np.asarray(res.bin_edges, dtype=np.float64)
        if self.edges is None:
            self.factor = max(1, int(round(self.bin_m / (e[1] - e[0]))))
            n = -(-p.shape[1] // self.factor) * self.factor
            self.edges = e[0] + (e[1] - e[0]) * np.arange(0, n + 1, self.factor)
            self.raw_edges = e
        elif not np.array_equal(e, self.raw_edges):
            raise RuntimeError("bin edges differ between renders")
        n = (len(self.edges) - 1) * self.factor
        p = np.concatenate([p, np.zeros((p.shape[0], n - p.shape[1], 4, 4))], axis=1)
        return p.reshape(p.shape[0], -1, self.factor, 4, 4).sum(axis=2)


class Table:
    """Mueller profiles over the body-frame line of sight, bilinear, roll applied exactly."""

    def __init__(self, target: Target, step_deg: float, instrument: Instrument, cache: Path | None = None) -> None:
        self.n_theta = int(round(180 / step_deg)) + 1
        self.n_phi = int(round(360 / step_deg))
        self.theta = np.linspace(0, math.pi, self.n_theta)
        self.phi = np.arange(self.n_phi) * 2 * math.pi / self.n_phi
        th, ph = np.meshgrid(self.theta, self.phi, indexing="ij")
        q = tumble.quaternion_multiply(q_axis(1, -th), q_axis(2, -ph)).reshape(-1, 4)
        key = np.array([step_deg, target.sensor.settings.resolution, target.bin_m])
        if cache is not None and cache.exists() and np.array_equal(np.load(cache)["key"], key):
            z = np.load(cache)
            self.profiles, self.build_s = z["profiles"], float(z["build_s"])
            target.edges, target.raw_edges, target.factor = z["edges"], z["raw_edges"], int(z["factor"])
        else:
            t0 = time.perf_counter()
            self.profiles = target.render(q).reshape(self.n_theta, self.n_phi, -1, 4, 4)
            self.build_s = time.perf_counter() - t0
            assert target.edges is not None  # set by the first render
            if cache is not None:
                np.savez(cache, key=key, profiles=self.profiles, build_s=self.build_s, edges=target.edges,
                         raw_edges=target.raw_edges, factor=target.factor)
        assert target.edges is not None
        self.edges: np.ndarray = target.edges
        self.set_instrument(instrument)

    def set_instrument(self, instrument: Instrument) -> None:
        self.instrument = instrument
        ch = instrument.channels
        assert not isinstance(ch, str)  # Instrument resolves a preset name to Channels
        self.rows = np.asarray(ch.rows) * instrument.counts_per_cross_section  # (C, 4)
        self.gens = np.asarray(ch.generators_array)  # (C, 4)
        self.background = instrument.background_counts(self.edges)  # (B, C)

    def decompose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r = matrices(q)
        d = r[:, 2, :]
        theta = np.arccos(np.clip(d[:, 2], -1, 1))
        phi = np.arctan2(d[:, 1], d[:, 0]) % (2 * math.pi)
        r0 = matrices(tumble.quaternion_multiply(q_axis(1, -theta), q_axis(2, -phi)))
        rz = r @ np.swapaxes(r0, -1, -2)
        psi = np.arctan2(rz[:, 1, 0], rz[:, 0, 0])
        return theta, phi, psi

    def mueller(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, B, 4, 4) profiles at the reference roll and (N,) rolls."""
        theta, phi, psi = self.decompose(q)
        x = theta / (math.pi / (self.n_theta - 1))
        i0 = np.clip(np.floor(x).astype(int), 0, self.n_theta - 2)
        fx = (x - i0)[:, None, None, None]
        y = phi / (2 * math.pi / self.n_phi)
        j0 = np.floor(y).astype(int) % self.n_phi
        j1 = (j0 + 1) % self.n_phi
        fy = (y - np.floor(y))[:, None, None, None]
        p = self.profiles
        m = (1 - fx) * ((1 - fy) * p[i0, j0] + fy * p[i0, j1]) + fx * ((1 - fy) * p[i0 + 1, j0] + fy * p[i0 + 1, j1])
        return m, psi

    def __call__(self, q: np.ndarray) -> np.ndarray:
        """(N, B, C) expected counts."""
        m, psi = self.mueller(q)
        lr = stokes_rotation(-psi)  # (N, 4, 4)
        a = np.einsum("ci,nij->ncj", self.rows, lr)
        g = np.einsum("nij,cj->nci", lr, self.gens)
        return np.einsum("nci,nbij,ncj->nbc", a, m, g) + self.background


#: Rolls of the whole motion about the line of sight for the observability diagnostic (deg).
ROLLS_DEG = (10, 30, 60, 90, 120, 150)


def draw_truth(rng: np.random.Generator, nominal: float) -> tuple[np.ndarray, np.ndarray]:
    """A random principal-axis truth (axis polar angle, azimuth, rate, phase): axis uniform
    on the sphere, rate 0.8-1.25 x ``nominal``, phase uniform; and the axis (3,). The fixed
    and the moving line-of-sight studies draw their truths with this, in the same order."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    rate = nominal * rng.uniform(0.8, 1.25)
    phase = rng.uniform(0, 2 * math.pi)
    return np.array([math.acos(axis[2]), math.atan2(axis[1], axis[0]), rate, phase]), axis


def roll_information(table: Table, q: np.ndarray, roll_deg: float) -> float:
    """Expected log-likelihood ratio (noise-free, the table's model) of a motion against the
    same motion turned by ``roll_deg`` about the line of sight: the KL divergence
    ``sum lam log(lam / lam') - lam + lam'``. 0 means the data cannot tell them apart."""
    b = math.radians(roll_deg)
    lam = table(q)
    lam2 = table(tumble.quaternion_multiply(np.array([math.cos(b / 2), 0.0, 0.0, math.sin(b / 2)]), q))
    return float(np.sum(lam * np.log(lam / lam2) - lam + lam2))


# ---------------------------------------------------------------------- moving line of sight (--sweep)


def sweep_geometry(times: np.ndarray, sweep_deg: float, range_m: float = 1.0e6) -> tumble.PulseGeometry:
    """A line of sight turning uniformly by ``sweep_deg`` about inertial ``+y`` over the pulses.

    ``l(t) = rot(y, beta) z`` with ``beta`` uniform in the pulse index, 0 at the middle pulse
    ``T // 2`` and turning by ``sweep_deg`` from the first pulse to the last; ``up = +y`` (the sweep axis, always across the line of sight)
    so the telescope turns about ``y`` with the line of sight and is the inertial frame at
    mid-pass (the fixed study's frame). No relative velocity: light time is a constant
    ``range / c`` and aberration (< 1e-4 rad) is far below a profile's noise.
    """
    n = times.size
    beta = math.radians(sweep_deg) * (np.arange(n) - n // 2) / max(n - 1, 1)
    los = np.stack([np.sin(beta), np.zeros(n), np.cos(beta)], axis=-1)
    return tumble.pulse_geometry(times, -range_m * los, up=(0.0, 1.0, 0.0))


def conj(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def principal_params(a: np.ndarray, rate: float, q_at_0: np.ndarray, body_axis: int) -> np.ndarray:
    """``(polar, azimuth, rate, phase)`` of the principal spin about unit ``a`` whose attitude at
    ``t = 0`` is ``q_at_0`` (its body axis must lie along ``a``)."""
    e = np.zeros(3)
    e[body_axis] = 1.0
    x = tumble.quaternion_multiply(q_at_0, conj(tumble._align(e, a)))  # rot(a, phase)
    phase = 2.0 * math.atan2(float(x[1:] @ a), float(x[0]))
    return np.array([math.acos(np.clip(a[2], -1, 1)), math.atan2(a[1], a[0]), rate, phase])


def ring_candidates(p1: np.ndarray, geometry: tumble.PulseGeometry, times: np.ndarray, mid: int, body_axis: int,
                    n_rolls: int, tilts_deg: tuple[float, ...]) -> np.ndarray:
    """Stage 2: the stage-1 (fixed line of sight, mid-pass telescope frame) spin ``p1`` turned
    about the mid-pass line of sight ``l_m`` by ``n_rolls`` angles (the family a fixed line of
    sight cannot tell apart), its axis tilted toward or away from ``l_m`` by ``tilts_deg``, and
    its spin angle corrected for the moving line of sight: ``alpha(t) = alpha_1(t) + psi(t) -
    psi(t_m)``, ``psi`` the azimuth of the line of sight about the candidate axis, fitted by a
    line (rate and phase). (C, 4) principal parameters in the inertial frame."""
    t_m = geometry.telescope[mid]
    l_m = geometry.line_of_sight[mid]
    los = geometry.line_of_sight
    q1 = tumble.quaternion_multiply(conj(t_m), tumble.principal_spin(p1, times, body_axis=body_axis))  # inertial
    a1 = tumble._rotate(conj(t_m), tumble._axis_from_angles(p1[0], p1[1]))
    out = []
    for gamma in np.arange(n_rolls) * 2 * math.pi / n_rolls:
        g = tumble._axis_angle(l_m, np.asarray(gamma))
        ag = tumble._rotate(g, a1)
        perp = np.cross(l_m, ag)
        for tilt in tilts_deg:
            if np.linalg.norm(perp) < 1e-6 and tilt != 0:
                continue
            a = ag if tilt == 0 else tumble._rotate(tumble._axis_angle(perp / np.linalg.norm(perp), np.asarray(math.radians(tilt))), ag)
            qb = tumble.quaternion_multiply(tumble.quaternion_multiply(tumble._align(ag, a), g), q1)  # spin about a
            u = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
            u /= np.linalg.norm(u)
            v = np.cross(a, u)
            psi = np.unwrap(np.arctan2(los @ v, los @ u))
            d1, d0 = np.polyfit(times, psi - psi[mid], 1)
            rate = p1[2] + d1
            if rate <= 0:
                continue
            q0 = tumble.quaternion_multiply(tumble._axis_angle(a, d0), qb[0])
            out.append(principal_params(a, rate, q0, body_axis))
    return np.array(out)


def mirror_image(q: np.ndarray, n: np.ndarray, body_mirror: int) -> np.ndarray:
    """``S R(q) M``: the motion reflected across the plane normal to ``n`` and the body reflected
    across its plane normal to body axis ``body_mirror`` (a symmetry of the target): a proper
    rotation. With a roll-invariant profile and a line of sight in that plane it shows the same
    body-frame lines of sight; its angular velocity is ``rot(n, pi) omega``."""
    from scipy.spatial.transform import Rotation

    s = np.eye(3) - 2 * np.outer(n, n)
    m = np.eye(3)
    m[body_mirror, body_mirror] = -1
    r = s @ matrices(q) @ m
    return Rotation.from_matrix(r).as_quat(scalar_first=True)


def kl(table: Table, like_geometry: tumble.PulseGeometry, q: np.ndarray, q2: np.ndarray) -> float:
    """Expected log-likelihood ratio (noise-free, the table's model) of motion ``q`` against ``q2``."""
    lam = table(like_geometry.attitudes(q))
    lam2 = table(like_geometry.attitudes(q2))
    return float(np.sum(lam * np.log(lam / lam2) - lam + lam2))


def git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def run_pass(args: argparse.Namespace, *, commit: str, rng: np.random.Generator, target: Target, table: Table,
             inst: Instrument, times0: np.ndarray, nominal: float, rate_bounds: tuple[float, float],
             axes: np.ndarray, setup: list[str], model_lines: list[str]) -> None:
    """The study with a moving line of sight (``--sweep``): writes ``args.out``."""
    g = sweep_geometry(times0, args.sweep)
    times = g.reflect_times
    mid = times.size // 2
    n_sweep = np.array([0.0, 1.0, 0.0])
    l_m = g.line_of_sight[mid]
    tilts = tuple(float(x) for x in args.tilts.split(","))
    windows = tuple(float(x) for x in args.windows.split(","))
    like_batch = 64

    def report() -> None:
        r = np.array(rows)
        ok = (r[:, 4] < 5.0) & (r[:, 6] < 0.01)
        ok_mirror = (r[:, 5] < 5.0) & (r[:, 6] < 0.01)
        roll_obs = r[:, 9] > 5.0
        mirror_obs = r[:, 10] > 5.0
        cmd = ("python scripts/spin_recovery.py " + " ".join(
            f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items() if k not in ("out", "cache")))
        lines = [
            f"# Spin-state recovery with a moving line of sight (sweep {args.sweep:g} deg)",
            "",
            f"Generated by `scripts/spin_recovery.py` (`{cmd}`) at commit {commit} on "
            f"{platform.node() or 'unknown host'} ({os.cpu_count()} CPUs, shared). The fixed line of sight "
            "study is [spin-recovery.md](spin-recovery.md): the same truths (its random stream is kept; "
            "each truth's counts here are drawn from their own stream), target, instrument and table.",
            "",
            "Issue 26's target: at SNR 30 per pulse and 100 pulses over a period, >= 90 % of 30 random "
            "principal-axis truths recover the axis within 5 deg and the rate within 1 %.",
            "",
            "## Result",
            "",
            f"- Truths run: **{len(rows)}** of the 30 the target asks for"
            + ("" if len(rows) >= 30 else " (the rest did not fit in the time; the command above with "
               "`--truths 30` runs all)") + ".",
            f"- Axis within 5 deg and rate within 1 %, no symmetry allowed: **{int(ok.sum())} / {len(rows)}** "
            f"({100 * ok.mean():.0f} %).",
            f"- The same, modulo the half turn about the sweep axis (`spin_error(..., line_of_sight=sweep "
            f"axis)`; the mirror image below): **{int(ok_mirror.sum())} / {len(rows)}** "
            f"({100 * ok_mirror.mean():.0f} %).",
            f"- Median axis error {np.median(r[:, 4]):.2f} deg ({np.median(r[:, 5]):.2f} deg modulo the "
            f"half turn), median rate error {np.median(r[:, 6]):.2e}; fit time per truth median "
            f"{np.median(r[:, 8]):.0f} s.",
            f"- Fits whose likelihood is at least the truth's (the search found the global mode or "
            f"better): {int(np.sum(r[:, 7] >= -1e-6))} / {len(rows)}.",
            f"- Roll observable (the truth against its motion turned about the mid-pass line of sight "
            f"by each of {', '.join(str(b) for b in ROLLS_DEG)} deg, with the pass geometry: the "
            f"smallest expected log-likelihood ratio, noise free, in the table's model, > 5): "
            f"{int(roll_obs.sum())} / {len(rows)}.",
            f"- Mirror image observable (log-likelihood ratio against the motion reflected across the "
            f"sweep plane with the body reflected across its `x = 0` symmetry plane, a proper "
            f"rotation whose angular velocity is the truth's turned by a half turn about the sweep "
            f"axis, > 5): {int(mirror_obs.sum())} / {len(rows)}; of those, axis within 5 deg "
            f"(no symmetry) and rate within 1 %: {int(np.sum(ok & mirror_obs))} / "
            f"{int(mirror_obs.sum())}. Of the others, within 5 deg modulo the half turn: "
            f"{int(np.sum(ok_mirror & ~mirror_obs))} / {int(np.sum(~mirror_obs))}.",
            "",
            "What the moving line of sight can still not see: with a roll-invariant profile (the "
            "single-bounce `M11 = -M22` profile, no linear cross terms) the data depend only on the "
            "body-frame line of sight; reflecting the motion across the sweep plane (which holds every "
            "line of sight) and the body across one of its symmetry planes keeps those, so `omega` and "
            "`rot(n, pi) omega` (`n` the sweep axis) remain indistinguishable. Where the polarization "
            "sees the roll, the reflection flips the sign of the `U` and `V` Stokes parameters and the "
            "data can tell them apart. Every rotation about a fixed line of sight (the fixed study's "
            "ambiguity) is broken: it no longer maps the moving lines of sight onto themselves.",
            "",
            "## Setup",
            "",
            f"- Line of sight: inertial, from the target toward the sensor, turning uniformly by "
            f"{args.sweep:g} deg about `+y` (across it) from the first pulse to the last, `+z` at "
            f"mid-pass; telescope `up = +y` (the sweep axis), so the telescope frame turns with the "
            f"line of sight and is the inertial frame at mid-pass (`tumble.pulse_geometry`, no "
            f"relative velocity). Why this and not an orbit: the study's time scale is the spin period "
            f"(everything scales with `T`), and near culmination a LEO pass's line of sight turns "
            f"nearly uniformly on a great circle at `v / rho` (0.87 deg/s for 7.6 km/s at 500 km): "
            f"{args.sweep:g} deg over one period is a {args.sweep / 0.87:.0f} s segment of an overhead "
            f"500 km pass seen for a tumbler of that period; a faster tumbler sees less sweep.",
        ] + setup + [
            f"- Fit (three stages, all in the table's model): (1) the fixed-line-of-sight fit of the "
            f"fixed study at the mid-pass line of sight ({axes.shape[0]} hemisphere axes x "
            f"{args.n_rates} rates x {args.n_phases} phases read off per-axis spin-angle tables, BOBYQA "
            f"from the {args.n_starts} best) on the pulses of windows about mid-pass of "
            f"{', '.join(f'{x:g}' for x in windows)} of the pass (a shorter window sweeps less, so a fixed "
            f"line of sight models it better where the line of sight's azimuth about the axis turns fast): "
            f"it finds the angle between axis and line of sight and the "
            f"rate; (2) each window's best (up to 3 distinct, within 50 in log-likelihood) optima turned about "
            f"the mid-pass line of sight by "
            f"{args.n_rolls} angles, axes tilted by {', '.join(f'{x:g}' for x in tilts)} deg toward the "
            f"line of sight, spin angle corrected for the sweep (`alpha(t) = alpha_1(t) + psi(t) - "
            f"psi(t_m)`, `psi` the line of sight's azimuth about the candidate axis, fitted by a line), "
            f"each scored with the pass geometry; (3) BOBYQA with the pass geometry "
            f"(`fit_spin(geometry=..., n_starts=0, starts=...)`) from the {args.n_refine} best distinct "
            f"(axes > 3 deg apart) candidates, then once more from the best.",
        ] + model_lines + [
            "",
            "## Per truth",
            "",
            "| # | axis-LOS angle at mid-pass (deg) | rate / nominal | SNR (median) | axis err (deg) | "
            "axis err mod half turn (deg) | rate err | logL fit - truth | roll information | "
            "mirror information | fit (s) |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for row in rows:
            lines.append(f"| {row[0]} | {row[1]:.1f} | {row[2]:.3f} | {row[3]:.1f} | {row[4]:.3f} | {row[5]:.3f} | "
                         f"{row[6]:.2e} | {row[7]:+.2f} | {row[9]:.3g} | {row[10]:.3g} | {row[8]:.0f} |")
        args.out.write_text("\n".join(lines) + "\n")

    rows: list[tuple] = []
    for i in range(args.truths):
        truth, axis = draw_truth(rng, nominal)
        rate = float(truth[2])
        q_truth = tumble.principal_spin(truth, times, body_axis=1)
        # the fixed study's counts, drawn only to keep its random stream: the same truths
        q_fixed = tumble.principal_spin(truth, times0, body_axis=1)
        rng.poisson(expected_counts(target.render(q_fixed), inst, bin_edges=table.edges) if args.truth == "render"
                    else table(q_fixed))
        if i < args.start:
            continue
        if args.truth == "render":
            lam = expected_counts(target.render(g.attitudes(q_truth)), inst, bin_edges=table.edges)
        else:
            lam = table(g.attitudes(q_truth))
        counts = np.random.default_rng([args.seed, i]).poisson(lam)
        roll_info = min(kl(table, g, q_truth, tumble.quaternion_multiply(tumble._axis_angle(l_m, np.asarray(math.radians(b))),
                                                                         q_truth)) for b in ROLLS_DEG)
        mirror_info = kl(table, g, q_truth, mirror_image(q_truth, n_sweep, 0))
        snr_pulse = np.sum(lam - table.background, axis=(1, 2)) / np.sqrt(np.sum(lam, axis=(1, 2)))
        t0 = time.perf_counter()
        # stage 1: a fixed line of sight at mid-pass (the mid-pass telescope frame as the inertial one), on
        # the whole pass and on windows about mid-pass (less sweep: a better fixed-line-of-sight model
        # where the line of sight's azimuth about the axis turns fast)
        keep: list[np.ndarray] = []
        for frac in windows:
            n_w = max(8, int(round(frac * times.size)))
            sl = slice(max(0, mid - n_w // 2), max(0, mid - n_w // 2) + n_w)
            fit1 = tumble.fit_spin(counts[sl], table, times[sl], rate_bounds=rate_bounds, body_axis=1, axes=axes,
                                   n_rates=args.n_rates, n_phases=args.n_phases, n_starts=args.n_starts)
            kept: list[np.ndarray] = []
            for c, ll in zip(fit1.candidates, fit1.candidate_log_likelihoods):
                cone = math.acos(abs(math.cos(c[0])))
                if ll < fit1.log_likelihood - 50 or len(kept) == 3:
                    break
                if all(abs(cone - math.acos(abs(math.cos(k[0])))) > math.radians(2) or abs(c[2] / k[2] - 1) > 0.01
                       for k in kept):
                    kept.append(c)
            keep += kept
        # stage 2: the roll family about the mid-pass line of sight, corrected for the sweep
        cands = np.vstack([ring_candidates(c, g, times, mid, 1, args.n_rolls, tilts) for c in keep])
        like = tumble._Likelihood(counts.astype(float), table, g)
        ll2 = np.concatenate([like(tumble.principal_spin(cands[j:j + like_batch], times, body_axis=1))
                              for j in range(0, len(cands), like_batch)])
        starts: list[np.ndarray] = []
        for j in np.argsort(-ll2):
            w = cands[j, 2] * tumble._axis_from_angles(cands[j, 0], cands[j, 1])
            if all(math.degrees(math.acos(np.clip(w @ (s[2] * tumble._axis_from_angles(s[0], s[1]))
                                                  / (abs(w @ w) ** 0.5 * abs(s[2])), -1, 1))) > 3.0 for s in starts):
                starts.append(cands[j])
            if len(starts) == args.n_refine:
                break
        # stage 3: BOBYQA with the pass geometry
        fit = tumble.fit_spin(counts, table, times, geometry=g, rate_bounds=rate_bounds, body_axis=1, n_starts=0,
                              starts=np.array(starts))
        # one BOBYQA restart from the best (its initial trust region again): it leaves narrow ridges
        fit2 = tumble.fit_spin(counts, table, times, geometry=g, rate_bounds=rate_bounds, body_axis=1, n_starts=0,
                               starts=fit.params[None])
        fit = fit2 if fit2.log_likelihood > fit.log_likelihood else fit
        seconds = time.perf_counter() - t0
        ll_truth = float(like(q_truth[None])[0])
        w_true = rate * axis
        strict = math.degrees(math.acos(np.clip(axis @ fit.omega / np.linalg.norm(fit.omega), -1, 1)))
        err_half, rate_err = tumble.spin_error(w_true, fit.omega, line_of_sight=n_sweep)
        cone = math.degrees(math.acos(abs(axis @ l_m)))
        rows.append((i, cone, rate / nominal, float(np.median(snr_pulse)), strict, err_half, rate_err,
                     fit.log_likelihood - ll_truth, seconds, roll_info, mirror_info))
        print(f"truth {i}: axis-LOS {cone:5.1f} deg, rate {rate / nominal:.3f} nominal, axis err {strict:7.3f} deg "
              f"({err_half:6.3f} mod half turn), rate err {rate_err:.2e}, dlogL(fit - truth) "
              f"{fit.log_likelihood - ll_truth:+.2f}, roll info {roll_info:.3g}, mirror info {mirror_info:.3g}, "
              f"{len(cands)} stage-2 candidates, {seconds:.1f} s", flush=True)
        report()
    print(f"wrote {args.out}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--truths", type=int, default=30)
    ap.add_argument("--pulses", type=int, default=100)
    ap.add_argument("--period", type=float, default=10.0, help="observation span T (s), one nominal period")
    ap.add_argument("--snr", type=float, default=30.0)
    ap.add_argument("--resolution", type=int, default=32)
    ap.add_argument("--step", type=float, default=3.0, help="table step in theta and phi (deg)")
    ap.add_argument("--bin", type=float, default=0.03, help="range bin (m)")
    ap.add_argument("--truth", choices=("render", "table"), default="render")
    ap.add_argument("--n-axes", type=int, default=200, help="grid axes on the hemisphere x >= 0")
    ap.add_argument("--n-rates", type=int, default=96)
    ap.add_argument("--n-phases", type=int, default=72)
    ap.add_argument("--n-starts", type=int, default=6)
    ap.add_argument("--check", type=int, default=64, help="random attitudes for the table error")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--cache", type=Path, default=None, help="an .npz to keep the table in between runs")
    ap.add_argument("--sweep", type=float, default=0.0,
                    help="line-of-sight sweep over the observation (deg); > 0: the moving line of sight study")
    ap.add_argument("--n-rolls", type=int, default=72, help="(--sweep) stage-2 turns about the line of sight")
    ap.add_argument("--tilts", default="-4,0,4", help="(--sweep) stage-2 axis tilts toward the line of sight (deg)")
    ap.add_argument("--n-refine", type=int, default=4, help="(--sweep) stage-3 BOBYQA starts")
    ap.add_argument("--start", type=int, default=0,
                    help="(--sweep) first truth to fit (the earlier ones are drawn, not fitted)")
    ap.add_argument("--windows", default="1,0.34",
                    help="(--sweep) stage-1 windows about mid-pass, fractions of the pulses")
    ap.add_argument("--out", type=Path, default=None,
                    help="default docs/spin-recovery.md, docs/spin-recovery-pass.md with --sweep")
    args = ap.parse_args()
    if args.out is None:
        args.out = ROOT / "docs" / ("spin-recovery-pass.md" if args.sweep else "spin-recovery.md")
    if not 0 <= args.sweep < 180:
        ap.error(f"--sweep {args.sweep}: expected 0 <= sweep < 180 (deg)")

    commit = git_commit()  # the code that runs, recorded before anything else is committed
    rng = np.random.default_rng(args.seed)
    target = Target(args.resolution, args.bin)
    # the instrument's scale is set on the table's mean profile below
    inst0 = Instrument(pulse_energy=1.0, target_range=1e6, channels="stokes")
    table = Table(target, args.step, inst0, args.cache)
    mean_profile = table.profiles.mean(axis=(0, 1))
    # S / sqrt(1.1 S) = snr -> S = 1.1 snr^2; background B = 0.1 S per pulse over all bins and channels
    s_target = 1.1 * args.snr**2
    inst = inst0.scaled_to(s_target, mean_profile, bin_edges=table.edges)
    n_bins, n_ch = len(table.edges) - 1, len(inst.channels)
    gate_s = 2 * (table.edges[-1] - table.edges[0]) / pprender.SPEED_OF_LIGHT
    bg_rate = 0.1 * s_target / (gate_s * n_ch)
    from dataclasses import replace

    inst = replace(inst, background_rate=bg_rate)
    table.set_instrument(inst)
    t_build = table.build_s

    # table error against direct renders
    q_check = so3.random(args.check, seed=args.seed + 1)
    direct = expected_counts(target.render(q_check), inst, bin_edges=table.edges)
    tab = table(q_check)
    sig_direct = direct - table.background
    rel_l1 = float(np.sum(np.abs(tab - direct)) / np.sum(sig_direct))
    chi2 = np.sum((tab - direct) ** 2 / np.maximum(direct, 1e-12), axis=(1, 2))  # per pulse
    snr_direct = np.sum(sig_direct, axis=(1, 2)) / np.sqrt(np.sum(direct, axis=(1, 2)))

    times = np.arange(args.pulses) * args.period / args.pulses
    nominal = 2 * math.pi / args.period
    rate_bounds = (0.7 * nominal, 1.4 * nominal)
    axes = tumble._fibonacci_sphere(2 * args.n_axes)
    axes = axes[axes[:, 0] >= 0]
    if args.sweep:
        setup = [
            f"- Target: 3U CubeSat (deployed panels, no antenna, `detail=0`), aluminium alpha 0.3, "
            f"`bounces=2`, `resolution={args.resolution}`; spin about body `y` (largest moment).",
            f"- Pulses: {args.pulses} over T = {args.period:g} s; truth rates 0.8-1.25 x 2 pi / T, axes uniform, "
            f"phases uniform; fit rate bounds 0.7-1.4 x 2 pi / T.",
            f"- Instrument: `\"stokes\"` preset, scaled so the table's mean signal is {s_target:.0f} counts per "
            f"pulse with 10 % background (SNR {args.snr:g}); {n_bins} bins of "
            f"{table.edges[1] - table.edges[0]:.3f} m x {n_ch} channels.",
            f"- Truth counts from: {'direct renders' if args.truth == 'render' else 'the table'}; fits use the table "
            f"(roll about the line of sight applied exactly, valid for any line of sight).",
        ]
        model_lines = [
            f"- Table: {table.n_theta} x {table.n_phi} line-of-sight directions ({args.step:g} deg); error "
            f"against direct renders on {args.check} random attitudes: sum |table - direct| / signal = "
            f"{rel_l1:.3f}, chi-square of the difference per pulse median {np.median(chi2):.1f} over "
            f"{n_bins * n_ch} bins x channels.",
        ]
        run_pass(args, commit=commit, rng=rng, target=target, table=table, inst=inst, times0=times, nominal=nominal,
                 rate_bounds=rate_bounds, axes=axes, setup=setup, model_lines=model_lines)
        return
    def report() -> None:
        r = np.array(rows)
        ok = (r[:, 4] < 5.0) & (r[:, 5] < 0.01)
        ok_cone = (r[:, 6] < 5.0) & (r[:, 5] < 0.01)
        observable = r[:, 10] > 5.0
        # the issue's score: modulo the symmetries the data cannot see. Where the roll about
        # the line of sight is observable, no symmetry is allowed beyond the half turn (which
        # a monostatic profile never sees); where it is not (a roll-invariant profile
        # throughout), the roll is a symmetry and only the axis-LOS angle and the rate count
        ok_issue = np.where(observable, ok, ok_cone)
        lines = [
            "# Spin-state recovery (principal-axis spin)",
            "",
            "Generated by `scripts/spin_recovery.py` (`python scripts/spin_recovery.py "
            + " ".join(f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items() if k not in ("out", "cache"))
            + f"`) at commit {commit} on {platform.node() or 'unknown host'} "
            f"({os.cpu_count()} CPUs, shared).",
            "",
            "Issue 26's target: at SNR 30 per pulse and 100 pulses over a period, >= 90 % of 30 random "
            "principal-axis truths recover the axis within 5 deg and the rate within 1 %.",
            "",
            "## Result",
            "",
            f"- Truths run: **{len(rows)}** of the 30 the target asks for"
            + ("" if len(rows) >= 30 else " (the rest did not fit in the time; the full-run command is above)")
            + ".",
            f"- Scored as the issue asks, modulo the symmetries the data cannot see: axis within 5 deg "
            f"and rate within 1 %, modulo the half turn about the line of sight where the roll is "
            f"observable (below), and modulo any roll about it where the roll is not (there the "
            f"axis-LOS angle within 5 deg): **{int(ok_issue.sum())} / {len(rows)}** "
            f"({100 * ok_issue.mean():.0f} %; the target is 27 / 30).",
            f"- Axis within 5 deg (modulo the half turn about the line of sight) and rate within 1 %, "
            f"whether or not the roll is observable: {int(ok.sum())} / {len(rows)} ({100 * ok.mean():.0f} %).",
            f"- Roll-invariant score (angle between axis and line of sight within 5 deg, rate within 1 %): "
            f"{int(ok_cone.sum())} / {len(rows)}.",
            f"- Median axis error {np.median(r[:, 4]):.2f} deg, median rate error {np.median(r[:, 5]):.2e}; "
            f"fit time per truth median {np.median(r[:, 8]):.0f} s "
            f"({int(np.median(r[:, 9]))} likelihood evaluations of {args.pulses} pulses each).",
            f"- Fits whose likelihood is at least the truth's (the optimizer found the global mode or "
            f"better): {int(np.sum(r[:, 7] >= -1e-6))} / {len(rows)}.",
            f"- Roll observable (the truth against its motion turned about the line of sight by each of "
            f"{', '.join(str(b) for b in ROLLS_DEG)} deg: the smallest expected log-likelihood ratio, "
            f"noise free, in the table's model, > 5): {int(np.sum(observable))} / {len(rows)}; of those, axis within 5 deg "
            f"and rate within 1 %: {int(np.sum(ok & observable))} / {int(np.sum(observable))}; of the "
            f"others, axis-LOS angle within 5 deg and rate within 1 %: "
            f"{int(np.sum(ok_cone & ~observable))} / {int(np.sum(~observable))} (the smallest ratio "
            f"of the observable ones is {r[observable, 10].min() if observable.any() else float('nan'):.3g}, "
            f"the largest of the others {r[~observable, 10].max() if (~observable).any() else float('nan'):.3g}: "
            f"the threshold does not decide any truth). Where the "
            f"ratio is 0 the line of sight never meets the panel-bus dihedrals during the observation; "
            f"the single-bounce Mueller profile (`M11 = -M22`, no off-diagonal linear terms) is then "
            f"exactly roll invariant and no estimator can find the axis's azimuth about the line of "
            f"sight.",
            "",
            "## Setup",
            "",
            f"- Target: 3U CubeSat (deployed panels, no antenna, `detail=0`), aluminium alpha 0.3, "
            f"`bounces=2`, `resolution={args.resolution}`; spin about body `y` (largest moment).",
            f"- Pulses: {args.pulses} over T = {args.period:g} s; truth rates 0.8-1.25 x 2 pi / T, axes uniform, "
            f"phases uniform; fit rate bounds 0.7-1.4 x 2 pi / T.",
            f"- Instrument: `\"stokes\"` preset, scaled so the table's mean signal is {s_target:.0f} counts per "
            f"pulse with 10 % background (SNR {args.snr:g}); the truths' median per-pulse SNR is "
            f"{np.median(r[:, 3]):.1f} (it varies with attitude: specular flashes); {n_bins} bins of "
            f"{table.edges[1] - table.edges[0]:.3f} m x {n_ch} channels.",
            f"- Truth counts from: {'direct renders' if args.truth == 'render' else 'the table'}; fits use the table.",
            f"- Fit grid: {axes.shape[0]} axes (hemisphere x >= 0: the line-of-sight half turn maps it onto "
            f"the other half) x {args.n_rates} rates x {args.n_phases} phases, then BOBYQA from the "
            f"{args.n_starts} best.",
            "",
            "## Forward-model table",
            "",
            f"- {table.n_theta} x {table.n_phi} line-of-sight directions ({args.step:g} deg), rendered in "
            f"{t_build:.0f} s; roll applied exactly as `L(-psi) M L(-psi)`.",
            f"- Error against direct renders on {args.check} random attitudes: sum |table - direct| / signal = "
            f"{rel_l1:.3f}; chi-square of the difference per pulse (sum (table - direct)^2 / direct): median "
            f"{np.median(chi2):.1f}, 90th percentile {np.percentile(chi2, 90):.1f} over {n_bins * n_ch} "
            f"bins x channels (1 per bin would equal the shot noise); direct per-pulse SNR median "
            f"{np.median(snr_direct):.1f}.",
            "",
            "## Per truth",
            "",
            "| # | axis-LOS angle (deg) | rate / nominal | SNR (median) | axis err (deg) | rate err | "
            "axis-LOS err (deg) | logL fit - truth | roll information | fit (s) |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for row in rows:
            lines.append(f"| {row[0]} | {row[1]:.1f} | {row[2]:.3f} | {row[3]:.1f} | {row[4]:.3f} | {row[5]:.2e} | "
                         f"{row[6]:.3f} | {row[7]:+.2f} | {row[10]:.3g} | {row[8]:.0f} |")
        args.out.write_text("\n".join(lines) + "\n")

    rows: list[tuple] = []
    for i in range(args.truths):
        truth, axis = draw_truth(rng, nominal)
        rate = float(truth[2])
        q_truth = tumble.principal_spin(truth, times, body_axis=1)
        if args.truth == "render":
            lam = expected_counts(target.render(q_truth), inst, bin_edges=table.edges)
        else:
            lam = table(q_truth)
        counts = rng.poisson(lam)
        roll_info = min(roll_information(table, q_truth, b) for b in ROLLS_DEG)
        snr_pulse = np.sum(lam - table.background, axis=(1, 2)) / np.sqrt(np.sum(lam, axis=(1, 2)))
        fit = tumble.fit_spin(counts, table, times, rate_bounds=rate_bounds, body_axis=1, axes=axes,
                              n_rates=args.n_rates, n_phases=args.n_phases, n_starts=args.n_starts)
        like = tumble._Likelihood(counts.astype(float), table, None)
        ll_truth = float(like(q_truth[None])[0])
        err, rate_err = tumble.spin_error(rate * axis, fit.omega)
        cone_err, _ = tumble.spin_error(rate * axis, fit.omega, roll_invariant=True)
        cone = math.degrees(math.acos(abs(axis[2])))
        rows.append((i, cone, rate / nominal, float(np.median(snr_pulse)), err, rate_err, cone_err,
                     fit.log_likelihood - ll_truth, fit.seconds, fit.evaluations, roll_info))
        print(f"truth {i}: axis-LOS {cone:5.1f} deg, rate {rate / nominal:.3f} nominal, "
              f"axis err {err:7.3f} deg, rate err {rate_err:.2e}, cone err {cone_err:6.3f} deg, "
              f"dlogL(fit - truth) {fit.log_likelihood - ll_truth:+.2f}, roll info {roll_info:.3g}, "
              f"{fit.seconds:.1f} s", flush=True)
        report()
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
