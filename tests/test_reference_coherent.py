"""The coherent backscatter tally of the explicit-microsurface reference (pprender.reference):
the binding's shapes, its link to the incoherent tally at bistatic angle 0, and bad inputs.
The physics tests are in Rust (src/reference/tests_coherent.rs)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pprender
from pprender import reference

PEC = complex(math.inf, 0.0)


def _dir(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def _run(**kw: object) -> dict:
    wi = kw.pop("wi", _dir(0.0))
    args = dict(
        wo=kw.pop("wo", np.stack([wi, _dir(20.0, 40.0)])),
        alpha=1.0,
        eta=PEC,
        rays=400_000,
        grid=64,
        correlation_length=4.0,
        cone=0.1,
        max_order=6,
        seed=2,
        batches=4,
    )
    args.update(kw)
    return reference.microsurface(wi, **args)


def test_bistatic_directions_have_the_angle_and_azimuth() -> None:
    wi = _dir(30.0, 50.0)
    beta = np.array([[0.0, 0.01, 0.2], [0.05, 0.1, 0.3]])
    az = np.array([0.0, math.pi / 2, 1.0])
    w = reference.bistatic_directions(wi, beta, az)
    assert w.shape == (2, 3, 3)
    np.testing.assert_allclose(np.linalg.norm(w, axis=-1), 1.0, atol=1e-14)
    np.testing.assert_allclose(np.arccos(np.clip(w @ wi, -1, 1)), beta, atol=1e-7)
    # Azimuth 0 stays in the plane of incidence, tilting away from the normal.
    w0 = reference.bistatic_directions(wi, 0.1)
    assert abs(np.dot(np.cross([0.0, 0.0, 1.0], wi), w0)) < 1e-14
    assert w0[2] < wi[2]


def test_shapes_and_beta_zero_order_two_against_the_incoherent_tally() -> None:
    wi = _dir(0.0)
    bist = reference.bistatic_directions(wi, np.array([[0.0, 0.02, 0.05], [0.0, 0.03, 0.1]]), np.array([[0.0], [1.5]]))
    out = _run(wi=wi, wavelength=1.0, bistatic=bist)
    assert out["coherent"].shape == (2, 2, 3, 4, 4)
    assert out["coherent_stderr"].shape == (2, 2, 3, 4, 4)
    assert out["coherent_unpaired"].shape == (2,)
    assert out["bistatic"].shape == (2, 3, 3) and out["bistatic_angle"].shape == (2, 3)
    assert out["wavelength"] == 1.0 and reference.COHERENT_ORDERS == (2, "3+")
    inc = out["mueller"][1, 0]
    assert out["counts"][1, 0] > 1000
    # At beta = 0 an order-2 path and its reverse agree (planar at exact backscatter); the
    # 0.1 rad cone leaves O(cone^2) ~ 1%: tolerance 2% of M00 per element.
    for row in (0, 1):
        np.testing.assert_allclose(out["coherent"][0, row, 0], inc, atol=0.02 * inc[0, 0])
    # The peak decays (lambda / (2 pi l) ~ 0.04 rad half width here).
    assert out["coherent"][0, 0, 2, 0, 0] < 0.7 * out["coherent"][0, 0, 0, 0, 0]


def test_without_wavelength_nothing_changes() -> None:
    a = _run(rays=20_000)
    b = _run(rays=20_000, wavelength=2.0)
    assert "coherent" not in a and a["wavelength"] is None
    np.testing.assert_array_equal(a["mueller"], b["mueller"])
    assert b["coherent"].shape == (2, 4, 4)  # default bistatic: wi alone, shape (3,)


@pytest.mark.parametrize(
    "kw, name",
    [
        ({"wavelength": 0.0}, "wavelength"),
        ({"wavelength": -1.0}, "wavelength"),
        ({"wavelength": math.nan}, "wavelength"),
        ({"wavelength": "1"}, "wavelength"),
        ({"bistatic": _dir(0.0)}, "bistatic"),
        ({"wavelength": 1.0, "bistatic": [_dir(60.0)]}, "bistatic"),
        ({"wavelength": 1.0, "bistatic": [[0.0, 0.0]]}, "bistatic"),
        ({"wavelength": 1.0, "wo": [_dir(10.0), _dir(0.0)]}, "wo"),
    ],
)
def test_bad_inputs_name_the_parameter(kw: dict, name: str) -> None:
    with pytest.raises(pprender.Error, match=name):
        _run(rays=100, **kw)


def test_bistatic_directions_rejects_bad_angles() -> None:
    with pytest.raises(pprender.Error, match="beta"):
        reference.bistatic_directions(_dir(10.0), 1.0)
    with pytest.raises(pprender.Error, match="wi"):
        reference.bistatic_directions([0.0, 0.0, 2.0], 0.1)
