"""The order-2 path bank's bindings (pprender._core.PathBank, OrderTable; issue 24). The
physics is tested in Rust (src/brdf/bank/tests.rs: node symmetries against the double term,
reciprocity, the perfect conductor's M33 = M00, the albedo, and order 2 against the
explicit surface); here: shapes, the reciprocity through the binding, and bad input."""

import numpy as np
import pytest

import pprender
from pprender import _core


@pytest.fixture(scope="module")
def bank():
    return _core.PathBank(0.8, 20_000, surfaces=2, grid=64, correlation_length=8.0, seed=5)


def test_shapes_and_reciprocity(bank) -> None:
    assert bank.albedo.shape == (36, 9) and bank.paths.shape == (36, 7) and bank.lost == 0
    assert np.allclose(bank.albedo.sum(axis=1), 1.0, atol=1e-12)
    assert bank.paths_at(0).shape == (bank.paths[0, 0], 4)
    assert bank.paths_at(3, n=3).shape == (bank.paths[3, 1], 6)
    t = bank.table(complex(1.5, 0.0))
    assert t.data.shape == (36, 36, 25, 4, 4)
    rng = np.random.default_rng(1)
    v = rng.normal(size=(20, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.1
    wi = v / np.linalg.norm(v, axis=1)[:, None]
    wo = np.roll(wi, 1, axis=0)
    a, b = t.eval(wi, wo), t.eval(wo, wi)
    # M(wo, wi) = C M(wi, wo)^T C, C = diag(1, 1, -1, 1) (sp frames)
    c = np.diag([1.0, 1.0, -1.0, 1.0])
    assert np.allclose(b, c @ np.swapaxes(a, 1, 2) @ c, rtol=1e-12, atol=1e-15)
    assert (a[:, 0, 0] >= 0).all()


def test_bad_input_names_the_parameter(bank) -> None:
    with pytest.raises(pprender.Error, match="alpha"):
        _core.PathBank(-0.1, 1000)
    with pytest.raises(pprender.Error, match="surfaces"):
        _core.PathBank(0.5, 1000, surfaces=0)
    with pytest.raises(pprender.Error, match="correlation_length"):
        _core.PathBank(0.5, 1000, grid=64, correlation_length=40.0)
    with pytest.raises(pprender.Error, match="eta"):
        bank.table(complex(-1.0, 0.0))
    with pytest.raises(pprender.Error, match=r"must be in \[0, 35\]"):
        bank.paths_at(36)
    with pytest.raises(pprender.Error, match="orders"):
        bank.table(2.0, orders=(1, 3))
    with pytest.raises(pprender.Error, match="shape"):
        bank.table(2.0).eval(np.zeros((2, 3)), np.zeros((3, 3)))
