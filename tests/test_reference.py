"""The explicit-microsurface Monte Carlo reference (pprender.reference).

Oracles independent of the code under test: Beckmann's slope distribution, the Fresnel
equations and Jones -> Mueller algebra written out here in NumPy, energy bookkeeping with a
perfect conductor, reciprocity, and the closed-form dihedral (V-groove) return.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import pprender
from pprender import reference

PEC = complex(math.inf, 0.0)
METAL = 1.2 + 2.5j

# --- independent oracles -------------------------------------------------------------


def fresnel(cos_t: float, eta: complex) -> tuple[complex, complex]:
    """Textbook rs, rp (conventions of src/optics/mod.rs), eta = n + ik."""
    if eta == PEC:
        return -1.0 + 0j, 1.0 + 0j
    w = np.sqrt(complex(eta) ** 2 - (1.0 - cos_t**2))
    rs = (cos_t - w) / (cos_t + w)
    rp = (eta**2 * cos_t - w) / (eta**2 * cos_t + w)
    return complex(rs), complex(rp)


PAULI = [
    np.eye(2, dtype=complex),
    np.diag([1.0, -1.0]).astype(complex),
    np.array([[0, 1], [1, 0]], dtype=complex),
    np.array([[0, 1j], [-1j, 0]], dtype=complex),
]


def mueller_of(j: np.ndarray) -> np.ndarray:
    """M_ij = 1/2 tr(sigma_i J sigma_j J^H)."""
    return np.array(
        [[0.5 * np.trace(PAULI[a] @ j @ PAULI[b] @ j.conj().T).real for b in range(4)] for a in range(4)]
    )


def sp_bases(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, ...]:
    """'sp' beam bases for directions off the normal: x = normalize(k x n), y = k x x."""
    n = np.array([0.0, 0.0, 1.0])
    k_in, k_out = -wi, wo
    x_in = np.cross(k_in, n)
    x_in /= np.linalg.norm(x_in)
    x_out = np.cross(k_out, n)
    x_out /= np.linalg.norm(x_out)
    return x_in, np.cross(k_in, x_in), x_out, np.cross(k_out, x_out)


def facet_mueller(wi: np.ndarray, wo: np.ndarray, eta: complex) -> np.ndarray:
    """Mueller matrix (sp frame) of one reflection off the facet h = normalize(wi + wo)."""
    h = (wi + wo) / np.linalg.norm(wi + wo)
    k_in = -wi
    s = np.cross(k_in, h)
    s /= np.linalg.norm(s)
    p_in, p_out = np.cross(k_in, s), np.cross(wo, s)
    rs, rp = fresnel(float(h @ wi), eta)
    P = rs * np.outer(s, s) + rp * np.outer(p_out, p_in)
    x_in, y_in, x_out, y_out = sp_bases(wi, wo)
    J = np.array([[x_out @ P @ x_in, x_out @ P @ y_in], [y_out @ P @ x_in, y_out @ P @ y_in]])
    return mueller_of(J)


def direction(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


# --- (a) the surfaces ------------------------------------------------------------------


def test_height_field_slopes_are_beckmann() -> None:
    alpha, n, surfaces = 0.5, 256, 6
    # Bins of t = tan^2(theta_h) / alpha^2, which is Exp(1) under Beckmann: the projected-area
    # histogram of facet normals against D(h) cos(theta_h).
    edges = np.array([0.0, 0.1, 0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.5, np.inf])
    p_want = np.exp(-edges[:-1]) - np.exp(-edges[1:])
    freqs, ratios, phi_freqs = [], [], []
    for b in range(surfaces):
        s = reference.height_field(alpha=alpha, grid=n, correlation_length=8.0, seed=11, batch=b)
        h, sl = s["heights"], s["slopes"]
        assert h.shape == (n, n) and sl.shape == (2 * n * n, 2)
        # Rescaled exactly; the facet slopes are the grid's forward differences (each edge
        # appears in two triangles).
        assert s["realized_alpha"] == pytest.approx(alpha, rel=1e-12)
        assert math.sqrt(np.mean(np.sum(sl**2, axis=1))) == pytest.approx(alpha, rel=1e-12)
        dx = (np.roll(h, -1, axis=0) - h).ravel()
        dy = (np.roll(h, -1, axis=1) - h).ravel()
        np.testing.assert_allclose(np.sort(sl[:, 0]), np.sort(np.repeat(dx, 2)), atol=1e-12)
        np.testing.assert_allclose(np.sort(sl[:, 1]), np.sort(np.repeat(dy, 2)), atol=1e-12)
        cov = s["slope_cov"]
        assert cov[0, 0] == pytest.approx(alpha**2 / 2, rel=0.08)
        assert cov[1, 1] == pytest.approx(alpha**2 / 2, rel=0.08)
        assert abs(cov[0, 1]) < 0.05 * alpha**2 / 2
        ratios.append(s["alpha_unscaled_ratio"])
        t = np.sum(sl**2, axis=1) / alpha**2
        freqs.append(np.histogram(t, edges)[0] / len(t))
        phi = np.arctan2(sl[:, 1], sl[:, 0])
        phi_freqs.append(np.histogram(phi, np.linspace(-np.pi, np.pi, 9))[0] / len(phi))
    # The synthesized rms slope before rescaling is right on average (finite-tile spread
    # of a few percent per surface).
    assert abs(np.mean(ratios) - 1.0) < 0.02, ratios
    assert np.all(np.abs(np.array(ratios) - 1.0) < 0.08), ratios
    f = np.array(freqs)
    err = f.std(axis=0, ddof=1) / math.sqrt(surfaces)
    assert np.all(np.abs(f.mean(axis=0) - p_want) < 4 * err + 2e-3), (f.mean(axis=0), p_want, err)
    pf = np.array(phi_freqs)
    assert np.all(np.abs(pf.mean(axis=0) - 1 / 8) < 4 * pf.std(axis=0, ddof=1) / math.sqrt(surfaces) + 2e-3)


def test_blinn_phong_m_maps_to_alpha() -> None:
    a = reference.height_field(m=48.0, grid=64, correlation_length=4.0, seed=1)
    b = reference.height_field(alpha=math.sqrt(2 / 50), grid=64, correlation_length=4.0, seed=1)
    np.testing.assert_array_equal(a["heights"], b["heights"])


# --- (b) flat surface = Fresnel mirror --------------------------------------------------


@pytest.mark.parametrize("frame", ["sp", "mitsuba"])
@pytest.mark.parametrize("eta", [1.5 + 0j, METAL, PEC])
def test_flat_surface_is_the_specular_fresnel_mirror(frame: str, eta: complex) -> None:
    wi = direction(50.0, 30.0)
    wo = np.array([-wi[0], -wi[1], wi[2]])
    out = reference.microsurface(
        wi, [wo, direction(20.0)], alpha=1e-8, eta=eta, rays=2000, grid=64, correlation_length=4.0, frame=frame, batches=2
    )
    want = pprender.specular(pprender.Material("beckmann", alpha=0.1, eta=eta), wi, frame)
    got = out["mueller"][0, 0] * out["projected_solid_angle"][0]
    np.testing.assert_allclose(got, want, atol=1e-9)
    assert out["counts"][0, 0] == 2000 and out["counts"][:, 1].sum() == 0
    assert out["counts"][1:].sum() == 0
    assert out["albedo"][0] == pytest.approx(want[0, 0], rel=1e-9)
    assert out["albedo"][1] == 0 and out["albedo"][2] == 0


# --- (c) energy ---------------------------------------------------------------------------


def test_perfect_conductor_energy_and_truncation() -> None:
    wi = direction(60.0)
    kw = dict(alpha=0.8, eta=PEC, rays=20_000, grid=128, batches=4, seed=3)
    full = reference.microsurface(wi, [[0.0, 0.0, 1.0]], max_order=10, **kw)  # type: ignore[arg-type]
    two = reference.microsurface(wi, [[0.0, 0.0, 1.0]], max_order=2, **kw)  # type: ignore[arg-type]
    for out in (full, two):
        assert out["lost"] == 0.0
        assert out["albedo"].sum() + out["truncated"] == pytest.approx(1.0, abs=1e-12)
    # Truncation only moves the orders it cuts: same rays, same first two orders.
    np.testing.assert_allclose(two["albedo"][:2], full["albedo"][:2], rtol=1e-12)
    assert two["albedo"][2] == 0.0
    assert two["truncated"] == pytest.approx(full["albedo"][2] + full["truncated"], abs=1e-12)
    assert full["albedo"][1] > 0.05  # a rough conductor has a real second bounce
    # An absorbing material loses energy at every bounce.
    metal = reference.microsurface(wi, [[0.0, 0.0, 1.0]], max_order=10, **{**kw, "eta": METAL})  # type: ignore[arg-type]
    assert metal["albedo"].sum() < 0.95 * full["albedo"].sum()


# --- (d) reciprocity -----------------------------------------------------------------------


def test_reciprocity_of_each_order() -> None:
    a, b = direction(30.0, 0.0), direction(55.0, 130.0)
    kw = dict(alpha=0.5, eta=METAL, rays=300_000, grid=128, cone=0.1, batches=8)
    ab = reference.microsurface(a, b, seed=1, **kw)  # type: ignore[arg-type]
    ba = reference.microsurface(b, a, seed=2, **kw)  # type: ignore[arg-type]
    c = np.diag([1.0, 1.0, -1.0, 1.0])  # M(wo, wi) = C M(wi, wo)^T C in the sp frame
    for o in (0, 1):
        m1, e1 = ab["mueller"][o], ab["stderr"][o]
        m2, e2 = c @ ba["mueller"][o].T @ c, ba["stderr"][o].T
        assert ab["counts"][o] > 200 and ba["counts"][o] > 200
        tol = 4.5 * np.sqrt(e1**2 + e2**2) + 1e-3 * m1[0, 0]
        assert np.all(np.abs(m1 - m2) <= tol), (o, m1, m2, tol)


# --- (e) V-groove = dihedral --------------------------------------------------------------


@pytest.mark.parametrize("tilt", [0.0, 20.0])
@pytest.mark.parametrize("eta", [PEC, METAL, 1.5 + 0j])
def test_v_groove_returns_the_dihedral_mueller_matrix(tilt: float, eta: complex) -> None:
    # 90-degree grooves along y: heights[i, j] = i mod 2 (faces at +-45 degrees).
    h = np.tile((np.arange(16) % 2)[:, None], (1, 16)).astype(float)
    wi = direction(tilt, 0.0)
    out = reference.microsurface(wi, wi, eta=eta, heights=h, rays=4000, batches=2)
    assert out["counts"][0] == 0 and out["counts"][2] == 0 and out["lost"] == 0
    if tilt == 0.0:
        assert out["counts"][1] == 4000
    # Both reflections in the plane y = const at theta1 + theta2 = 90 degrees: Jones
    # diag(rs1 rs2, rp1 rp2) in the s/p frame of that plane (PHYSICS.md section 5).
    rs1, rp1 = fresnel(math.cos(math.radians(45 - tilt)), eta)
    rs2, rp2 = fresnel(math.cos(math.radians(45 + tilt)), eta)
    want = mueller_of(np.diag([rs1 * rs2, rp1 * rp2]))
    per_ray = out["mueller"][1] * out["projected_solid_angle"] * out["rays"] / out["counts"][1]
    np.testing.assert_allclose(per_ray, want, atol=1e-10)
    if eta == PEC and tilt == 0.0:
        # A dihedral keeps circular handedness, unlike the flat mirror diag(1, 1, -1, -1).
        np.testing.assert_allclose(per_ray, np.eye(4), atol=1e-12)


def test_v_groove_along_x_at_normal_incidence() -> None:
    h = np.tile((np.arange(16) % 2)[None, :], (16, 1)).astype(float)
    out = reference.microsurface([0, 0, 1.0], [0, 0, 1.0], eta=PEC, heights=h, rays=1000, batches=2)
    np.testing.assert_allclose(out["mueller"][1] * out["projected_solid_angle"], np.eye(4), atol=1e-12)


# --- polarization and normalization of the first order on a rough surface ------------------


def test_first_order_polarization_is_the_facet_fresnel_matrix() -> None:
    wi, wo = direction(40.0, 0.0), direction(35.0, 120.0)
    out = reference.microsurface(wi, wo, alpha=0.4, eta=METAL, rays=200_000, grid=128, cone=0.03, batches=4)
    m = out["mueller"][0]
    assert out["counts"][0] > 100
    want = facet_mueller(wi, wo, METAL)
    # All order-1 rays into the cone reflect off facets within cone/2 of h: the normalized
    # matrix is the facet's, blurred by the cone (a few 1e-3 here).
    np.testing.assert_allclose(m / m[0, 0], want / want[0, 0], atol=1e-2)


def _smith_lambda(cos_t: float, alpha: float) -> float:
    tan = math.sqrt(max(1 - cos_t**2, 0.0)) / cos_t
    if tan == 0:
        return 0.0
    a = 1 / (alpha * tan)
    return (math.erf(a) - 1) / 2 + math.exp(-a * a) / (2 * a * math.sqrt(math.pi))


def test_first_order_brdf_is_close_to_beckmann_smith() -> None:
    """Normalization on a rough surface: order 1 against D G2 F / (4 cos_i cos_o) with
    Beckmann D and height-correlated Smith G2. Smith is not exact for a correlated Gaussian
    surface (order-1 albedos come out 1-4% above Smith's), hence the 6% allowance."""
    alpha = 0.3
    wi = direction(30.0)
    wos = np.array([direction(30.0), direction(0.0), direction(30.0, 180.0), direction(45.0, 90.0)])
    out = reference.microsurface(wi, wos, alpha=alpha, eta=PEC, rays=1_000_000, grid=128, cone=0.08, batches=8)
    for k, wo in enumerate(wos):
        h = (wi + wo) / np.linalg.norm(wi + wo)
        c2 = h[2] ** 2
        d = math.exp(-(1 - c2) / c2 / alpha**2) / (math.pi * alpha**2 * c2 * c2)
        g2 = 1 / (1 + _smith_lambda(wi[2], alpha) + _smith_lambda(wo[2], alpha))
        f = d * g2 / (4 * wi[2] * wo[2])
        got, err = out["mueller"][0, k, 0, 0], out["stderr"][0, k, 0, 0]
        assert abs(got - f) < 3 * err + 0.06 * f, (k, got, err, f)


# --- determinism and errors ----------------------------------------------------------------


def test_seeded_and_shaped() -> None:
    wi = direction(20.0)
    wo = np.array([[direction(20.0), direction(0.0)], [direction(40.0, 180.0), direction(10.0, 90.0)]])
    kw = dict(alpha=0.3, eta=METAL, rays=5000, grid=64, correlation_length=4.0, batches=3)
    a = reference.microsurface(wi, wo, seed=4, **kw)  # type: ignore[arg-type]
    b = reference.microsurface(wi, wo, seed=4, **kw)  # type: ignore[arg-type]
    c = reference.microsurface(wi, wo, seed=5, **kw)  # type: ignore[arg-type]
    assert a["mueller"].shape == (3, 2, 2, 4, 4) and a["stderr"].shape == (3, 2, 2, 4, 4)
    assert a["counts"].shape == (3, 2, 2) and a["projected_solid_angle"].shape == (2, 2)
    assert a["albedo"].shape == (3,) and a["slope_cov"].shape == (3, 2, 2)
    assert a["orders"] == (1, 2, "3+") and a["realized_alpha"] == pytest.approx(0.3)
    np.testing.assert_array_equal(a["mueller"], b["mueller"])
    assert not np.array_equal(a["albedo"], c["albedo"])
    single = reference.microsurface(wi, direction(20.0), seed=4, **kw)  # type: ignore[arg-type]
    assert single["mueller"].shape == (3, 4, 4)
    np.testing.assert_array_equal(single["albedo"], a["albedo"])


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(alpha=0.3, m=10.0), "m"),
        (dict(), "alpha"),
        (dict(alpha=0.0), "alpha"),
        (dict(alpha=float("nan")), "alpha"),
        (dict(m=-1.0), "m"),
        (dict(alpha=0.3, grid=8), "grid"),
        (dict(alpha=0.3, correlation_length=1.0), "correlation_length"),
        (dict(alpha=0.3, grid=64, correlation_length=20.0), "correlation_length"),
        (dict(alpha=0.3, cone=0.0), "cone"),
        (dict(alpha=0.3, cone=1.0), "cone"),
        (dict(alpha=0.3, rays=0), "rays"),
        (dict(alpha=0.3, rays=1.5), "rays"),
        (dict(alpha=0.3, batches=1), "batches"),
        (dict(alpha=0.3, max_order=0), "max_order"),
        (dict(alpha=0.3, frame="xy"), "frame"),
        (dict(alpha=0.3, seed=-1), "seed"),
        (dict(alpha=0.3, eta=complex(float("nan"), 0)), "eta"),
        (dict(alpha=0.3, eta=-1.5 + 0j), "eta"),
        (dict(alpha=0.3, eta="glass"), "eta"),
        (dict(alpha=0.3, heights=np.zeros((4, 4))), "heights"),
        (dict(heights=np.zeros((4, 5))), "heights"),
        (dict(heights=np.full((4, 4), np.nan)), "heights"),
    ],
)
def test_bad_parameters_raise_named_errors(kwargs: dict, name: str) -> None:
    wi = direction(30.0)
    with pytest.raises(pprender.Error, match=name):
        reference.microsurface(wi, wi, rays=kwargs.pop("rays", 100), **kwargs)


