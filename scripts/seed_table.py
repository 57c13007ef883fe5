#!/usr/bin/env python3
"""Regenerate docs/seed-approximation.md: the seed's closed-form masking (eq. 19-23)
measured against mpmath, and the exact references checked on the way.

Usage: python scripts/seed_table.py [--out docs/seed-approximation.md]   (about 10 s)

References (mpmath, 30 digits), independent of the Rust code:
- A(m) = sqrt(pi)/2 Gamma((m+1)/2) / Gamma(m/2+1);
- F_m(a) = int_a^{pi/2} cos^m by mpmath.quad with breakpoints on the peak's scale;
- <h.k>+ from the exact reduction of seed eq. 18 (derived in the doc; tests/test_masking.py
  checks it, and the code, against a quadrature of the definition).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import mpmath as mp
import numpy as np

import pprender
import pprender._core as core
import pprender.microfacet as mf

mp.mp.dps = 30
HALF_PI = math.pi / 2
M_GRID = [0.0, 1.0, 10.0, 100.0, 1e3, 1e4, 1e5, 1e6, 1e7]


# ----------------------------------------------------------------------------- references
def mp_wallis(m: float) -> mp.mpf:
    m = mp.mpf(m)
    return mp.sqrt(mp.pi) / 2 * mp.gamma((m + 1) / 2) / mp.gamma(m / 2 + 1)


def mp_incomplete(m: float, a: float) -> mp.mpf:
    """int_a^{pi/2} cos^m(t) dt by mpmath.quad, breakpoints doubling from a on the scale
    of the integrand (min of the peak width and the tail's decay length)."""
    m, a = mp.mpf(m), mp.mpf(a)
    if a >= mp.pi / 2:
        return mp.mpf(0)
    if a < 0:
        return 2 * mp_wallis(m) - mp_incomplete(m, -a)
    width = 1 / mp.sqrt(m + 1)
    d = width if a == 0 else min(width, 1 / ((m + 1) * mp.tan(a)))
    d /= 4
    pts, k = [a], 0
    lca = mp.log(mp.cos(a))
    while True:
        x = a + d * 2**k
        k += 1
        if x >= mp.pi / 2:
            break
        pts.append(x)
        if m * (mp.log(mp.cos(x)) - lca) < -160:  # the rest is below 1e-69 relative
            break
    pts.append(mp.pi / 2)
    # integrate (cos t / cos a)^m = O(1) (mpmath's tolerance is absolute), scale back
    ca = mp.cos(a)
    return ca**m * mp.quad(lambda t: (mp.cos(t) / ca) ** m, pts)


def mp_hk_plus(m: float, theta: float) -> mp.mpf:
    """Exact <h.k>+ from the reduction of eq. 18 (see the doc)."""
    m, t = mp.mpf(m), mp.mpf(theta)
    return (m + 1) / mp.pi * mp_wallis(m + 2) * (
        mp.cos(t) * (2 * mp_wallis(m + 1) - mp_incomplete(m + 1, mp.pi / 2 - t))
        + mp.sin(t) ** (m + 2) / (m + 1)
    )


# ----------------------------------------------------------------------------- grids
def theta_grid(m: float) -> list[float]:
    """theta_k from 0 to within 1e-7 of grazing, plus offsets on the scale 1/sqrt(m) where
    the seed's error peaks. Shared with tests/test_masking.py (keep in sync)."""
    fixed = [0.0, 0.3, 0.7, 1.0, 1.2, 1.4, 1.5, 1.55]
    near = [HALF_PI - d for d in (1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 1e-6, 1e-7)]
    scaled = [HALF_PI - x * math.sqrt(2.0 / (m + 2.0)) for x in (0.1, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0)]
    return sorted({t for t in fixed + near + scaled if 0.0 <= t <= HALF_PI})


def alpha_grid(m: float) -> list[float]:
    """alpha in [0, pi/2]: tiny, on the peak scale, moderate, near pi/2."""
    fixed = [0.0, 1e-7, 1e-4, 0.1, 0.5, 1.0, 1.2, 1.5, HALF_PI - 1e-3, HALF_PI - 1e-7]
    scaled = [x * math.sqrt(2.0 / (m + 1.0)) for x in (0.1, 0.3, 0.5642, 1.0, 2.0, 4.0)]
    return sorted({a for a in fixed + scaled if 0.0 <= a <= HALF_PI})


def rel(x: float, ref) -> float:
    ref = float(ref)
    if not math.isfinite(x):
        return math.inf
    if ref == 0.0:
        return 0.0 if x == 0.0 else math.inf
    return abs(x / ref - 1.0)


def fmt(x: float, digits: int = 2) -> str:
    if isinstance(x, str):
        return x
    if not math.isfinite(x):
        return "NaN" if math.isnan(x) else "inf"
    if x == 0.0:
        return "0"
    return f"{x:.{digits}e}"


def ceil_sig(x: float, sig: int = 3) -> float:
    """x rounded *up* to `sig` significant digits (for the documented bounds)."""
    if x <= 0:
        return 0.0
    e = math.floor(math.log10(x)) - sig + 1
    return float(f"{math.ceil(x / 10.0**e)}e{e}")


# ----------------------------------------------------------------------------- measurements
def wallis_rows():
    ms = [0, 1, 2, 10, 100, 169, 170, 171, 172, 1000, 5000, 1e4, 1e5, 1e6, 1e7]
    rows = []
    for m in ms:
        ref = mp_wallis(m)
        # hypothesis for the seed's "unstable above ~5000": the same log-gamma route in
        # float32 (GPU single precision), with correctly rounded float32 lgamma values
        lg = lambda x: np.float32(float(mp.loggamma(x)))  # noqa: E731
        ln_a32 = (
            np.float32(math.log(HALF_PI)) + lg(m + 1) - np.float32(m) * np.float32(math.log(2.0)) - np.float32(2) * lg(m / 2 + 1)
        )
        a32 = math.exp(float(ln_a32))
        rows.append(
            dict(
                m=m,
                exact=float(ref),
                eq22=rel(float(mf.seed_wallis(m)), ref),
                wallis=rel(float(mf.wallis(m)), ref),
                factorial=rel(float(mf.wallis_factorial(m)), ref),
                lgamma64=rel(float(core._wallis_lgamma(m)), ref),
                lgamma32=rel(a32, ref),
            )
        )
    return rows


def factorial_failure():
    """First integer m where eq. 20 in f64 factorials stops being finite / accurate."""
    ms = np.arange(0, 400)
    lit = mf.wallis_factorial(ms.astype(float))
    first_nonfinite = int(ms[~np.isfinite(lit)][0])
    errs = [rel(float(lit[i]), mp_wallis(int(m))) for i, m in enumerate(ms[:first_nonfinite])]
    return first_nonfinite, max(errs)


def incomplete_rows():
    rows = []
    for m in M_GRID:
        a_exact = mp_wallis(m)
        worst_code = worst_beta = worst19 = worst19s = 0.0
        at19 = None
        for a in alpha_grid(m):
            ref = mp_incomplete(m, a)
            if ref > mp.mpf("1e-290"):  # below that float64 underflows
                worst_code = max(worst_code, rel(float(mf.incomplete_cos_pow(m, a)), ref))
                worst_beta = max(worst_beta, rel(float(core._incomplete_cos_pow_beta_reg(m, a)), ref))
            else:
                assert float(mf.incomplete_cos_pow(m, a)) < 1e-280
            e19 = abs(float(mf.seed_incomplete_cos_pow(m, a, exact_wallis=True)) - float(ref)) / float(a_exact)
            e19s = abs(float(mf.seed_incomplete_cos_pow(m, a)) - float(ref)) / float(a_exact)
            if e19 > worst19:
                worst19, at19 = e19, a
            worst19s = max(worst19s, e19s)
        # negative lower limits (the form eq. 23 uses) for the exact route
        for a in (-HALF_PI, -1.0, -1e-3, -1e-7):
            worst_code = max(worst_code, rel(float(mf.incomplete_cos_pow(m, a)), mp_incomplete(m, a)))
        pr0 = float(mf.seed_incomplete_cos_pow_printed(m, 0.0)) / float(a_exact)
        pr1 = float(mf.seed_incomplete_cos_pow_printed(m, HALF_PI)) / float(a_exact)
        prn = float(mf.seed_incomplete_cos_pow_printed(m, -HALF_PI)) / float(a_exact)
        rows.append(dict(m=m, code=worst_code, beta=worst_beta, eq19=worst19, eq19_x=at19 * math.sqrt((m + 1) / 2),
                         eq19_seed=worst19s, printed0=pr0, printed1=pr1, printedm=prn))
    return rows


def hk_rows():
    rows, detail = [], {}
    for m in M_GRID:
        th = np.array(theta_grid(m))
        ref = [mp_hk_plus(m, t) for t in th]
        ref_f = np.array([float(r) for r in ref])
        hn = (m + 1) / (m + 2)
        p_ref = np.array([float(hn * mp.cos(mp.mpf(t)) / r) for t, r in zip(th, ref)])
        seed = mf.seed_hk_plus(m, th)
        seed_x = mf.seed_hk_plus(m, th, exact_wallis=True)
        printed = mf.seed_hk_plus_printed(m, th)
        code = mf.hk_plus(th, m=m)
        eq18 = mf.hk_plus_eq18(m, th)
        p_seed = mf.seed_aps_p(m, th)
        p_code = mf.aps_masking(th, m=m)
        r = lambda x: np.abs(x / ref_f - 1.0)  # noqa: E731
        i = int(np.argmax(r(seed)))
        j = int(np.argmax(np.abs(p_seed - p_ref)))
        prel = np.abs(p_seed[p_ref > 0] / p_ref[p_ref > 0] - 1)
        rows.append(dict(
            m=m, seed=float(r(seed).max()), seed_at=HALF_PI - th[i], seed_x=(HALF_PI - th[i]) * math.sqrt((m + 2) / 2),
            eq19only=float(r(seed_x).max()), printed=float(r(printed).max()),
            code=float(r(code).max()), eq18=float(r(eq18).max()),
            p_abs=float(np.abs(p_seed - p_ref).max()), p_at=HALF_PI - th[j], p_rel=float(prel.max()),
            p0=float(p_seed[0]), p_code=float(np.abs(p_code - p_ref).max()),
        ))
        if m in (10.0, 1e5):
            detail[m] = [(HALF_PI - t, pr, float(ps), float(s / rf - 1.0), float(x / rf - 1.0))
                         for t, pr, ps, s, x, rf in zip(th, p_ref, p_seed, seed, seed_x, ref_f)]
    return rows, detail


# ----------------------------------------------------------------------------- document
DOC_HEAD = r"""# The seed's closed-form APS masking (seed eq. 18-23): reading and measured error

*Generated by `scripts/seed_table.py` (`make docs`); do not edit by hand. Every number
below is measured against mpmath at 30 digits.*

Blinn-Phong, `rho(h) = (m+1)/(2 pi) cos^m(theta_h)`, `<h.n> = (m+1)/(m+2)`,
`<h.k>+ = int rho(h) max(0, h.k) d omega`, APS masking `P(k) = <h.n> cos(theta_k) / <h.k>+`.
`A(m) = int_0^{pi/2} cos^m` (Wallis), `F_m(a) = int_a^{pi/2} cos^m = A(m) I_{cos^2 a}((m+1)/2, 1/2)`.
Code: `pprender.microfacet` (`src/microfacet/seed.rs`). Angles in radians.

## 1. What the seed prints

The text of eq. 18-23 (as extracted, garbled in places):

- eq. 18: `<k.h>+ = (m+1)/pi ∬_{k.h>0} (k.h) sin(theta)^{m+1} cos(phi)^m dtheta dphi`
- eq. 19: `int_alpha^{pi/2} cos(theta)^m dtheta ≅ 2A(m) - A(m) (1 - A(m) cos(alpha))^{m+1}`
- eq. 20: `A(m) = (pi/2) m! / (2^m ((m/2)!)^2)`
- eq. 21: `m! ≅ sqrt(2 pi m + 1) e^{-m} m^m` ("exact for m = 0, Stirling for large m")
- eq. 22: `A(m) ≅ (pi/2) sqrt(2 pi m + 1) / (n pi + 1)` — the `n` is `m`
- eq. 23: `<k.h>+ = (m+1)/pi cos(alpha) [2A(m+1) - A(m+1) cos(alpha)^{m+2} + tan(alpha) sin(alpha)^{m+1}/(m+1)] A(m+2)`

and claims the factorial series "becomes unstable for m > 5000" while the closed form
works for `0 <= m < 1e6`.

Eq. 22 follows from eq. 21 exactly: `((m/2)!)^2 ≅ (pi m + 1) e^{-m} (m/2)^m`, so
`m!/(2^m ((m/2)!)^2) ≅ sqrt(2 pi m + 1)/(pi m + 1)`. It is exact at m = 0 and its
relative error is about `(1/4 - 3/(4 pi))/m = 0.0113/m` for large m.

## 2. Eq. 18 reduced exactly

The integrand `sin^{m+1}(theta) cos^m(phi)` fixes the parametrization: the polar axis of
`h` is the surface tangent `t = n x k / |n x k|` (perpendicular to the plane of
incidence), `theta` is measured from `t` and `phi` around it from `n`, so
`n.h = sin(theta) cos(phi)`, `cos^m(theta_h) d omega = sin^{m+1}(theta) cos^m(phi) dtheta dphi`
and `k.h = sin(theta) cos(phi - theta_k)`. The `theta` integral separates
(`int_0^pi sin^{m+2} = 2 A(m+2)`), and `n.h > 0`, `k.h > 0` leave
`phi` in `(theta_k - pi/2, pi/2)` (the seed's `(m+1)/pi` is `rho`'s `(m+1)/(2 pi)` times 2, for
`theta` in [0, pi/2] by symmetry):

    <h.k>+ = (m+1)/pi A(m+2) int_{theta_k - pi/2}^{pi/2} cos^m(phi) cos(phi - theta_k) dphi
           = (m+1)/pi cos(theta_k) [ int_{theta_k - pi/2}^{pi/2} cos^{m+1} + tan(theta_k) sin^{m+1}(theta_k)/(m+1) ] A(m+2)

using `int cos^m sin = -cos^{m+1}/(m+1)`. This is exact: `tests/test_masking.py` checks
it against a quadrature of the definition (agreement 4e-15 for m up to 1e7), and
`cargo test seed` against the independent reduction in `masking::hk_plus` (2.4e-13); with
`int_{-b}^{pi/2} cos^{m+1} = 2 A(m+1) - F_{m+1}(b)` it is `hk_plus_eq18`:

    <h.k>+ = <h.n> cos(theta_k) (1 - I/2) + A(m+2) sin^{m+2}(theta_k)/pi,   I = F_{m+1}(pi/2 - theta_k)/A(m+1)

(two non-negative terms). At normal incidence it gives `<h.n>`, at grazing `A(m+2)/pi`.

## 3. Reading eq. 19 and eq. 23

Eq. 23 has exactly the structure of this reduction with `alpha = theta_k`: the prefactor
`(m+1)/pi cos(alpha) [...] A(m+2)`, the term `tan(alpha) sin(alpha)^{m+1}/(m+1)`, and in
place of `int_{theta_k - pi/2}^{pi/2} cos^{m+1}` the expression `2A(m+1) - A(m+1) cos(.)^{m+2}`,
which is eq. 19 with `m -> m+1`. So:

1. **Eq. 19 is about a negative lower limit**, `alpha = theta_k - pi/2` in [-pi/2, 0]:
   `int_alpha^{pi/2} cos^m = 2 A(m) - int_{|alpha|}^{pi/2} cos^m`, hence the `2A(m) - A(m) X` shape.
2. **The quantity raised to `m+1` is `cos(alpha)`**: eq. 23 prints `A(m+1) cos(alpha)^{m+2}`,
   i.e. `A(m') cos^{m'+1}` with `m' = m+1`. The printed `(1 - A(m) cos(alpha))` is garbled.
   Our reading of eq. 19:

       int_alpha^{pi/2} cos^m(t) dt ≅ 2 A(m) - A(m) cos^{m+1}(alpha),  alpha in [-pi/2, 0],
       equivalently  F_m(b) = int_b^{pi/2} cos^m ≅ A(m) cos^{m+1}(b),  b = |alpha| in [0, pi/2].

   Derivation: `cos^m` has no elementary antiderivative but `cos^m sin` does,
   `int_b^{pi/2} cos^m(t) sin(t) dt = cos^{m+1}(b)/(m+1)`; replacing `cos^m` by
   `c cos^m sin` and fixing `c = (m+1) A(m)` by the exact value at `b = 0` gives the
   formula. It is exact at both ends: `A(m)` at `alpha = 0` and `2 A(m)` at `alpha = -pi/2`
   (`A(m)` and 0 for `b = 0`, `pi/2`). The printed form gives `2A - A(1 - A)^{m+1}` at
   `alpha = 0` (for m = 0: `2.57 A`; NaN for non-integer m where `1 - A < 0`) and `A` at
   `alpha = ±pi/2`: it satisfies neither end (table 2).
3. **In eq. 23 the power's argument is eq. 19's `alpha`**, `theta_k - pi/2`, so
   `cos(theta_k - pi/2)^{m+2} = sin^{m+2}(theta_k)`; the printed `cos(alpha)^{m+2}` uses
   eq. 23's `alpha = theta_k` instead, which halves `<h.k>+` at normal incidence
   (`P(0) = 2`) — table 3, "printed eq. 23". Our reading of eq. 23:

       <h.k>+ ≅ (m+1)/pi A(m+2) [ cos(theta_k) A(m+1) (2 - sin^{m+2}(theta_k)) + sin^{m+2}(theta_k)/(m+1) ]

   with `A` from eq. 22 (`seed_hk_plus`; `exact_wallis=True` uses the exact `A` and isolates
   eq. 19's error). It is exact at grazing (up to eq. 22) and, with the exact `A`, at normal
   incidence. `seed_aps_p = <h.n> cos(theta_k) / seed_hk_plus`, clamped to [0, 1]; it is
   finite and in [0, 1] for all m in [0, 1e10] (with eq. 22, `P(0)` is slightly below 1:
   0.966 at m = 0, 0.997 at m = 10, 0.99998 at m = 1e3).

**Where eq. 19 fails.** Its slope at `b = 0` is 0 instead of -1. For large m,
`F_m(b)/A(m) -> erfc(x)` while `cos^{m+1}(b) -> exp(-x^2)`, `x = b sqrt(m/2)`: the
difference peaks at `x = 1/sqrt(pi)` with `0.302 A(m)`, and in the tail the ratio
`exp(-x^2)/erfc(x) ~ sqrt(pi) x` grows without bound (eq. 19's *relative* error is
unbounded where `F` is tiny). In `<h.k>+` the error enters as `cos(theta_k) A(m+1) x error`,
which vanishes at normal incidence (the `F` term is exponentially small there) and at
grazing (`cos(theta_k) = 0`), and peaks where `pi/2 - theta_k ≈ 0.75 sqrt(2/m)`:
about 13% in `<h.k>+` and 0.12 in `P(k)` for every m >= 100 (tables 3 and 4). Eq. 22's
error is minor in comparison (2.4% at m = 1, < 1e-4 for m >= 100).
"""


def build_doc(wrows, fail, irows, hrows, detail, elapsed) -> tuple[str, dict]:
    out = [DOC_HEAD]
    first_nonfinite, fail_err = fail
    out.append("\n## 4. The Wallis integral and the factorial route\n\n")
    out.append(
        "Table 1. Relative error of `A(m)`: eq. 22 (`seed_wallis`); the exact `wallis` (Stirling-"
        "series difference); eq. 20 evaluated literally with f64 factorials (`wallis_factorial`); "
        "`exp` of a float64 log-gamma difference (statrs, the first implementation); the same in "
        "float32 with correctly rounded float32 log-gammas (a hypothesis for the seed's "
        "\"unstable above 5000\": GPU single precision).\n\n"
    )
    out.append("| m | A(m) | eq. 22 | `wallis` | eq. 20 literal (f64) | lgamma f64 | lgamma f32 |\n")
    out.append("|---:|---:|---:|---:|---:|---:|---:|\n")
    for r in wrows:
        out.append(
            f"| {r['m']:g} | {r['exact']:.10g} | {fmt(r['eq22'])} | {fmt(r['wallis'])} | "
            f"{fmt(r['factorial'])} | {fmt(r['lgamma64'])} | {fmt(r['lgamma32'])} |\n"
        )
    out.append(
        f"\nThe literal factorial route (eq. 20 in float64) is accurate to {fmt(fail_err)} up to "
        f"m = {first_nonfinite - 1} and returns inf/NaN from **m = {first_nonfinite}** on "
        "(statrs' `gamma` overflows just before `171!` does), far below the seed's 5000. Done "
        "with float64 log-gammas it never becomes unstable but loses about `m ln(m) eps` "
        "(3e-9 at m = 1e7); with float32 log-gammas the error passes 0.1% between m = 1000 and "
        "5000 (0.55% at 5000) and reaches 3% at m = 1e5, which may be what the seed observed on the GPU. Eq. 22 needs no "
        "factorials at all; `wallis` is exact to ~1e-15 for every m.\n"
    )

    out.append("\n## 5. The incomplete integral\n\n")
    out.append(
        "Table 2. Over `alpha` in [0, pi/2] (tiny, on the peak scale `x sqrt(2/(m+1))`, moderate, "
        "within 1e-7 of pi/2; values below 1e-290 are checked to underflow): maximum relative "
        "error of the exact route `incomplete_cos_pow` (also at alpha = -pi/2, -1, -1e-3, -1e-7) "
        "and of statrs' `beta_reg` with the complement on the accurate side; eq. 19 (our reading) "
        "as maximum `|error| / A(m)` with exact `A` and with eq. 22, and where (`x = alpha "
        "sqrt((m+1)/2)`); the printed eq. 19 divided by `A(m)` at alpha = 0 (should be 1), "
        "pi/2 (should be 0 for `alpha >= 0`) and -pi/2 (should be 2).\n\n"
    )
    out.append("| m | `incomplete_cos_pow` | statrs `beta_reg` | eq. 19 (exact A) | at x | eq. 19 (eq. 22 A) | printed(0)/A | printed(pi/2)/A | printed(-pi/2)/A |\n")
    out.append("|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n")
    for r in irows:
        out.append(
            f"| {r['m']:g} | {fmt(r['code'])} | {fmt(r['beta'])} | {r['eq19']:.4f} | {r['eq19_x']:.2f} | "
            f"{r['eq19_seed']:.4f} | {fmt(r['printed0'], 4)} | {fmt(r['printed1'], 4)} | {fmt(r['printedm'], 4)} |\n"
        )
    out.append(
        "\nThe exact route substitutes `cos t = exp(-w^2/2)`, which turns the integral into "
        "`cos^{m+1}(alpha) int_0^inf exp(-(m+1) s (s + 2 w0)/2) g(w0 + s) ds` with the smooth "
        "`g(w) = w/sqrt(1 - exp(-w^2))`, integrated by Gauss-Legendre on panels of the exponent: "
        "no cancellation and no gamma functions, uniform in m. statrs' `beta_reg` forms its "
        "prefactor from `ln_gamma` and so loses digits like the lgamma route of table 1 "
        "(its continued fraction, capped at 140 terms, converges in time here since b = 1/2). "
        "Errors near 1e-14 in the deep tail are the conditioning of `cos^{m+1}(alpha)` "
        "(an exponent up to 708 carried in float64).\n"
    )

    out.append("\n## 6. `<h.k>+` and `P(k)`\n\n")
    out.append(
        "Table 3. Over `theta_k` from 0 to within 1e-7 rad of grazing (plus `pi/2 - theta_k = "
        "x sqrt(2/(m+2))`, x = 0.1 ... 3): maximum relative error of `<h.k>+` for the seed's "
        "closed form (`seed_hk_plus`: eq. 19 reading + eq. 22) and where (`pi/2 - theta_k`, and "
        "`x`), with the exact `A` (eq. 19 alone), and the printed eq. 23; the maximum absolute "
        "and relative error of `seed_aps_p`, where, and `seed_aps_p` at normal incidence. The "
        "last two columns check the exact routes `hk_plus` (masking.rs) and `hk_plus_eq18`.\n\n"
    )
    out.append("| m | seed `<h.k>+` | at pi/2-θ | x | eq. 19 only | printed eq. 23 | P abs | at pi/2-θ | P rel | P(0) | `hk_plus` | `hk_plus_eq18` |\n")
    out.append("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n")
    for r in hrows:
        out.append(
            f"| {r['m']:g} | {r['seed']:.4f} | {r['seed_at']:.3g} | {r['seed_x']:.2f} | {r['eq19only']:.4f} | "
            f"{r['printed']:.4f} | {r['p_abs']:.4f} | {r['p_at']:.3g} | {r['p_rel']:.4f} | {r['p0']:.5f} | "
            f"{fmt(r['code'])} | {fmt(r['eq18'])} |\n"
        )
    for m, rows in detail.items():
        out.append(
            f"\nTable 4{'a' if m == 10.0 else 'b'}. m = {m:g}, per angle: exact `P`, seed `P`, relative error "
            "of the seed's `<h.k>+` (eq. 22 A, and exact A).\n\n"
        )
        out.append("| pi/2 - theta_k | P exact | P seed | `<h.k>+` err | err (exact A) |\n|---:|---:|---:|---:|---:|\n")
        for d, pe, ps, e, ex in rows:
            out.append(f"| {d:.3g} | {pe:.6f} | {ps:.6f} | {e:+.4f} | {ex:+.4f} |\n")

    bounds = {
        "seed_wallis_rel": ceil_sig(max(r["eq22"] for r in wrows)),
        "wallis_rel": ceil_sig(max(r["wallis"] for r in wrows)),
        "incomplete_rel": ceil_sig(max(r["code"] for r in irows)),
        "eq19_abs_over_A": ceil_sig(max(max(r["eq19"], r["eq19_seed"]) for r in irows)),
        "seed_hk_plus_rel": ceil_sig(max(r["seed"] for r in hrows)),
        "seed_p_abs": ceil_sig(max(r["p_abs"] for r in hrows)),
        "seed_p_rel": ceil_sig(max(r["p_rel"] for r in hrows)),
        "hk_plus_rel": ceil_sig(max(max(r["code"], r["eq18"]) for r in hrows)),
    }
    out.append(
        "\n## 7. Summary and documented bounds\n\n"
        f"Over m in {{{', '.join(f'{m:g}' for m in M_GRID)}}} and the angle grids above:\n\n"
        f"- eq. 22: relative error <= {bounds['seed_wallis_rel']:.3g} (at m = 1);\n"
        f"- eq. 19 (our reading): |error| <= {bounds['eq19_abs_over_A']:.3g} A(m);\n"
        f"- seed `<h.k>+` (eq. 23, our reading): relative error <= {bounds['seed_hk_plus_rel']:.3g};\n"
        f"- seed `P(k)`: absolute error <= {bounds['seed_p_abs']:.3g}, relative <= {bounds['seed_p_rel']:.3g};\n"
        f"- exact references: `wallis` <= {bounds['wallis_rel']:.3g}, `incomplete_cos_pow` <= "
        f"{bounds['incomplete_rel']:.3g}, `hk_plus`/`hk_plus_eq18` <= {bounds['hk_plus_rel']:.3g} relative.\n\n"
        "So the closed form is *stable* for 0 <= m <= 1e7 as the seed claims (finite, no "
        "factorials), but not accurate where `pi/2 - theta_k` is of the order of the slope width `sqrt(2/m)` "
        "(near grazing for smooth surfaces, 13% in `<h.k>+`): use `masking=\"exact\"` or `\"table\"` when "
        "the masking matters. `tests/test_masking.py` re-measures these bounds against its own "
        "mpmath references (machine-readable copy below, read by the test).\n\n"
        f"<!-- seed-bounds {json.dumps(bounds)} -->\n\n"
        f"*Generated in {elapsed:.0f} s with pprender {pprender.__version__}, mpmath {mp.__version__}.*\n"
    )
    return "".join(out), bounds


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent.parent / "docs" / "seed-approximation.md")
    args = ap.parse_args()
    t0 = time.time()
    wrows = wallis_rows()
    fail = factorial_failure()
    irows = incomplete_rows()
    hrows, detail = hk_rows()
    doc, bounds = build_doc(wrows, fail, irows, hrows, detail, time.time() - t0)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(doc)
    print(f"wrote {args.out} in {time.time() - t0:.1f} s")
    print(json.dumps(bounds, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
