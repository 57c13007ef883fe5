"""Explicit-microsurface Monte Carlo reference for the polarized BRDF (PHYSICS.md section 6).

A random Gaussian height field (Gaussian heights, Gaussian autocorrelation, so the facet
slopes are exactly Gaussian: a Beckmann surface) on a periodic ``grid x grid`` tile,
triangulated (two planar facets per cell), is ray traced in geometric optics: each
primary ray arrives along ``-wi`` at a uniformly random point of the tile, reflects off
the facets (no transmission) with the complex Fresnel amplitudes of ``eta`` in each
facet's s/p basis, carrying its full polarization (the 3x3 polarization ray-tracing
matrix), until it leaves the surface or reaches ``max_order`` reflections. Rays leaving
within a cone of half-angle ``cone`` around a detector direction ``wo`` are tallied as
Mueller matrices, separately for 1, 2 and 3 or more reflections. No code is shared with
the analytic model except the Fresnel amplitudes and the frame conventions of
``pprender`` (``src/optics/mod.rs``); incoherent, with an optional separate coherent
backscatter tally (``wavelength``, ``bistatic``; derivation in ``src/reference/mod.rs``).

Roughness: Beckmann ``alpha`` with ``alpha**2 = 2 var(slope component) = E[sx**2 + sy**2]``;
Blinn-Phong ``m`` converts with ``alpha = sqrt(2/(m+2))``. The heights are rescaled so the
realized rms slope of the tile's facets equals ``alpha`` exactly; the realized value
before rescaling, relative to its ensemble expectation, is reported per batch.

Estimator (derivation in ``src/reference/mod.rs``): with ``R`` rays,
``f = sum over rays in the cone of M_ray / (R * pi sin(cone)**2 cos(theta_o))``, which is
the cos-weighted mean of the BRDF over the cone (bias O(cone**2) from the curvature of
``f``). The output Stokes basis is the frame's basis at ``wo`` carried to each ray's own
direction by the minimal rotation (parallel transport), so no power is lost and the
basis is smooth across the cone even at the pole.

Units: BRDFs in 1/sr without the cosine factor, as :func:`pprender.brdf`.
"""

from __future__ import annotations

import math
import numbers
from typing import Any, Dict, Optional

import numpy as np

from . import _core
from ._core import Error

__all__ = ["microsurface", "height_field", "bistatic_directions", "ORDERS", "COHERENT_ORDERS"]

ORDERS = (1, 2, "3+")
COHERENT_ORDERS = (2, "3+")


def _int(x: object, name: str, lo: int, hi: int) -> int:
    if isinstance(x, bool) or not isinstance(x, numbers.Integral):
        raise Error(f"invalid {name} = {x!r}: must be an integer in [{lo}, {hi}]")
    v = int(x)
    if not lo <= v <= hi:
        raise Error(f"invalid {name} = {v}: must be an integer in [{lo}, {hi}]")
    return v


def _float(x: object, name: str) -> float:
    if isinstance(x, bool) or not isinstance(x, numbers.Real):
        raise Error(f"invalid {name} = {x!r}: must be a real number")
    return float(x)


def _alpha(alpha: object, m: object, required: bool = True) -> Optional[float]:
    if alpha is not None and m is not None:
        raise Error("invalid m: give either alpha or m, not both")
    if m is not None:
        mm = _float(m, "m")
        if not (math.isfinite(mm) and mm >= 0.0):
            raise Error(f"invalid m = {mm}: must be finite and >= 0")
        return math.sqrt(2.0 / (mm + 2.0))
    if alpha is not None:
        return _float(alpha, "alpha")
    if required:
        raise Error("invalid alpha = None: give a roughness (alpha or m)")
    return None


def _eta(eta: object) -> complex:
    if isinstance(eta, bool) or not isinstance(eta, numbers.Complex):
        raise Error(f"invalid eta = {eta!r}: must be a complex number n + ik (inf for a perfect conductor)")
    return complex(eta)