@pytest.mark.parametrize(
    "wi, wo, name",
    [
        ([0, 0, 2.0], [0, 0, 1.0], "wi"),
        ([1.0, 0, 0], [0, 0, 1.0], "wi"),
        ([0, 0, -1.0], [0, 0, 1.0], "wi"),
        ([0, 0, 1.0, 0], [0, 0, 1.0], "wi"),
        ([0, 0, 1.0], [0, 0, 0.5], "wo"),
        ([0, 0, 1.0], [[0, 0, 1.0], [1.0, 0, 0]], "wo"),
        ([0, 0, 1.0], [math.sin(1.55), 0, math.cos(1.55)], "wo"),
        ([0, 0, 1.0], [[0, 0]], "wo"),
        ([0, 0, 1.0], [[0, 0, float("inf")]], "wo"),
    ],
)
def test_bad_directions_raise_named_errors(wi: list, wo: list, name: str) -> None:
    with pytest.raises(pprender.Error, match=name):
        reference.microsurface(wi, wo, alpha=0.3, rays=100)


def test_height_field_errors() -> None:
    with pytest.raises(pprender.Error, match="batch"):
        reference.height_field(alpha=0.3, batch=-1)
    with pytest.raises(pprender.Error, match="alpha"):
        reference.height_field(alpha=5.0)
    with pytest.raises(pprender.Error, match="grid"):
        reference.height_field(alpha=0.3, grid=4096 * 2)
