"""APS masking for Blinn-Phong: exact references vs mpmath, and the seed's approximation.

References here are computed with mpmath (30 digits) from the definitions, independently
of the code's reductions:

- ``<h.k>+ = int rho(h) max(0, h.k) d omega`` with ``rho = (m+1)/(2 pi) cos^m(theta_h)``,
  as an integral over ``theta_h`` of the azimuthal integral of ``max(0, A cos(phi) + B)``
  (``A = sin theta_h sin theta_k``, ``B = cos theta_h cos theta_k``), done in closed form
  ``2 (sqrt(A^2 - B^2) + B acos(-B/A))`` (or ``2 pi B``) and checked here against a nested
  2D ``mpmath.quad`` over ``(theta_h, phi)``;
- ``int_a^{pi/2} cos^m`` by ``mpmath.quad`` with breakpoints on the integrand's scale;
- ``A(m)`` from mpmath's gamma function.

Tolerances: the references carry ~25 correct digits, so the tolerance is the float64
evaluation's own error. The code's answers are float64 functions of float64 inputs; their
rounding error is a few eps times the number of operations plus the conditioning of
``cos^{m+1}`` (exponents up to ~708 carried in float64: < 1e-13), so 1e-12 (1e-10 for
``<h.k>+``, whose quadrature panels sum ~100 terms and whose grazing offset ``pi/2 - theta_k``
inherits FRAC_PI_2's 6e-17 error, ~2e-13 relative at m = 1e7) catches any algorithmic or
truncation error, which would show at 1e-9 or above. The code claims ~1e-13.
"""

from __future__ import annotations

import functools
import json
import math
import re
from pathlib import Path

import mpmath as mp
import numpy as np
import pytest

import pprender
import pprender.microfacet as mf

mp.mp.dps = 30
HALF_PI = math.pi / 2
DOC = Path(__file__).resolve().parent.parent / "docs" / "seed-approximation.md"

M_TEST = [0.0, 1.0, 10.0, 1e3, 1e5, 1e7]
THETA_TEST = [0.0, 0.5, 1.2, HALF_PI - 1e-3, HALF_PI - 1e-7]


# ----------------------------------------------------------------------------- references
def _phi_integral(th: mp.mpf, tk: mp.mpf) -> mp.mpf:
    """int_0^{2 pi} max(0, A cos(phi) + B) dphi, closed form (A, B >= 0)."""
    a, b = mp.sin(th) * mp.sin(tk), mp.cos(th) * mp.cos(tk)
    if a <= b:
        return 2 * mp.pi * b
    return 2 * (mp.sqrt(a * a - b * b) + b * mp.acos(-b / a))


def _theta_points(m: float, tk: mp.mpf) -> list:
    """Breakpoints in theta_h: the peak's scale 1/sqrt(m+1) and the kink at pi/2 - theta_k."""
    w = 1 / mp.sqrt(mp.mpf(m) + 1)
    pts = {mp.mpf(0), mp.pi / 2, mp.pi / 2 - tk}
    pts.update(w * x for x in (0.25, 0.5, 1, 2, 3, 4, 6, 8, 11, 15, 20))
    return sorted(p for p in pts if 0 <= p <= mp.pi / 2)


def mp_hk_plus(m: float, theta_k: float) -> mp.mpf:
    """<h.k>+ from its definition: theta_h quadrature of the closed-form phi integral, at
    the working precision (cached per precision)."""
    return _mp_hk_plus(m, theta_k, mp.mp.dps)


@functools.lru_cache(maxsize=None)
def _mp_hk_plus(m: float, theta_k: float, _dps: int) -> mp.mpf:
    mm, tk = mp.mpf(m), mp.mpf(theta_k)
    norm = (mm + 1) / (2 * mp.pi)
    f = lambda th: norm * mp.cos(th) ** mm * mp.sin(th) * _phi_integral(th, tk)  # noqa: E731
    return mp.quad(f, _theta_points(m, tk))


