"""The renderer's BRDF table (pprender.brdf_table) against the public f64 evaluation.

Tolerances come from docs/render-table.md (scripts/render_table_error.py): for this
material (Beckmann 0.3, metal) the default grids give a cell-centre error of 6e-5 of
max(M00, 1e-10 M00_peak) at beta = 0 and 1.5e-4 at beta = 2 deg (bisector frame; the
multiple term near grazing dominates). Random points are no worse than cell centres, and
the test material uses the table's double_order so that only interpolation is measured.
5e-4 leaves a factor 3.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import pprender

TOL = 5e-4


@pytest.fixture(scope="module")
def metal() -> pprender.Material:
    return pprender.Material(
        "beckmann", alpha=0.3, eta=complex(0.2, 3.4), terms=("single", "double", "multiple"), double_order=32
    )


def _pairs(beta: float, theta: np.ndarray, psi: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    st, ct = np.sin(theta), np.cos(theta)
    b = np.stack([st, 0 * st, ct], -1)
    t = np.stack([np.cos(psi) * ct, np.sin(psi), -np.cos(psi) * st], -1)
    wi = math.cos(beta / 2) * b + math.sin(beta / 2) * t
    wo = math.cos(beta / 2) * b - math.sin(beta / 2) * t
    c, s = np.cos(phi), np.sin(phi)
    rot = lambda w: np.stack([c * w[:, 0] - s * w[:, 1], s * w[:, 0] + c * w[:, 1], w[:, 2]], -1)  # noqa: E731
    return rot(wi), rot(wo)


@pytest.mark.parametrize("beta_deg", [0.0, 2.0])
def test_table_matches_brdf_at_random_points(metal: pprender.Material, beta_deg: float, rng: np.random.Generator) -> None:
    beta = math.radians(beta_deg)
    table = pprender.brdf_table(metal, beta, double_order=32)
    n = 60
    theta = np.radians(85.0) * rng.random(n)
    psi = math.pi * (2 * rng.random(n) - 1)
    phi = 2 * math.pi * rng.random(n)
    wi, wo = _pairs(beta, theta, psi, phi)
    want = pprender.brdf(metal, wi, wo, "sp")
    got = np.array([table.eval_dirs(a, b) for a, b in zip(wi, wo)])
    peak = pprender.brdf(metal, [0, 0, 1], [0, 0, 1])[0, 0]
    denom = np.maximum(want[:, 0, 0], 1e-10 * peak)
    err = np.abs(got - want).max(axis=(1, 2)) / denom
    assert err.max() < TOL, (err.max(), np.degrees(theta[err.argmax()]), np.degrees(psi[err.argmax()]))


def test_table_api(metal: pprender.Material) -> None:
    table = pprender.brdf_table(
        metal,
        math.radians(1.0),
        n_z=16,
        n_psi=4,
        n_z_double=8,
        n_psi_double=2,
        double_order=16,
        scale=1.0,
        scale_lambertian=1.0,
        scale_double=1.0,
    )
    assert table.kinds == ["single", "multiple+diffuse", "double"]
    assert table.frame == "bisector" and table.build_seconds > 0
    arrays = table.arrays()
    assert [(a[1], a[2], a[3].shape) for a in arrays][0] == (16, 4, (5, 17, 16))
    assert arrays[2][3].shape == (3, 9, 16)
    # nodes hold ln M00 and M_ij / M00: the matrix at a node is exp(v0) [1, v1..v15], over
    # cos(theta) for the single term with correlated masking (its nodes hold M cos(theta))
    assert table.cos_weighted == [True, False, False]
    scale, n_z, n_psi, data = arrays[0]
    theta = math.atan2(1 - 0.5, scale * 0.5)
    m = table.eval(theta, math.pi / 2)
    v = sum(np.exp(a[3][a[2] // 2 if a[2] else 0, a[1] // 2, 0]) / (math.cos(theta) if w else 1.0)
            for a, w in zip(arrays, table.cos_weighted))
    assert abs(m[0, 0] - v) < 1e-12 * v
    # mirror relation
    d = np.diag([1.0, 1.0, -1.0, -1.0])
    np.testing.assert_allclose(table.eval(0.4, -1.0), d @ table.eval(0.4, 1.0) @ d, rtol=0, atol=1e-14)
    e = table.max_error(theta_max=math.radians(60))
    assert set(e) == {"max", "parts"} and len(e["parts"]) == 3
    assert {"kind", "max", "theta", "psi", "element", "points"} <= set(e["parts"][0])


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(bistatic_angle=-0.1), "bistatic_angle"),
        (dict(bistatic_angle=math.pi / 2), "bistatic_angle"),
        (dict(bistatic_angle=math.nan), "bistatic_angle"),
        (dict(n_z=2), "n_z"),
        (dict(bistatic_angle=0.01, n_psi=1), "n_psi"),
        (dict(double_order=2), "double_order"),
        (dict(n_z_double=1), "n_z_double"),
        (dict(scale=-1.0), "scale"),
        (dict(frame="mitsuba"), "frame"),
    ],
)
def test_bad_input(metal: pprender.Material, kwargs: dict, name: str) -> None:
    with pytest.raises(pprender.Error, match=rf"\b{name}\b"):
        pprender.brdf_table(metal, **kwargs)


def test_bad_eval_input(metal: pprender.Material) -> None:
    table = pprender.brdf_table(metal, 0.0, n_z=8, n_z_double=4, double_order=8)
    with pytest.raises(pprender.Error, match=r"\btheta\b"):
        table.eval(2.0, 0.0)
    with pytest.raises(pprender.Error, match=r"\bpsi\b"):
        table.eval(0.1, 4.0)
    with pytest.raises(pprender.Error, match=r"\bwi\b"):
        table.eval_dirs([0.0, 0.0, -1.0], [0.0, 0.0, 1.0])
