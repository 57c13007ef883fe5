"""Double bounce and coherent backscatter (issue 3): limits, reductions, energy, trends."""

from __future__ import annotations

import numpy as np
import pytest

import pprender
from pprender import _core, polarimetry

PEC = complex(np.inf, 0.0)


def sph(theta: float, phi: float = 0.0) -> np.ndarray:
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def jones_to_mueller(J: np.ndarray) -> np.ndarray:
    """Textbook Mueller matrix of a Jones matrix in this library's Stokes convention
    (V = 2 Im(Ex Ey*)): M_ij = 1/2 tr(s_i J s_j J^H)."""
    s = [np.eye(2), np.diag([1.0, -1.0]), np.array([[0, 1], [1, 0]]), np.array([[0, 1j], [-1j, 0]])]
    return np.array([[0.5 * np.trace(s[i] @ J @ s[j] @ J.conj().T).real for j in range(4)] for i in range(4)])


def fresnel(cos_t: float, eta: complex) -> tuple[complex, complex]:
    w = np.sqrt(eta**2 - (1 - cos_t**2) + 0j)
    return (cos_t - w) / (cos_t + w), (eta**2 * cos_t - w) / (eta**2 * cos_t + w)


# --- dihedral limits ---------------------------------------------------------------


@pytest.mark.parametrize("psi_deg, m11, m21abs", [(0.0, 1.0, 0.0), (22.5, 0.0, 1.0), (45.0, -1.0, 0.0)])
def test_perfect_conductor_dihedral(psi_deg: float, m11: float, m21abs: float) -> None:
    """A 90-degree dihedral seen along its bisector (wi = wo = n), edge at angle psi from
    the sp frame's x axis (x_in = (0, 1, 0) at normal incidence): linear H stays co-polar
    at 0 deg, becomes +-45 (mixed) at 22.5 deg and fully cross-polarized at 45 deg; the two
    reflections keep circular handedness (M33 = +1, where one mirror gives -1)."""
    mat = pprender.Material("beckmann", alpha=0.5, eta=PEC, terms=("double",))
    psi = np.radians(psi_deg)
    x_in = np.array([0.0, 1.0, 0.0])
    y_in = np.cross([0, 0, -1.0], x_in)
    edge = np.cos(psi) * x_in + np.sin(psi) * y_in
    b = np.cross([0, 0, 1.0], edge)  # horizontal, perpendicular to the edge
    h1 = (b + np.array([0, 0, 1.0])) / np.sqrt(2)
    n = np.array([0.0, 0.0, 1.0])
    out = _core.double_jones(mat, n, n, h1, "sp")
    assert out is not None
    J, d, h2 = np.array(out[0]), np.array(out[1]), np.array(out[2])
    np.testing.assert_allclose(np.dot(h1, h2), 0.0, atol=1e-14)
    M = jones_to_mueller(J)
    np.testing.assert_allclose(M[0, 0], 1.0, atol=1e-14)
    np.testing.assert_allclose(M[1, 1], m11, atol=1e-14)
    np.testing.assert_allclose(abs(M[2, 1]), m21abs, atol=1e-14)
    np.testing.assert_allclose(M[3, 3], 1.0, atol=1e-14)


# --- the backscatter reduction (seed eq. 14-16) ------------------------------------


@pytest.mark.parametrize("eta", [0.2 + 3.4j, 1.5 + 0j, 2.5 + 0.5j])
def test_backscatter_reduces_to_shared_plane_dihedral(eta: complex) -> None:
    rng = np.random.default_rng(3)
    mat = pprender.Material("beckmann", alpha=0.5, eta=eta, terms=("double",))
    checked = 0
    for _ in range(200):
        wi = sph(rng.uniform(0, 1.3), rng.uniform(0, 2 * np.pi))
        h1 = sph(rng.uniform(0, 1.2), rng.uniform(0, 2 * np.pi))
        out = _core.double_jones(mat, wi, wi, h1, "sp")
        if out is None:
            continue
        J, d, h2 = np.array(out[0]), np.array(out[1]), np.array(out[2])
        # h1 perpendicular to h2, theta1 + theta2 = 90 deg
        assert abs(np.dot(h1, h2)) < 1e-12
        t1, t2 = np.arccos(np.dot(wi, h1)), np.arccos(np.dot(wi, h2))
        assert abs(t1 + t2 - np.pi / 2) < 1e-12
        # Jones in the shared plane's s/p basis: diag(rs1 rs2, rp1 rp2)
        s = np.cross(-wi, h1)
        s /= np.linalg.norm(s)
        p_in = np.cross(-wi, s)
        p_out = np.cross(wi, s)
        xi = np.array([0.0, 0.0, 0.0])
        # sp-frame bases used by the library for wi = wo: x_in = e_phi, x_out = -e_phi
        phi = np.arctan2(wi[1], wi[0])
        x_in = np.array([-np.sin(phi), np.cos(phi), 0.0])
        y_in = np.cross(-wi, x_in)
        x_out = -x_in
        y_out = np.cross(wi, x_out)
        A_in = np.array([[s @ x_in, s @ y_in], [p_in @ x_in, p_in @ y_in]])  # sp-frame -> (s, p_in)
        A_out = np.array([[s @ x_out, p_out @ x_out], [s @ y_out, p_out @ y_out]])  # (s, p_out) -> sp frame
        J_sp_basis = np.linalg.inv(A_out) @ J @ np.linalg.inv(A_in)
        rs1, rp1 = fresnel(np.cos(t1), eta)
        rs2, rp2 = fresnel(np.cos(t2), eta)
        np.testing.assert_allclose(J_sp_basis, np.diag([rs1 * rs2, rp1 * rp2]), atol=1e-12)
        del xi
        checked += 1
    assert checked > 50