def mp_hk_plus_2d(m: float, theta_k: float) -> mp.mpf:
    """The same by a nested 2D quadrature over (theta_h, phi), phi split where h.k = 0."""
    mm, tk = mp.mpf(m), mp.mpf(theta_k)
    norm = (mm + 1) / (2 * mp.pi)

    def inner(th):
        a, b = mp.sin(th) * mp.sin(tk), mp.cos(th) * mp.cos(tk)
        phi0 = mp.pi if a <= b else mp.acos(-b / a)  # h.k > 0 for |phi| < phi0
        return 2 * mp.quad(lambda p: a * mp.cos(p) + b, [0, phi0])

    return mp.quad(lambda th: norm * mp.cos(th) ** mm * mp.sin(th) * inner(th), _theta_points(m, tk))


@functools.lru_cache(maxsize=None)
def mp_wallis(m: float) -> mp.mpf:
    mm = mp.mpf(m)
    return mp.sqrt(mp.pi) / 2 * mp.gamma((mm + 1) / 2) / mp.gamma(mm / 2 + 1)


@functools.lru_cache(maxsize=None)
def mp_incomplete(m: float, alpha: float) -> mp.mpf:
    """int_alpha^{pi/2} cos^m by mpmath.quad; (cos t/cos alpha)^m is integrated (O(1), as
    mpmath's tolerance is absolute) with breakpoints doubling from alpha."""
    mm, a = mp.mpf(m), mp.mpf(alpha)
    if a < 0:
        return mp.quad(lambda t: mp.cos(t) ** mm, [a, 0]) + mp_incomplete(m, 0.0)
    if a >= mp.pi / 2:
        return mp.mpf(0)
    scale = 1 / mp.sqrt(mm + 1)
    if a > 0:
        scale = min(scale, 1 / ((mm + 1) * mp.tan(a)))
    pts, x, ca = [a], a, mp.cos(a)
    step = scale / 4
    while True:
        x = x + step
        step *= 2
        if x >= mp.pi / 2:
            break
        pts.append(x)
        if mm * mp.log(mp.cos(x) / ca) < -160:
            break
    pts.append(mp.pi / 2)
    return ca**mm * mp.quad(lambda t: (mp.cos(t) / ca) ** mm, pts)


def rel(x: float, ref: mp.mpf) -> float:
    return float(abs(mp.mpf(float(x)) / ref - 1))


# ----------------------------------------------------------------------------- the reference itself
@pytest.mark.parametrize("m,theta_k", [(0.0, 0.5), (0.0, HALF_PI - 1e-3), (10.0, 1.2), (10.0, HALF_PI - 1e-7), (1e3, 1.5)])
def test_reference_phi_closed_form_matches_2d_quadrature(m, theta_k):
    mp.mp.dps = 20
    try:
        two_d = mp_hk_plus_2d(m, theta_k)
    finally:
        mp.mp.dps = 30
    assert abs(two_d / mp_hk_plus(m, theta_k) - 1) < 1e-15


def test_reference_limits():
    # <h.k>+ = <h.n> = (m+1)/(m+2) at normal incidence, A(m+2)/pi at grazing (closed forms)
    for m in (0.0, 10.0, 1e5):
        assert abs(mp_hk_plus(m, 0.0) / ((m + 1) / mp.mpf(m + 2)) - 1) < 1e-25
        g = mp.quad(lambda th: (m + 1) / (2 * mp.pi) * mp.cos(th) ** m * mp.sin(th) * _phi_integral(th, mp.pi / 2),
                    _theta_points(m, mp.pi / 2))
        assert abs(g / (mp_wallis(m + 2) / mp.pi) - 1) < 1e-25


# ----------------------------------------------------------------------------- exact references
@pytest.mark.parametrize("m", M_TEST)
def test_hk_plus_exact(m):
    th = np.array(THETA_TEST)
    code = mf.hk_plus(th, m=m)
    eq18 = mf.hk_plus_eq18(m, th)
    for t, c, e in zip(THETA_TEST, code, eq18):
        ref = mp_hk_plus(m, t)
        assert rel(c, ref) < 1e-10, f"hk_plus m={m} theta={t}: {rel(c, ref):.2e}"
        assert rel(e, ref) < 1e-10, f"hk_plus_eq18 m={m} theta={t}: {rel(e, ref):.2e}"
    # P = <h.n> cos / <h.k>+
    p = mf.aps_masking(th, m=m)
    hn = (m + 1) / (m + 2)
    for t, pv in zip(THETA_TEST, p):
        ref = hn * mp.cos(mp.mpf(t)) / mp_hk_plus(m, t)
        assert abs(pv - float(ref)) <= 1e-10 * float(ref) + 1e-300


