"""Tests of pprender.polarimetry: bindings (shapes, broadcasting, errors) and independent
NumPy checks of the Rust results."""

from __future__ import annotations

import numpy as np
import pytest

import pprender
from pprender import polarimetry as pol

# Pauli basis of src/optics/mod.rs (sigma_3 = [[0, i], [-i, 0]]).
SIGMA = np.array(
    [
        [[1, 0], [0, 1]],
        [[1, 0], [0, -1]],
        [[0, 1], [1, 0]],
        [[0, 1j], [-1j, 0]],
    ],
    dtype=complex,
)
MIRROR = np.diag([1.0, 1.0, -1.0, -1.0])
DEPOLARIZER = np.diag([1.0, 0.0, 0.0, 0.0])


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240611)


def jones_to_mueller(j: np.ndarray) -> np.ndarray:
    """Textbook map M_ij = 1/2 tr(sigma_i J sigma_j J^H), batched over leading dims."""
    jh = np.conj(np.swapaxes(j, -1, -2))
    m = np.einsum("iab,...bc,jcd,...da->...ij", SIGMA, j, SIGMA, jh)
    return 0.5 * m.real


def random_physical(rng: np.random.Generator, shape: tuple[int, ...], k: int) -> np.ndarray:
    """Positive sums of k random non-depolarizing Mueller matrices."""
    j = rng.normal(size=shape + (k, 2, 2)) + 1j * rng.normal(size=shape + (k, 2, 2))
    w = rng.uniform(0.1, 1.0, size=shape + (k, 1, 1))
    return (w * jones_to_mueller(j)).sum(axis=-3)


def polarizer(theta: float) -> np.ndarray:
    c, s = np.cos(2 * theta), np.sin(2 * theta)
    return 0.5 * np.array([[1, c, s, 0], [c, c * c, c * s, 0], [s, c * s, s * s, 0], [0, 0, 0, 0]])


def coherency_textbook(m: np.ndarray) -> np.ndarray:
    """Cloude's H = 1/4 sum_ij M_ij kron(sigma_i, conj(sigma_j)), batched."""
    basis = np.einsum("iab,jcd->ijacbd", SIGMA, np.conj(SIGMA)).reshape(4, 4, 4, 4)
    return 0.25 * np.einsum("...ij,ijkl->...kl", m, basis)


# ---------------------------------------------------------------------------------------
# Shapes and broadcasting
# ---------------------------------------------------------------------------------------


def test_stokes_shapes() -> None:
    s = np.array([2.0, 0.6, 0.8, -1.0])
    assert np.isclose(pol.dop(s), np.sqrt(2) / 2)
    assert np.isclose(pol.dolp(s), 0.5)
    assert np.isclose(pol.docp(s), 0.5)
    assert np.ndim(pol.dop(s)) == 0
    batch = np.broadcast_to(s, (2, 3, 4))
    for f in (pol.dop, pol.dolp, pol.docp):
        out = f(batch)
        assert out.shape == (2, 3)
        assert out.dtype == np.float64
        np.testing.assert_allclose(out, f(s))
    assert pol.dop(np.zeros((0, 4))).shape == (0,)
    # Lists and integer arrays are converted.
    assert pol.dop([1, 1, 0, 0]) == 1.0
    assert pol.dop(np.zeros(4)) == 0.0


def test_mueller_shapes(rng: np.random.Generator) -> None:
    m = random_physical(rng, (2, 3), 2)
    for f in (
        pol.diattenuation,
        pol.polarizance,
        pol.depolarization_index,
        pol.linear_depolarization_ratio,
        pol.circular_depolarization_ratio,
        pol.retardance,
        pol.linear_retardance,
        pol.optical_rotation,
    ):
        assert f(m).shape == (2, 3), f
        assert np.ndim(f(m[0, 0])) == 0, f
    for f in (pol.diattenuation_vector, pol.polarizance_vector, pol.retardance_vector):
        assert f(m).shape == (2, 3, 3), f
    assert pol.cloude_eigenvalues(m).shape == (2, 3, 4)
    phys = pol.is_physical(m)
    assert phys.shape == (2, 3) and phys.dtype == np.bool_ and phys.all()
    assert isinstance(pol.is_physical(m[0, 0]), np.bool_)
    parts = pol.lu_chipman(m)
    assert len(parts) == 3 and all(p.shape == (2, 3, 4, 4) for p in parts)
    assert pol.lu_chipman(np.zeros((0, 4, 4)))[0].shape == (0, 4, 4)


