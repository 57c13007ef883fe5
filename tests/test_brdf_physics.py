"""Physics of the Mueller BRDF: conventions, reciprocity, realizability, limits."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

import pprender
from pprender import polarimetry

MIRROR = np.diag([1.0, 1.0, -1.0, -1.0])


def sph(theta: float, phi: float = 0.0) -> np.ndarray:
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def random_dirs(rng: np.random.Generator, n: int, min_z: float = 0.0) -> np.ndarray:
    """Uniform on the upper hemisphere (z > min_z)."""
    z = rng.uniform(min_z, 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def fresnel_textbook(cos_t: float, eta: complex) -> tuple[complex, complex]:
    """rs, rp for eta = n + ik (Born and Wolf, with rp's sign so that rp = -rs at normal
    incidence: the convention of PHYSICS.md / Mitsuba)."""
    sin2 = 1 - cos_t**2
    w = np.sqrt(eta**2 - sin2 + 0j)
    return (cos_t - w) / (cos_t + w), (eta**2 * cos_t - w) / (eta**2 * cos_t + w)


# --- conventions -----------------------------------------------------------------


@pytest.mark.parametrize("theta", [0.0, 0.3, 1.0, 1.5])
@pytest.mark.parametrize("phi", [0.0, 1.1, -2.5])
def test_perfect_mirror_is_diag_1_1_m1_m1_in_sp_frame(theta: float, phi: float) -> None:
    mat = pprender.white_furnace(m=10.0, terms=("single",))
    M = pprender.specular(mat, sph(theta, phi), frame="sp")
    np.testing.assert_allclose(M, MIRROR, atol=1e-14)


@pytest.mark.parametrize("theta", [0.0, 0.4, 1.2])
def test_backscatter_single_term_is_a_mirror_in_sp_frame(theta: float) -> None:
    # In exact backscatter every facet is hit at normal incidence: the single bounce is
    # polarization preserving with the mirror flip, M = f00 diag(1, 1, -1, -1).
    mat = pprender.Material("beckmann", alpha=0.3, eta=0.2 + 3.4j, terms=("single",))
    w = sph(theta, 0.7)
    M = pprender.brdf(mat, w, w)
    np.testing.assert_allclose(M / M[0, 0], MIRROR, atol=1e-12)


def test_normal_incidence_mueller_is_frame_independent_when_both_along_n() -> None:
    mat = pprender.Material("ggx", alpha=0.2, eta=1.5, terms=("single",))
    n = np.array([0.0, 0.0, 1.0])
    M = pprender.brdf(mat, n, n)
    np.testing.assert_allclose(M / M[0, 0], MIRROR, atol=1e-14)


def test_direction_along_n_takes_the_other_plane_of_incidence() -> None:
    # wi along n: the sp frame of the incident beam uses wo's plane; the result is the
    # limit of wi tilted toward wo's azimuth (documented behaviour).
    mat = pprender.Material("beckmann", alpha=0.4, eta=0.5 + 2.0j, terms=("single",))
    wo = sph(0.9, 2.0)
    at = pprender.brdf(mat, [0, 0, 1.0], wo)
    near = pprender.brdf(mat, sph(1e-6, 2.0), wo)
    # first order in the 1e-6 tilt: measured 2.8e-6 relative
    np.testing.assert_allclose(at, near, atol=1e-5 * at[0, 0])


@pytest.mark.parametrize("eta", [1.5 + 0j, 0.2 + 3.4j, 1.0 + 1e-6j, 1e3 + 1e3j])
@pytest.mark.parametrize("theta", [0.0, 0.5, 1.2, np.pi / 2 - 1e-7])
def test_specular_matches_textbook_fresnel(eta: complex, theta: float) -> None:
    mat = pprender.Material("beckmann", alpha=0.1, eta=eta, terms=("single",))
    M = pprender.specular(mat, sph(theta), frame="sp")
    rs, rp = fresnel_textbook(np.cos(theta), eta)
    Rs, Rp = abs(rs) ** 2, abs(rp) ** 2
    want = np.array(
        [
            [(Rs + Rp) / 2, (Rs - Rp) / 2, 0, 0],
            [(Rs - Rp) / 2, (Rs + Rp) / 2, 0, 0],
            [0, 0, (rs * np.conj(rp)).real, -(rs * np.conj(rp)).imag],
            [0, 0, (rs * np.conj(rp)).imag, (rs * np.conj(rp)).real],
        ]
    )
    np.testing.assert_allclose(M, want, atol=1e-12 * max(1.0, want[0, 0]), rtol=1e-10)


@pytest.mark.parametrize("eta", [1.5, 0.2 + 3.4j, 1e3 + 1e3j, 1 + 1e-6])
def test_normal_incidence_reflectance(eta: complex) -> None:
    mat = pprender.Material("beckmann", alpha=0.1, eta=eta, terms=("single",))
    R = abs((eta - 1) / (eta + 1)) ** 2
    M = pprender.specular(mat, [0, 0, 1.0])
    np.testing.assert_allclose(M, R * MIRROR, rtol=1e-12, atol=1e-15 * R)


def test_brewster_angle_kills_p() -> None:
    n = 1.5
    mat = pprender.Material("beckmann", alpha=0.1, eta=n, terms=("single",))
    M = pprender.specular(mat, sph(np.arctan(n)))
    # rp = 0: the reflected light is fully s-polarized for any input (M00 = M01 = M10 = M11).
    np.testing.assert_allclose(M[0, 1] / M[0, 0], 1.0, atol=1e-14)
    np.testing.assert_allclose(M[2:, :], 0.0, atol=1e-16)


def test_circular_handedness_flips_and_linear_kept_for_a_mirror() -> None:
    mat = pprender.Material("beckmann", alpha=0.1, eta=0.2 + 3.4j, terms=("single",))
    M = pprender.specular(mat, [0, 0, 1.0])
    s_out = M @ np.array([1, 0, 0, 1.0])
    assert s_out[3] < 0 and abs(s_out[3] + s_out[0]) < 1e-14
    for s_in in ([1, 1, 0, 0], [1, -1, 0, 0]):
        s = M @ np.array(s_in, float)
        assert abs(abs(s[1]) - s[0]) < 1e-14 and abs(s[2]) < 1e-15 and abs(s[3]) < 1e-15


# --- reciprocity -----------------------------------------------------------------

C = np.diag([1.0, 1.0, -1.0, 1.0])


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(distribution="blinn_phong", m=20.0, eta=0.2 + 3.4j),
        dict(distribution="beckmann", alpha=0.4, eta=1.5, shadowing="smith"),
        dict(distribution="ggx", alpha=0.2, eta=2.5 + 0.5j, correlation="aps"),
        dict(distribution="beckmann", alpha=0.3, eta=1.5, terms=("single", "multiple", "diffuse"), diffuse_albedo=0.5),
    ],
)
def test_reciprocity_sp_frame(kwargs: dict) -> None:
    """M(wo, wi) = C M(wi, wo)^T C, C = diag(1, 1, -1, 1) in the sp frame (derivation in
    src/optics/mueller.rs `reciprocal`: Jones reciprocity J_rev = J^T in fixed physical
    bases plus the sp frames' basis flips)."""
    mat = pprender.Material(**kwargs)
    rng = np.random.default_rng(2024)
    wi = random_dirs(rng, 200, 1e-3)
    wo = random_dirs(rng, 200, 1e-3)
    a = pprender.brdf(mat, wi, wo)
    b = pprender.brdf(mat, wo, wi)
    want = C @ np.swapaxes(a, -1, -2) @ C
    scale = a[..., 0, 0][:, None, None]
    assert np.all(np.abs(b - want) <= 1e-11 * scale), np.abs(b - want).max()


# --- realizability and bounds (property-based) ------------------------------------


def _pure_states(n: int) -> np.ndarray:
    g = np.random.default_rng(7)
    v = g.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return np.concatenate([np.ones((n, 1)), v], axis=1)


PURE = _pure_states(64)

materials = st.builds(
    lambda d, r, n, k, sh, multi: pprender.Material(
        d,
        **({"m": 10 ** (r * 7 / 3 - 1) if r > 0 else 0.0} if d == "blinn_phong" else {"alpha": 10 ** (-2 + r)}),
        eta=complex(n, k),
        shadowing=sh,
        terms=("single", "multiple") if multi else ("single",),
    ),
    st.sampled_from(["blinn_phong", "beckmann", "ggx"]),
    st.floats(0.0, 3.0),
    st.floats(1e-3, 10.0),
    st.floats(0.0, 20.0),
    st.sampled_from(["aps", "smith"]),
    st.booleans(),
)
angles = st.tuples(st.floats(0.0, np.pi / 2 - 1e-7), st.floats(0.0, 2 * np.pi))


@settings(max_examples=60, deadline=None)
@given(materials, angles, angles)
# found by hypothesis (stop 21): a Mueller matrix wholly subnormal (M00 = 7.6e-319)
@example(pprender.Material("blinn_phong", m=10 ** (2.02734375 * 7 / 3 - 1), eta=1 + 1j, terms=("single",)),
         (0.0, 0.0), (1.0234375, 0.0))
def test_mueller_is_physical(mat: pprender.Material, a: tuple, b: tuple) -> None:
    M = pprender.brdf(mat, sph(*a), sph(*b))
    assert np.all(np.isfinite(M))
    assert M[0, 0] >= 0
    assert np.all(np.abs(M) <= M[0, 0] * (1 + 1e-12) + 1e-300)
    # Stokes-output check: every pure input state gives a physical output state.
    S = PURE @ M.T
    dop = np.linalg.norm(S[:, 1:], axis=1)
    assert np.all(dop <= S[:, 0] * (1 + 1e-10) + 1e-300)
    # Cloude: the coherency matrix is positive semidefinite (tolerance 1e-9 M00). Only where
    # M00 > 1e-300: below, the elements' rounding (subnormal steps of 4.9e-324) is no longer
    # small against 1e-9 M00 (a Blinn-Phong lobe of m = 5376 gives M00 = 7.6e-319 at 1 rad
    # off its peak, and its normalized matrix is then quantized to about 1e-5).
    if M[0, 0] > 1e-300:
        assert polarimetry.is_physical(M / M[0, 0], tol=1e-9)


@settings(max_examples=40, deadline=None)
@given(materials, angles)
def test_grazing_and_backscatter_finite(mat: pprender.Material, a: tuple) -> None:
    w = sph(*a)
    for wo in (w, sph(np.pi / 2 - 1e-7, a[1] + 1.0), np.array([0, 0, 1.0])):
        M = pprender.brdf(mat, w, wo)
        assert np.all(np.isfinite(M)) and M[0, 0] >= 0


def test_horizon_gives_zero() -> None:
    mat = pprender.Material("ggx", alpha=0.3, eta=1.5)
    M = pprender.brdf(mat, [1.0, 0, 0], [0, 0, 1.0])
    assert np.all(M == 0)


def test_broadcasting_shapes() -> None:
    mat = pprender.Material("ggx", alpha=0.3, eta=1.5)
    wi = np.broadcast_to(sph(0.3), (5, 1, 3))
    wo = np.stack([sph(t) for t in np.linspace(0, 1, 4)])
    out = pprender.brdf(mat, wi, wo)
    assert out.shape == (5, 4, 4, 4)
    np.testing.assert_allclose(out[2, 1], pprender.brdf(mat, sph(0.3), wo[1]))


def test_masking_modes_agree() -> None:
    """table vs exact masking: same BRDF within the table's error (below 1e-8 relative)."""
    kw = dict(distribution="blinn_phong", m=200.0, eta=0.2 + 3.4j, terms=("single",))
    t = pprender.Material(**kw, masking="table")
    e = pprender.Material(**kw, masking="exact")
    g = np.random.default_rng(3)
    wi, wo = random_dirs(g, 300, 1e-4), random_dirs(g, 300, 1e-4)
    a, b = pprender.brdf(t, wi, wo), pprender.brdf(e, wi, wo)
    err = np.abs(a - b).max(axis=(1, 2)) / b[:, 0, 0]
    assert err.max() < 1e-7, err.max()


def test_seed_masking_option_within_its_documented_error() -> None:
    """masking="seed" (the seed's closed form) stays finite and non-negative and agrees
    with the exact masking near normal incidence. It is NOT energy conserving: its P(k)
    errs by up to 0.12 (docs/seed-approximation.md), and the white furnace then reaches
    1.07 near grazing for m = 100 (measured; 0.9999998 minimum). The bound below
    documents that violation so that a regression beyond it fails."""
    kw = dict(distribution="blinn_phong", m=100.0, eta=0.2 + 3.4j, terms=("single", "multiple"))
    s = pprender.Material(**kw, masking="seed")
    e = pprender.Material(**kw, masking="exact")
    g = np.random.default_rng(5)
    wi, wo = random_dirs(g, 500, 1e-6), random_dirs(g, 500, 1e-6)
    a, b = pprender.brdf(s, wi, wo), pprender.brdf(e, wi, wo)
    assert np.all(np.isfinite(a)) and np.all(a[:, 0, 0] >= 0)
    f = pprender.Material("blinn_phong", m=100.0, eta=float("inf"), masking="seed")
    t = np.linspace(0, np.pi / 2 - 1e-3, 60)
    furnace = pprender.albedo(f, np.stack([np.sin(t), 0 * t, np.cos(t)], -1))
    assert np.all(np.isfinite(furnace))
    assert furnace.min() > 1 - 1e-4 and furnace.max() < 1.08, (furnace.min(), furnace.max())
    # near normal incidence both P are ~1 and the BRDFs agree closely
    near = (wi[:, 2] > 0.95) & (wo[:, 2] > 0.95)
    np.testing.assert_allclose(a[near], b[near], rtol=0.02, atol=1e-12)