def _alpha_test(m: float) -> list[float]:
    w = math.sqrt(2 / (m + 1))
    # (alpha = HALF_PI is taken as pi/2 exactly, where the integral is 0: asserted below)
    return [0.0, 1e-300, 1e-7, 1e-3, 0.3 * w, w, 3 * w, 0.5, 1.2, HALF_PI - 1e-3, HALF_PI - 1e-7,
            -1e-7, -0.5, -HALF_PI]


@pytest.mark.parametrize("m", M_TEST)
def test_incomplete_cos_pow_exact(m):
    alphas = [a for a in _alpha_test(m) if abs(a) <= HALF_PI]
    got = mf.incomplete_cos_pow(m, np.array(alphas))
    for a, g in zip(alphas, got):
        ref = mp_incomplete(m, a)
        if ref > mp.mpf("1e-290"):
            assert rel(g, ref) < 1e-12, f"m={m} alpha={a}: {g} vs {mp.nstr(ref, 17)}"
        else:  # below float64's range: must underflow, not blow up
            assert 0.0 <= g < 1e-280
    assert mf.incomplete_cos_pow(m, HALF_PI) == 0.0


@pytest.mark.parametrize("m", [0.0, 0.5, 1.0, 2.0, 3.3, 15.99, 16.0, 16.01, 100.0, 1e3, 12345.678, 1e5, 1e6, 1e7, 1e10])
def test_wallis_exact(m):
    assert rel(mf.wallis(m), mp_wallis(m)) < 5e-15


# ----------------------------------------------------------------------------- the seed's approximation
def _doc_bounds() -> dict:
    text = DOC.read_text()
    match = re.search(r"<!-- seed-bounds (\{.*?\}) -->", text)
    assert match, "docs/seed-approximation.md lacks its seed-bounds block: run scripts/seed_table.py"
    return json.loads(match.group(1))


def _theta_grid(m: float) -> list[float]:
    """Same as scripts/seed_table.py's theta_grid (the documented grid)."""
    fixed = [0.0, 0.3, 0.7, 1.0, 1.2, 1.4, 1.5, 1.55]
    near = [HALF_PI - d for d in (1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 1e-6, 1e-7)]
    scaled = [HALF_PI - x * math.sqrt(2.0 / (m + 2.0)) for x in (0.1, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0)]
    return sorted({t for t in fixed + near + scaled if 0.0 <= t <= HALF_PI})


def test_seed_approximation_within_documented_bounds():
    """Re-measure the seed's <h.k>+ and P(k) errors against this file's own references on
    (a subset of) the documented grid: they must stay within the documented bounds, and
    the bounds must be attained (not loose)."""
    bounds = _doc_bounds()
    # 20 digits: the errors measured are 1e-4 and up, the references good to ~1e-18 there
    # (test_reference_phi_closed_form_matches_2d_quadrature checks them at 20 digits)
    with mp.workdps(20):
        worst_hk, worst_pa, worst_pr = _seed_worst()
    assert worst_hk <= bounds["seed_hk_plus_rel"], worst_hk
    assert worst_pa <= bounds["seed_p_abs"], worst_pa
    assert worst_pr <= bounds["seed_p_rel"], worst_pr
    assert worst_hk > 0.95 * bounds["seed_hk_plus_rel"]
    assert worst_pa > 0.95 * bounds["seed_p_abs"]