def test_non_contiguous_input(rng: np.random.Generator) -> None:
    m = random_physical(rng, (6,), 3)
    mt = np.swapaxes(np.swapaxes(m, -1, -2).copy(), -1, -2)  # same values, F-ordered blocks
    assert not mt.flags.c_contiguous
    np.testing.assert_array_equal(pol.depolarization_index(mt), pol.depolarization_index(m))
    np.testing.assert_array_equal(pol.diattenuation(m[::2]), pol.diattenuation(m)[::2])


def test_shape_errors_name_parameter() -> None:
    assert issubclass(pprender.Error, ValueError)
    with pytest.raises(pprender.Error, match="stokes"):
        pol.dop(np.zeros((2, 3)))
    with pytest.raises(pprender.Error, match="mueller"):
        pol.diattenuation(np.zeros((4, 3)))
    with pytest.raises(pprender.Error, match="mueller"):
        pol.lu_chipman(np.zeros(16))
    with pytest.raises(pprender.Error, match="mueller"):
        pol.is_physical(np.zeros((2, 4)))


def test_value_errors() -> None:
    bad = np.eye(4)
    bad[1, 2] = np.nan
    for f in (pol.diattenuation, pol.lu_chipman, pol.cloude_eigenvalues, pol.is_physical, pol.retardance):
        with pytest.raises(pprender.Error, match="mueller"):
            f(np.stack([np.eye(4), bad]))
    with pytest.raises(pprender.Error, match="stokes"):
        pol.dop([1.0, np.inf, 0.0, 0.0])
    with pytest.raises(pprender.Error, match="stokes"):
        pol.dolp([-1.0, 0.0, 0.0, 0.0])
    with pytest.raises(pprender.Error, match="M00"):
        pol.depolarization_index(-np.eye(4))
    with pytest.raises(pprender.Error, match="tol"):
        pol.is_physical(np.eye(4), tol=-1.0)
    # Any finite matrix has Cloude eigenvalues; M00 < 0 is simply not physical.
    assert not pol.is_physical(-np.eye(4))


# ---------------------------------------------------------------------------------------
# Analytic cases
# ---------------------------------------------------------------------------------------


def test_analytic_elements() -> None:
    for theta in (0.0, 0.3, np.pi / 4, 1.1):
        p = polarizer(theta)
        assert np.isclose(pol.diattenuation(p), 1.0)
        assert np.isclose(pol.polarizance(p), 1.0)
        assert np.isclose(pol.depolarization_index(p), 1.0)
        rec = np.einsum("ij,jk,kl->il", *pol.lu_chipman(p))
        np.testing.assert_allclose(rec, p, atol=1e-14)
    assert pol.depolarization_index(MIRROR) == 1.0
    assert pol.linear_depolarization_ratio(MIRROR) == 0.0
    assert pol.circular_depolarization_ratio(MIRROR) == 0.0
    assert np.isclose(pol.retardance(MIRROR), np.pi)
    assert pol.depolarization_index(DEPOLARIZER) == 0.0
    assert pol.linear_depolarization_ratio(DEPOLARIZER) == 1.0
    assert pol.circular_depolarization_ratio(DEPOLARIZER) == 1.0
    # Randomly oriented particles: delta_C = 2 delta_L / (1 - delta_L).
    m = np.diag([1.0, 0.7, -0.7, 1.0 - 1.4])
    dl = pol.linear_depolarization_ratio(m)
    assert np.isclose(pol.circular_depolarization_ratio(m), 2 * dl / (1 - dl))


def test_retarder_and_rotator() -> None:
    delta, t = 0.8, 0.3
    c, s = np.cos(t), np.sin(t)
    rot = np.array([[c, -s], [s, c]])
    j = rot @ np.diag([1.0, np.exp(1j * delta)]) @ rot.T  # fast axis at t
    m = jones_to_mueller(j)
    assert np.isclose(pol.retardance(m), delta)
    assert np.isclose(pol.linear_retardance(m), delta, atol=1e-7)
    assert abs(pol.optical_rotation(m)) < 1e-12
    assert pol.diattenuation(m) < 1e-15
    np.testing.assert_allclose(pol.retardance_vector(m), delta * np.array([np.cos(2 * t), np.sin(2 * t), 0]), atol=1e-12)
    psi = 0.4
    r = jones_to_mueller(np.array([[np.cos(psi), -np.sin(psi)], [np.sin(psi), np.cos(psi)]]))
    assert np.isclose(pol.optical_rotation(r), psi)
    assert np.isclose(pol.retardance(r), 2 * psi)


