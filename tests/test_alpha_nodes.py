"""``Material(alpha_step=h)``: the albedo and escape tables interpolated in ln(alpha) from
materials at alpha nodes kept by the process, against the exact build at the same alpha
(the reference it approximates); the full sweep and the build times are
``benchmarks/bench_material_build.py`` (docs/material-build.md)."""

from __future__ import annotations

import numpy as np
import pytest

import pprender
from pprender import _core
from pprender.inverse import database, fit

ALUMINIUM = dict(distribution="beckmann", eta=1.38 + 10.2j, terms=["single", "multiple"])


def _pairs(n: int = 1500) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)

    def dirs() -> np.ndarray:
        th, ph = np.arccos(rng.uniform(0.02, 1.0, n)), rng.uniform(0.0, 2.0 * np.pi, n)
        return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], 1)

    return dirs(), dirs()


@pytest.mark.parametrize("alpha", [0.0123, 0.331, 2.3])
def test_interpolated_tables_match_the_exact_build(alpha):
    """Between nodes 5% apart, the BRDF (16 elements, relative to max(M00, 0.01 /sr):
    relative where it matters, absolute below, where a smooth metal's multiple term is
    1e-25 /sr) and the directional albedo (the white-furnace error the interpolation adds)
    against the material built at alpha itself. Measured (docs/material-build.md, 1000
    pairs, 5 alphas, this material): 3.1e-5 and 8.2e-6; limits about 3x those. Interpolating the albedos
    themselves instead of ln(1 - E) left a median relative error of 6e-4 on the
    multiple term of alpha 0.0123."""
    wi, wo = _pairs()
    exact = pprender.Material(alpha=alpha, **ALUMINIUM)
    nodes = pprender.Material(alpha=alpha, alpha_step=0.05, **ALUMINIUM)
    assert nodes.alpha == alpha and nodes.alpha_step == 0.05 and exact.alpha_step is None
    fe, fi = _core.brdf(exact, wi, wo, "sp"), _core.brdf(nodes, wi, wo, "sp")
    err = np.abs(fi - fe).max(axis=(1, 2)) / np.maximum(fe[:, 0, 0], 1e-2)
    assert 0.0 < err.max() < 1e-4
    cos = np.linspace(0.01, 1.0, 30)
    assert np.abs(_core.albedo(nodes, cos, 128) - _core.albedo(exact, cos, 128)).max() < 2.5e-5


def test_the_result_does_not_depend_on_what_the_process_built_before():
    """The first material of a range of alpha builds its nodes, a second one reads them:
    the same numbers bit for bit, whichever came first."""
    wi, wo = _pairs(50)
    a = pprender.Material(alpha=0.5123, alpha_step=0.05, **ALUMINIUM)  # builds the nodes
    b = pprender.Material(alpha=0.5123, alpha_step=0.05, **ALUMINIUM)  # reads them
    np.testing.assert_array_equal(_core.brdf(a, wi, wo, "sp"), _core.brdf(b, wi, wo, "sp"))
    assert a.e_avg == b.e_avg and a.f_ms == b.f_ms


def test_alpha_step_is_kept_by_rebuilds_and_databases():
    m = pprender.Material(alpha=0.3, alpha_step=0.1, **ALUMINIUM)
    assert fit._material_with(m, 0.25, None).alpha_step == 0.1
    params = database._material_params(m)
    assert params["alpha_step"] == 0.1
    assert database._material_from_params(params).alpha_step == 0.1
    # without it the record is as before (databases written earlier stay valid)
    assert "alpha_step" not in database._material_params(pprender.Material(alpha=0.3, **ALUMINIUM))


@pytest.mark.parametrize("kw, match", [
    (dict(alpha=0.3, alpha_step=0.0), r"alpha_step.*\(0, 1\]"),
    (dict(alpha=0.3, alpha_step=2.0), r"alpha_step.*\(0, 1\]"),
    (dict(alpha=0.3, alpha_step=float("nan")), r"alpha_step"),
    (dict(alpha=0.3, alpha_step="0.05"), r"alpha_step"),
])
def test_bad_alpha_step_is_refused(kw, match):
    with pytest.raises(pprender.Error, match=match):
        pprender.Material(**ALUMINIUM, **kw)
    with pytest.raises(pprender.Error, match="alpha_step.*beckmann"):
        pprender.Material("blinn_phong", m=20.0, alpha_step=0.05)


@pytest.mark.parametrize("alpha", [0.7013, 0.745])
def test_surface_orders_alpha_nodes_match_the_exact_build_and_conserve_energy(alpha):
    """``orders="surface"``: the nodes give the single term's calibration to the traced
    surface (the slow part of the build), the banks' orders are mixed at alpha itself.
    Against the material built at alpha (the reference it approximates), white furnace
    (F = 1: single + orders 2-8 + the remainder past them is the whole light, an analytic
    limit) and BRDF, with 2e4-ray banks (the tests' size; their orders mixed in ln M00
    curve more in alpha than the default banks'). Measured at step 0.05 (alpha 0.7013,
    0.745): white albedo within 7.3e-5 and 2.0e-4 of 1 (the exact build's own: 1.0e-4,
    2.1e-5), within 3.8e-5 and 2.1e-4 of the exact build's, BRDF within 7.0e-5 and
    4.0e-4 (relative to max(M00, 0.01 /sr)); limits 1.5 to 4 times those. (Before the
    banks' tables were interpolated along the similarity, src/brdf/orders/similar.rs,
    0.745 gave 1.1e-4, 1.1e-4 and 1.2e-4: the similar angles are read between the
    tables' incidence nodes linearly, so the calibration's target has kinks in alpha
    inside an interval too, where the angles cross nodes, which the nodes round.)
    Alpha 0.7013 sits just above the banks' node 0.7: nodes ``exp(j h)`` as for other materials straddled it and missed the furnace by 5.3e-4 even
    at step 0.02 (default banks); the nodes now stay within [0.7, 0.8]
    (``material::tests::bank_alpha_nodes_stay_in_one_interval_and_are_exact_for_quadratics``)."""
    kw = dict(distribution="beckmann", eta=float("inf"), terms=("single", "double", "multiple"),
              orders="surface", bank_rays=20_000)
    nodes = pprender.Material(alpha=alpha, alpha_step=0.05, **kw)
    exact = pprender.Material(alpha=alpha, **kw)
    assert nodes.alpha_step == 0.05 and nodes.orders == "surface"
    cos = np.linspace(0.01, 1.0, 60)
    e_nodes, e_exact = _core.albedo(nodes, cos, 128), _core.albedo(exact, cos, 128)
    wi, wo = _pairs(300)
    fe, fi = _core.brdf(exact, wi, wo, "sp"), _core.brdf(nodes, wi, wo, "sp")
    err = np.abs(fi - fe).max(axis=(1, 2)) / np.maximum(fe[:, 0, 0], 1e-2)
    assert np.abs(e_exact - 1.0).max() < 2e-4
    assert 0.0 < np.abs(e_nodes - e_exact).max() < 3.5e-4 and np.abs(e_nodes - 1.0).max() < 3e-4
    assert err.max() < 6e-4
    # with the single term alone orders has nothing to do and the nodes apply as usual
    single = dict(ALUMINIUM, terms=("single",))
    m = pprender.Material(alpha=0.77, alpha_step=0.05, orders="surface", bank_rays=20_000, **single)
    assert m.alpha_step == 0.05 and m.orders == "surface"