def _seed_worst() -> tuple[float, float, float]:
    """The seed's largest <h.k>+ relative error and P(k) absolute and relative errors over
    M_TEST and the documented theta grid, against this file's references."""
    worst_hk = worst_pa = worst_pr = 0.0
    for m in M_TEST:
        th = _theta_grid(m)
        seed_hk = mf.seed_hk_plus(m, np.array(th))
        seed_p = mf.seed_aps_p(m, np.array(th))
        hn = (m + 1) / (m + 2)
        for t, s, p in zip(th, seed_hk, seed_p):
            ref = mp_hk_plus(m, t)
            p_ref = float(hn * mp.cos(mp.mpf(t)) / ref)
            worst_hk = max(worst_hk, rel(s, ref))
            worst_pa = max(worst_pa, abs(p - p_ref))
            if p_ref > 0:
                worst_pr = max(worst_pr, abs(p / p_ref - 1))
    return worst_hk, worst_pa, worst_pr


def test_seed_wallis_and_eq19_within_documented_bounds():
    bounds = _doc_bounds()
    ms = [0.0, 1.0, 10.0, 100.0, 1e3, 1e4, 1e5, 1e6, 1e7]
    worst = max(rel(mf.seed_wallis(m), mp_wallis(m)) for m in ms)
    assert worst <= bounds["seed_wallis_rel"]
    assert mf.seed_wallis(0.0) == HALF_PI  # eq. 22 is exact at m = 0
    # eq. 19 (our reading): |error| / A(m) on the peak scale, where it is largest
    worst19 = 0.0
    for m in M_TEST:
        alphas = [x * math.sqrt(2 / (m + 1)) for x in (0.3, 0.5642, 1.0)]
        alphas = [a for a in alphas if a <= HALF_PI]
        approx = mf.seed_incomplete_cos_pow(m, np.array(alphas), exact_wallis=True)
        for a, v in zip(alphas, approx):
            worst19 = max(worst19, float(abs(v - mp_incomplete(m, a)) / mp_wallis(m)))
    assert worst19 <= bounds["eq19_abs_over_A"]
    assert worst19 > 0.9 * bounds["eq19_abs_over_A"]  # the max 0.302 A is at x = 1/sqrt(pi)


def test_seed_forms_limits():
    ms = np.array([0.0, 1.0, 10.0, 1e3, 1e7])
    a = mf.wallis(ms)
    # our eq. 19 reading is exact at alpha = 0, -pi/2 (and pi/2) with the exact A
    assert np.allclose(mf.seed_incomplete_cos_pow(ms, 0.0, exact_wallis=True), a, rtol=1e-15)
    assert np.allclose(mf.seed_incomplete_cos_pow(ms, -HALF_PI, exact_wallis=True), 2 * a, rtol=1e-15)
    assert np.all(mf.seed_incomplete_cos_pow(ms, HALF_PI, exact_wallis=True) < 1e-15)
    # the printed eq. 19 gives A at alpha = pi/2 and not A at alpha = 0
    assert np.allclose(mf.seed_incomplete_cos_pow_printed(ms, HALF_PI), a, rtol=1e-14)
    assert np.all(np.abs(mf.seed_incomplete_cos_pow_printed(ms, 0.0) / a - 1) > 0.9)
    # our eq. 23 reading with exact A: exact at normal incidence; the printed one: half
    hn = (ms + 1) / (ms + 2)
    assert np.allclose(mf.seed_hk_plus(ms, 0.0, exact_wallis=True), hn, rtol=1e-14)
    assert np.allclose(mf.seed_hk_plus_printed(ms, 0.0) / mf.seed_hk_plus(ms, 0.0), 0.5, rtol=1e-14)


def test_seed_aps_p_finite_in_unit_interval():
    m = np.array([0.0, 1e-300, 0.5, 1.0, 10.0, 1e3, 1e5, 1e7, 1e10])[:, None]
    th = np.concatenate([np.linspace(0, HALF_PI, 201), HALF_PI - np.logspace(-16, -1, 31), np.logspace(-16, -1, 16)])[None, :]
    p = mf.seed_aps_p(m, th)
    assert p.shape == (m.shape[0], th.shape[1])
    assert np.all(np.isfinite(p)) and np.all((p >= 0) & (p <= 1))
    hk = mf.seed_hk_plus(m, th)
    assert np.all(np.isfinite(hk)) and np.all(hk > 0)
    assert np.all(mf.seed_aps_p(m, HALF_PI) < 1e-10)