def test_degenerate_never_nan() -> None:
    cases = np.stack([np.zeros((4, 4)), DEPOLARIZER, polarizer(0.2), np.diag([1.0, -1.0, 1.0, -1.0]), np.eye(4)])
    outs = [
        pol.diattenuation(cases),
        pol.polarizance(cases),
        pol.depolarization_index(cases),
        pol.linear_depolarization_ratio(cases),
        pol.circular_depolarization_ratio(cases),
        pol.retardance(cases),
        pol.linear_retardance(cases),
        pol.optical_rotation(cases),
        pol.retardance_vector(cases),
        pol.cloude_eigenvalues(cases),
        *pol.lu_chipman(cases),
    ]
    assert not any(np.isnan(o).any() for o in outs)
    # Zero matrix: nothing transmitted, so nothing polarized.
    assert pol.depolarization_index(np.zeros((4, 4))) == 0.0
    # Half-wave plate at 45 degrees: no co-polarized linear return.
    assert pol.linear_depolarization_ratio(np.diag([1.0, -1.0, 1.0, -1.0])) == np.inf


# ---------------------------------------------------------------------------------------
# Independent NumPy checks
# ---------------------------------------------------------------------------------------


def test_cloude_eigenvalues_match_numpy(rng: np.random.Generator) -> None:
    m = np.concatenate([random_physical(rng, (50,), k) for k in (1, 2, 4)])
    m = np.concatenate([m, rng.normal(size=(50, 4, 4))])  # mostly non-physical
    h = coherency_textbook(m)
    np.testing.assert_allclose(h, np.conj(np.swapaxes(h, -1, -2)), atol=1e-15)
    want = np.linalg.eigvalsh(h)[..., ::-1]
    got = pol.cloude_eigenvalues(m)
    np.testing.assert_allclose(got, want, atol=1e-12 * np.abs(m).max())
    np.testing.assert_allclose(got.sum(-1), m[..., 0, 0], atol=1e-12)
    np.testing.assert_array_equal(pol.is_physical(m), want.min(-1) >= -1e-9 * m[..., 0, 0])
    assert pol.is_physical(m[:150]).all()


def test_decomposition_reconstructs(rng: np.random.Generator) -> None:
    m = np.concatenate([random_physical(rng, (100,), k) for k in (1, 2, 3, 6)])
    md, mr, mdd = pol.lu_chipman(m)
    np.testing.assert_allclose(md @ mr @ mdd, m, atol=1e-12 * m[..., 0, 0].max())
    # Factor structure: M_D is the diattenuator of M (same first row), M_R a rotation,
    # M_delta a depolarizer with symmetric lower block.
    np.testing.assert_allclose(mdd[..., 0, :], m[..., 0, :], atol=1e-14)
    r3 = mr[..., 1:, 1:]
    np.testing.assert_allclose(r3 @ np.swapaxes(r3, -1, -2), np.broadcast_to(np.eye(3), r3.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r3), 1.0, atol=1e-12)
    np.testing.assert_allclose(md[..., 1:, 1:], np.swapaxes(md[..., 1:, 1:], -1, -2), atol=1e-13)
    np.testing.assert_array_equal(md[..., 0, :], np.broadcast_to([1.0, 0, 0, 0], md[..., 0, :].shape))
    # Retardance from the numpy-side M_R.
    tr = np.trace(mr, axis1=-2, axis2=-1)
    np.testing.assert_allclose(pol.retardance(m), np.arccos(np.clip(tr / 2 - 1, -1, 1)), atol=1e-7)


