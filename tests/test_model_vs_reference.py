"""The analytic model against the explicit-microsurface reference, by bounce order.

Small, seeded versions of ``scripts/compare_microsurface.py``; every tolerance is justified
by the full run's numbers in ``docs/microsurface-comparison.md`` (quoted in the comments as
"doc: ..."). Where the doc shows the model to be off, the test asserts the documented
discrepancy with a margin instead of pretending agreement: if the model is improved, these
tests fail on purpose and the doc must be regenerated with them.

The reference is deterministic for a given seed (fixed work chunks, any thread count), so
the tests are reproducible; the tolerances still include 3 standard errors of the small
runs so that a change of seed would not break them. The model is averaged over the same
detector cone, with the same weights and Stokes bases, as the reference tallies
(``cone_average`` of the script), so no O(cone^2) bias enters. The reference is incoherent:
``coherent_backscatter=False`` throughout.
"""

from __future__ import annotations

import functools
import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType
from typing import Any, Dict, Tuple

import numpy as np
import pytest

import pprender


def _load_script() -> ModuleType:
    path = Path(__file__).resolve().parent.parent / "scripts" / "compare_microsurface.py"
    spec = importlib.util.spec_from_file_location("compare_microsurface", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("compare_microsurface", mod)
    spec.loader.exec_module(mod)
    return mod


cm = _load_script()
PEC, AL, GLASS = cm.PEC, 0.2 + 3.4j, 1.5 + 0j
CALLS, BATCHES = 8, 4  # 32 surfaces per run


@functools.lru_cache(maxsize=None)
def material(alpha: float, eta: complex, kind: str) -> pprender.Material:
    kw: Dict[str, Any] = dict(alpha=alpha, eta=eta, coherent_backscatter=False)
    if kind in ("aps", "smith"):
        return pprender.Material("beckmann", shadowing=kind, terms=("single",), **kw)
    masking = {"seed": "seed", "unc": "uncorrelated"}[kind]
    return pprender.Material("beckmann", shadowing="aps", terms=("double",), double_masking=masking, **kw)


@functools.lru_cache(maxsize=None)
def ref_run(alpha: float, eta: complex, theta_i: float, names: Tuple[str, ...], cone: float, rays: int, seed: int) -> Dict[str, Any]:
    wi = cm.direction(theta_i)
    wos = [cm.geometry_wo(n) for n in names]
    return cm.reference_run(wi, wos, alpha=alpha, eta=eta, rays=rays, cone=cone, seed=seed, calls=CALLS, batches=BATCHES)


def compare(alpha: float, eta: complex, theta_i: float, names: Tuple[str, ...], cone: float, rays: int, seed: int,
            order: int, kind: str) -> list:
    """Per detector: (ref M00, its standard error, model cone-mean M00, ref normalized,
    its standard errors, model normalized, rays in the cone)."""
    r = ref_run(alpha, eta, theta_i, names, cone, rays, seed)
    mat = material(alpha, eta, kind)
    wi = cm.direction(theta_i)
    rule = cm.RULE1 if order == 0 else cm.RULE2
    model = cm.cone_average(lambda a, b: pprender.brdf(mat, a, b), wi, [cm.geometry_wo(n) for n in names], cone, rule)
    out = []
    for j in range(len(names)):
        per_call = r["mueller"][:, order, j]
        m00, se = cm.mean_se(per_call[:, 0, 0])
        nm, nse = cm.normalized(per_call)
        out.append((float(m00), float(se), float(model[j][0, 0]), nm, nse, model[j] / model[j][0, 0], int(r["counts"][order, j])))
    return out


# ----------------------------------------------------------------------------- order 1


@pytest.mark.parametrize("kind", ["aps", "smith"])
def test_order1_m00_within_the_measured_bound(kind: str) -> None:
    """Single term vs order 1 at alpha = 0.5 (PEC): backscatter at 0 and 30 deg, 20 deg
    bistatic in and out of the plane, specular. Doc: all 72 measured order-1 rows (all
    roughnesses, materials, geometries) have model/reference in 0.94-1.11 with standard
    errors of 1-13 % (66/72 within 2 of them, the 1.11 is 1.11 ± 0.14), no resolved trend;
    the albedo E1 is 0-1.9 % below the surface's. Bound: |ratio - 1| <= 5 % + 3 standard
    errors (a 10 % model error would fail it at these 2-4 % errors)."""
    cases = [(0.0, ("bs0",), 800_000, 11), (30.0, ("bs30", "in20", "out20", "spec30"), 1_500_000, 12)]
    for theta_i, names, rays, seed in cases:
        for name, (ref, se, mod, *_rest) in zip(names, compare(0.5, PEC, theta_i, names, cm.CONE1, rays, seed, 0, kind)):
            counts = _rest[-1]
            assert counts > 500, (name, counts)
            ratio, err = mod / ref, mod / ref * se / ref
            assert abs(ratio - 1) <= 0.05 + 3 * err, (kind, name, ratio, err)


def test_aps_and_smith_differ_only_at_backscatter() -> None:
    """At exact backscatter APS's correlated shadowing gives P(wi, wi) = P(wi) (lit = seen,
    as on a real surface), the separable Smith product G1(wi)^2; for Beckmann APS's P(k) is
    Smith's G1 (doc: equal to 1e-8 with the correlation off), so the ratio is 1/G1(wi),
    checked here against the closed-form Beckmann Lambda. In the specular direction
    f(phi = 180 deg) = 0 and the two coincide. Doc (alpha 0.8, 50 deg backscatter): APS
    1.00 ± 0.04, Smith 0.99 ± 0.04 of the reference: the 2 % difference is below the Monte
    Carlo error wherever order-1 backscatter is measurable, so only the model side is
    asserted here."""
    wi = cm.direction(50.0)[None]
    aps = pprender.brdf(material(0.8, PEC, "aps"), wi, wi)[0, 0, 0]
    smith = pprender.brdf(material(0.8, PEC, "smith"), wi, wi)[0, 0, 0]
    a = 1 / (0.8 * math.tan(math.radians(50.0)))
    lam = (math.erf(a) - 1) / 2 + math.exp(-a * a) / (2 * a * math.sqrt(math.pi))
    assert aps / smith == pytest.approx(1 + lam, rel=1e-6)  # 1 / G1 = 1 + Lambda
    wo = cm.direction(50.0, 180.0)[None]
    assert pprender.brdf(material(0.8, PEC, "aps"), wi, wo)[0, 0, 0] == pytest.approx(
        pprender.brdf(material(0.8, PEC, "smith"), wi, wo)[0, 0, 0], rel=1e-6)


@pytest.mark.parametrize("eta", [AL, GLASS], ids=["Al", "glass"])
def test_order1_normalized_mueller_is_fresnel(eta: complex) -> None:
    """The normalized single-bounce Mueller matrix depends only on the Fresnel amplitudes at
    the facet normalize(wi + wo) and on the frames. Doc: over 72 rows (all materials,
    roughnesses, geometries) the largest |model - reference| of any normalized element is
    0.0014 and the largest |z| 2.8. Tolerance: 4 standard errors + 2e-3 (a sign or frame
    error moves elements by 0.1-2)."""
    names = ("in20", "out20", "spec30")
    rows = compare(0.35, eta, 30.0, names, cm.CONE1, 1_000_000, 21, 0, "aps")
    for name, (_, _, _, nm, nse, mn, counts) in zip(names, rows):
        assert counts > 500, (name, counts)
        assert np.all(np.abs(mn - nm) <= 4 * nse + 2e-3), (name, nm, mn, nse)
    # non-trivial signal where it is expected: diattenuation and retardance terms
    spec = rows[2]
    if eta == GLASS:
        assert spec[3][0, 1] > 0.3  # M01/M00 of glass at 30 deg on the facet's 30 deg
    else:
        assert spec[3][2, 3] < -0.1  # M23/M00: the metal's retardance


# ----------------------------------------------------------------------------- order 2


def test_order2_backscatter_m00_is_documented_underestimate() -> None:
    """Double term vs order 2, PEC, cone 0.1 rad. The model treats the two facets as
    independent draws; on the real surface the second facet is the opposite wall of the
    same valley, which concentrates the second bounce toward retroreflection. Doc
    (seed masking; "uncorrelated" is identical at normal incidence): alpha 0.8 exact
    backscatter 0.65 ± 0.01 of the reference, alpha 0.5 0.29 ± 0.01, while 60 deg away
    from backscatter (alpha 0.5) the model is 2.19 ± 0.13 times the reference: the model's
    lobe is too wide, not just too weak. In the specular direction at 50 deg (alpha 0.8)
    the model holds: 1.03 ± 0.01. Asserted: the documented ratios within 0.08 + 3 standard
    errors (0.5 for the 60 deg ratio)."""
    (ref, se, mod, *_), = compare(0.8, PEC, 0.0, ("bs0",), cm.CONE2, 500_000, 31, 1, "seed")
    r, e = mod / ref, mod / ref * se / ref
    assert abs(r - 0.65) <= 0.08 + 3 * e, (r, e)
    bs, n60 = compare(0.5, PEC, 0.0, ("bs0", "n60"), cm.CONE2, 3_000_000, 32, 1, "seed")
    r0, e0 = bs[2] / bs[0], bs[2] / bs[0] * bs[1] / bs[0]
    r60, e60 = n60[2] / n60[0], n60[2] / n60[0] * n60[1] / n60[0]
    assert bs[6] > 1000 and n60[6] > 200
    assert abs(r0 - 0.29) <= 0.08 + 3 * e0, (r0, e0)
    assert abs(r60 - 2.19) <= 0.5 + 3 * e60, (r60, e60)
    assert r60 > 3 * r0
    (ref, se, mod, *_), = compare(0.8, PEC, 50.0, ("spec50",), cm.CONE2, 1_000_000, 33, 1, "seed")
    r, e = mod / ref, mod / ref * se / ref
    assert abs(r - 1.0) <= 0.08 + 3 * e, (r, e)


@pytest.mark.parametrize("eta", [PEC, AL, GLASS], ids=["PEC", "Al", "glass"])
def test_order2_polarization_at_normal_backscatter(eta: complex) -> None:
    """At normal-incidence backscatter the double bounce is a dihedral (theta1 + theta2 =
    90 deg, one plane of incidence) averaged over its azimuth; the model's normalized
    matrix matches the reference there. Doc (alpha 0.8, bs0): largest |model - reference|
    0.017 (PEC), 0.018 (Al), 0.025 (glass), |z| <= 3.0; depolarization index DI of order 2:
    PEC 0.578 vs 0.577 (diag(1, 0, 0, 1): two reflections keep the circular handedness),
    Al 0.409, glass 0.370, against 1.000 for order 1 (one facet at normal incidence:
    diag(1, 1, -1, -1)). Tolerance for the elements: 4 standard errors + 0.01."""
    o1 = compare(0.8, eta, 0.0, ("bs0",), cm.CONE1, 300_000, 41, 0, "aps")[0]
    o2 = compare(0.8, eta, 0.0, ("bs0",), cm.CONE2, 500_000, 31, 1, "seed")[0]
    n1, m1, n2, nse2, m2 = o1[3], o1[5], o2[3], o2[4], o2[5]
    assert np.all(np.abs(m2 - n2) <= 4 * nse2 + 0.01), (n2, m2, nse2)

    def di(n: np.ndarray) -> float:
        return math.sqrt(max(np.sum(n**2) - 1.0, 0.0) / 3.0)

    for n in (n1, m1):  # order 1: polarization preserving, handedness flipped
        assert di(n) > 0.99 and n[3, 3] < -0.99
    for n in (n2, m2):  # order 2: depolarizing, more than order 1
        assert di(n) < 0.65
    if eta == PEC:
        assert n2[3, 3] > 0.9 and m2[3, 3] > 0.9  # handedness kept
        assert abs(n2[1, 1]) < 0.15 and abs(m2[1, 1]) < 0.15  # linear states scrambled


# ----------------------------------------------------------------------------- albedo


def test_albedo_by_order() -> None:
    """Unpolarized albedo by order at normal incidence (PEC). Doc: E1 (APS) is 1.0-1.8 %
    below the reference's A1 (alpha 0.5: 0.9430 vs 0.9521, alpha 0.8: 0.6419 vs 0.6536);
    E2 matches A2 at alpha 0.8 (0.3251 vs 0.3310) but is 16 % high at alpha 0.5 (0.0550 vs
    0.0473); the multiple term carries 0.0330 at alpha 0.8 where the surface's orders 3+
    carry 0.0154 (2.1x). The reference's albedo errors are below 0.001 here, so the
    windows below are set by the model's documented offsets with margins of about a third
    of each."""
    out = {}
    for alpha, rays, seed in ((0.8, 500_000, 31), (0.5, 3_000_000, 32)):
        names = ("bs0",) if alpha == 0.8 else ("bs0", "n60")
        r = ref_run(alpha, PEC, 0.0, names, cm.CONE2, rays, seed)
        a, se = cm.mean_se(r["albedo"])
        assert np.all(se < 0.002)
        assert a.sum() + np.mean(r["truncated"]) == pytest.approx(1.0, abs=1e-9)
        wi = cm.direction(0.0)[None]
        e1 = pprender.albedo(material(alpha, PEC, "aps"), wi)[0]
        e2 = pprender.albedo(material(alpha, PEC, "seed"), wi)[0]
        ms = cm.MultipleTerm(material(alpha, PEC, "aps"), material(alpha, PEC, "seed")).albedo(PEC, wi)[0]
        out[alpha] = (a, e1, e2, ms)
    for alpha, (a, e1, e2, ms) in out.items():
        assert -0.03 < e1 / a[0] - 1 < 0.0, (alpha, e1, a[0])
    a, e1, e2, ms = out[0.8]
    assert abs(e2 / a[1] - 1) < 0.05, (e2, a[1])
    assert 1.6 < ms / a[2] < 2.8, (ms, a[2])
    a, e1, e2, ms = out[0.5]
    assert 1.10 < e2 / a[1] < 1.30, (e2, a[1])
