"""Inter-reflections in the co- and cross-polarized linear channels against live Mitsuba 3
renders: the polarizer-sheet set-up (``mitsuba_corners.mitsuba_polarized_totals``).

Mitsuba's emitters are unpolarized, so its ``stokes`` renders show only the first column of
a Mueller matrix. An ideal linear polarizer sheet between the orthographic camera's origin
and its near-clip plane (``volpath``) polarizes the next-event rays toward the emitter and
not the camera rays, so Mitsuba renders ``M s_t`` for a linear transmitted state ``s_t``.
The tests check that the sheet does that (Malus on a flat plate; the camera rays, once made
to cross it, are analyzed), fix which sheet angle is which pprender ``polarization`` (one
bounce on flat plates), then compare a rough-aluminium dihedral's second bounce in the co
and cross channels (H transmit) and the full Stokes vector per bounce order (+45 transmit).

Noise and tolerances: Mitsuba (two seeds, 1 and 2) and pprender (two seeds, 0 and 1) are
each the mean of two renders; the standard deviation of that mean comes from the per-pixel
seed differences, ``sqrt(sum_pix (a - b)^2) / 2`` (pixels are independent in both
renderers; many more degrees of freedom than the two totals' difference). A value agrees
when ``|pprender - Mitsuba| < 4 sqrt(sd_M^2 + sd_p^2)`` plus a small systematic allowance,
0.3% of the order's S0: Mitsuba's float32 images, and its illumination tilted by +-2e-3 rad
(the set-up's work-around for a wrong Fresnel frame at exact backscatter), which moves the
dihedral's S0 by under 1e-4; ``scripts/corner_co_cross.py`` finds the second bounce's co
and cross within 0.2% with 16 times Mitsuba's samples and 8 times pprender's paths
(docs/corner-co-cross.md). pprender uses analytic pixel coverage, so its one-bounce part is
exact (no noise). At these sizes the tolerance on the second bounce's dominant channel (co
at psi = 0, cross at 45 deg) is 1.7-2.3% of it, and 2-3.5% on co and cross at 22.5 deg; a
V transmit (a wrong convention) swaps co and cross at psi = 0 and 45 deg, by factors of
4 to 50, and fails by far (checked).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

import mitsuba_corners as mc

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
from corner_co_cross import aluminium, mitsuba_orders, plate, pprender_orders, ry, rz  # noqa: E402

import pprender  # noqa: E402

RES, SPP, PATHS = 48, 64, 32
H = (1.0, 1.0, 0.0, 0.0)


def _agree(ours: np.ndarray, our_sd: np.ndarray, theirs: np.ndarray, their_sd: np.ndarray, scale: np.ndarray,
           rel: float = 3e-3) -> np.ndarray:
    """Where ``|ours - theirs| < 4 combined standard deviations + rel * scale``."""
    return np.abs(ours - theirs) < 4.0 * np.hypot(our_sd, their_sd) + rel * scale


def test_the_sheet_polarizes_the_illumination_and_not_the_camera_rays(mitsuba):
    """A face-on plate returns the illumination's linear polarization: turning the sheet by
    theta gives S1/S0 = cos 2 theta, S2/S0 = -sin 2 theta (Malus: I_X = S0 cos^2 theta)
    with S0 that of unpolarized light (the emitter's irradiance is doubled to make up for
    the sheet's half), so the shadow rays cross the sheet. With the near-clip plane moved
    so that the camera rays cross it too, the sheet also analyzes the received light: the
    dihedral at psi = 45 deg (nearly a cross-polarizer) then returns only its small
    co-polarized part, (S0 + S1)/2 of the set-up's render within 4 standard deviations of
    the difference (per-pixel, independent seeds); so in the set-up the camera rays do not
    cross it."""
    mesh = plate()
    unpol = mc.mitsuba_polarized_totals(mesh, mc.roughconductor(0.3), np.eye(3), 2, 16, 32, 1, polarizer_deg=None)[0]
    for theta in (0.0, 30.0, 60.0, 90.0, 135.0):
        s = mc.mitsuba_polarized_totals(mesh, mc.roughconductor(0.3), np.eye(3), 2, 16, 32, 1, polarizer_deg=theta)[0]
        t = math.radians(theta)
        assert abs(s[0] / unpol[0] - 1) < 1e-4, (theta, s, unpol)
        np.testing.assert_allclose(s[1:] / s[0], [math.cos(2 * t), -math.sin(2 * t), 0.0], atol=1e-4)
    rot = rz(45.0) @ mc.dihedral_rotation(0.0)
    bsdf = mc.roughconductor(0.1)
    res = 32
    setup, a = mc.mitsuba_polarized_totals(mc.dihedral(), bsdf, rot, 3, 64, res, 1, return_images=True)
    crossing, b = mc.mitsuba_polarized_totals(mc.dihedral(), bsdf, rot, 3, 64, res, 2, sheet_analyzes=True,
                                              return_images=True)
    co = 0.5 * (setup[0, 0] + setup[0, 1])
    scale = 4.0 * math.pi * (2.0 * mc.extent(mc.dihedral()) / res) ** 2
    sd = scale * math.sqrt(float(np.sum((0.5 * (a[0, ..., 0] + a[0, ..., 1]) - b[0, ..., 0]).astype(np.float64) ** 2)))
    assert co < 0.1 * setup[0, 0], setup  # the set-up sees the cross-polarized return
    assert abs(crossing[0, 0] - co) < 4 * sd, (crossing, co, sd)
    assert abs(crossing[0, 1] - crossing[0, 0]) < 1e-6 * crossing[0, 0]  # analyzed: all along X


def test_sheet_angles_are_pprenders_transmitted_states(mitsuba):
    """One bounce on a flat plate (alpha 0.3; face-on, 30 deg about Y, and that rolled by
    25 deg), where pprender's Mueller matrix is already validated: sheet theta 0, 90 and 45
    are pprender's H [1, 1, 0, 0], V [1, -1, 0, 0] and +45 [1, 0, 1, 0] (transmit basis
    (X, -Y)), and the flipped sheet at 45 is -45: the normalized Stokes vectors agree to
    1e-4 and S0 to 0.5% (Mitsuba samples the plate's edges in the pixels: 64 spp at 32 x 32)."""
    mesh = plate()
    rots = np.stack([np.eye(3), ry(30.0), rz(25.0) @ ry(30.0)])
    sc = pprender.Scene(mesh, aluminium(0.3))
    for theta, flipped, transmit in ((0.0, False, [1, 1, 0, 0]), (90.0, False, [1, -1, 0, 0]),
                                     (45.0, False, [1, 0, 1, 0]), (45.0, True, [1, 0, -1, 0])):
        m = mc.mitsuba_polarized_totals(mesh, mc.roughconductor(0.3), rots, 2, 64, 32, 1, polarizer_deg=theta,
                                        flip_sheet=flipped)
        p = pprender.render(sc, pprender.Lidar(resolution=32, polarization=transmit, arithmetic="f64",
                                               coverage="analytic"), rots, outputs=("profile",)).cross_section
        np.testing.assert_allclose(m / m[:, :1], p / p[:, :1], atol=1e-4, err_msg=f"theta {theta} {transmit}")
        np.testing.assert_allclose(m[:, 0], p[:, 0], rtol=5e-3)


def test_dihedral_second_bounce_co_and_cross_match_mitsuba(mitsuba):
    """The 0.3 m, 90 deg rough-aluminium dihedral (alpha 0.3 and 0.1) seen along its axis
    and 20 deg across its opening, its edge rolled to psi = 0, 22.5 and 45 deg from the
    image's Y axis, H transmit: the second bounce's co (S0 + S1)/2, cross (S0 - S1)/2, S2
    and S3 agree with Mitsuba's (``max_depth`` 3 minus 2, same seed) within 4 combined
    standard deviations + 0.3% of its S0 (module docstring). And the physics: nearly
    co-polarized at psi = 0 (cross under 25% of co), nearly a cross-polarizer at 45 (co
    under 30% of cross), mixed at 22.5 (co and cross within 5% of S0)."""
    mesh = mc.dihedral()
    views = [(t, p) for t in (0.0, 20.0) for p in (0.0, 22.5, 45.0)]
    rots = np.stack([rz(p) @ mc.dihedral_rotation(t) for t, p in views])
    for alpha in (0.3, 0.1):
        mit, mit_sd = mitsuba_orders(mesh, alpha, rots, 2, 0.0, SPP, RES)
        ours, our_sd = pprender_orders(mesh, alpha, rots, 2, H, RES, PATHS)
        m, p, msd, psd = mit[:, 1], ours[:, 1], mit_sd[:, 1], our_sd[:, 1]  # (view, S0..S3 co cross)
        ok = _agree(p[:, 2:], psd[:, 2:], m[:, 2:], msd[:, 2:], m[:, :1])
        assert ok.all(), (alpha, views, np.c_[m[:, 2:], p[:, 2:]], msd[:, 2:], psd[:, 2:])
        for x in (m, p):
            co, cross = x[:, 4], x[:, 5]
            psi = np.array([v[1] for v in views])
            assert np.all(cross[psi == 0.0] < 0.25 * co[psi == 0.0]), (alpha, x)
            assert np.all(co[psi == 45.0] < 0.3 * cross[psi == 45.0]), (alpha, x)
            assert np.all(np.abs(co - cross)[psi == 22.5] < 0.05 * x[psi == 22.5, 0]), (alpha, x)


def test_dihedral_full_stokes_per_bounce_order_for_plus_45(mitsuba):
    """+45 transmit (sheet theta 45, pprender [1, 0, 1, 0]): the dihedral at alpha 0.3,
    20 deg across its opening, edge at psi = 22.5 deg, where every Stokes component is
    non-zero after two bounces (S3 from the aluminium's retardance: it checks the circular
    sign convention the flat plate cannot). Orders 1, 2 and 3 (Mitsuba ``max_depth`` 2,
    3 - 2, 4 - 3): each of S0..S3 within 4 combined standard deviations + 0.3% of the
    order's S0."""
    mesh = mc.dihedral()
    rot = (rz(22.5) @ mc.dihedral_rotation(20.0))[None]
    mit, mit_sd = mitsuba_orders(mesh, 0.3, rot, 3, 45.0, SPP, RES)
    ours, our_sd = pprender_orders(mesh, 0.3, rot, 3, (1.0, 0.0, 1.0, 0.0), RES, PATHS)
    m, p, msd, psd = mit[0, :, :4], ours[0, :, :4], mit_sd[0, :, :4], our_sd[0, :, :4]
    assert np.all(np.abs(m[1]) > 0.05 * m[1, 0]), m  # all four components present in the second bounce
    assert m[2, 0] > 0.02 * m[:, 0].sum(), m  # the third order is not negligible here
    ok = _agree(p, psd, m, msd, m[:, :1])
    assert ok.all(), (m, p, msd, psd)