def microsurface(
    wi: object,
    wo: object,
    *,
    alpha: Optional[float] = None,
    m: Optional[float] = None,
    eta: complex = 1.5 + 0j,
    rays: int = 100_000,
    grid: int = 256,
    correlation_length: float = 8.0,
    cone: float = 0.05,
    max_order: int = 10,
    frame: str = "sp",
    seed: int = 0,
    batches: int = 10,
    heights: object = None,
    wavelength: Optional[float] = None,
    bistatic: object = None,
) -> Dict[str, Any]:
    """Monte Carlo Mueller BRDF of an explicit random microsurface, per bounce order.

    Parameters
    ----------
    wi : array_like, shape (3,)
        Unit vector toward the transmitter, ``z > 0``.
    wo : array_like, shape (..., 3)
        Detector directions (unit, ``z > sin(cone)``), all tallied from the same rays.
    alpha, m : float, optional
        Beckmann roughness, or the Blinn-Phong exponent (``alpha = sqrt(2/(m+2))``);
        exactly one unless ``heights`` is given. ``alpha`` in [1e-8, 4].
    eta : complex, optional
        Complex index ``n + ik`` of the surface; ``complex(inf, 0)`` is a perfect conductor
        (``rs = -1, rp = 1``). Default 1.5.
    rays : int, optional
        Total number of primary rays (all batches together). Default 100000.
    grid : int, optional
        Tile size in grid cells (16 to 4096). Default 256.
    correlation_length : float, optional
        Height correlation length in grid units, in [2, grid/4] (``C(r) ~ exp(-r**2 / l**2)``;
        the tile holds ``grid / l`` correlation lengths per side). Default 8.
    cone : float, optional
        Detector half-angle in radians, (0, pi/4]. Default 0.05.
    max_order : int, optional
        Maximum number of reflections followed (1 to 1000); power still on the surface after
        it is reported as ``truncated``. Default 10.
    frame : {"sp", "mitsuba"}, optional
        Stokes bases (see :mod:`pprender`). Default ``"sp"``.
    seed : int, optional
        Non-negative integer; batch ``b`` traces the surface
        ``height_field(..., seed=seed, batch=b)`` with its own rays. Default 0.
    batches : int, optional
        Number of independent batches (>= 2), each with its own surface realization;
        standard errors are those of the mean of the batch estimates. Default 10.
    heights : array_like, optional
        ``(n, n)`` array of heights (``heights[i, j]`` at ``x = i, y = j``, grid units,
        periodic) traced instead of random surfaces (then give no roughness; every batch uses
        this surface).
    wavelength : float, optional
        Turns on the coherent backscatter tally: the wavelength in grid units (the units of
        the tile and of ``correlation_length``), finite and > 0. Then the first direction of
        ``wo`` must be ``wi`` itself (exact backscatter): the paths of order >= 2 tallied
        there each interfere with their reverse path (the same facets in reverse order),
        with the phase ``q . rho``, ``q = (2 pi / wavelength) (wo_b - wi)``, ``rho`` the last
        hit point minus the first. The reverse path's Jones matrix is traced at exact
        backscatter and used for every ``wo_b`` (small-angle approximation: the bistatic
        dependence is in the phase only). Default None (no coherent tally).
    bistatic : array_like, shape (..., 3), optional
        Bistatic receiver directions ``wo_b`` (unit, ``z > 0``, within pi/4 of ``wi``) for
        the coherent tally; :func:`bistatic_directions` builds them from angles. Only with
        ``wavelength``. Default: ``wi`` alone (bistatic angle 0; ``coherent`` is then
        ``(2, 4, 4)``).

    Returns
    -------
    dict
        With ``mueller``: ``(3, ..., 4, 4)`` Mueller BRDF in 1/sr for orders ``ORDERS = (1, 2,
        "3+")`` and the leading shape of ``wo``; ``stderr``: its standard errors;
        ``counts``: ``(3, ...)`` rays tallied; ``projected_solid_angle``: ``(...)``
        ``pi sin(cone)**2 cos(theta_o)``;
        ``albedo``, ``albedo_stderr``: ``(3,)`` escaped unpolarized power fraction per order;
        ``truncated`` (+ ``_stderr``): power left after ``max_order``; ``lost``: fraction of
        rays lost by the traversal (numerical failures, expected 0);
        ``realized_alpha``: rms facet slope of the traced surfaces (mean over batches);
        ``slope_cov`` ``(batches, 2, 2)``: realized slope covariance per batch;
        ``alpha_unscaled_ratio`` ``(batches,)``: rms slope before rescaling over its
        ensemble expectation (NaN for ``heights``); ``height_scale`` ``(batches,)``;
        ``elapsed_s``, ``rays_per_second``; and the parameters (``orders``, ``wi``, ``wo``,
        ``alpha``, ``eta``, ``rays``, ``grid``, ``correlation_length``, ``cone``,
        ``max_order``, ``frame``, ``seed``, ``batches``, ``wavelength``). With
        ``wavelength`` also ``coherent``: ``(2, ..., 4, 4)`` interference term in 1/sr for
        orders ``COHERENT_ORDERS = (2, "3+")`` and the leading shape of ``bistatic``,
        normalized as ``mueller[:, first wo]`` (coherent plus incoherent is the total at that
        order: ``mueller[1, 0] + coherent[0, b]`` for order 2 with a ``(K, 3)`` ``wo``);
        ``coherent_stderr``; ``coherent_unpaired`` ``(2,)``: tallied paths whose reversed
        facet sequence does not exist (a facet faces away), which add nothing; and
        ``bistatic`` ``(..., 3)``, ``bistatic_angle`` ``(...)`` (radians from ``wi``).

    Raises
    ------
    pprender.Error
        For an invalid argument (it is a ``ValueError``), naming the bad parameter.
    """
    if frame not in ("sp", "mitsuba"):
        raise Error(f'invalid frame = {frame!r}: expected "sp" or "mitsuba"')
    h: Optional[np.ndarray] = None
    if heights is not None:
        if alpha is not None or m is not None:
            raise Error("invalid heights: give either a roughness (alpha or m) or heights, not both")
        try:
            h = np.ascontiguousarray(heights, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise Error(f"invalid heights: cannot convert to a float64 array ({e})") from None
        if h.ndim != 2 or h.shape[0] != h.shape[1]:
            raise Error(f"invalid heights: expected a square (n, n) array, got shape {h.shape}")
        a = None
    else:
        a = _alpha(alpha, m)
    try:
        wi_a = np.ascontiguousarray(wi, dtype=np.float64)
        wo_a = np.asarray(wo, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise Error(f"invalid wi or wo: cannot convert to a float64 array ({e})") from None
    if wi_a.shape != (3,):
        raise Error(f"invalid wi: expected shape (3,), got {wi_a.shape}")
    if wo_a.ndim == 0 or wo_a.shape[-1] != 3 or wo_a.size == 0:
        raise Error(f"invalid wo: expected shape (..., 3), got {wo_a.shape}")
    lead = wo_a.shape[:-1]
    eta_c = _eta(eta)
    n_rays = _int(rays, "rays", 1, 1 << 40)
    n_grid = _int(grid, "grid", 16, 4096) if h is None else h.shape[0]
    n_max = _int(max_order, "max_order", 1, 1000)
    n_seed = _int(seed, "seed", 0, (1 << 64) - 1)
    n_batches = _int(batches, "batches", 2, 100_000)
    ell = _float(correlation_length, "correlation_length")
    cone_f = _float(cone, "cone")
    lam: Optional[float] = None
    bist: Optional[np.ndarray] = None
    lead_b: tuple = ()
    if wavelength is not None:
        lam = _float(wavelength, "wavelength")
        if not (math.isfinite(lam) and lam > 0.0):
            raise Error(f"invalid wavelength = {lam}: must be finite and > 0 (grid units)")
        b = wi_a if bistatic is None else bistatic
        try:
            bist = np.asarray(b, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise Error(f"invalid bistatic: cannot convert to a float64 array ({e})") from None
        if bist.ndim == 0 or bist.shape[-1] != 3 or bist.size == 0:
            raise Error(f"invalid bistatic: expected shape (..., 3), got {bist.shape}")
        lead_b = bist.shape[:-1]
    elif bistatic is not None:
        raise Error("invalid bistatic: given without wavelength (the coherent tally needs a wavelength > 0)")
    out: Dict[str, Any] = _core.reference_microsurface(
        wi_a,
        np.ascontiguousarray(wo_a.reshape(-1, 3)),
        a,
        eta_c,
        n_rays,
        n_grid,
        ell,
        cone_f,
        n_max,
        frame,
        n_seed,
        n_batches,
        h,
        lam,
        None if bist is None else np.ascontiguousarray(bist.reshape(-1, 3)),
    )
    out["mueller"] = out["mueller"].reshape((3,) + lead + (4, 4))
    out["stderr"] = out["stderr"].reshape((3,) + lead + (4, 4))
    out["counts"] = out["counts"].reshape((3,) + lead)
    out["projected_solid_angle"] = out["projected_solid_angle"].reshape(lead)
    if bist is not None:
        out["coherent"] = out["coherent"].reshape((2,) + lead_b + (4, 4))
        out["coherent_stderr"] = out["coherent_stderr"].reshape((2,) + lead_b + (4, 4))
        wb = bist / np.linalg.norm(bist, axis=-1, keepdims=True)
        out["bistatic"] = wb
        out["bistatic_angle"] = np.arccos(np.clip(wb @ (wi_a / np.linalg.norm(wi_a)), -1.0, 1.0))
    out["realized_alpha"] = float(np.mean(out["realized_alpha"]))
    out["rays_per_second"] = n_rays / max(out["elapsed_s"], 1e-12)
    out.update(
        orders=ORDERS,
        wi=wi_a / np.linalg.norm(wi_a),
        wo=wo_a / np.linalg.norm(wo_a, axis=-1, keepdims=True),
        alpha=a,
        eta=eta_c,
        rays=n_rays,
        grid=n_grid,
        correlation_length=ell if h is None else None,
        cone=cone_f,
        max_order=n_max,
        frame=frame,
        seed=n_seed,
        batches=n_batches,
        wavelength=lam,
    )
    return out


def bistatic_directions(wi: object, beta: object, azimuth: object = 0.0) -> np.ndarray:
    """Receiver directions at bistatic angle ``beta`` from ``wi``, for ``bistatic``.

    ``wo_b = cos(beta) wi + sin(beta) (cos(azimuth) e_theta + sin(azimuth) e_phi)``, with
    ``e_theta``, ``e_phi`` the polar and azimuthal unit vectors at ``wi``: azimuth 0 tilts
    in the plane of incidence away from the normal, pi/2 across it. At normal incidence
    the plane of incidence is taken as x-z (``e_theta = x``, ``e_phi = y``).

    Parameters
    ----------
    wi : array_like, shape (3,)
        Unit vector toward the transmitter, ``z > 0``.
    beta : array_like
        Bistatic angles in radians, in [0, pi/4] (the limit :func:`microsurface` accepts).
    azimuth : array_like, optional
        Azimuths about ``wi`` in radians, broadcast against ``beta``. Default 0.

    Returns
    -------
    numpy.ndarray
        Shape ``broadcast(beta, azimuth).shape + (3,)``, unit vectors.

    Raises
    ------
    pprender.Error
        For an invalid argument (it is a ``ValueError``), naming the bad parameter.
    """
    try:
        w = np.asarray(wi, dtype=np.float64)
        b = np.asarray(beta, dtype=np.float64)
        a = np.asarray(azimuth, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise Error(f"invalid wi, beta or azimuth: cannot convert to a float64 array ({e})") from None
    if w.shape != (3,) or not np.all(np.isfinite(w)) or abs(np.linalg.norm(w) - 1.0) > 1e-6 or w[2] <= 0.0:
        raise Error(f"invalid wi = {w.tolist()}: must be a unit vector with z > 0, shape (3,)")
    if not np.all(np.isfinite(b)) or np.any(b < 0.0) or np.any(b > math.pi / 4):
        raise Error(f"invalid beta = {b.tolist()}: must be in [0, pi/4] radians")
    if not np.all(np.isfinite(a)):
        raise Error(f"invalid azimuth = {a.tolist()}: must be finite")
    w = w / np.linalg.norm(w)
    th = math.acos(min(w[2], 1.0))
    ph = math.atan2(w[1], w[0]) if math.hypot(w[0], w[1]) > 1e-14 else 0.0
    e_t = np.array([math.cos(th) * math.cos(ph), math.cos(th) * math.sin(ph), -math.sin(th)])
    e_p = np.array([-math.sin(ph), math.cos(ph), 0.0])
    b, a = np.broadcast_arrays(b, a)
    return (
        np.cos(b)[..., None] * w
        + np.sin(b)[..., None] * (np.cos(a)[..., None] * e_t + np.sin(a)[..., None] * e_p)
    )


def height_field(
    *,
    alpha: Optional[float] = None,
    m: Optional[float] = None,
    grid: int = 256,
    correlation_length: float = 8.0,
    seed: int = 0,
    batch: int = 0,
) -> Dict[str, Any]:
    """The random surface that batch ``batch`` of :func:`microsurface` traces.

    Cell ``(i, j)`` is split along its main diagonal when ``i + j`` is even, along the
    anti-diagonal when odd.

    Parameters
    ----------
    alpha, m : float, optional
        Beckmann roughness, or the Blinn-Phong exponent (``alpha = sqrt(2/(m+2))``); exactly
        one.
    grid : int, optional
        Tile size in grid cells (16 to 4096). Default 256.
    correlation_length : float, optional
        Height correlation length in grid units. Default 8.
    seed : int, optional
        Non-negative integer, as in :func:`microsurface`. Default 0.
    batch : int, optional
        The batch, in [0, 2**32). Default 0.

    Returns
    -------
    dict
        With ``heights`` ``(grid, grid)`` (``heights[i, j]`` at ``x = i, y = j``, grid
        units), ``slopes`` ``(2 grid**2, 2)``: the slopes ``(dz/dx, dz/dy)`` of the triangles
        (each of projected area 1/2; cell ``(i, j)`` gives rows ``2 (i grid + j)`` and
        ``+1``), ``realized_alpha`` (``sqrt(mean(sx**2 + sy**2))``, equal to ``alpha``),
        ``slope_cov`` ``(2, 2)``, ``alpha_unscaled_ratio`` and ``height_scale``.

    Raises
    ------
    pprender.Error
        For an invalid argument (it is a ``ValueError``), naming the bad parameter.
    """
    a = _alpha(alpha, m)
    assert a is not None
    out: Dict[str, Any] = _core.reference_height_field(
        a,
        _int(grid, "grid", 16, 4096),
        _float(correlation_length, "correlation_length"),
        _int(seed, "seed", 0, (1 << 64) - 1),
        _int(batch, "batch", 0, (1 << 32) - 1),
    )
    return out