# --- energy and reciprocity ---------------------------------------------------------

ANGLES = np.radians([0.0, 30.0, 60.0, 80.0, 89.0])


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(distribution="blinn_phong", m=0.0),
        dict(distribution="blinn_phong", m=10.0),
        dict(distribution="blinn_phong", m=1e4),
        dict(distribution="beckmann", alpha=0.5),
        dict(distribution="ggx", alpha=0.3),
        dict(distribution="beckmann", alpha=0.5, shadowing="smith"),
        dict(distribution="blinn_phong", m=3.0, double_masking="uncorrelated", correlation="none"),
    ],
)
def test_white_furnace_with_double(kwargs: dict) -> None:
    """single + double + multiple = 1 (F = 1): the multiple term carries what the two
    explicit orders do not. Tolerance 1e-4 to 80 deg and 3e-4 at 89 deg (measured below
    1e-5 to 80 deg and 5e-5 at 89 and 89.9 deg over these materials; before the escape and
    albedo integrals got phi panels at phi_v +- 90 deg, 1.3e-4 at 89 deg and 4e-4 at 89.9
    deg; see docs/double-bounce.md)."""
    mat = pprender.white_furnace(terms=("single", "double", "multiple"), **kwargs)
    w = np.stack([sph(t) for t in ANGLES])
    a = pprender.albedo(mat, w, order=128)
    np.testing.assert_allclose(a[:-1], 1.0, atol=1e-4)
    np.testing.assert_allclose(a[-1], 1.0, atol=3e-4)


def test_albedo_with_double_at_most_one() -> None:
    for eta in (0.2 + 3.4j, 1.5, 2.5 + 0.5j):
        mat = pprender.Material("beckmann", alpha=0.6, eta=eta, terms=("single", "double", "multiple"))
        a = pprender.albedo(mat, np.stack([sph(t) for t in ANGLES]))
        assert np.all(a <= 1 + 1e-4) and np.all(a > 0), a


@pytest.mark.parametrize("double_masking", ["seed", "uncorrelated"])
def test_double_is_reciprocal(double_masking: str) -> None:
    C = np.diag([1.0, 1.0, -1.0, 1.0])
    mat = pprender.Material(
        "beckmann", alpha=0.5, eta=0.2 + 3.4j, terms=("double",), coherent_backscatter=False,
        double_masking=double_masking,
    )
    rng = np.random.default_rng(8)
    for _ in range(6):
        wi = sph(rng.uniform(0, 1.4), rng.uniform(0, 2 * np.pi))
        wo = sph(rng.uniform(0, 1.4), rng.uniform(0, 2 * np.pi))
        a = pprender.brdf(mat, wi, wo)
        b = pprender.brdf(mat, wo, wi)
        # quadrature nodes differ between the two directions: agreement to the
        # quadrature accuracy (default order 160: measured below 1e-7 of M00 on these geometries)
        np.testing.assert_allclose(b, C @ a.T @ C, rtol=0, atol=1e-4 * a[0, 0])


# --- coherent backscatter -----------------------------------------------------------


def co_pol_hh(M: np.ndarray) -> float:
    """Intensity through an H analyser for H input: (M00 + M01 + M10 + M11) / 2."""
    return 0.5 * (M[0, 0] + M[0, 1] + M[1, 0] + M[1, 1])


def test_cbe_factor_two_at_backscatter_falling_to_one() -> None:
    kw = dict(distribution="beckmann", alpha=0.5, eta=0.2 + 3.4j, terms=("double",))
    coh = pprender.Material(**kw, correlation_length=10e-6, wavelength=1064e-9)
    inc = pprender.Material(**kw, coherent_backscatter=False)
    wi = sph(0.5, 0.2)
    ratio0 = co_pol_hh(pprender.brdf(coh, wi, wi)) / co_pol_hh(pprender.brdf(inc, wi, wi))
    assert abs(ratio0 - 2.0) < 1e-9, ratio0
    # bistatic: the enhancement follows gamma = exp(-(q l)^2 / 2)
    ratios = []
    for beta in [1e-3, 2e-2, 0.2]:
        wo = sph(0.5 + beta, 0.2)
        r = co_pol_hh(pprender.brdf(coh, wi, wo)) / co_pol_hh(pprender.brdf(inc, wi, wo))
        g = _core.cbe_gamma(coh, wi, wo)
        ratios.append(r)
        assert abs(r - (1 + g)) < 0.05, (beta, r, g)
    assert ratios[0] > ratios[1] > ratios[2] and ratios[2] < 1.001