# ----------------------------------------------------------------------------- other exact functions
def test_smith_g1_beckmann_closed_form():
    for alpha in (0.1, 0.5):
        for t in (0.3, 1.0, 1.5):
            a = 1 / (alpha * mp.tan(mp.mpf(t)))
            lam = (mp.exp(-a * a) / (a * mp.sqrt(mp.pi)) - mp.erfc(a)) / 2
            ref = 1 / (1 + lam)
            # statrs 0.19's erfc is good to ~1e-10 relative (erfc(0.5): 0.479500122236 vs
            # 0.479500122187), which limits the "exact" Smith G1 to ~1e-11
            assert rel(mf.smith_g1(t, "beckmann", alpha=alpha), ref) < 1e-10
            assert abs(mf.smith_g1(t, "beckmann", alpha=alpha, variant="walter") - float(ref)) < 4e-3
    # GGX: Lambda = (sqrt(1 + alpha^2 tan^2) - 1)/2
    t, alpha = 1.1, 0.4
    ref = 2 / (1 + math.sqrt(1 + alpha**2 * math.tan(t) ** 2))
    assert abs(mf.smith_g1(t, "ggx", alpha=alpha) - ref) < 1e-14
    assert mf.smith_g1(0.0, "blinn_phong", m=20.0) == 1.0


def test_aps_masking_other_distributions():
    th = np.linspace(0, HALF_PI, 7)
    for dist in ("beckmann", "ggx"):
        p = mf.aps_masking(th, dist, alpha=0.3)
        assert p[0] == 1.0 and p[-1] < 1e-12 and np.all(np.diff(p) <= 1e-15)
        hk = mf.hk_plus(th, dist, alpha=0.3)
        assert np.allclose(p * hk / np.cos(th), p[0] * hk[0], rtol=1e-12)  # <h.n> cos / hk


# ----------------------------------------------------------------------------- the Python layer
def test_scalars_arrays_and_broadcasting():
    assert isinstance(mf.wallis(2.0), float)
    assert isinstance(mf.seed_aps_p(10, 0.3), float)
    out = mf.incomplete_cos_pow(np.array([1.0, 10.0])[:, None], [0.0, 0.5, 1.0])
    assert out.shape == (2, 3) and out.dtype == np.float64
    assert mf.hk_plus([0.1, 0.2], m=[[1.0], [2.0]]).shape == (2, 2)
    with pytest.raises(pprender.Error, match="do not broadcast"):
        mf.seed_hk_plus([1.0, 2.0], [0.1, 0.2, 0.3])


@pytest.mark.parametrize(
    "call,name",
    [
        (lambda: mf.wallis(-1.0), "m"),
        (lambda: mf.wallis(float("nan")), "m"),
        (lambda: mf.seed_aps_p(1e11, 0.1), "m"),
        (lambda: mf.seed_aps_p(1.0, HALF_PI + 1e-9), "theta_k"),
        (lambda: mf.seed_hk_plus(1.0, -0.1), "theta_k"),
        (lambda: mf.seed_hk_plus(1.0, [0.1, float("nan")]), "theta_k"),
        (lambda: mf.incomplete_cos_pow(1.0, 2.0), "alpha"),
        (lambda: mf.hk_plus(0.3, m=1.0, alpha=0.2), "m"),
        (lambda: mf.hk_plus(0.3), "m"),
        (lambda: mf.hk_plus(0.3, "phong", m=1.0), "distribution"),
        (lambda: mf.aps_masking(0.3, "beckmann", alpha=-1.0), "alpha"),
        (lambda: mf.smith_g1(0.3, "ggx", alpha=0.1, variant="fast"), "variant"),
    ],
)
def test_invalid_inputs_name_the_parameter(call, name):
    with pytest.raises(pprender.Error, match=rf"^invalid {name}\b"):
        call()
    assert issubclass(pprender.Error, ValueError)
