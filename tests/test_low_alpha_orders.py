"""``orders="surface"`` below alpha 0.3 (issue 24: path banks from alpha 0.05, interpolated
in alpha by the small-slope similarity, src/brdf/orders/similar.rs) against the explicit
microsurface (``pprender.reference.microsurface``, its own surfaces and seeds), at an alpha
between two bank nodes (0.12: nodes 0.1 and 0.15), toward grazing incidence where orders
>= 2 live at such roughness.

A small version of the comparisons of ``scripts/bank_alpha_interpolation.py``
(docs/bank-alpha-interpolation.md) and ``scripts/surface_orders_reference.py``."""

import numpy as np
import pytest

import pprender
from pprender import reference

ALPHA = 0.12
ETA = 1.3763 + 10.2449j  # aluminium at 1064 nm
THETAS = (70.0, 75.0, 80.0)
RAYS = 1_000_000
CONE = 0.1


@pytest.fixture(scope="module")
def runs():
    out = []
    for deg in THETAS:
        t = np.radians(deg)
        wi = np.array([np.sin(t), 0.0, np.cos(t)])
        out.append((wi, reference.microsurface(wi, wi[None], alpha=ALPHA, eta=ETA, rays=RAYS, cone=CONE,
                                               seed=24_012, batches=8, max_order=10)))
    return out


def _material(terms, orders="surface"):
    kw = dict(orders=orders, bank_rays=200_000) if orders == "surface" else {}
    return pprender.Material("beckmann", alpha=ALPHA, eta=ETA, terms=terms, coherent_backscatter=False, **kw)


def test_orders_two_and_beyond_match_the_surface_between_nodes(runs) -> None:
    """Order 2's albedo within 5% + 3 se of the surface's and orders 3+ within 25% + 3 se
    (the issue's target for 3+). Measured (2e5-ray banks): order 2 0.0122, 0.0290, 0.0495
    against 0.0118, 0.0293, 0.0503 (se 0.0004-0.0009) at 70, 75, 80 deg; 3+ 0.0004, 0.0022,
    0.0070 against 0.00039, 0.00217, 0.00693. 5%: the interpolation between the nodes
    misses the midpoint banks' M00 by up to about 10% in L1 where order 2 is strong
    (docs/bank-alpha-interpolation.md), which the albedo averages down; the fixed-angle mix
    the banks used before was off by 20-65% there."""
    double = _material(("double",))
    both = _material(("double", "multiple"))
    for wi, r in runs:
        o2 = pprender.albedo(double, wi[None])[0]
        rest = pprender.albedo(both, wi[None])[0] - o2
        (a2, a3), (s2, s3) = r["albedo"][1:], r["albedo_stderr"][1:]
        assert abs(o2 - a2) <= 0.05 * a2 + 3 * s2, (wi, o2, a2, s2)
        assert abs(rest - a3) <= 0.25 * a3 + 3 * s3, (wi, rest, a3, s3)


def test_no_grazing_backscatter_from_orders_two_and_beyond(runs) -> None:
    """Regression: at grazing incidence a smooth metal's orders >= 2 leave forward; the
    surface sends nothing back (no ray of 1e6 in the 0.1 rad backscatter cone at 70-80 deg).
    The seed's depolarizing multiple term, which pprender.materials' metals carried by default
    before they took the surface orders, returned
    0.012, 0.073 and 0.24 /sr there. Bound: 3 rays (95% for zero counts) over the cone's
    projected solid angle, 2.5e-4 to 5.5e-4 /sr; the surface orders give below 1.1e-4."""
    both = _material(("double", "multiple"))
    seed = _material(("multiple",), orders="seed")
    for wi, r in runs:
        assert r["counts"][:, 0].sum() == 0, r["counts"]
        bound = 3.0 / RAYS / r["projected_solid_angle"][0]
        w = wi[None]
        assert pprender.brdf(both, w, w)[0, 0, 0] < bound, (wi, bound)
        assert pprender.brdf(seed, w, w)[0, 0, 0] > 10 * bound, (wi, bound)


def test_below_the_lowest_node_is_refused() -> None:
    with pytest.raises(pprender.Error, match=r"alpha.*\[0.05, 1\]"):
        pprender.Material("beckmann", alpha=0.04, eta=ETA, terms=("double",), orders="surface", bank_rays=200_000)