# --- polarimetric trends ------------------------------------------------------------


def test_smooth_surface_returns_no_cross_pol_and_rough_depolarizes_more() -> None:
    # Normal-incidence backscatter: a smooth surface returns the mirror flip only; off
    # normal a smooth surface returns almost nothing, and that little is the depolarized
    # multiple term.
    wi = sph(0.0)
    dep, cross = [], []
    for alpha in [0.02, 0.3, 0.6, 1.0]:
        mat = pprender.Material("beckmann", alpha=alpha, eta=0.2 + 3.4j, terms=("single", "double", "multiple"))
        M = pprender.brdf(mat, wi, wi)
        dep.append(1 - float(polarimetry.depolarization_index(M)))
        cross.append(float(polarimetry.linear_depolarization_ratio(M)))
    assert cross[0] < 1e-6, cross
    assert all(a < b for a, b in zip(dep, dep[1:])), dep
    assert all(a < b for a, b in zip(cross, cross[1:])), cross


def test_double_quadrature_default_order_accuracy() -> None:
    """The default order (160) against order 384, on rough materials where the double bounce
    matters: max element error below 1e-4 of the double term's M00 (measured below 1e-5;
    order 48 reaches 1e-3 on the grazing pairs)."""
    pairs = [
        (sph(0.6, 0.3), sph(0.9, 2.0)), (sph(0.6, 0.3), sph(0.6, 0.3)), (sph(0.0), sph(0.0)),
        (sph(0.2, 1), sph(1.2, -2)), (sph(1.218, 3.0), sph(0.613, 0.4)), (sph(1.276, 5.0), sph(0.52, 1.0)),
    ]
    wi = np.stack([p[0] for p in pairs])
    wo = np.stack([p[1] for p in pairs])
    for kw in [dict(distribution="beckmann", alpha=0.5), dict(distribution="ggx", alpha=0.3), dict(distribution="blinn_phong", m=2.0)]:
        base = dict(eta=0.2 + 3.4j, terms=("double",), coherent_backscatter=False, **kw)
        ref = pprender.brdf(pprender.Material(**base, double_order=384), wi, wo)
        got = pprender.brdf(pprender.Material(**base), wi, wo)
        err = np.abs(got - ref).max(axis=(1, 2)) / ref[:, 0, 0]
        assert err.max() < 1e-4, (kw, err)


# --- tables and extremes ------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, bound",
    [
        (dict(distribution="beckmann", alpha=0.5, eta=0.2 + 3.4j), 1e-4),
        (dict(distribution="blinn_phong", m=10.0, eta=1.5), 1e-4),
        (dict(distribution="beckmann", alpha=1.0, eta=1.5), 1e-4),
        # GGX's long tails make the double term large near grazing, where the order-48
        # table is least accurate: measured 2.8e-4 of the total (the same at default orders
        # 96 and 160); the bound was set when an earlier quadrature measured ~2e-3.
        (dict(distribution="ggx", alpha=0.5, eta=0.2 + 3.4j), 5e-3),
    ],
)
def test_monostatic_table_error(kwargs: dict, bound: float) -> None:
    mat = pprender.Material(terms=("single", "double", "multiple"), **kwargs)
    t = pprender.monostatic_table(mat, nodes=64, double_order=48)
    assert t.theta.shape == (65,) and t.mueller.shape == (65, 4, 4)
    assert t.max_error is not None and t.max_error < bound, t.max_error
    # the nodes are exact evaluations of the double term
    w = sph(float(t.theta[10]))
    direct = pprender.brdf(pprender.Material(terms=("double",), double_order=48, **kwargs), w, w)
    np.testing.assert_allclose(t.mueller[10], direct, rtol=1e-12, atol=1e-12 * direct[0, 0])


@pytest.mark.parametrize("m", [0.0, 1e-6, 1.0, 5000.0, 1e6, 1e7])
@pytest.mark.parametrize("eta", [1 + 1e-6, 1e3 + 1e3j])
def test_double_extremes_finite_and_physical(m: float, eta: complex) -> None:
    mat = pprender.Material("blinn_phong", m=m, eta=eta, terms=("single", "double", "multiple"), double_order=24)
    t = np.array([0.0, 0.7, np.pi / 2 - 1e-3, np.pi / 2 - 1e-7])
    wi = np.stack([np.sin(t), 0 * t, np.cos(t)], -1)
    wo = np.stack([np.sin(t[::-1]) * np.cos(2.0), np.sin(t[::-1]) * np.sin(2.0), np.cos(t[::-1])], -1)
    for a, b in [(wi, wo), (wi, wi)]:
        M = pprender.brdf(mat, a, b)
        assert np.all(np.isfinite(M))
        assert np.all(M[:, 0, 0] >= 0)
        assert np.all(np.abs(M) <= M[:, :1, :1] * (1 + 1e-9) + 1e-300)
