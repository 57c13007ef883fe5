"""pprender against Mitsuba 3 (``roughconductor``, ``conductor``) and textbook Fresnel.

Convention mapping (see ``src/optics/mod.rs`` and SETUP-NOTES): Mitsuba's ``si.wi`` is our
``wo`` (toward the receiver/sensor) and its ``wo`` argument is our ``wi`` (toward the
transmitter/light). Mitsuba's ``eval`` includes ``cos(theta)`` of its ``wo``, i.e. our
``wi.z``, and its Mueller matrix maps ``stokes_basis(-wi)`` on the incident beam to
``stokes_basis(wo)`` on the reflected beam, which is our ``frame="mitsuba"``. Mitsuba's
``roughconductor`` uses the uncorrelated Smith product ``G1(wi) G1(wo)`` with Walter's
rational approximation of the Beckmann ``G1`` (GGX is exact), so the matching material is
``Material(dist, alpha=a, eta=n+1j*k, shadowing="smith", correlation="none",
smith_g1="walter", terms=("single",))`` and::

    Mitsuba eval  ==  pprender.brdf(material, wi, wo, frame="mitsuba") * wi.z

Precision and tolerances
------------------------
The wheel has no double-precision variant (``mi.variants()`` lists only float32 scalar,
llvm and cuda variants), so Mitsuba is evaluated in ``llvm_ad_mono_polarized`` (float32,
vectorized). The requested 1e-5 relative agreement is therefore checked two ways:

1. pprender (float64) against an independent float64 implementation of Mitsuba's
   ``roughconductor`` formulas written below (textbook Fresnel amplitudes, the s/p Jones
   matrix projected on Mitsuba's ``stokes_basis``, Beckmann/GGX ``D``, Walter's/exact
   ``G1``): ``|M_ours - M_ref| <= 1e-10 * M00`` element-wise over the whole 4x4 matrix.
2. pprender against Mitsuba itself, with float32-limited tolerance. Element-wise relative
   errors are meaningless for near-zero elements (e.g. ``M03``, which is ~1e-17 in float64
   and exactly 0 in float32), so every element is compared relative to ``M00``, the
   largest element of a Mueller matrix (``|M_ij| <= M00``)::

       |M_ours - M_mitsuba|_ij <= 32 * eps32 * kappa * M00,   eps32 = 2**-24,
       kappa = 1 + tan^2(theta_h)/alpha^2 + 1/cos(theta_i) + 1/cos(theta_o) + 1/|wi - wo|

   Each term of ``kappa`` is a condition number of Mitsuba's float32 evaluation:
   ``tan^2(theta_h)/alpha^2`` is the argument of the Beckmann exponential / of the GGX
   denominator, whose absolute float32 error becomes a relative error of ``D``;
   ``1/cos`` comes from the divisions by cos(theta) (and tan(theta) in ``G1``) computed from
   float32 z components near grazing; ``1/|wi - wo|`` comes from Mitsuba computing the two
   s axes ``cross(H, -wo)`` and ``cross(H, wi)`` separately: near backscatter they have
   length ~|wi - wo|/2 and absolute rounding error ~eps32, so the input and output frames
   rotate by ~eps32/|wi - wo| relative to each other and the mirror-like QU block (~M00)
   picks that up. For bitwise-identical ``wi`` and ``wo`` (exact backscatter) both cross
   products are exactly zero, so that term is dropped. The observed error is at most
   ~10 eps32 kappa over 20 000 random pairs per material; 32 leaves a factor ~3 of margin.
   Inputs are rounded to float32 first and the same rounded directions go to both codes.
   Without the near-backscatter term the tolerance would be ~1e-5..1e-4; near exact
   backscatter (|wi - wo| ~ 1e-4) Mitsuba's own error reaches ~1e-2 * M00, while pprender
   still agrees with the float64 reference to 1e-12.

Mitsuba sets ``D = 0`` where ``D(h) cos(theta_h) <= 1e-20``; such pairs are checked to be
exactly zero in Mitsuba and excluded from the comparison (pprender does not cut), as are
pairs within 0.1% of that threshold (float32 decides them either way).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

import pprender

EPS32 = 2.0**-24
C_F32 = 32.0  # float32 safety factor on the condition number (observed <= ~10)
TOL_REF = 1e-10  # pprender vs the float64 reference, relative to M00
TOL_SPECULAR_F32 = 32.0 * EPS32  # smooth conductor: Fresnel + exact frames, no amplification
D_CUT = 1e-20  # Mitsuba's microfacet cut-off on D(h) cos(theta_h)

DISTS = ("beckmann", "ggx")
ALPHAS = (0.05, 0.1, 0.3, 0.6)
ETAS = (0.2 + 3.4j, 1.5 + 0j, 2.5 + 0.5j, 0.05 + 4j)
SILVER = 0.136125 + 4.010625j  # Ag at 635.8 nm, as in Mitsuba's test_conductor.py

# --------------------------------------------------------------------------------------
# Independent float64 reference of Mitsuba's roughconductor / conductor formulas
# --------------------------------------------------------------------------------------

PAULI = np.array(
    [[[1, 0], [0, 1]], [[1, 0], [0, -1]], [[0, 1], [1, 0]], [[0, 1j], [-1j, 0]]], dtype=complex
)


def stokes_basis(w: np.ndarray) -> np.ndarray:
    """Mitsuba's ``mueller.stokes_basis``: first vector of ``coordinate_system`` (Duff et al.)."""
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    sign = np.where(np.signbit(z), -1.0, 1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    return np.stack([sign * x * x * a + 1.0, sign * b, -sign * x], axis=-1)


def fresnel_amplitudes(cos_t: np.ndarray, eta: complex) -> tuple[np.ndarray, np.ndarray]:
    """Textbook rs, rp for ``eta = n + ik`` (k >= 0), Verdet-like sign (rp = -rs at 0 deg)."""
    e2 = complex(eta) ** 2
    w = np.sqrt(e2 - (1.0 - cos_t**2) + 0j)
    rs = (cos_t - w) / (cos_t + w)
    rp = (e2 * cos_t - w) / (e2 * cos_t + w)
    return rs, rp


def jones_to_mueller(j: np.ndarray) -> np.ndarray:
    """``M_ij = 1/2 tr(sigma_i J sigma_j J^H)`` (Stokes V = 2 Im(Ex Ey*))."""
    jh = np.conj(np.swapaxes(j, -1, -2))
    return 0.5 * np.einsum("iab,...bc,jcd,...da->...ij", PAULI, j, PAULI, jh).real


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sum(a * b, axis=-1)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def reflection_mueller_mitsuba_frame(wi: np.ndarray, wo: np.ndarray, eta: complex) -> np.ndarray:
    """Mueller matrix of the facet reflection wi -> wo (facet normal h = normalize(wi + wo)),
    incident beam in ``stokes_basis(-wi)``, reflected beam in ``stokes_basis(wo)``."""
    k_in, k_out = -wi, wo
    h = _unit(wi + wo)
    s = np.cross(k_in, h)
    ns = np.linalg.norm(s, axis=-1, keepdims=True)
    # (Near-)exact backscatter: the s axis is undefined (and h.wi = 1, rs = -rp, so the
    # result does not depend on it); cross() of two nearly parallel vectors is rounding
    # noise below ~1e-8, so take any axis perpendicular to the beam there.
    degenerate = ns < 1e-8
    s = np.where(degenerate, stokes_basis(k_in), s / np.where(degenerate, 1.0, ns))
    p_in, p_out = np.cross(k_in, s), np.cross(k_out, s)
    rs, rp = fresnel_amplitudes(np.clip(_dot(wi, h), 0.0, 1.0), eta)
    x_in = stokes_basis(k_in)
    y_in = np.cross(k_in, x_in)
    x_out = stokes_basis(k_out)
    y_out = np.cross(k_out, x_out)

    def proj(a: np.ndarray, b: np.ndarray) -> np.ndarray:  # a_out . P . b_in
        return rs * _dot(a, s) * _dot(s, b) + rp * _dot(a, p_out) * _dot(p_in, b)

    j = np.stack(
        [np.stack([proj(x_out, x_in), proj(x_out, y_in)], -1), np.stack([proj(y_out, x_in), proj(y_out, y_in)], -1)],
        -2,
    )
    return jones_to_mueller(j)


def tan2_over_alpha2(h: np.ndarray, alpha: float) -> np.ndarray:
    return (h[..., 0] ** 2 + h[..., 1] ** 2) / (h[..., 2] ** 2 * alpha**2)


def ndf(dist: str, alpha: float, h: np.ndarray) -> np.ndarray:
    c4 = h[..., 2] ** 4
    x = tan2_over_alpha2(h, alpha)
    if dist == "beckmann":
        return np.exp(-x) / (math.pi * alpha**2 * c4)
    return 1.0 / (math.pi * alpha**2 * c4 * (1.0 + x) ** 2)


def smith_g1(dist: str, alpha: float, v: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Mitsuba's G1: Walter's rational fit for Beckmann, exact for GGX."""
    t2a2 = (v[..., 0] ** 2 + v[..., 1] ** 2) * alpha**2 / v[..., 2] ** 2
    if dist == "beckmann":
        with np.errstate(divide="ignore", invalid="ignore"):
            a = 1.0 / np.sqrt(t2a2)
            g = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a))
    else:
        g = 2.0 / (1.0 + np.sqrt(1.0 + t2a2))
    return np.where(_dot(v, h) * v[..., 2] > 0, g, 0.0)


def reference_eval(dist: str, alpha: float, eta: complex, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Float64 Mitsuba ``roughconductor.eval``: F D G1 G1 / (4 cos_i cos_o) * cos_i."""
    h = _unit(wi + wo)
    f = ndf(dist, alpha, h) * smith_g1(dist, alpha, wi, h) * smith_g1(dist, alpha, wo, h) / (4.0 * wo[..., 2])
    return reflection_mueller_mitsuba_frame(wi, wo, eta) * f[..., None, None]


# --------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------


def sph(theta: "np.ndarray | float", phi: "np.ndarray | float") -> np.ndarray:
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def uniform_hemisphere(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniform in solid angle over the upper hemisphere."""
    z = rng.random(n)
    r = np.sqrt(1.0 - z * z)
    phi = 2.0 * math.pi * rng.random(n)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def sample_normals(rng: np.random.Generator, dist: str, alpha: float, n: int) -> np.ndarray:
    """Microfacet normals distributed as D(h) cos(theta_h)."""
    u = rng.random(n)
    t2 = -(alpha**2) * np.log1p(-u) if dist == "beckmann" else alpha**2 * u / (1.0 - u)
    return sph(np.arctan(np.sqrt(t2)), 2.0 * math.pi * rng.random(n))


def reflect_about(w: np.ndarray, h: np.ndarray) -> np.ndarray:
    return 2.0 * _dot(w, h)[..., None] * h - w


def importance_pairs(rng: np.random.Generator, dist: str, alpha: float, w_fixed: np.ndarray, n: int) -> np.ndarray:
    """For each fixed direction, a partner reflected about a sampled normal (so the BRDF is
    not negligible); only pairs with both directions above the horizon are kept."""
    reps = 8
    w = np.repeat(w_fixed, reps, axis=0)
    h = sample_normals(rng, dist, alpha, len(w))
    other = _unit(reflect_about(w, h))
    ok = (other[:, 2] > 1e-4) & (_dot(w, h) > 0)
    pairs = np.stack([w[ok], other[ok]], axis=1)[:n]
    assert len(pairs) >= n // 2, "not enough valid importance-sampled pairs"
    return pairs


def near_backscatter_pairs(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    wi = sph(np.radians(rng.uniform(0.0, 80.0, n)), rng.uniform(0.0, 2 * math.pi, n))
    delta = 10.0 ** rng.uniform(-4.0, -1.5, n)
    t = _unit(np.cross(wi, rng.normal(size=(n, 3))))
    wo = _unit(wi + delta[:, None] * t)
    return wi, wo


def f32(w: np.ndarray) -> np.ndarray:
    """Round to float32 (what Mitsuba sees) and back."""
    return np.asarray(w, dtype=np.float32).astype(np.float64)


# --------------------------------------------------------------------------------------
# Evaluation
# --------------------------------------------------------------------------------------


def _mueller_from_mitsuba(value: object, n: int) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64).reshape(4, 4, -1)
    assert a.shape[-1] == n
    return np.moveaxis(a, -1, 0)


def mitsuba_rough_eval(mi, dist: str, alpha: float, eta: complex, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    import drjit as dr

    bsdf = mi.load_dict(
        {"type": "roughconductor", "distribution": dist, "alpha": alpha, "eta": eta.real, "k": eta.imag}
    )
    n = len(wi)
    wi32 = np.asarray(wi, np.float32)
    wo32 = np.asarray(wo, np.float32)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(wo32[:, 0], wo32[:, 1], wo32[:, 2])  # Mitsuba si.wi = our wo (sensor)
    value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wi32[:, 0], wi32[:, 1], wi32[:, 2]))  # wo = our wi
    return _mueller_from_mitsuba(value, n)


def matching_material(dist: str, alpha: float, eta: complex) -> pprender.Material:
    return pprender.Material(
        dist, alpha=alpha, eta=eta, shadowing="smith", correlation="none", smith_g1="walter", terms=("single",)
    )


def check_rough(mi, dist: str, alpha: float, eta: complex, wi: np.ndarray, wo: np.ndarray, min_compared: int) -> dict:
    """Compare pprender with the float64 reference and with Mitsuba; returns statistics."""
    wi, wo = f32(wi), f32(wo)
    n = len(wi)
    exact_bs = np.all(wi == wo, axis=-1)
    wi_u, wo_u = _unit(wi), _unit(wo)

    ours = pprender.brdf(matching_material(dist, alpha, eta), wi, wo, frame="mitsuba") * wi_u[:, 2, None, None]
    ref = reference_eval(dist, alpha, eta, wi_u, wo_u)
    theirs = mitsuba_rough_eval(mi, dist, alpha, eta, wi, wo)

    h = _unit(wi_u + wo_u)
    d_cos = ndf(dist, alpha, h) * h[:, 2]
    cut = d_cos < D_CUT * (1 - 1e-3)
    near_cut = np.abs(d_cos / D_CUT - 1) <= 1e-3
    assert np.all(theirs[cut] == 0.0), "Mitsuba should cut D cos(theta_h) <= 1e-20 to zero"

    # Far from the specular configuration the Beckmann exponential underflows float64 too.
    zero = ref[:, 0, 0] < 1e-290
    assert np.all(np.abs(ours[zero]) < 1e-290), "pprender nonzero where the float64 reference underflows"
    ours, ref, theirs = ours[~zero], ref[~zero], theirs[~zero]
    wi, wo, wi_u, wo_u, h = wi[~zero], wo[~zero], wi_u[~zero], wo_u[~zero], h[~zero]
    exact_bs, cut, near_cut = exact_bs[~zero], cut[~zero], near_cut[~zero]
    m00 = ours[:, 0, 0]
    assert np.all(m00 > 0), "pprender M00 must be positive for directions above the horizon"

    # 1. pprender vs independent float64 reference (pairs cut by Mitsuba included).
    err_ref = np.max(np.abs(ours - ref), axis=(1, 2)) / m00
    i = int(np.argmax(err_ref))
    assert err_ref[i] <= TOL_REF, (
        f"pprender vs float64 reference: max |dM|/M00 = {err_ref[i]:.3e} > {TOL_REF:.0e} at "
        f"wi={wi[i].tolist()}, wo={wo[i].tolist()}\nours=\n{ours[i]}\nref=\n{ref[i]}"
    )

    # 2. pprender vs Mitsuba (float32), relative to M00 with the conditioning model.
    cmp = ~cut & ~near_cut
    assert cmp.sum() >= min_compared, f"only {cmp.sum()} of {n} pairs comparable (min {min_compared})"
    with np.errstate(divide="ignore"):
        inv_sep = np.where(exact_bs, 0.0, 1.0 / np.linalg.norm(wi - wo, axis=-1))
    kappa = 1.0 + tan2_over_alpha2(h, alpha) + 1.0 / wi_u[:, 2] + 1.0 / wo_u[:, 2] + inv_sep
    tol = C_F32 * EPS32 * kappa
    err = np.max(np.abs(ours - theirs), axis=(1, 2)) / m00
    ratio = np.where(cmp, err / tol, 0.0)
    i = int(np.argmax(ratio))
    assert ratio[i] <= 1.0, (
        f"pprender vs Mitsuba: |dM|/M00 = {err[i]:.3e} > tol {tol[i]:.3e} (kappa {kappa[i]:.3g}) at "
        f"wi={wi[i].tolist()}, wo={wo[i].tolist()}\nours=\n{ours[i]}\nmitsuba=\n{theirs[i]}"
    )
    # Sanity: Mitsuba agrees with the float64 reference within the same float32 bound.
    err_mr = np.max(np.abs(theirs - ref), axis=(1, 2)) / m00
    assert np.all(err_mr[cmp] <= tol[cmp] * 1.01)
    return {
        "n": n,
        "compared": int(cmp.sum()),
        "cut": int(cut.sum()),
        "max_err_ref": float(err_ref.max()),
        "max_err_mitsuba": float(err[cmp].max()),
        "max_err_over_tol": float(ratio.max()),
        "max_err_mitsuba_excl_near_backscatter": float(np.max(err[cmp & (inv_sep < 10)], initial=0.0)),
    }


# --------------------------------------------------------------------------------------
# Tests: frames and mapping
# --------------------------------------------------------------------------------------


def test_reference_stokes_basis_is_mitsubas(mitsuba, rng):
    mi = mitsuba
    v = np.concatenate([_unit(rng.normal(size=(200, 3))), [[0, 0, 1.0], [0, 0, -1.0], [0.6, 0.0, -0.8]]])
    v32 = np.asarray(v, np.float32)
    theirs = np.asarray(mi.mueller.stokes_basis(mi.Vector3f(v32[:, 0], v32[:, 1], v32[:, 2])), np.float64).T
    np.testing.assert_allclose(stokes_basis(f32(v)), theirs, rtol=0, atol=1e-6)


def test_mitsuba_fixture_variant(mitsuba):
    assert mitsuba.variant() == "llvm_ad_mono_polarized"
    assert mitsuba.__version__.startswith("3.")


# --------------------------------------------------------------------------------------
# Tests: roughconductor
# --------------------------------------------------------------------------------------

BACKSCATTER_THETA_DEG = (0.0, 0.01, 5.0, 15.0, 30.0, 45.0, 60.0, 70.0, 80.0, 85.0, 87.0, 89.0, 89.9)
ROUGH_CASES = [(d, a, e) for d in DISTS for a in ALPHAS for e in ETAS]
ROUGH_IDS = [f"{d}-a{a}-eta{e.real}{e.imag:+}j" for d, a, e in ROUGH_CASES]


@pytest.mark.parametrize("dist,alpha,eta", ROUGH_CASES, ids=ROUGH_IDS)
def test_roughconductor_backscatter(mitsuba, dist, alpha, eta, record_property):
    """Exact backscatter (wi == wo bitwise) at generic azimuths; see the next test for
    directions in the x-z and y-z planes."""
    theta, phi = np.meshgrid(np.radians(BACKSCATTER_THETA_DEG), [0.8, 2.5, 4.0], indexing="ij")
    w = sph(theta.ravel(), phi.ravel())
    # Beckmann D falls below Mitsuba's cut-off beyond tan(theta) ~ 6.8 alpha; the 12 points
    # with theta <= 15 deg always remain.
    stats = check_rough(mitsuba, dist, alpha, eta, w, w.copy(), min_compared=12)
    record_property("stats", stats)


FRAME_FREE = ((0, 0), (0, 3), (3, 0), (3, 3))  # elements unchanged by rotations of the s axes


@pytest.mark.parametrize("dist", DISTS)
def test_roughconductor_backscatter_in_axis_planes(mitsuba, dist, record_property):
    """Exact backscatter with wi in the x-z or y-z plane.

    Mitsuba 3.9.0 computes the s axis as cross(H, -wo); at exact backscatter that is zero or
    rounding noise, and when it is exactly zero (e.g. theta = 30/60 deg in these planes)
    Mitsuba falls back to s = (1, 0, 0), which is not perpendicular to the beam: its Q/U
    block then comes out rotated (theta = 30, 60 deg at phi = 0) or NaN (phi = pi/2).
    At exact backscatter the physical answer is R diag(1, 1, -1, -1) in any frames with a
    consistent s axis, which pprender returns (checked against the float64 reference).
    Against Mitsuba only the frame-independent elements M00, M03, M30, M33 are compared."""
    alpha, eta = 0.6, ETAS[0]
    theta, phi = np.meshgrid(np.radians(BACKSCATTER_THETA_DEG), [0.0, math.pi / 2, math.pi], indexing="ij")
    w = f32(sph(theta.ravel(), phi.ravel()))
    wu = _unit(w)
    ours = pprender.brdf(matching_material(dist, alpha, eta), w, w, frame="mitsuba") * wu[:, 2, None, None]
    ref = reference_eval(dist, alpha, eta, wu, wu)
    theirs = mitsuba_rough_eval(mitsuba, dist, alpha, eta, w, w)
    keep = ndf(dist, alpha, wu) * wu[:, 2] > D_CUT * (1 + 1e-3)  # above Mitsuba's cut-off
    assert keep.sum() >= 24
    w, wu, ours, ref, theirs = w[keep], wu[keep], ours[keep], ref[keep], theirs[keep]
    m00 = ours[:, 0, 0]
    np.testing.assert_allclose(ours / m00[:, None, None], ref / ref[:, :1, :1], rtol=0, atol=TOL_REF)
    # Exact backscatter on an isotropic surface: a mirror at normal incidence on the facet.
    mirror = np.broadcast_to(np.diag([1.0, 1.0, -1.0, -1.0]), ours.shape)
    np.testing.assert_allclose(ours / m00[:, None, None], mirror, rtol=0, atol=1e-12)

    kappa = 1.0 + tan2_over_alpha2(wu, alpha) + 2.0 / wu[:, 2]
    tol = C_F32 * EPS32 * kappa
    for i, j in FRAME_FREE:
        err = np.abs(ours[:, i, j] - theirs[:, i, j]) / m00
        assert np.all(err <= tol), f"M{i}{j}: max |dM|/M00 = {err.max():.3e}"
    full = np.max(np.abs(ours - theirs), axis=(1, 2)) / m00
    record_property(
        "stats",
        {
            "mitsuba_nonfinite": int(np.sum(~np.isfinite(full))),
            "mitsuba_full_matrix_off_by_more_than_tol": int(np.sum(~(full <= tol))),
            "points": len(w),
        },
    )


@pytest.mark.parametrize("dist,alpha,eta", ROUGH_CASES, ids=ROUGH_IDS)
def test_roughconductor_bistatic(mitsuba, rng, dist, alpha, eta, record_property):
    wi_u = uniform_hemisphere(rng, 1000)
    wo_u = uniform_hemisphere(rng, 1000)
    imp = importance_pairs(rng, dist, alpha, uniform_hemisphere(rng, 600), 600)
    wi_b, wo_b = near_backscatter_pairs(rng, 200)
    wi = np.concatenate([wi_u, imp[:, 0], wi_b])
    wo = np.concatenate([wo_u, imp[:, 1], wo_b])
    # Swap roles for half of the importance-sampled pairs (the formulas are not symmetric
    # in their frames).
    swap = np.zeros(len(wi), bool)
    swap[1000 : 1000 + len(imp) : 2] = True
    wi[swap], wo[swap] = wo[swap].copy(), wi[swap].copy()
    stats = check_rough(mitsuba, dist, alpha, eta, wi, wo, min_compared=700)
    record_property("stats", stats)


@pytest.mark.parametrize("dist,alpha,eta", ROUGH_CASES, ids=ROUGH_IDS)
def test_roughconductor_near_grazing(mitsuba, rng, dist, alpha, eta, record_property):
    def grazing(n: int) -> np.ndarray:
        return sph(np.radians(rng.uniform(85.0, 89.9, n)), rng.uniform(0.0, 2 * math.pi, n))

    a = importance_pairs(rng, dist, alpha, grazing(200), 200)  # grazing wi, reflected wo
    b = importance_pairs(rng, dist, alpha, grazing(200), 200)[:, ::-1]  # grazing wo
    both_i, both_o = grazing(100), grazing(100)  # both grazing, random azimuths
    bs = grazing(20)  # grazing exact backscatter
    wi = np.concatenate([a[:, 0], b[:, 0], both_i, bs])
    wo = np.concatenate([a[:, 1], b[:, 1], both_o, bs])
    stats = check_rough(mitsuba, dist, alpha, eta, wi, wo, min_compared=150)
    record_property("stats", stats)


def test_roughconductor_horizon_is_zero(mitsuba):
    """A direction exactly on the horizon gives the zero matrix in both codes."""
    wi = np.array([[1.0, 0.0, 0.0], [0.0, 0.6, 0.8], [0.6, -0.8, 0.0]])
    wo = np.array([[0.0, 0.6, 0.8], [1.0, 0.0, 0.0], [-0.6, 0.8, 0.0]])
    for dist in DISTS:
        ours = pprender.brdf(matching_material(dist, 0.3, ETAS[0]), wi, wo, frame="mitsuba")
        theirs = mitsuba_rough_eval(mitsuba, dist, 0.3, ETAS[0], wi, wo)
        assert np.all(ours == 0.0) and np.all(theirs == 0.0)


# --------------------------------------------------------------------------------------
# Tests: smooth conductor (delta reflection)
# --------------------------------------------------------------------------------------

@functools.lru_cache(maxsize=None)
def flat_material(eta: complex) -> pprender.Material:
    """For ``pprender.specular`` (roughness and shadowing are ignored there); single-term
    Smith so that no albedo tables are built."""
    return pprender.Material("ggx", alpha=0.1, eta=eta, shadowing="smith", terms=("single",))


SPECULAR_THETA_DEG = (0.0, 0.01, 10.0, 30.0, 45.0, 56.31, 60.0, 75.0, 85.0, 88.0, 89.0, 89.9)


@pytest.mark.parametrize("eta", ETAS + (SILVER,), ids=lambda e: f"eta{e.real}{e.imag:+}j")
def test_conductor_sampled_weight(mitsuba, eta, record_property):
    import drjit as dr

    mi = mitsuba
    theta, phi = np.meshgrid(np.radians(SPECULAR_THETA_DEG), [0.0, 0.9, 3.0, 5.5], indexing="ij")
    wi = f32(sph(theta.ravel(), phi.ravel()))  # ours: toward the light
    wo = wi * np.array([-1.0, -1.0, 1.0])  # mirror direction, toward the sensor
    n = len(wi)

    bsdf = mi.load_dict({"type": "conductor", "eta": eta.real, "k": eta.imag})
    ctx = mi.BSDFContext()
    ctx.type_mask = mi.BSDFFlags.DeltaReflection
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    wo32 = np.asarray(wo, np.float32)
    si.wi = mi.Vector3f(wo32[:, 0], wo32[:, 1], wo32[:, 2])
    bs, weight = bsdf.sample(ctx, si, mi.Float(np.full(n, 0.5)), mi.Point2f(np.full(n, 0.5), np.full(n, 0.5)))
    sampled = np.asarray(bs.wo, np.float64).reshape(3, -1).T
    np.testing.assert_allclose(sampled, wi, rtol=0, atol=1e-6)  # Mitsuba's sampled wo is our wi
    theirs = _mueller_from_mitsuba(weight, n)

    ours = pprender.specular(flat_material(eta), wi, frame="mitsuba")
    ref = reflection_mueller_mitsuba_frame(_unit(wi), _unit(wo), eta)
    m00 = ours[:, 0, 0]
    err_ref = np.max(np.abs(ours - ref), axis=(1, 2)) / m00
    assert err_ref.max() <= 1e-12, f"pprender.specular vs float64 reference: {err_ref.max():.3e}"
    err = np.max(np.abs(ours - theirs), axis=(1, 2)) / m00
    i = int(np.argmax(err))
    assert err[i] <= TOL_SPECULAR_F32, (
        f"pprender.specular vs Mitsuba conductor: |dM|/M00 = {err[i]:.3e} > {TOL_SPECULAR_F32:.2e} at "
        f"wi={wi[i].tolist()}\nours=\n{ours[i]}\nmitsuba=\n{theirs[i]}"
    )
    record_property("stats", {"max_err_ref": float(err_ref.max()), "max_err_mitsuba": float(err.max())})


# --------------------------------------------------------------------------------------
# Tests: physics of specular reflection on pprender output (frame "sp"), as in Mitsuba's
# test_conductor.py, against textbook Fresnel
# --------------------------------------------------------------------------------------

PHYS_THETA_DEG = (0.0, 20.0, 45.0, 60.0, 80.0, 89.0)


def _sp_specular(eta: complex, theta_deg: float, phi: float = 0.7) -> np.ndarray:
    wi = sph(np.radians(theta_deg), phi)
    return pprender.specular(flat_material(eta), wi, frame="sp")


@pytest.mark.parametrize("eta", ETAS + (SILVER,), ids=lambda e: f"eta{e.real}{e.imag:+}j")
@pytest.mark.parametrize("theta_deg", PHYS_THETA_DEG)
def test_specular_unpolarized_is_scalar_fresnel(eta, theta_deg):
    m = _sp_specular(eta, theta_deg)
    rs, rp = fresnel_amplitudes(np.cos(np.radians(theta_deg)), eta)
    r_unpol = 0.5 * (abs(rs) ** 2 + abs(rp) ** 2)
    out = m @ np.array([1.0, 0.0, 0.0, 0.0])
    assert out[0] == pytest.approx(r_unpol, rel=1e-12)
    # Full matrix: the Jones matrix in the s/p frames is diag(rs, rp).
    np.testing.assert_allclose(m, jones_to_mueller(np.diag([rs, rp])), rtol=0, atol=1e-13)


@pytest.mark.parametrize("eta", ETAS + (SILVER,), ids=lambda e: f"eta{e.real}{e.imag:+}j")
@pytest.mark.parametrize("theta_deg", PHYS_THETA_DEG)
@pytest.mark.parametrize("q", [+1.0, -1.0], ids=["horizontal", "vertical"])
def test_specular_linear_states_stay_linear(eta, theta_deg, q):
    m = _sp_specular(eta, theta_deg)
    out = m @ np.array([1.0, q, 0.0, 0.0])
    rs, rp = fresnel_amplitudes(np.cos(np.radians(theta_deg)), eta)
    intensity = abs(rs) ** 2 if q > 0 else abs(rp) ** 2  # x = s: horizontal = s-polarized
    assert out[0] == pytest.approx(intensity, rel=1e-12)
    assert out[1] == pytest.approx(q * out[0], rel=1e-12)  # same linear state
    assert abs(out[2]) <= 1e-13 * out[0] and abs(out[3]) <= 1e-13 * out[0]  # U = V = 0
    dop = np.sqrt(out[1] ** 2 + out[2] ** 2 + out[3] ** 2) / out[0]
    assert dop == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("eta", ETAS + (SILVER,), ids=lambda e: f"eta{e.real}{e.imag:+}j")
@pytest.mark.parametrize("v", [+1.0, -1.0], ids=["right", "left"])
def test_specular_circular_handedness_flips_at_normal_incidence(eta, v):
    r = abs((eta - 1) / (eta + 1)) ** 2
    for phi in (0.0, 1.3):
        m = _sp_specular(eta, 0.0, phi)
        out = m @ np.array([1.0, 0.0, 0.0, v])
        np.testing.assert_allclose(out, [r, 0.0, 0.0, -v * r], rtol=0, atol=1e-14)


@pytest.mark.parametrize("theta_deg", (30.0, 45.0, 60.0))
def test_specular_diagonal_and_circular_signs_for_silver(theta_deg):
    """Mitsuba's test_conductor.py: for silver at oblique incidence, +45 deg linear light
    becomes -45-ish with some circular part, and circular handedness flips. The sign of the
    circular part follows the textbook Im(rs rp*) in our convention."""
    m = _sp_specular(SILVER, theta_deg)
    rs, rp = fresnel_amplitudes(np.cos(np.radians(theta_deg)), SILVER)
    for u in (+1.0, -1.0):
        out = m @ np.array([1.0, 0.0, u, 0.0])
        assert np.sign(out[2]) == -u
        assert out[3] == pytest.approx(u * np.imag(rs * np.conj(rp)), rel=1e-12)
        assert out[3] != 0.0
    for v in (+1.0, -1.0):
        out = m @ np.array([1.0, 0.0, 0.0, v])
        assert np.sign(out[3]) == -v