def test_scalar_indices_match_numpy(rng: np.random.Generator) -> None:
    m = random_physical(rng, (40,), 3)
    m00 = m[..., 0, 0]
    np.testing.assert_allclose(pol.diattenuation(m), np.linalg.norm(m[..., 0, 1:], axis=-1) / m00, rtol=1e-14)
    np.testing.assert_allclose(pol.polarizance_vector(m), m[..., 1:, 0] / m00[:, None], rtol=1e-14)
    di = np.sqrt((m**2).sum(axis=(-1, -2)) - m00**2) / (np.sqrt(3) * m00)
    np.testing.assert_allclose(pol.depolarization_index(m), di, rtol=1e-12)
    assert ((di >= 0) & (di <= 1)).all()
    # Depolarization ratios from the channels of H/V and both circular inputs.
    def out(s: list[float]) -> np.ndarray:
        return m @ np.array(s)

    h, v = out([1, 1, 0, 0]), out([1, -1, 0, 0])
    co = (h[:, 0] + h[:, 1]) / 2 + (v[:, 0] - v[:, 1]) / 2
    cross = (h[:, 0] - h[:, 1]) / 2 + (v[:, 0] + v[:, 1]) / 2
    np.testing.assert_allclose(pol.linear_depolarization_ratio(m), cross / co, rtol=1e-12)
    r, l = out([1, 0, 0, 1]), out([1, 0, 0, -1])
    co = (r[:, 0] - r[:, 3]) / 2 + (l[:, 0] + l[:, 3]) / 2  # mirror-like: V flipped
    cross = (r[:, 0] + r[:, 3]) / 2 + (l[:, 0] - l[:, 3]) / 2
    np.testing.assert_allclose(pol.circular_depolarization_ratio(m), cross / co, rtol=1e-12)


def test_stokes_of_fields_match_numpy(rng: np.random.Generator) -> None:
    # Partially polarized Stokes vectors: sums of pure states, plus an unpolarized part.
    e = rng.normal(size=(30, 3, 2)) + 1j * rng.normal(size=(30, 3, 2))
    ex, ey = e[..., 0], e[..., 1]
    s = np.stack([abs(ex) ** 2 + abs(ey) ** 2, abs(ex) ** 2 - abs(ey) ** 2, 2 * (ex * ey.conj()).real, 2 * (ex * ey.conj()).imag], -1).sum(1)
    s[:, 0] += rng.uniform(0, 1, size=30)
    np.testing.assert_allclose(pol.dop(s), np.linalg.norm(s[:, 1:], axis=-1) / s[:, 0], rtol=1e-14)
    np.testing.assert_allclose(pol.dolp(s), np.hypot(s[:, 1], s[:, 2]) / s[:, 0], rtol=1e-14)
    np.testing.assert_allclose(pol.docp(s), abs(s[:, 3]) / s[:, 0], rtol=1e-14)
    assert (pol.dop(s) <= 1).all()


def test_lu_chipman_closed_form(rng: np.random.Generator) -> None:
    """Factors against Lu & Chipman's own formulas (eqs. 12-13, 21-23, 36), in NumPy."""
    m = random_physical(rng, (60,), 4)
    md, mr, mdd = pol.lu_chipman(m)
    for k in range(len(m)):
        n = m[k] / m[k, 0, 0]
        d = n[0, 1:]
        dn = np.linalg.norm(d)
        a = np.sqrt(1 - dn**2)
        m_d = a * np.eye(3) + (1 - a) * np.outer(d, d) / dn**2
        big_md = m[k, 0, 0] * np.block([[np.ones((1, 1)), d[None, :]], [d[:, None], m_d]])
        mp = m[k] @ np.linalg.inv(big_md)
        small = mp[1:, 1:]
        lam = np.sqrt(np.linalg.eigvalsh(small @ small.T))
        inv = np.linalg.inv(small @ small.T + (lam[0] * lam[1] + lam[1] * lam[2] + lam[2] * lam[0]) * np.eye(3))
        m_delta = np.sign(np.linalg.det(small)) * inv @ (lam.sum() * small @ small.T + lam.prod() * np.eye(3))
        np.testing.assert_allclose(mdd[k], big_md, atol=1e-12)
        np.testing.assert_allclose(md[k, 1:, 1:], m_delta, atol=1e-10)
        np.testing.assert_allclose(md[k, 1:, 0], mp[1:, 0], atol=1e-10)
        np.testing.assert_allclose(mr[k, 1:, 1:], np.linalg.inv(m_delta) @ small, atol=1e-9)
