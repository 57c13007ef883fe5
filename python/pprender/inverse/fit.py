"""Fitting PPR measurements: Poisson likelihood, a rendering forward model, nlopt and emcee.

Conventions (written once here):

* Parameters (:data:`PARAMETERS`), SI units:

  - ``rx, ry, rz`` (rad): a rotation vector ``r`` (axis times angle). The attitude is
    ``R = exp([r]x) R_ref`` with ``attitude_frame="telescope"`` (``r`` in the telescope
    frame ``X, Y, Z``, ``Z`` toward the receiver: ``rz`` rolls about the line of sight) or
    ``R = R_ref exp([r]x)`` with ``attitude_frame="body"`` (``r`` in the body frame, e.g.
    ``rz`` a spin about the body's z axis), or ``R = exp(rz [Z]x) exp([(rx, ry, 0)]x) R_ref``
    with ``attitude_frame="roll"`` (swing then twist: ``(rx, ry)`` a rotation about an axis
    across the line of sight, which sets the direction the body is seen from, then ``rz``
    a roll about the line of sight). Monostatic, with one bounce, the profile does not
    depend on the roll at all (a facet seen in backscatter is a mirror at normal incidence,
    the same for every orientation of the polarization; ``tests/test_render.py`` checks
    the invariance): fit ``(rx, ry)`` in the ``"roll"`` frame and leave ``rz`` fixed. With
    ``rx, ry, rz`` all free in another frame the roll is a curved valley of constant
    likelihood through the parameter space, which local fits and the Gaussian
    uncertainties do not describe (docs/fit-recovery.md). ``R_ref`` is ``reference_attitude``
    (default identity); ``R`` maps body to telescope coordinates as in :func:`pprender.render`.
  - ``alpha``: microfacet roughness of the fitted materials (Beckmann/GGX ``alpha``;
    converted to ``m`` for Blinn-Phong as :class:`pprender.Material` does).
  - ``n``, ``k``: the fitted materials' refractive index ``eta = n + i k``.
  - ``scale``: size factor ``s``; the mesh's vertices are multiplied by ``s`` about the
    body origin (cross-sections scale as ``s^2``, ranges as ``s``). Implemented exactly by
    rescaling the mesh and rendering it, not by rebinning.

  A model has some parameters free (the vector ``theta``, in the order given) and the
  others fixed (``fixed``; defaults: rotation 0, scale 1, and each material's own
  ``alpha``/``eta``).
* Priors: uniform within ``bounds`` (``DEFAULT_BOUNDS`` where not given); the log prior is
  0 inside (normalization dropped) and ``-inf`` outside. Parameters for which no material
  can be built (e.g. ``alpha <= 0`` when the bounds allow it) or any non-finite value also
  give ``-inf``: :meth:`ForwardModel.log_prob` never raises for a parameter value.
* Likelihood: independent Poisson counts in every range bin and channel,
  ``log L = sum_bc [k log(lam) - lam - log(k!)]`` (:func:`poisson_log_likelihood`).
  With an instrument's :class:`~pprender.inverse.speckle.Speckle`: each count's exact
  marginal law, a negative binomial (Poisson over a gamma speckle intensity of shape
  ``M``, each count's marginal dof) convolved with the Poisson background
  (:func:`pprender.inverse.speckle.speckle_log_likelihood`), multiplied over bins and
  channels. That is a composite likelihood: channels of one transmitted state see one
  speckle field and are correlated; the estimates stay consistent, but where speckle
  dominates the noise the Fisher information (:func:`fisher_information`) overstates
  what the data say (``docs/speckle.md``: sd too small by up to 1.4x for co/cross
  channels, 2.2x for the six-channel polarimeter, 1 for an unpolarized return on
  co/cross). ``M`` is computed at each ``theta`` (one ``dof`` or one ``target_area``:
  :meth:`ForwardModel.speckle_dof`) or taken from the measurement (per-bin areas) and
  held fixed in the derivatives. ``M = inf`` everywhere is the Poisson likelihood, bit
  for bit.
  With an instrument ``detector`` or ``atmosphere`` (:class:`~pprender.inverse.instrument.Instrument`)
  the likelihood is that of what the receiver records,
  :func:`pprender.inverse.detector.record_log_likelihood` (Coates' multinomial for a dead
  time, a Gaussian with the APD's two moments, scintillation per pulse group), and the
  data of a linear-mode APD may be real numbers; :func:`fisher_information` and
  :func:`diagnose_fit` follow (their docstrings say how).
  Speckle together with a dead time, an APD or scintillation is refused by
  :class:`~pprender.inverse.instrument.Instrument` (their joint statistics are not modelled).
* Attitudes (``reference_attitude``, :func:`attitude_error`): rotation matrices
  ``(..., 3, 3)`` (body to telescope), quaternions ``(..., 4)`` in pprender's scalar-first
  order ``(w, x, y, z)``, or :class:`scipy.spatial.transform.Rotation` objects (converted
  with ``as_matrix()``). Scipy's own quaternion arrays are ``(x, y, z, w)``: pass the
  ``Rotation`` itself (or ``r.as_quat(scalar_first=True)``), never ``r.as_quat()``.
* Failed fits are not results: :func:`fit_nlopt` raises :class:`pprender.Error` when the
  log-likelihood is ``-inf`` at every point it tried (it would otherwise hand back ``x0``
  as if converged), and :func:`sample_emcee` refuses starts where it is ``-inf``.
* Numbers are numbers: text (``"1e-3"``), None or complex values for numeric parameters
  raise :class:`pprender.Error` naming the parameter.
* Rendering batches: walkers whose material and scale agree are rendered in one
  :func:`pprender.render` call (when only the attitude is free, all of them together);
  materials and scenes are cached on their parameter values (least recently used first
  out, ``cache_size`` entries).
"""

from __future__ import annotations

import math
import time
import warnings
from collections import OrderedDict
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import numpy as np
from scipy.special import gammaln, xlogy
from scipy.stats import norm
from scipy.spatial.transform import Rotation

from .. import lidar as _lidar
from .. import _core
from .._core import Error, Material
from ..materials import SURFACE_ALPHA
from . import speckle as _speckle
from .atmosphere import pulse_groups
from .detector import Detector, coates_probabilities, record, record_log_likelihood
from .instrument import (
    Instrument,
    Measurement,
    _channel_cross_sections,
    _check_edges,
    _check_number,
    _numeric_array,
    _speckle_state,
    expected_counts,
    jitter_matrix,
)

__all__ = [
    "DEFAULT_BOUNDS",
    "PARAMETERS",
    "FitResult",
    "ForwardModel",
    "attitude_error",
    "fisher_information",
    "fit_nlopt",
    "FitWarning",
    "diagnose_fit",
    "maximum_likelihood",
    "attitude_starts",
    "chain_summary",
    "ChainSummary",
    "poisson_log_likelihood",
    "sample_emcee",
]

#: Parameter names, in canonical order (module docstring).
PARAMETERS = ("rx", "ry", "rz", "alpha", "n", "k", "scale")

#: Uniform-prior bounds used for free parameters without explicit ``bounds``.
DEFAULT_BOUNDS: dict[str, tuple[float, float]] = {
    "rx": (-math.pi, math.pi),
    "ry": (-math.pi, math.pi),
    "rz": (-math.pi, math.pi),
    "alpha": (0.01, 1.0),
    "n": (0.05, 10.0),
    "k": (0.0, 20.0),
    "scale": (0.1, 10.0),
}

_MATERIAL_PARAMS = ("alpha", "n", "k")


class FitWarning(UserWarning):
    """A fit not to be trusted as it stands, or a model set up so that fits fail.

    :attr:`FitResult.problems` says why; also for ambiguous fits
    (:attr:`FitResult.alternatives`) and short emcee chains (:func:`chain_summary`).
    """


def _fit_settings(lidar: _lidar.Lidar, settings: Any, device: str, free: Sequence[str]) -> _lidar.Settings:
    """The settings a :class:`ForwardModel` renders with (its ``settings`` parameter)."""
    if isinstance(settings, str) and settings == "lidar":
        out = lidar.settings
    elif isinstance(settings, _lidar.Settings):
        out = settings
    elif settings is None:
        out = lidar.settings
        if out.coverage != "analytic":
            out = replace(out, coverage="analytic", pixel_samples=None)
        if out.quality != "reference" and out.arithmetic is None:
            try:
                on_cpu = _lidar.device_info(device).get("device_type") == "Cpu"
            except Error:
                on_cpu = False
            if on_cpu:
                out = replace(out, arithmetic="f64")
    else:
        raise Error(f'invalid settings = {settings!r}: None (continuous, the default), "lidar" or a pprender.Settings')
    if out.coverage != "analytic" and any(p in free for p in ("rx", "ry", "rz", "scale")):
        warnings.warn(
            "ForwardModel: sampled coverage (pixel_samples) makes the expected counts step where a silhouette "
            "edge crosses a sample point, so the likelihood is piecewise flat in the attitude and scale: "
            "optimizers stop on its steps and the Fisher information by finite differences is unreliable. "
            "Leave settings=None (analytic coverage) for fits",
            FitWarning,
            stacklevel=3,
        )
    return out


# ---------------------------------------------------------------------- likelihood


def _counts_array(counts: Any, real: bool = False) -> np.ndarray:
    try:
        k = np.asarray(counts)
    except (TypeError, ValueError):
        raise Error("invalid counts: not an array of numbers") from None
    if k.dtype == object or not (np.issubdtype(k.dtype, np.integer) or np.issubdtype(k.dtype, np.floating)):
        raise Error(f"invalid counts: dtype {k.dtype}, expected integers")
    k = k.astype(np.float64)
    if real:  # a linear-mode APD's photo-electron estimates: any finite value
        if not np.all(np.isfinite(k)):
            raise Error("invalid counts: a linear-mode APD's records must be finite numbers")
        return k
    if not np.all(np.isfinite(k)) or np.any(k < 0) or np.any(k != np.round(k)):
        raise Error("invalid counts: must be finite non-negative integers")
    return k


def _loglik(k: np.ndarray, lam: np.ndarray, log_k_factorial: Any = None) -> Any:
    # xlogy(0, 0) = 0; xlogy(k > 0, 0) = -inf: both the exact limits of k log(lam) - lam
    lgk = gammaln(k + 1.0) if log_k_factorial is None else log_k_factorial
    return np.sum(xlogy(k, lam) - lam - lgk, axis=(-2, -1))


def poisson_log_likelihood(counts: Any, expected: Any) -> Any:
    """Exact Poisson log-likelihood ``sum [k log(lam) - lam - log(k!)]`` over the last two axes.

    The last two axes are range bins and channels. ``lam = 0`` with ``k = 0`` contributes 0
    (the pmf is 1); ``lam = 0`` with ``k > 0`` gives ``-inf`` (impossible data), never NaN.

    Parameters
    ----------
    counts : array_like
        (..., B, C) non-negative integers.
    expected : array_like
        (..., B, C) finite means ``>= 0``; broadcast against ``counts``.

    Returns
    -------
    float or numpy.ndarray
        The log-likelihood over the leading axes, which are kept (a float for 2-D inputs).

    Raises
    ------
    pprender.Error
        For counts that are not finite non-negative integers, expected counts that are not
        finite and ``>= 0``, or shapes that are not (..., B, C) or do not broadcast.
    """
    k = _counts_array(counts)
    lam = _numeric_array(expected, "expected", "an array of expected counts")
    if not np.all(np.isfinite(lam)) or np.any(lam < 0):
        raise Error("invalid expected: must be finite and >= 0 (counts)")
    if k.ndim < 2 or lam.ndim < 2:
        raise Error(f"invalid counts/expected: shapes {k.shape} and {lam.shape}, expected (..., B, C)")
    try:
        np.broadcast_shapes(k.shape, lam.shape)
    except ValueError:
        raise Error(f"invalid counts/expected: shapes {k.shape} and {lam.shape} do not broadcast") from None
    out = _loglik(k, lam)
    return float(out) if np.ndim(out) == 0 else out


# ---------------------------------------------------------------------- attitude


def _attitude_matrices(r: Any, name: str) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from matrices, (w, x, y, z) quaternions (..., 4) or a
    :class:`scipy.spatial.transform.Rotation` (module docstring)."""
    if isinstance(r, Rotation):
        return np.asarray(r.as_matrix(), dtype=np.float64)
    a = _numeric_array(r, name, "rotation matrices (..., 3, 3), (w, x, y, z) quaternions (..., 4) or a scipy Rotation")
    if not np.all(np.isfinite(a)):
        raise Error(f"invalid {name}: not finite")
    if a.ndim >= 1 and a.shape[-1:] == (4,):
        n = np.linalg.norm(a, axis=-1, keepdims=True)
        if np.any(n == 0):
            raise Error(f"invalid {name}: a zero quaternion")
        q = a / n
        # the one quaternion convention: the renderer's (w, x, y, z), converted in Rust
        return np.asarray(_core.quaternions_to_rotations(np.ascontiguousarray(q.reshape(-1, 4)))).reshape(
            a.shape[:-1] + (3, 3))
    if a.ndim < 2 or a.shape[-2:] != (3, 3):
        raise Error(f"invalid {name}: shape {a.shape}, expected (..., 3, 3) or (..., 4)")
    eye = np.einsum("...ji,...jk->...ik", a, a)
    if not (np.allclose(eye, np.eye(3), rtol=0, atol=1e-6) and np.all(np.linalg.det(a) > 0)):
        raise Error(f"invalid {name}: not a rotation matrix (orthonormal with determinant +1, to 1e-6)")
    return a


def _frame_rotation(r: np.ndarray, frame: str) -> np.ndarray:
    """(n, 3, 3) ``E(r)`` of :class:`ForwardModel`'s attitude frames (module docstring):
    ``exp([r]x)``, or for ``"roll"`` ``exp(r_z [Z]x) exp([(r_x, r_y, 0)]x)``."""
    r = np.asarray(r, dtype=np.float64).reshape(-1, 3)
    if frame != "roll":
        return Rotation.from_rotvec(r).as_matrix()
    swing = Rotation.from_rotvec(np.column_stack([r[:, 0], r[:, 1], np.zeros(len(r))]))
    return (Rotation.from_rotvec(np.column_stack([np.zeros((len(r), 2)), r[:, 2]])) * swing).as_matrix()


def _frame_parameters(E: np.ndarray, frame: str) -> np.ndarray:
    """(n, 3) ``r`` with ``_frame_rotation(r, frame) = E`` (angles in [-pi, pi])."""
    rot = Rotation.from_matrix(np.asarray(E).reshape(-1, 3, 3))
    if frame != "roll":
        return rot.as_rotvec()
    # twist about Z: the angle of the quaternion's (w, z) part; the swing what is left
    q = rot.as_quat()  # (x, y, z, w)
    twist = 2.0 * np.arctan2(q[:, 2], q[:, 3])
    twist = (twist + np.pi) % (2 * np.pi) - np.pi
    swing = Rotation.from_rotvec(np.column_stack([np.zeros((len(q), 2)), -twist])) * rot
    return np.column_stack([swing.as_rotvec()[:, :2], twist])


def attitude_error(r_a: Any, r_b: Any) -> Any:
    """Rotation angle (rad, in [0, pi]) of ``R_a R_b^T``: the angle between attitudes.

    Parameters
    ----------
    r_a, r_b : array_like or scipy.spatial.transform.Rotation
        Rotation matrices (..., 3, 3), quaternions (..., 4) ``(w, x, y, z)`` (scalar first,
        not scipy's ``as_quat()`` order) or :class:`scipy.spatial.transform.Rotation` objects
        (single or stacked); they broadcast.

    Returns
    -------
    float or numpy.ndarray
        The angles (rad), a float for single attitudes.

    Raises
    ------
    pprender.Error
        For values that are not finite, a zero quaternion, or a matrix that is not a rotation
        (orthonormal with determinant +1, to 1e-6).
    """
    a, b = _attitude_matrices(r_a, "attitude r_a"), _attitude_matrices(r_b, "attitude r_b")
    tr = np.einsum("...ij,...ij->...", a, b)  # trace(A B^T)
    ang = np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))
    return float(ang) if np.ndim(ang) == 0 else ang


# ---------------------------------------------------------------------- materials


def _material_with(m: Material, alpha: float | None, eta: complex | None) -> Material:
    """``m`` rebuilt with a new roughness and/or refractive index (other settings kept)."""
    kw: dict[str, Any] = dict(
        eta=m.eta if eta is None else eta,
        shadowing=m.shadowing,
        correlation=m.correlation,
        smith_g1=m.smith_g1,
        masking=m.masking,
        terms=list(m.terms),
        diffuse_albedo=m.diffuse_albedo,
        name=m.name,
        double_order=m.double_order,
        coherent_backscatter=m.coherent_backscatter,
        double_masking=m.double_masking,
        wavelength=m.wavelength,
        correlation_length=m.correlation_length,
        orders=m.orders,
        bank_rays=m.bank_rays,
        alpha_step=m.alpha_step,
    )
    if alpha is not None:
        kw["alpha"] = alpha
    elif m.distribution == "blinn_phong":
        kw["m"] = m.m
    else:
        kw["alpha"] = m.alpha
    return Material(m.distribution, **kw)


# ---------------------------------------------------------------------- forward model


class ForwardModel:
    """Parameters -> expected counts, by rendering (see the module docstring).

    Parameters
    ----------
    mesh : trimesh.Trimesh or (vertices, faces)
        The target in its body frame (metres), e.g. from :mod:`pprender.models`.
    materials : Material, str, list or mapping
        As for :class:`pprender.Scene` (a mapping needs a model's parts).
    instrument : Instrument
        The instrument (link budget, channels, jitter, background; with ``speckle``, the
        speckle likelihood: module docstring, :meth:`log_likelihood`).
    bin_edges : array (B + 1,)
        Range bin edges of the data (m), e.g. ``measurement.bin_edges``; rendered profiles
        are mapped onto them with the instrument's jitter (:func:`expected_counts`).
        Signal rendered outside them is dropped, as by a range gate: make them cover the
        target at the largest ``scale`` within the bounds.
    free : sequence of str
        Free parameter names (from :data:`PARAMETERS`), in the order of ``theta``.
    lidar : Lidar, optional
        Pulse, bin width, resolution, supersampling, bistatic angle (default
        ``Lidar(wavelength=instrument.wavelength)``). Its ``polarization`` must be None:
        the model sets the transmitted state from the instrument's channels.
    fixed : mapping, optional
        Values of parameters that are not free.
    bounds : mapping, optional
        ``name -> (low, high)`` for free parameters (default :data:`DEFAULT_BOUNDS`). With
        ``alpha`` free and a fitted material with ``orders="surface"`` (the default of
        ``pprender.materials``' Beckmann metals), ``alpha`` must stay where such a material
        can be built: within [0.05, 1]. The default bounds are narrowed to that range;
        given bounds outside it are refused. (With ``alpha_step``, within one node of
        either end the interpolation is the quadratic through the three nodes there, so
        no node outside is needed.)
    reference_attitude : (3, 3), (4,) or scipy Rotation, optional
        ``R_ref`` (default identity): one rotation matrix, one ``(w, x, y, z)`` quaternion
        (scalar first) or a single :class:`scipy.spatial.transform.Rotation` (a stack of
        one is accepted, of several refused).
    attitude_frame : {"telescope", "body", "roll"}
        Frame of the rotation vector (module docstring); ``"roll"`` separates the roll
        about the line of sight, which a monostatic single-bounce profile cannot see.
    fitted_parts : sequence of str or int, optional
        Material entries (part names, or indices into the material list) that
        ``alpha``/``n``/``k`` apply to; default all.
    smooth : bool
        Smooth shading (as :class:`pprender.Scene`).
    face_material : array, optional
        As for :class:`pprender.Scene`.
    cache_size : int
        Number of scenes (and of materials) kept (least recently used dropped).
    device : str
        Passed to :func:`pprender.render`.
    settings : Settings or "lidar", optional
        How the model renders. Default (None): the ``lidar``'s settings with
        ``coverage="analytic"`` (each pixel's visible area clipped exactly), so that the
        expected counts, and the likelihood, are continuous in the attitude and the scale;
        and, where ``device`` resolves to a CPU (lavapipe), ``arithmetic="f64"``, the
        native CPU renderer (about twice the cost of one sampled visibility sample on
        lavapipe, docs/fit-smoothness.md). With sampled visibility (``pixel_samples``)
        the profile steps whenever a silhouette edge crosses a sample point: the likelihood
        is piecewise flat along the attitude, local optimizers stop on its steps, and
        finite-difference Fisher information is wrong (docs/fit-smoothness.md measures
        both). ``"lidar"`` renders with the ``lidar``'s own
        settings; a :class:`pprender.Settings` is used as given. Settings with sampled
        coverage and a free attitude or scale warn (:class:`FitWarning`). Simulated data
        for a fit: render the truth as the model does (``pprender.render(scene,
        model.lidar, attitudes, settings=model.settings)``, or take :meth:`expected` at
        the truth): a plain ``render`` with the sensor's sampled
        coverage differs from the analytic one by up to about 1 % of the signal at a few
        dozen pixels across the target (0.85 % on a 1U box at resolution 32), which biases
        a high-SNR fit by that much.
    alpha_step : float or None, optional
        With ``alpha`` free: the expected counts at any ``alpha`` are the Catmull-Rom
        interpolation (C1, exact for quadratics in ``ln alpha``) of those rendered with
        materials built at the nodes ``alpha = exp(j * alpha_step)``, the four about it.
        Materials are then built once per node (about a second each for a metal with the
        multiple term) instead of once per new ``alpha`` value, so a roughness fit costs
        about four renders per evaluation instead of a material build
        (docs/fit-recovery.md measures both, and the interpolation's error: at 2e4 counts
        log L within 0.01 of the exact one about the optimum, expected counts within 5e-4
        of the peak bin). In (0, 1], or None to render every ``alpha`` exactly. Default
        ``"auto"``: 0.05 (nodes 5.1% apart) when a fitted material has terms beyond
        ``"single"`` and ``"diffuse"`` (1.6 s to build with the double term, 2.9 s with
        double and multiple), None when it has not (such a material builds in about 36 ms,
        cheaper than the three extra renders: 25 against 58 ms per evaluation for 12
        walkers on notebook 04's box).
    """

    def __init__(
        self,
        mesh: Any,
        materials: Any,
        instrument: Instrument,
        bin_edges: Any,
        free: Sequence[str],
        *,
        lidar: _lidar.Lidar | None = None,
        fixed: Mapping[str, float] | None = None,
        bounds: Mapping[str, tuple[float, float]] | None = None,
        reference_attitude: Any = None,
        attitude_frame: str = "telescope",
        fitted_parts: Sequence[str | int] | None = None,
        smooth: bool = False,
        face_material: Any = None,
        cache_size: int = 64,
        device: str = "auto",
        settings: Any = None,
        alpha_step: float | str | None = "auto",
    ) -> None:
        if not isinstance(instrument, Instrument):
            raise Error(f"invalid instrument of type {type(instrument).__name__}: expected Instrument")
        self.instrument = instrument
        self.bin_edges = _check_edges(bin_edges, "bin_edges").copy()
        if instrument.detector is not None:
            instrument.detector.regime(self.bin_edges)  # a dead time within the range gate is refused
        # parameters
        if isinstance(free, str):
            free = (free,)
        free = tuple(free)
        bad = [p for p in free if p not in PARAMETERS]
        if bad or not free or len(set(free)) != len(free):
            raise Error(f"invalid free = {free!r}: distinct names from {PARAMETERS}, at least one")
        self.names: tuple[str, ...] = free
        fixed = dict(fixed or {})
        for name, v in fixed.items():
            if name not in PARAMETERS:
                raise Error(f"invalid fixed parameter {name!r}: choose from {PARAMETERS}")
            if name in free:
                raise Error(f"invalid fixed parameter {name!r}: it is also free")
            if isinstance(v, (bool, np.bool_)) or not (
                isinstance(v, (int, float, np.integer, np.floating)) and math.isfinite(float(v))
            ):
                raise Error(f"invalid fixed {name} = {v!r}: a finite number")
        self.fixed = {k: float(v) for k, v in fixed.items()}
        bounds = dict(bounds or {})
        for name in bounds:
            if name not in free:
                raise Error(f"invalid bounds for {name!r}: not a free parameter (free: {free})")
        lo, hi = [], []
        for name in free:
            b = bounds.get(name, DEFAULT_BOUNDS[name])
            try:
                lo_, hi_ = b
            except (TypeError, ValueError):
                raise Error(f"invalid bounds for {name!r}: {b!r}, expected (low, high)") from None
            if not all(
                isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))
                for v in (lo_, hi_)
            ):
                raise Error(f"invalid bounds for {name!r}: {b!r}, expected (low, high) numbers")
            lo_, hi_ = float(lo_), float(hi_)
            if not (math.isfinite(lo_) and math.isfinite(hi_) and lo_ < hi_):
                raise Error(f"invalid bounds for {name!r}: {b!r}, expected finite low < high")
            lo.append(lo_)
            hi.append(hi_)
        self.lower = np.array(lo)
        self.upper = np.array(hi)
        if attitude_frame not in ("telescope", "body", "roll"):
            raise Error(f'invalid attitude_frame = {attitude_frame!r}: "telescope", "body" or "roll"')
        self.attitude_frame = attitude_frame
        if reference_attitude is None:
            self.reference_attitude = np.eye(3)
        else:
            ref = _attitude_matrices(reference_attitude, "reference_attitude")
            if ref.shape == (1, 3, 3):
                ref = ref[0]
            if ref.shape != (3, 3):
                raise Error(
                    f"invalid reference_attitude: {ref.shape[:-2]} attitudes; expected one: a (3, 3) "
                    "matrix, a (4,) (w, x, y, z) quaternion or a single scipy Rotation"
                )
            self.reference_attitude = np.ascontiguousarray(ref)
        # sensor
        if lidar is None:
            lidar = _lidar.Lidar(wavelength=instrument.wavelength)
        if not isinstance(lidar, _lidar.Lidar):
            raise Error(f"invalid lidar of type {type(lidar).__name__}: expected pprender.Lidar")
        if lidar.polarization is not None:
            raise Error(
                "invalid lidar: polarization must be None; the model takes the transmitted state(s) "
                "from instrument.channels"
            )
        if abs(lidar.wavelength - instrument.wavelength) > 1e-6 * instrument.wavelength:
            raise Error(
                f"invalid lidar: wavelength {lidar.wavelength!r} differs from the instrument's "
                f"{instrument.wavelength!r}"
            )
        ch = instrument.channels
        self.lidar = replace(lidar, polarization=tuple(ch.transmit)) if ch.single_generator else lidar  # type: ignore[union-attr]
        self.device = device
        self.settings = _fit_settings(lidar, settings, device, free)
        if alpha_step is not None and not (isinstance(alpha_step, str) and alpha_step == "auto"):
            alpha_step = _check_number("alpha_step", alpha_step, 0.0, 1.0, True, False,
                                       'step in ln(alpha), None or "auto"')
        # geometry and materials (validated once by building the reference scene)
        base = _lidar.Scene(mesh, materials, smooth=smooth, face_material=face_material, wavelength=instrument.wavelength)
        verts, faces, meta, vn = _lidar._mesh_arrays(mesh)
        fm: Any
        if face_material is not None:
            fm = np.asarray(face_material)
        elif isinstance(materials, (Material, str)):
            fm = np.zeros(len(faces), dtype=np.int64)
        else:
            fm = meta.get("pprender_material") if meta else None
            fm = np.zeros(len(faces), dtype=np.int64) if fm is None else np.asarray(fm)
        self._vertices, self._faces, self._face_material = verts, faces, np.asarray(fm).astype(np.int64)
        self._normals = vn if smooth else None
        self.materials: list[Material] = list(base.materials)
        self.parts = base.parts
        if fitted_parts is None:
            idx = list(range(len(self.materials)))
        else:
            idx = []
            for p in fitted_parts:
                if isinstance(p, str):
                    if self.parts is None or p not in self.parts:
                        raise Error(f"invalid fitted_parts: unknown part {p!r} (parts: {self.parts})")
                    idx.append(self.parts.index(p))
                elif isinstance(p, (int, np.integer)) and 0 <= p < len(self.materials):
                    idx.append(int(p))
                else:
                    raise Error(f"invalid fitted_parts entry {p!r}: a part name or a material index")
        self.fitted = sorted(set(idx))
        if isinstance(alpha_step, str):  # "auto": interpolate where a material is slow to build
            cheap = {"single", "diffuse"}
            alpha_step = 0.05 if any(set(self.materials[i].terms) - cheap for i in self.fitted) else None
        self.alpha_step: float | None = alpha_step if "alpha" in free else None
        self._alpha_nodes: tuple[tuple[int, int], tuple[float, float]] | None = None
        if "alpha" in free:
            self._bound_alpha(free.index("alpha"), "alpha" in bounds)
        if isinstance(cache_size, (bool, np.bool_)) or not isinstance(cache_size, (int, np.integer)) or cache_size < 1:
            raise Error(f"invalid cache_size = {cache_size!r}: an integer >= 1")
        self._cache_size = int(cache_size)
        self._materials_cache: OrderedDict[tuple, list[Material]] = OrderedDict()
        self._scenes: OrderedDict[tuple, _lidar.Scene] = OrderedDict()
        self.render_calls = 0
        self.render_seconds = 0.0
        # full parameter vectors: index of every name
        self._index = {name: i for i, name in enumerate(PARAMETERS)}
        self._base = np.full(len(PARAMETERS), np.nan)  # NaN: the material's own value
        self._base[[0, 1, 2]] = 0.0
        self._base[6] = 1.0
        for name, v in self.fixed.items():
            self._base[self._index[name]] = v
        self._free_idx = np.array([self._index[n] for n in free])
        # speckle: the background counts on the data's bins; whether the model computes each
        # count's dof at theta (one dof or one area) or takes them from the data (per bin)
        self._background = instrument.background_counts(self.bin_edges)
        self._speckle_at_theta = instrument.speckle is not None and not instrument.speckle.per_bin

    def _bound_alpha(self, i: int, given: bool) -> None:
        """Keep a free ``alpha`` (row ``i`` of the bounds) where the fitted materials can
        be built (``bounds`` in the class docstring): narrow the default bounds, refuse
        ``given`` ones outside; with ``alpha_step``, note the nodes inside that range
        (``_alpha_nodes``: the interpolation's edge stencils)."""
        surface = [self.materials[j] for j in self.fitted
                   if self.materials[j].orders == "surface"]
        if not surface:
            return
        lo, hi = SURFACE_ALPHA
        h = self.alpha_step
        if h is not None:
            u_lo, u_hi = math.log(lo) / h, math.log(hi) / h
            self._alpha_nodes = ((math.ceil(u_lo - 1e-9), math.floor(u_hi + 1e-9)), (u_lo, u_hi))
        if given:
            if self.lower[i] < lo or self.upper[i] > hi:
                raise Error(
                    f"invalid bounds for 'alpha': ({self.lower[i]:g}, {self.upper[i]:g}) leaves "
                    f"[{lo:g}, {hi:g}], where the fitted materials with orders=\"surface\" "
                    f"{[m.name for m in surface]} exist; narrow the bounds or fit materials with "
                    f"orders=\"seed\""
                )
            return
        self.lower[i] = max(self.lower[i], lo)
        self.upper[i] = min(self.upper[i], hi)

    # -------------------------------------------------------------- basics

    @property
    def ndim(self) -> int:
        return len(self.names)

    @property
    def bounds(self) -> np.ndarray:
        """(ndim, 2) uniform-prior bounds."""
        return np.stack([self.lower, self.upper], axis=1)

    @property
    def channel_names(self) -> tuple[str, ...]:
        return self.instrument.channel_names

    def _thetas(self, thetas: Any) -> tuple[np.ndarray, bool]:
        th = _numeric_array(thetas, "theta", f"parameter values {self.names}")
        single = th.ndim == 1
        th = np.atleast_2d(th)
        if th.ndim != 2 or th.shape[1] != self.ndim:
            raise Error(f"invalid theta: shape {np.shape(thetas)}, expected ({self.ndim},) or (n, {self.ndim}) for {self.names}")
        return th, single

    def full_parameters(self, theta: Any) -> dict[str, float | None]:
        """All parameters at ``theta`` (None: each material's own value)."""
        th, _ = self._thetas(theta)
        full = self._full(th)[0]
        return {n: (None if np.isnan(full[i]) else float(full[i])) for i, n in enumerate(PARAMETERS)}

    def _full(self, th: np.ndarray) -> np.ndarray:
        full = np.repeat(self._base[None, :], len(th), axis=0)
        full[:, self._free_idx] = th
        return full

    def rotations(self, thetas: Any) -> np.ndarray:
        """(n, 3, 3) attitudes (body to telescope) at ``thetas``."""
        th, _ = self._thetas(thetas)
        return self._rotations(self._full(th))

    def _rotations(self, full: np.ndarray) -> np.ndarray:
        e = _frame_rotation(full[:, :3], self.attitude_frame)
        if self.attitude_frame == "body":
            return self.reference_attitude @ e
        return e @ self.reference_attitude

    # -------------------------------------------------------------- scenes

    def _get_materials(self, key: tuple) -> list[Material]:
        mats = self._materials_cache.get(key)
        if mats is not None:
            self._materials_cache.move_to_end(key)
            return mats
        alpha, n, k = key
        mats = list(self.materials)
        for i in self.fitted:
            m = mats[i]
            eta = None
            if n is not None or k is not None:
                eta = complex(m.eta.real if n is None else n, m.eta.imag if k is None else k)
            mats[i] = _material_with(m, alpha, eta)
        self._materials_cache[key] = mats
        if len(self._materials_cache) > self._cache_size:
            self._materials_cache.popitem(last=False)
        return mats

    def scene(self, key: tuple) -> _lidar.Scene:
        """The scene for ``(alpha, n, k, scale)`` (None: the material's own value)."""
        sc = self._scenes.get(key)
        if sc is not None:
            self._scenes.move_to_end(key)
            return sc
        mats = self._get_materials(key[:3])
        s = 1.0 if key[3] is None else key[3]
        sc = _lidar.Scene(
            (self._vertices * s, self._faces), mats, face_material=self._face_material,
            normals=self._normals, wavelength=self.instrument.wavelength,
        )
        self._scenes[key] = sc
        if len(self._scenes) > self._cache_size:
            self._scenes.popitem(last=False)
        return sc

    @staticmethod
    def _key(row: np.ndarray) -> tuple:
        return tuple(None if np.isnan(x) else float(x) for x in row[3:7])

    # -------------------------------------------------------------- expected counts

    def _expected_full(self, full: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Expected counts (n, B, C), validity (n,) and, with speckle whose dof the model
        computes, the speckle variance of each bin's signal (n, B, C; else None) for full
        parameter rows; invalid rows (no material can be built, non-finite results) are
        NaN. With ``alpha_step``, rows with a free ``alpha`` are the Catmull-Rom
        interpolation of the renders at the four alpha nodes about it (class docstring),
        the speckle variance with the same weights."""
        n = len(full)
        if self.alpha_step is None:
            return self._rendered(full)
        ia = self._index["alpha"]
        u = np.log(np.where(full[:, ia] > 0, full[:, ia], np.nan)) / self.alpha_step
        u = np.where(np.abs(u - np.round(u)) < 1e-9, np.round(u), u)  # on a node: one render
        j = np.floor(u)
        t = u - j
        w = np.stack([(-t**3 + 2 * t**2 - t) / 2, (3 * t**3 - 5 * t**2 + 2) / 2,
                      (-3 * t**3 + 4 * t**2 + t) / 2, (t**3 - t**2) / 2], axis=1)  # (n, 4)
        base = j - 1  # the first of the four nodes
        inside = np.isfinite(u)
        if self._alpha_nodes is not None:
            # the fitted materials exist only between nodes j_lo and j_hi (_bound_alpha):
            # within one node of either end, the quadratic through the three nodes there
            # (what Catmull-Rom gives with the missing node extrapolated quadratically, so
            # still C1 at the next node), and nothing beyond the materials' own range
            (j_lo, j_hi), (u_lo, u_hi) = self._alpha_nodes
            inside &= (u >= u_lo - 1e-9) & (u <= u_hi + 1e-9)
            for edge, b0 in ((u < j_lo + 1, j_lo), (u > j_hi - 1, j_hi - 2)):
                sq = u[edge] - b0
                w[edge] = np.stack([(sq - 1) * (sq - 2) / 2, -sq * (sq - 2), sq * (sq - 1) / 2,
                                    np.zeros_like(sq)], axis=1)
                base[edge] = b0
        rows, weights, src = [], [], []
        for m in range(4):
            node = full.copy()
            node[:, ia] = np.exp((base + m) * self.alpha_step)
            keep = inside & (w[:, m] != 0.0)
            rows.append(node[keep])
            weights.append(w[keep, m])
            src.append(np.flatnonzero(keep))
        lam_all, ok_all, var_all = self._rendered(np.concatenate(rows))
        out = np.zeros((n, len(self.bin_edges) - 1, len(self.channel_names)))
        var = None if var_all is None else np.zeros_like(out)
        ok = inside.copy()
        at = 0
        for m in range(4):
            k = len(src[m])
            good = ok_all[at:at + k, None, None]
            out[src[m]] += weights[m][:, None, None] * np.where(good, lam_all[at:at + k], 0.0)
            if var is not None and var_all is not None:
                var[src[m]] += weights[m][:, None, None] * np.where(good, var_all[at:at + k], 0.0)
            ok[src[m][~ok_all[at:at + k]]] = False
            at += k
        # the interpolant may dip below zero between nodes where a bin is ~0: counts >= 0
        out = np.maximum(out, 0.0)
        out[~ok] = np.nan
        if var is not None:
            var = np.maximum(var, 0.0)
        return out, ok, var

    def _rendered(self, full: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Expected counts rendered at exactly these parameter rows (and the speckle
        variance, as :meth:`_expected_full`)."""
        n = len(full)
        out = np.full((n, len(self.bin_edges) - 1, len(self.channel_names)), np.nan)
        var = np.full_like(out, np.nan) if self._speckle_at_theta else None
        ok = np.zeros(n, dtype=bool)
        if n == 0:
            return out, ok, var
        rot = self._rotations(full)
        groups: dict[tuple, list[int]] = {}
        for i in range(n):
            groups.setdefault(self._key(full[i]), []).append(i)
        for key, rows in groups.items():
            try:
                sc = self.scene(key)
            except Error:
                continue  # e.g. alpha or n out of the material's range: -inf
            t0 = time.perf_counter()
            res = _lidar.render(sc, self.lidar, rot[rows], outputs=("profile",), device=self.device,
                                settings=self.settings)
            self.render_seconds += time.perf_counter() - t0
            self.render_calls += 1
            lam = expected_counts(res.profile, self.instrument, bin_edges=res.bin_edges, out_edges=self.bin_edges)
            good = np.all(np.isfinite(lam), axis=(1, 2))
            out[rows] = lam
            ok[rows] = good
            if var is not None:
                assert res.profile is not None
                var[rows] = self._speckle_variance(res.profile, res.bin_edges)
        return out, ok, var

    def _speckle_draws(self, theta: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, B, C) speckled counts at one ``theta`` (rendered exactly there), drawn as
        :func:`~pprender.inverse.instrument.measure` draws them: channels of one
        transmitted state share a field. Only where the model computes the dof itself."""
        full = self._full(np.atleast_2d(theta))
        sc = self.scene(self._key(full[0]))
        res = _lidar.render(sc, self.lidar, self._rotations(full), outputs=("profile",), device=self.device,
                            settings=self.settings)
        assert res.profile is not None
        p = np.asarray(res.profile[0], dtype=np.float64)
        stokes, gi, dof = _speckle_state(p, p.shape[-2:] == (4, 4), self.instrument)
        rows = self.instrument.channels.rows  # type: ignore[union-attr]
        inten = _speckle.sample_intensity(np.broadcast_to(stokes, (n,) + stokes.shape), rows, gi, dof, rng)
        k = jitter_matrix(res.bin_edges, self.bin_edges, self.instrument.jitter_range)
        return rng.poisson(np.einsum("ji,...ic->...jc", k, inten) + self._background)

    def _speckle_variance(self, profile: np.ndarray, src_edges: np.ndarray) -> np.ndarray:
        """(n, B, C) speckle variance of each output bin's signal, ``sum_i K_ji^2 s_i^2 /
        M_i`` over the rendered bins ``i`` (``K`` the jitter/rebinning matrix, ``M_i`` each
        channel's marginal dof, :func:`~pprender.inverse.speckle.channel_dof`): the
        denominator of :func:`~pprender.inverse.speckle.blurred_dof`."""
        inst = self.instrument
        p = np.asarray(profile, dtype=np.float64)
        mueller = p.shape[-2:] == (4, 4)
        _channel_cross_sections(p, mueller, inst.channels)  # type: ignore[arg-type]  # the same checks
        stokes, gi, dof = _speckle_state(p, mueller, inst)
        rows = inst.channels.rows  # type: ignore[union-attr]
        s_src = np.clip(np.einsum("ci,...ci->...c", rows, stokes[..., gi, :]), 0.0, None)
        m_c = _speckle.channel_dof(stokes, rows, gi, dof)
        v_src = np.where(np.isinf(m_c), 0.0, s_src * s_src / m_c)
        k = jitter_matrix(src_edges, self.bin_edges, inst.jitter_range)
        return np.einsum("ji,...ic->...jc", k * k, v_src)

    def expected(self, thetas: Any) -> np.ndarray:
        """Expected counts at ``thetas``: (B, C) for one ``theta`` (ndim,), (n, B, C) for
        (n, ndim). Raises :class:`pprender.Error` outside the bounds or where no material
        can be built."""
        th, single = self._thetas(thetas)
        if not np.all(np.isfinite(self.log_prior(th))):
            raise Error(f"invalid theta: outside the bounds {dict(zip(self.names, self.bounds.tolist()))}")
        lam, ok, _ = self._expected_full(self._full(th))
        if not np.all(ok):
            raise Error(f"invalid theta: no valid model at {th[~ok].tolist()} (material parameters out of range)")
        return lam[0] if single else lam

    # -------------------------------------------------------------- probabilities

    def log_prior(self, thetas: Any) -> Any:
        """0 inside the bounds (inclusive), -inf outside or for non-finite values."""
        th, single = self._thetas(thetas)
        inside = np.all(np.isfinite(th) & (th >= self.lower) & (th <= self.upper), axis=1)
        lp = np.where(inside, 0.0, -np.inf)
        return float(lp[0]) if single else lp

    def _counts(self, data: Any) -> tuple[np.ndarray, Any]:
        if isinstance(data, Measurement):
            if data.channel_names != self.channel_names:
                raise Error(
                    f"invalid measurement: channels {data.channel_names} differ from the model's "
                    f"{self.channel_names}"
                )
            if data.bin_edges.shape != self.bin_edges.shape or not np.allclose(
                data.bin_edges, self.bin_edges, rtol=0, atol=1e-12
            ):
                raise Error("invalid measurement: its bin_edges differ from the model's")
            counts = data.counts
        else:
            counts = data
        det = self.instrument.detector
        k = _counts_array(counts, real=det is not None and det.kind == "linear")
        shape = (len(self.bin_edges) - 1, len(self.channel_names))
        if k.shape != shape:
            raise Error(
                f"invalid counts: shape {k.shape}, expected {shape} (bins, channels); index a "
                "batched Measurement first, e.g. measurement[0]"
            )
        return k, gammaln(k + 1.0)

    def _data_dof(self, data: Any) -> np.ndarray | None:
        """The data's recorded speckle dof (B, C) where the model takes them from the data
        (a per-bin Speckle, class docstring); None where it computes them itself."""
        sp = self.instrument.speckle
        if sp is None or self._speckle_at_theta:
            return None
        dof = data.speckle_dof if isinstance(data, Measurement) else None
        if dof is None:
            raise Error(
                f"invalid data: the instrument's Speckle ({sp.source}) has per-bin degrees of freedom, which the "
                "model takes from the measurement: pass the Measurement that measure() returned (its speckle_dof), "
                "or use Speckle(dof=...) or a single Speckle(target_area=...)"
            )
        dof = np.asarray(dof, dtype=np.float64)
        shape = (len(self.bin_edges) - 1, len(self.channel_names))
        if dof.shape != shape:
            raise Error(f"invalid data: speckle_dof of shape {dof.shape}, expected {shape}; index a batched Measurement first")
        return dof

    def speckle_dof(self, thetas: Any, data: Any = None) -> np.ndarray:
        """Each count's marginal speckle degrees of freedom at ``thetas`` (what the likelihood uses).

        ``s^2 / v`` with ``s`` the expected signal and ``v`` its speckle variance through the
        jitter (:func:`~pprender.inverse.speckle.blurred_dof`) when the instrument's
        :class:`~pprender.inverse.speckle.Speckle` has one ``dof`` or one ``target_area``;
        for per-bin areas (or the render's), the data's recorded ``speckle_dof``.

        Parameters
        ----------
        thetas : array_like
            (ndim,) or (n, ndim) parameter values, inside the bounds.
        data : Measurement, optional
            Needed for per-bin degrees of freedom.

        Returns
        -------
        numpy.ndarray
            (B, C) or (n, B, C), in [1, inf] (inf: no speckle).

        Raises
        ------
        pprender.Error
            Without speckle, outside the bounds, or without the data where they are needed.
        """
        if self.instrument.speckle is None:
            raise Error("invalid model: its instrument has no speckle (Instrument(speckle=None))")
        th, single = self._thetas(thetas)
        if not np.all(np.isfinite(self.log_prior(th))):
            raise Error(f"invalid theta: outside the bounds {dict(zip(self.names, self.bounds.tolist()))}")
        lam, ok, var = self._expected_full(self._full(th))
        if not np.all(ok):
            raise Error(f"invalid theta: no valid model at {th[~ok].tolist()} (material parameters out of range)")
        _, m = self._signal_dof(lam, var, self._data_dof(data))
        return m[0] if single else m

    def _signal_dof(self, lam: np.ndarray, var: np.ndarray | None, dof_data: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Expected signal ``lam - background`` (>= 0) and each count's marginal dof (n, B, C)."""
        s = np.clip(lam - self._background, 0.0, None)
        if var is not None:
            pos = var > 0
            m = np.where(pos, np.maximum(s * s / np.where(pos, var, 1.0), 1.0), np.inf)
        else:
            assert dof_data is not None
            m = np.broadcast_to(dof_data, s.shape)
        return s, m

    def _loglik_rows(self, k: np.ndarray, lgk: Any, lam: np.ndarray, ok: np.ndarray, var: np.ndarray | None,
                     dof_data: np.ndarray | None) -> np.ndarray:
        """Log-likelihood of the counts for each row of expected counts; -inf where not ok."""
        lam = np.where(ok[:, None, None], lam, 1.0)
        if self.instrument.speckle is None:
            return np.where(ok, self._records_loglik(k, lam, lgk), -np.inf)
        s, m = self._signal_dof(lam, None if var is None else np.where(ok[:, None, None], var, 0.0), dof_data)
        if np.all(np.isinf(m)):
            return np.where(ok, _loglik(k, lam, lgk), -np.inf)  # no speckle anywhere: Poisson, bit for bit
        ll = _speckle.speckle_log_likelihood(np.broadcast_to(k, s.shape), s, self._background, m)
        return np.where(ok, ll, -np.inf)

    @property
    def _plain(self) -> bool:
        """Whether the data are plain Poisson counts (no detector, no atmosphere)."""
        return self.instrument.detector is None and self.instrument.atmosphere is None

    def _records_loglik(self, k: np.ndarray, lam: np.ndarray, lgk: Any) -> Any:
        """Log-likelihood of records ``k`` (B, C) at expected counts ``lam`` (n, B, C):
        Poisson, or :func:`pprender.inverse.detector.record_log_likelihood` for the
        instrument's detector and atmosphere."""
        if self._plain:
            return _loglik(k, lam, lgk)
        inst = self.instrument
        return record_log_likelihood(
            k, lam, inst.pulses, detector=inst.detector, atmosphere=inst.atmosphere, bin_edges=self.bin_edges,
            groups=pulse_groups(inst.channels.generators_array),  # type: ignore[union-attr]
        )

    def log_likelihood(self, thetas: Any, data: Any) -> Any:
        """Log-likelihood of ``data`` (a :class:`Measurement` or counts (B, C)) at ``thetas``;
        ``-inf`` where the model is invalid. Not bounded by the prior.

        Poisson (:func:`poisson_log_likelihood`) without speckle, detector or atmosphere;
        with the instrument's ``detector`` or ``atmosphere``, the likelihood of what the
        receiver records (module docstring); with the instrument's
        :class:`~pprender.inverse.speckle.Speckle`, the composite speckle likelihood
        :func:`~pprender.inverse.speckle.speckle_log_likelihood` (each count's exact
        marginal law, channels multiplied as if independent; ``docs/speckle.md``: where
        channels share a field and speckle dominates, its curvature overstates the
        information by up to 1.4x (co/cross) to 2.2x (six-channel) in variance terms)
        with the dof of :meth:`speckle_dof`; dof inf everywhere gives the Poisson one bit
        for bit. Per-bin speckle dof (a per-bin ``target_area`` or the render's areas) are
        the data's: ``data`` must then be the :class:`Measurement`.
        """
        th, single = self._thetas(thetas)
        k, lgk = self._counts(data)
        dof_data = self._data_dof(data)
        out = np.full(len(th), -np.inf)
        fin = np.all(np.isfinite(th), axis=1)
        lam, ok, var = self._expected_full(self._full(th[fin]))
        ll = self._loglik_rows(k, lgk, lam, ok, var, dof_data)
        out[fin] = ll
        out = np.where(np.isnan(out), -np.inf, out)
        return float(out[0]) if single else out

    def log_prob(self, thetas: Any, data: Any) -> Any:
        """Log posterior (up to a constant): :meth:`log_prior` + :meth:`log_likelihood`.

        ``thetas``: (ndim,) -> float, or (n_walkers, ndim) -> (n_walkers,) for emcee's
        ``vectorize=True``; walkers outside the bounds are not rendered. Never raises for
        parameter values (``-inf`` instead); a wrong shape or data raises
        :class:`pprender.Error`.
        """
        th, single = self._thetas(thetas)
        k, lgk = self._counts(data)
        dof_data = self._data_dof(data)
        lp = np.asarray(self.log_prior(th), dtype=np.float64).reshape(-1)
        out = np.full(len(th), -np.inf)
        inside = np.isfinite(lp)
        if np.any(inside):
            lam, ok, var = self._expected_full(self._full(th[inside]))
            ll = self._loglik_rows(k, lgk, lam, ok, var, dof_data)
            out[inside] = lp[inside] + np.where(np.isnan(ll), -np.inf, ll)
        return float(out[0]) if single else out


# ---------------------------------------------------------------------- Fisher information


def fisher_information(model: ForwardModel, theta: Any, step: Any = None, data: Any = None) -> np.ndarray:
    """Fisher information (ndim, ndim) of Poisson (or speckled) counts at ``theta``.

    ``F_ij = sum_bc (d lam / d theta_i)(d lam / d theta_j) / lam``, the derivatives by central
    differences of the rendered expected counts. ``sqrt(diag(inv(F)))`` is the Cramer-Rao
    standard deviation.

    With the instrument's :class:`~pprender.inverse.speckle.Speckle`, ``1 / lam`` is
    replaced by :func:`~pprender.inverse.speckle.fisher_weight` of each count's signal,
    background and marginal dof (:meth:`ForwardModel.speckle_dof`; the dof held fixed):
    the inverse variance ``1 / (lam + s^2 / M)``, a lower bound on each count's
    information, so the sd are conservative by at most ``sqrt(1.15)``
    (``docs/speckle.md``). This is the information of the composite (channels
    independent) likelihood; where channels share a speckle field and speckle dominates,
    the true spread of the estimates is larger than its ``sqrt(diag(inv(F)))``
    (``docs/speckle.md``: up to 1.4x for co/cross channels, 2.2x for the six-channel
    polarimeter, in sd).

    With the instrument's ``detector`` or ``atmosphere``, the expected minus Hessian of the
    log-likelihood the fits use (:func:`pprender.inverse.detector.record_log_likelihood`):

    * dead time at least the gate: per channel the multinomial's
      ``n sum_{b, none} (dp_b / dtheta_i)(dp_b / dtheta_j) / p_b`` over Coates'
      probabilities (averaged over the scintillation factor), exact; with scintillation
      the likelihood leaves out the correlation between channels sharing pulses, so the
      Cramer-Rao sd it gives are too small where that correlation matters;
    * linear APD: the Gaussian's ``dmu_i dmu_j / v + dv_i dv_j / (2 v^2)``, ``mu = lam``,
      ``v = F lam + lam^2 sigma_I^2 / n + n (sigma_a / G)^2``: exact for that likelihood
      (it needs only the records' first two moments); behind scintillation that likelihood
      leaves out the correlation between bins sharing pulses, so its Cramer-Rao sd are too
      small where ``lam^2 sigma_I^2 / n`` is not small against ``F lam``;
    * photon counting without dead time, with scintillation: the moment-based
      (quasi-likelihood) information of each pulse group, ``dlam^T Sigma^-1 dlam`` with
      ``Sigma = diag(lam) + (sigma_I^2 / n) lam lam^T`` the counts' exact covariance:
      exact for the shape of the profile within a group (the multinomial given the total)
      and ``1 / Var K`` for its total ``K``, which is exact for a gamma factor (negative
      binomial totals) and a lower bound on the information otherwise.

    Parameters
    ----------
    model : ForwardModel
        The forward model.
    theta : array_like
        One parameter vector (ndim,), inside the bounds and not on one.
    step : float or array_like, optional
        Per-parameter step (default ``1e-3`` of the bound width; shrunk to stay within the
        bounds). Rendering is rasterized, so ``step`` must be large enough that
        pixel-coverage noise (of order 1e-4 relative at resolution 48 with supersampling 2) is
        small against the change it causes.
    data : Measurement, optional
        The measurement whose recorded ``speckle_dof`` a per-bin Speckle needs (ignored
        otherwise).

    Returns
    -------
    numpy.ndarray
        (ndim, ndim) Fisher information matrix.

    Raises
    ------
    pprender.Error
        For a ``theta`` that is not one vector, outside the bounds or on a bound (central
        differences need room on both sides), or a ``step`` that is not positive and finite.
    """
    th, single = model._thetas(theta)
    if not single:
        raise Error("invalid theta: one parameter vector (ndim,)")
    th = th[0]
    if not np.isfinite(model.log_prior(th)):
        raise Error("invalid theta: outside the bounds")
    h = 1e-3 * (model.upper - model.lower) if step is None else _per_parameter(step, "step", model)
    if not np.all(np.isfinite(h) & (h > 0)):
        raise Error(f"invalid step = {step!r}: positive, finite")
    h = np.minimum(h, 0.5 * np.minimum(th - model.lower, model.upper - th))
    if np.any(h <= 0):
        raise Error("invalid theta: on a bound (central differences need room on both sides)")
    pts = [th]
    for i in range(model.ndim):
        for sgn in (1.0, -1.0):
            p = th.copy()
            p[i] += sgn * h[i]
            pts.append(p)
    lam = model.expected(np.array(pts))
    jac = np.stack([(lam[1 + 2 * i] - lam[2 + 2 * i]) / (2 * h[i]) for i in range(model.ndim)])  # (p, B, C)
    if not model._plain:
        return _records_fisher(model, lam, h)
    lam0 = lam[0]
    w = np.where(lam0 > 0, 1.0 / np.where(lam0 > 0, lam0, 1.0), 0.0)
    if model.instrument.speckle is not None:
        m = model.speckle_dof(th, data)
        s = np.clip(lam0 - model._background, 0.0, None)
        pos = s > 0
        w = np.where(pos, _speckle.fisher_weight(np.where(pos, s, 1.0), model._background, m), w)
    return np.einsum("ibc,jbc,bc->ij", jac, jac, w)


def _records_fisher(model: ForwardModel, lam: np.ndarray, h: np.ndarray) -> np.ndarray:
    """The expected minus Hessian of the log-likelihood of the instrument's detector and
    atmosphere (:func:`fisher_information`), from ``lam`` at ``theta`` and ``theta +- h_i e_i``."""
    inst = model.instrument
    det = Detector() if inst.detector is None else inst.detector
    atm = inst.atmosphere if inst.atmosphere is not None and inst.atmosphere.scintillation != "none" else None
    mode = det.regime(model.bin_edges)
    n = inst.pulses

    def diff(a: np.ndarray) -> np.ndarray:
        return np.stack([(a[1 + 2 * i] - a[2 + 2 * i]) / (2 * h[i]) for i in range(model.ndim)])

    if mode == "coates":
        # per channel, multinomial over n pulses: n sum_{bins, none} dp_i dp_j / p
        prob = coates_probabilities(lam / n, None if atm is None else atm.laplace)  # (2p + 1, B + 1, C)
        dp, p0 = diff(prob), prob[0]
        w = np.where(p0 > 0, n / np.where(p0 > 0, p0, 1.0), 0.0)
        return np.einsum("ibc,jbc,bc->ij", dp, dp, w)
    s = 0.0 if atm is None else atm.index / n  # (C,): the mean factor's variance per channel
    if mode == "linear":
        # Gaussian with mean lam and variance v: dmu^2 / v + dv^2 / (2 v^2)
        v = det.excess_noise * lam + lam**2 * s + n * (det.amplifier_noise / det.gain) ** 2
        dm, dv, v0 = diff(lam), diff(v), v[0]
        w1 = np.where(v0 > 0, 1.0 / np.where(v0 > 0, v0, 1.0), 0.0)
        return np.einsum("ibc,jbc,bc->ij", dm, dm, w1) + np.einsum("ibc,jbc,bc->ij", dv, dv, 0.5 * w1**2)
    # Poisson with scintillation, per pulse group: dl^T Sigma^-1 dl, Sigma = diag(lam) + s lam lam^T
    # (Sherman-Morrison: sum dl_i dl_j / lam - s (sum dl_i)(sum dl_j) / (1 + s Lam))
    dl, lam0 = diff(lam), lam[0]
    w = np.where(lam0 > 0, 1.0 / np.where(lam0 > 0, lam0, 1.0), 0.0)
    F = np.einsum("ibc,jbc,bc->ij", dl, dl, w)
    if atm is not None:
        g = pulse_groups(inst.channels.generators_array)  # type: ignore[union-attr]
        for j in range(int(g.max()) + 1):
            cols = np.flatnonzero(g == j)
            sg = float(atm.index / n[cols[0]])
            tot = np.sum(dl[..., cols], axis=(-2, -1))
            F = F - sg * np.outer(tot, tot) / (1.0 + sg * float(np.sum(lam0[:, cols])))
    return F


# ---------------------------------------------------------------------- nlopt


@dataclass
class FitResult:
    """A maximum-likelihood fit and how far to trust it (:func:`diagnose_fit`).

    Made by :func:`fit_nlopt` and :func:`maximum_likelihood`.

    Attributes
    ----------
    x : numpy.ndarray
        (ndim,) optimum.
    log_likelihood : float
        The log-likelihood there.
    n_evaluations : int
        Likelihood evaluations, all starts (the global stage's and the diagnosis' included).
    names : tuple of str
        The free parameters' names.
    algorithm : str
        The nlopt algorithm.
    return_code : int
        nlopt's return code, for the best start.
    message : str
        nlopt's message, for the best start.
    seconds : float
        Wall time.
    starts : list of tuple
        Per local start ``(x0, x, log_likelihood)``.
    sd : numpy.ndarray or None
        (ndim,) Cramer-Rao standard deviations at ``x``, ``sqrt(diag(inv(fisher)))`` (set by
        the diagnosis; None where the Fisher information is singular).
    covariance : numpy.ndarray or None
        (ndim, ndim) ``inv(fisher)``.
    fisher : numpy.ndarray or None
        (ndim, ndim) the Fisher information at ``x`` (:func:`fisher_information`).
    observed_information : numpy.ndarray or None
        (ndim, ndim) minus the Hessian of the log-likelihood at ``x`` (central differences
        with steps of one Cramer-Rao sd).
    curvature_ratio : tuple of float or None
        The smallest and largest eigenvalue of ``fisher^(-1/2) observed fisher^(-1/2)``: both
        near 1 where the likelihood is the Gaussian the Cramer-Rao sd describe.
    newton_distance : float or None
        Distance (in Cramer-Rao sd, Mahalanobis) from ``x`` to the maximum of the local
        quadratic model of the log-likelihood: small at a converged maximum.
    deviance : float or None
        ``2 sum [k log(k / lam) - (k - lam)]`` at ``x``; with speckle, Pearson's
        ``sum (k - lam)^2 / (lam + s^2 / M)``; ``-2 log L`` with an instrument
        ``detector`` or ``atmosphere`` (:func:`diagnose_fit`).
    deviance_p : float or None
        Probability of a deviance at least as large under the fitted model (500 Poisson draws
        of the expected counts at ``x``, speckled ones with speckle; beyond the largest draw,
        the tail of a normal fitted to them): near 0 when the model cannot explain the data.
    n_agree : int or None
        Local starts whose optimum is the best one (log-likelihood within 1 and position
        within 3 sd), out of ``len(starts)``.
    alternatives : list of tuple
        ``(x, log_likelihood)`` of other optima found, more than 3 sd from ``x`` with a
        log-likelihood within :data:`RIVAL_DELTA_LOG_L` of the best: the data do not decide
        between them and ``x`` (e.g. attitudes a monostatic profile cannot tell apart).
    problems : list of str
        Why the result should not be trusted as it stands (empty when none was found).
    diagnosed : bool
        Whether the diagnosis ran.
    trustworthy : bool
        ``diagnosed and not problems``.
    """

    x: np.ndarray
    log_likelihood: float
    n_evaluations: int
    names: tuple[str, ...]
    algorithm: str
    return_code: int
    message: str
    seconds: float
    starts: list[tuple[np.ndarray, np.ndarray, float]] = field(default_factory=list)
    sd: np.ndarray | None = None
    covariance: np.ndarray | None = None
    fisher: np.ndarray | None = None
    observed_information: np.ndarray | None = None
    curvature_ratio: tuple[float, float] | None = None
    newton_distance: float | None = None
    deviance: float | None = None
    deviance_p: float | None = None
    n_agree: int | None = None
    alternatives: list[tuple[np.ndarray, float]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    diagnosed: bool = False

    @property
    def trustworthy(self) -> bool:
        """``diagnosed and not problems``."""
        return self.diagnosed and not self.problems

    def as_dict(self) -> dict[str, float]:
        return dict(zip(self.names, (float(v) for v in self.x)))

    def summary(self) -> str:
        """A few lines: the estimate with its Cramer-Rao sd, and the diagnosis."""
        lines = []
        for i, n in enumerate(self.names):
            sd = "" if self.sd is None else f" +- {self.sd[i]:.4g}"
            lines.append(f"{n} = {self.x[i]:.6g}{sd}")
        lines.append(f"log L = {self.log_likelihood:.2f} ({self.n_evaluations} evaluations, {self.seconds:.1f} s)")
        if not self.diagnosed:
            lines.append("not diagnosed")
        elif self.problems:
            lines += ["NOT TRUSTWORTHY:"] + [f"  - {p}" for p in self.problems]
        else:
            if self.alternatives:
                lines.append(f"{len(self.alternatives)} other optimum(s) explain the data as well: see alternatives")
            lines.append(f"trustworthy: {self.n_agree} of {len(self.starts)} start(s) agree; curvature/Fisher "
                         f"{self.curvature_ratio[0]:.2f}-{self.curvature_ratio[1]:.2f}; deviance p = "  # type: ignore[index]
                         f"{self.deviance_p:.2f}")
        return "\n".join(lines)


#: Limits of the diagnosis (:func:`diagnose_fit`): the observed information's eigenvalues
#: in units of the Fisher information, the distance to the quadratic model's maximum (sd),
#: the deviance p-value, and what counts as a second optimum nearly as likely (log L).
CURVATURE_RANGE = (0.5, 2.0)
NEWTON_LIMIT = 0.3
DEVIANCE_P_LIMIT = 1e-3
RIVAL_DELTA_LOG_L = 3.0


def _deviance(k: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Poisson deviance over the last two axes."""
    lam = np.maximum(lam, 1e-300)
    return 2.0 * np.sum(xlogy(k, k / lam) - (k - lam), axis=(-2, -1))


#: Largest number of pulses per channel the diagnosis's bootstrap simulates one by one for a
#: dead-time detector behind scintillation (above it, per-channel multinomial draws).
BOOTSTRAP_N_EXACT = 1000


def _deviance_draws(model: "ForwardModel", k: np.ndarray, lam: np.ndarray, rng: np.random.Generator) -> tuple[float, np.ndarray]:
    """The deviance of ``k`` at ``lam`` and of 500 draws there (:func:`diagnose_fit`)."""
    if model._plain:
        D = float(_deviance(k, lam))
        return D, _deviance(rng.poisson(lam[None], size=(500,) + lam.shape).astype(np.float64), lam[None])
    inst = model.instrument
    groups = pulse_groups(inst.channels.generators_array)  # type: ignore[union-attr]
    draws = record(np.broadcast_to(lam, (500,) + lam.shape), inst.pulses, rng, detector=inst.detector,
                   atmosphere=inst.atmosphere, bin_edges=model.bin_edges, groups=groups,
                   n_exact=BOOTSTRAP_N_EXACT)
    D = -2.0 * float(model._records_loglik(k, lam[None], None)[0])
    return D, -2.0 * np.asarray(model._records_loglik(draws, lam[None], None), dtype=np.float64)


def diagnose_fit(model: "ForwardModel", measurement: Any, result: FitResult, *, seed: int = 0) -> FitResult:
    """How far to trust a maximum-likelihood fit: a copy of ``result`` with its diagnosis.

    Checks, each adding to :attr:`FitResult.problems` when it fails:

    * the optimum is not on (within one sd of) a bound, where Gaussian uncertainties fail;
    * the Fisher information is invertible (every parameter constrained);
    * the observed information (minus the Hessian of ``log L``, central differences with
      steps of one Cramer-Rao sd) is positive definite (a maximum, not a saddle or a
      step) and agrees with the Fisher information: eigenvalues of
      ``F^(-1/2) J F^(-1/2)`` within :data:`CURVATURE_RANGE` (else the Cramer-Rao sd do
      not describe the likelihood: a rough or non-Gaussian likelihood);
    * the local quadratic model's maximum lies within :data:`NEWTON_LIMIT` sd (converged);
    * the model explains the data: deviance p-value above :data:`DEVIANCE_P_LIMIT`
      (parametric bootstrap, 500 Poisson draws at the optimum, seeded with ``seed``);
      a failure means a wrong shape, material or instrument, or a missed global optimum.
      With the instrument's speckle the statistic is Pearson's ``sum (k - lam)^2 / (lam +
      s^2 / M)`` (each count's speckle variance) and its 500 draws are speckled counts at
      the optimum: drawn as :func:`~pprender.inverse.instrument.measure` draws them (one
      render at ``x``; channels of one transmitted state share a field) where the model
      computes ``M`` (one ``dof`` or one ``target_area``), and from each count's marginal
      law (a gamma intensity of shape ``M``, then Poisson with the background; channels
      independent) where ``M`` is the measurement's (per-bin areas): there, where
      channels of one state share a field and speckle dominates, the real statistic
      spreads more than these draws and the p-value can be too small (a false alarm);
      With the instrument's ``detector`` or ``atmosphere`` the statistic is
      ``-2 log L`` at the optimum (the likelihood of
      :func:`pprender.inverse.detector.record_log_likelihood`, no saturated model
      subtracted) and the 500 draws are what the receiver records there
      (:func:`pprender.inverse.detector.record`, pulse by pulse up to
      :data:`BOOTSTRAP_N_EXACT` pulses);

    Not a problem but reported (:attr:`FitResult.alternatives`, and a
    :class:`FitWarning`): other optima, more than 3 sd away, whose log-likelihood is within
    :data:`RIVAL_DELTA_LOG_L` of the best. The data do not decide between them: a monostatic
    profile cannot tell apart attitudes related by the target's symmetries or by a
    half turn about the line of sight (co/cross channels), among others. Each is as good an
    estimate as ``x``; report them all, or add what breaks the tie (a prior, another
    channel set, a sequence of attitudes).

    Parameters
    ----------
    model : ForwardModel
        The forward model of the fit.
    measurement : Measurement or array_like
        The data of the fit.
    result : FitResult
        The fit (its ``x`` and ``starts``).
    seed : int, optional
        Seed of the deviance draws (default 0).

    Returns
    -------
    FitResult
        A copy with ``sd``, ``covariance``, ``fisher``, ``observed_information``,
        ``curvature_ratio``, ``newton_distance``, ``deviance``, ``deviance_p``, ``n_agree``,
        ``alternatives``, ``problems`` and ``diagnosed`` set.

    Raises
    ------
    pprender.Error
        For a model or data that do not match (as :meth:`ForwardModel.log_likelihood`).
    """
    if not isinstance(model, ForwardModel):
        raise Error(f"invalid model of type {type(model).__name__}: expected ForwardModel")
    k, _ = model._counts(measurement)
    x = np.asarray(result.x, dtype=np.float64)
    n = model.ndim
    problems: list[str] = []
    out = replace(result, problems=problems, diagnosed=True)
    n_eval = 0
    width = model.upper - model.lower
    room = np.minimum(x - model.lower, model.upper - x)
    F = None
    if np.all(room > 1e-9 * width):
        try:
            F = fisher_information(model, x, data=measurement)
            n_eval += 2 * n + 1
        except Error as e:
            problems.append(f"no Fisher information at the optimum: {e}")
    cov = None
    if F is not None:
        w, V = np.linalg.eigh(0.5 * (F + F.T))
        if not (np.all(np.isfinite(w)) and w.min() > 1e-12 * max(w.max(), 1e-300)):
            weak = [model.names[i] for i in np.flatnonzero(np.abs(V[:, 0]) > 0.3)]
            problems.append(f"the Fisher information is singular: the data do not constrain {weak} (degenerate parameters)")
        else:
            cov = (V / w) @ V.T
            out.fisher, out.covariance, out.sd = F, cov, np.sqrt(np.diag(cov))
    else:
        at = [model.names[i] for i in np.flatnonzero(room <= 1e-9 * width)]
        problems.append(f"the optimum is on the bound(s) of {at}: widen the bounds, or the data prefer a value outside them")
    if cov is not None:
        sd = out.sd
        assert sd is not None and F is not None
        near = [model.names[i] for i in np.flatnonzero(room < sd)]
        if near:
            problems.append(f"the optimum is within one sd of the bound(s) of {near}: the Gaussian uncertainties do not hold there")
        h = np.minimum(sd, 0.999 * room)
        if np.all(h > 0):
            # Hessian by central differences, one batch: x, x +- h_i e_i, x +- h_i e_i +- h_j e_j
            pts = [x]
            for i in range(n):
                for sg in (1.0, -1.0):
                    p = x.copy()
                    p[i] += sg * h[i]
                    pts.append(p)
            pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
            for i, j in pairs:
                for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                    p = x.copy()
                    p[i] += si * h[i]
                    p[j] += sj * h[j]
                    pts.append(p)
            ll = model.log_likelihood(np.array(pts), measurement)
            n_eval += len(pts)
            if not np.all(np.isfinite(ll)):
                problems.append("the log-likelihood is not finite within one sd of the optimum")
            else:
                H = np.zeros((n, n))
                g = np.zeros(n)
                for i in range(n):
                    lp, lm = ll[1 + 2 * i], ll[2 + 2 * i]
                    H[i, i] = (lp - 2 * ll[0] + lm) / h[i] ** 2
                    g[i] = (lp - lm) / (2 * h[i])
                base = 1 + 2 * n
                for m, (i, j) in enumerate(pairs):
                    a, b, c, d = ll[base + 4 * m: base + 4 * m + 4]
                    H[i, j] = H[j, i] = (a - b - c + d) / (4 * h[i] * h[j])
                J = -H
                out.observed_information = J
                L = np.linalg.cholesky(F)
                Li = np.linalg.inv(L)
                ev = np.linalg.eigvalsh(Li @ J @ Li.T)
                out.curvature_ratio = (float(ev.min()), float(ev.max()))
                if ev.min() <= 0:
                    problems.append(
                        "not a maximum: the log-likelihood curves upward along some direction within one sd "
                        f"(curvature/Fisher eigenvalues {ev.min():.2g} to {ev.max():.2g}): a saddle, a step of a "
                        "rough likelihood, or a stop before convergence"
                    )
                else:
                    if ev.min() < CURVATURE_RANGE[0] or ev.max() > CURVATURE_RANGE[1]:
                        problems.append(
                            f"the curvature of log L differs from the Fisher information (eigenvalues {ev.min():.2f} "
                            f"to {ev.max():.2f} of it, expected within {CURVATURE_RANGE}): the Cramer-Rao sd do not "
                            "describe this likelihood (rough, non-Gaussian, or a model that does not fit)"
                        )
                    step = np.linalg.solve(J, g)
                    dist = float(np.sqrt(step @ F @ step))
                    out.newton_distance = dist
                    if dist > NEWTON_LIMIT:
                        problems.append(
                            f"not converged: the maximum of the local quadratic model lies {dist:.2f} sd from the "
                            f"optimum, at {np.round(x + step, 6).tolist()}"
                        )
    # goodness of fit
    lam = model.expected(x) if np.all(np.isfinite(model.log_prior(x))) else None
    n_eval += 1
    if lam is not None:
        rng = np.random.default_rng(seed)
        if model.instrument.speckle is None:
            D, sims = _deviance_draws(model, k, lam, rng)
        else:
            # speckle: Pearson's statistic with each count's variance lam + s^2 / M; its
            # draws speckled as measure() draws them (channels of one state share a field),
            # or, where the dof are the data's, from each count's marginal law
            bg = model._background
            sig = np.clip(lam - bg, 0.0, None)
            m_c = model.speckle_dof(x, measurement)
            finite = np.isfinite(m_c)
            var = lam + np.where(finite, sig * sig / np.where(finite, m_c, 1.0), 0.0)
            var = np.where(var > 0, var, 1.0)
            D = float(np.sum((k - lam) ** 2 / var))
            if model._speckle_at_theta:
                draws = model._speckle_draws(x, 500, rng).astype(np.float64)
            else:
                mf = np.where(finite, m_c, 1.0)
                g = rng.standard_gamma(np.broadcast_to(mf, (500,) + lam.shape)) / mf
                draws = rng.poisson(np.where(finite, sig * g, sig) + bg).astype(np.float64)
            sims = np.sum((draws - lam) ** 2 / var, axis=(-2, -1))
        above = int(np.sum(sims >= D))
        # beyond the draws, the tail of a normal fitted to them (the deviance of many bins
        # is near normal); the empirical p-value cannot go below 1 / 501
        p_value = float(above / len(sims)) if above else float(norm.sf((D - sims.mean()) / max(sims.std(), 1e-300)))
        out.deviance, out.deviance_p = D, p_value
        if p_value < DEVIANCE_P_LIMIT:
            problems.append(
                f"the model does not fit the data: deviance {D:.1f} against {sims.mean():.1f} +- {sims.std():.1f} "
                f"expected (p = {p_value:.1g}): a wrong shape, material or instrument, or a missed global optimum"
            )
    # agreement of the starts, and other optima that explain the data as well
    alternatives: list[tuple[np.ndarray, float]] = []
    agree = 0
    for _, xs, lls in sorted(result.starts, key=lambda t: -t[2]):
        if not math.isfinite(lls):
            continue
        dx = xs - x
        sep = float(np.sqrt(dx @ out.fisher @ dx)) if out.fisher is not None else float(np.max(np.abs(dx) / width) * 1e3)
        if result.log_likelihood - lls < 1.0 and sep < 3.0:
            agree += 1
        elif sep >= 3.0 and result.log_likelihood - lls < RIVAL_DELTA_LOG_L:
            if all(np.max(np.abs(xs - a) / width) > 1e-3 for a, _ in alternatives):
                alternatives.append((xs, float(lls)))
    out.n_agree = max(agree, 1)
    out.alternatives = alternatives
    out.n_evaluations = result.n_evaluations + n_eval
    return out


def _warn_untrustworthy(result: FitResult, what: str) -> None:
    if result.problems:
        warnings.warn(f"{what}: the result is not trustworthy: " + "; ".join(result.problems), FitWarning, stacklevel=3)
    if result.alternatives:
        alt = "; ".join(f"{np.round(a, 6).tolist()} (log L {ll - result.log_likelihood:+.2f})" for a, ll in result.alternatives)
        warnings.warn(
            f"{what}: {len(result.alternatives)} other optimum(s) explain the data as well as {np.round(result.x, 6).tolist()}: "
            f"{alt}. The data do not decide between them (FitResult.alternatives)",
            FitWarning, stacklevel=3,
        )


_ALGORITHMS = ("BOBYQA", "NELDERMEAD", "COBYLA")
_NLOPT_MESSAGES = {
    1: "success", 2: "stopval reached", 3: "ftol reached", 4: "xtol reached", 5: "maxeval reached",
    6: "maxtime reached", -1: "failure", -2: "invalid arguments", -3: "out of memory",
    -4: "roundoff limited", -5: "forced stop",
}


def _algorithm(algorithm: Any) -> str:
    """The nlopt algorithm's canonical name (:data:`_ALGORITHMS`)."""
    algo = str(algorithm).upper().replace("-", "").replace("_", "")
    if algo not in _ALGORITHMS:
        raise Error(f"invalid algorithm = {algorithm!r}: one of {_ALGORITHMS}")
    return algo


def _per_parameter(value: Any, name: str, model: ForwardModel) -> np.ndarray:
    """A number or one per free parameter, as a float64 (ndim,) array."""
    v = _numeric_array(value, name, f"a number or one per free parameter {model.names}")
    try:
        return np.broadcast_to(v, (model.ndim,)).copy()
    except ValueError:
        raise Error(f"invalid {name}: shape {v.shape}, expected () or ({model.ndim},) for {model.names}") from None


def _x0(model: ForwardModel, x0: Any) -> np.ndarray:
    x = _numeric_array(x0, "x0", f"a starting point {model.names}")
    if x.shape != (model.ndim,):
        raise Error(f"invalid x0: shape {x.shape}, expected ({model.ndim},) for {model.names}")
    if not np.all(np.isfinite(x)) or np.any(x < model.lower) or np.any(x > model.upper):
        raise Error(f"invalid x0 = {x.tolist()}: must lie within the bounds {model.bounds.tolist()}")
    return x


def fit_nlopt(
    model: ForwardModel,
    measurement: Any,
    x0: Any,
    algorithm: str = "BOBYQA",
    *,
    ftol_abs: float = 1e-6,
    xtol_abs: Any = None,
    maxeval: int = 2000,
    initial_step: Any = None,
    n_starts: int = 1,
    seed: int | None = None,
    diagnose: bool = True,
) -> FitResult:
    """Maximum-likelihood fit with a derivative-free nlopt algorithm, from given starts.

    A local optimizer: it finds the maximum whose basin holds a start.
    :func:`maximum_likelihood` is the robust fit (a global stage, several local starts,
    the diagnosis); this is its local stage, for a start known to be close.

    No gradients are offered: the renderer rasterizes the target, so the expected counts
    are piecewise smooth in the attitude and scale (they step when a silhouette edge
    crosses a pixel centre), and their derivatives are not available from the renderer;
    finite differences would need ``2 ndim`` renders per step and be dominated by that
    rasterization noise at small steps. BOBYQA (quadratic trust-region models),
    Nelder-Mead (simplex) and COBYLA (linear models) need only values.

    Parameters
    ----------
    model : ForwardModel
        The forward model.
    measurement : Measurement or array_like
        The data: a :class:`Measurement` or counts (B, C).
    x0 : array_like
        (ndim,) starting point, inside the bounds (the nlopt box constraints).
    algorithm : {"BOBYQA", "NELDERMEAD", "COBYLA"}, optional
        The nlopt algorithm. Default ``"BOBYQA"``.
    ftol_abs : float, optional
        Stop when an iteration changes ``log L`` by less than this (default 1e-6; a
        change of 0.5 in ``log L`` is one standard deviation).
    xtol_abs : float or array_like, optional
        Stop when ``x`` moves less, one value or (ndim,) (default ``1e-8`` of the bound
        widths).
    maxeval : int, optional
        Likelihood evaluations per start. Default 2000.
    initial_step : float or array_like, optional
        Initial step / trust radius, one value or (ndim,) (default ``0.05`` of the bound
        widths).
    n_starts : int, optional
        ``x0`` and ``n_starts - 1`` further starts drawn uniformly within the bounds
        with ``numpy.random.default_rng(seed)``; the best optimum is returned. Default 1.
    seed : int, optional
        Seed of the further starts, an integer >= 0 (default None).
    diagnose : bool, optional
        Diagnose the optimum (:func:`diagnose_fit`: about ``2 ndim^2 + 2 ndim + 2`` more
        renders) and warn (:class:`FitWarning`) when it is not trustworthy. Default True.

    Returns
    -------
    FitResult
        The best start's optimum, with every start in ``starts`` and, with ``diagnose``,
        its uncertainty and diagnosis.

    Raises
    ------
    pprender.Error
        For bad arguments, and when the log-likelihood is ``-inf`` everywhere tried.

    Warns
    -----
    FitWarning
        With ``diagnose``, when the diagnosis finds problems (:attr:`FitResult.problems`).

    Notes
    -----
    Log-likelihoods of ``-inf`` (invalid materials; zero expected counts where counts
    were recorded, impossible with background) are passed to nlopt as ``-1e30``. If it is
    ``-inf`` at every point tried, over all starts, there is no fit: nlopt would stop
    ("xtol reached") at ``x0`` on the flat ``-1e30``, and :class:`pprender.Error` is raised
    instead. A start that never found a finite value is kept in ``starts`` with
    ``log_likelihood = -inf``; the best start is returned.
    """
    if not isinstance(model, ForwardModel):
        raise Error(f"invalid model of type {type(model).__name__}: expected ForwardModel")
    algo = _algorithm(algorithm)
    x0 = _x0(model, x0)
    model._counts(measurement)  # validate the data once
    if isinstance(n_starts, (bool, np.bool_)) or not isinstance(n_starts, (int, np.integer)) or n_starts < 1:
        raise Error(f"invalid n_starts = {n_starts!r}: an integer >= 1")
    if isinstance(maxeval, (bool, np.bool_)) or not isinstance(maxeval, (int, np.integer)) or maxeval < 1:
        raise Error(f"invalid maxeval = {maxeval!r}: an integer >= 1")
    ftol = _check_number("ftol_abs", ftol_abs, 0.0, math.inf, False, True, "log-likelihood units")
    width = model.upper - model.lower
    step = 0.05 * width if initial_step is None else _per_parameter(initial_step, "initial_step", model)
    xtol = 1e-8 * width if xtol_abs is None else _per_parameter(xtol_abs, "xtol_abs", model)
    if not np.all(np.isfinite(step) & (step > 0)):
        raise Error(f"invalid initial_step = {initial_step!r}: positive, finite")
    if not np.all(np.isfinite(xtol) & (xtol >= 0)):
        raise Error(f"invalid xtol_abs = {xtol_abs!r}: finite, >= 0")
    if seed is not None and (isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0):
        raise Error(f"invalid seed = {seed!r}: an integer >= 0 or None")
    rng = np.random.default_rng(seed)
    starts = [x0] + [model.lower + width * rng.random(model.ndim) for _ in range(n_starts - 1)]
    t0 = time.perf_counter()
    result = _local_fits(model, measurement, starts, algo, ftol, xtol, int(maxeval), step)
    result.seconds = time.perf_counter() - t0
    if diagnose:
        result = diagnose_fit(model, measurement, result)
        result.seconds = time.perf_counter() - t0
        _warn_untrustworthy(result, "fit_nlopt")
    return result


def _local_fits(model: ForwardModel, measurement: Any, starts: Sequence[np.ndarray], algo: str, ftol: float,
                xtol: np.ndarray, maxeval: int, step: np.ndarray) -> FitResult:
    """nlopt from every start; the best optimum, with every start's (module docstring)."""
    import nlopt

    code = getattr(nlopt, {"BOBYQA": "LN_BOBYQA", "NELDERMEAD": "LN_NELDERMEAD", "COBYLA": "LN_COBYLA"}[algo])
    n_eval = 0
    results = []
    best: tuple[float, np.ndarray, int] | None = None
    for start in starts:
        state: dict[str, Any] = {"best": -np.inf, "x": np.array(start, dtype=np.float64), "n": 0}

        def objective(x: np.ndarray, grad: np.ndarray) -> float:
            ll = model.log_likelihood(np.array(x, dtype=np.float64), measurement)
            state["n"] += 1
            if ll > state["best"]:
                state["best"], state["x"] = ll, np.array(x, dtype=np.float64)
            return float(ll) if math.isfinite(ll) else -1e30

        opt = nlopt.opt(code, model.ndim)
        opt.set_lower_bounds(model.lower.tolist())
        opt.set_upper_bounds(model.upper.tolist())
        opt.set_max_objective(objective)
        opt.set_ftol_abs(ftol)
        opt.set_xtol_abs(np.asarray(xtol, float).tolist())
        opt.set_maxeval(int(maxeval))
        opt.set_initial_step(np.asarray(step, float).tolist())
        try:
            opt.optimize(np.asarray(start, float).tolist())
            rc = int(opt.last_optimize_result())
        except nlopt.RoundoffLimited:
            rc = -4
        except (RuntimeError, ValueError) as e:  # nlopt failure: keep the best point seen
            rc = -1
            if state["n"] == 0:
                raise Error(f"nlopt failed before any evaluation: {e}") from None
        n_eval += state["n"]
        results.append((np.asarray(start, float), state["x"], float(state["best"])))
        if best is None or state["best"] > best[0]:
            best = (float(state["best"]), state["x"], rc)
    assert best is not None
    if not math.isfinite(best[0]):
        raise Error(
            f"the fit found nothing: the log-likelihood is -inf at every one of the {n_eval} points tried "
            f"({len(starts)} start(s) from {np.asarray(starts[0]).tolist()}), so there is nothing to maximize and the "
            "start is not an estimate. Usually the counts are impossible under the model: counts recorded in bins "
            "where it expects none (zero expected counts and no background; check that bin_edges cover "
            "the target's range window and that the instrument's background_rate is right), or no "
            "material can be built within the bounds"
        )
    return FitResult(
        x=best[1],
        log_likelihood=best[0],
        n_evaluations=n_eval,
        names=model.names,
        algorithm=algo,
        return_code=best[2],
        message=_NLOPT_MESSAGES.get(best[2], "unknown"),
        seconds=0.0,
        starts=results,
    )


def _unit_sobol(n: int, d: int, seed: int) -> np.ndarray:
    from scipy.stats import qmc

    return qmc.Sobol(d, scramble=True, seed=seed).random(n)


def _global_points(model: ForwardModel, n: int, seed: int) -> np.ndarray:
    """``n`` points spread over the bounds: an SO(3) grid for a free rotation (all three of
    ``rx, ry, rz``), scrambled Sobol' points otherwise (and for the other parameters)."""
    from . import so3

    width = model.upper - model.lower
    pts = model.lower + width * _unit_sobol(n, model.ndim, seed)
    rot = [model.names.index(p) for p in ("rx", "ry", "rz") if p in model.names]
    if len(rot) == 3:
        # many more grid rotations than points: keep those inside the bounds
        for m in (n, 4 * n, 16 * n, 64 * n):
            q = so3.grid(m)
            R = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
            ref = model.reference_attitude
            E = ref.T @ R if model.attitude_frame == "body" else R @ ref.T
            r = _frame_parameters(E, model.attitude_frame)
            ok = np.all((r >= model.lower[rot]) & (r <= model.upper[rot]), axis=1)
            if ok.sum() >= n:
                pick = np.flatnonzero(ok)
                pick = pick[np.linspace(0, len(pick) - 1, n).round().astype(int)]
                pts[:, rot] = r[pick]
                break
    return pts


def _mirror_starts(model: ForwardModel, x: np.ndarray) -> np.ndarray:
    """(47, ndim) starts seeing the body from its line of sight at ``x`` mapped by the
    other signed permutations of the body axes (:func:`maximum_likelihood`, step 3)."""
    import itertools

    d = model.rotations(x)[0][2]  # R^T Z: the line of sight in the body frame
    z = np.array([[0.0, 0.0, 1.0]])
    mats = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            if perm == (0, 1, 2) and signs == (1.0, 1.0, 1.0):
                continue
            dm = np.asarray(signs) * d[list(perm)]
            C, _ = Rotation.align_vectors(z, dm[None])  # C dm = Z: seen from dm
            mats.append(C.as_matrix())
    return attitude_starts(model, np.array(mats), x0=x)


def attitude_starts(model: ForwardModel, attitudes: Any, x0: Any = None) -> np.ndarray:
    """Start points (n, ndim) of ``model`` at given attitudes.

    E.g. a classifier's best candidates (``Classifier.top_k(data, k).attitude[0]``).

    The rotation vector is ``log(R R_ref^T)`` (``attitude_frame="telescope"``),
    ``log(R_ref^T R)`` (``"body"``) or the swing and twist of ``R R_ref^T`` (``"roll"``);
    its free components are kept (fixed ones stay fixed,
    so an attitude is projected onto the free ones), clipped into the bounds. The other
    free parameters take ``x0``'s values, or the middle of their bounds.

    Parameters
    ----------
    model : ForwardModel
        The forward model.
    attitudes : array_like or scipy.spatial.transform.Rotation
        (n, 4) quaternions ``(w, x, y, z)``, (n, 3, 3) matrices or a Rotation (body to
        telescope, as :func:`pprender.render`).
    x0 : array_like, optional
        (ndim,) values of the other free parameters.

    Returns
    -------
    numpy.ndarray
        (n, ndim) start points within the bounds.

    Raises
    ------
    pprender.Error
        For attitudes that are not rotations, or an ``x0`` of the wrong shape or outside
        the bounds.
    """
    R = _attitude_matrices(attitudes, "attitudes").reshape(-1, 3, 3)
    ref = model.reference_attitude
    E = ref.T @ R if model.attitude_frame == "body" else R @ ref.T
    r = _frame_parameters(E, model.attitude_frame)
    base = 0.5 * (model.lower + model.upper) if x0 is None else _x0(model, x0)
    pts = np.repeat(base[None], len(R), axis=0)
    for j, p in enumerate(("rx", "ry", "rz")):
        if p in model.names:
            pts[:, model.names.index(p)] = r[:, j]
    return np.clip(pts, model.lower, model.upper)


def maximum_likelihood(
    model: ForwardModel,
    measurement: Any,
    x0: Any = None,
    *,
    starts: Any = None,
    n_global: int | None = None,
    n_local: int = 8,
    algorithm: str = "BOBYQA",
    maxeval: int = 2000,
    ftol_abs: float = 1e-6,
    seed: int = 0,
    diagnose: bool = True,
    n_mirror: int = 8,
) -> FitResult:
    """The robust maximum-likelihood fit: a global stage, local fits, a diagnosis.

    1. **Global stage.** The log-likelihood is evaluated, in batches (one render call per
       batch), at ``x0`` (if given), at every point of ``starts`` (e.g. a classifier's best
       candidates through :func:`attitude_starts`) and at ``n_global`` points spread over
       the bounds (an SO(3) grid when ``rx, ry, rz`` are all free, scrambled Sobol' points
       otherwise, seeded with ``seed``; with the model's ``alpha_step``, their ``alpha`` on
       every 8th node, where no interpolation is needed).
    2. **Local stage.** :func:`fit_nlopt`'s optimizer from the ``n_local`` best of them that
       lie apart (more than the global points' spacing), with an initial step of half that
       spacing, plus ``x0`` and every ``starts`` point; the best optimum wins.
    3. **Mirror views** (with ``rx`` and ``ry`` free): a body symmetric about planes
       through its axes (as :mod:`pprender.models` builds satellites) gives the same
       profile seen from the directions its line of sight takes under those symmetries,
       and the search above often finds only one of them (docs/fit-recovery.md: a fit
       that found the mirror view alone, 182 sd from the truth, and called itself
       trustworthy). The line of sight in the body frame at the best optimum, ``d``, is
       mapped by the 47 other signed permutations of its components; the attitudes that
       see the body from there (other parameters as at the optimum, rotations projected
       onto the free ones by :func:`attitude_starts`) are evaluated in one batch, and local
       fits run from the ``n_mirror`` best that lie apart. Their optima join the others:
       those as likely as the best are reported as ``alternatives``.
    4. **Diagnosis** (:func:`diagnose_fit`): Cramer-Rao uncertainties, the curvature of
       ``log L`` against the Fisher information, convergence, goodness of fit and the
       agreement of the local starts; a :class:`FitWarning` when it finds problems.

    The likelihood is continuous in the attitude with the model's default settings
    (:class:`ForwardModel`, analytic coverage): local optimizers then converge from
    anywhere in the basin of the maximum.

    Parameters
    ----------
    model : ForwardModel
        The forward model.
    measurement : Measurement or array_like
        The data: a :class:`Measurement` or counts (B, C).
    x0 : array_like, optional
        (ndim,) a first guess, inside the bounds.
    starts : array_like, optional
        (n, ndim) further candidate starts inside the bounds.
    n_global : int, optional
        Points of the global stage, an integer in [0, 100000] (default ``128 * ndim``; 0
        skips it, then ``x0`` or ``starts`` are needed).
    n_local : int, optional
        Local fits from the global stage's best points, in [1, 64]. Default 8: PPR
        likelihoods often have several optima nearly as likely (docs/fit-recovery.md: with
        4 local fits from 192 points, 2 of 3 truths' modes were never visited).
    algorithm : {"BOBYQA", "NELDERMEAD", "COBYLA"}, optional
        The local optimizer (:func:`fit_nlopt`). Default ``"BOBYQA"``.
    maxeval : int, optional
        Likelihood evaluations per local fit, >= 1. Default 2000.
    ftol_abs : float, optional
        Local fits stop when ``log L`` changes by less (default 1e-6).
    seed : int, optional
        Seed of the global points and of the diagnosis' draws, >= 0. Default 0.
    diagnose : bool, optional
        Run the diagnosis (default True).
    n_mirror : int, optional
        Local fits from the best optimum's mirror views (step 3), in [0, 47]; default 8, 0
        skips them.

    Returns
    -------
    FitResult
        The best optimum, every local start in ``starts``, and the diagnosis
        (``trustworthy``, ``problems``, ``sd``).

    Raises
    ------
    pprender.Error
        For bad arguments, and when the log-likelihood is ``-inf`` everywhere tried.

    Warns
    -----
    FitWarning
        When the diagnosis finds problems.
    """
    if not isinstance(model, ForwardModel):
        raise Error(f"invalid model of type {type(model).__name__}: expected ForwardModel")
    algo = _algorithm(algorithm)
    model._counts(measurement)
    d = model.ndim
    n_glob = 128 * d if n_global is None else n_global
    for name, v, lo, hi in (("n_global", n_glob, 0, 100_000), ("n_local", n_local, 1, 64), ("n_mirror", n_mirror, 0, 47),
                            ("maxeval", maxeval, 1, 10**9), ("seed", seed, 0, 2**63 - 1)):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
            raise Error(f"invalid {name} = {v!r}: an integer in [{lo}, {hi}]")
    ftol = _check_number("ftol_abs", ftol_abs, 0.0, math.inf, False, True, "log-likelihood units")
    given: list[np.ndarray] = []
    if x0 is not None:
        given.append(_x0(model, x0))
    if starts is not None:
        st = _numeric_array(starts, "starts", f"start points (n, {d}) for {model.names}")
        st = np.atleast_2d(st)
        if st.ndim != 2 or st.shape[1] != d:
            raise Error(f"invalid starts: shape {np.shape(starts)}, expected (n, {d}) for {model.names}")
        bad = ~np.all(np.isfinite(st) & (st >= model.lower) & (st <= model.upper), axis=1)
        if np.any(bad):
            raise Error(f"invalid starts: rows {np.flatnonzero(bad)[:10].tolist()} lie outside the bounds {model.bounds.tolist()}")
        given += list(st)
    if n_glob == 0 and not given:
        raise Error("invalid n_global = 0 without x0 or starts: nothing to start from")
    t0 = time.perf_counter()
    width = model.upper - model.lower
    spacing = width * max(n_glob, 1) ** (-1.0 / d)
    local: list[np.ndarray] = list(given)
    n_eval = 0
    if n_glob > 0:
        pts = _global_points(model, n_glob, seed)
        if model.alpha_step is not None:
            # the global stage's alphas on every 8th node: one render and few materials each
            ia = model.names.index("alpha")
            coarse = 8 * model.alpha_step
            lo, hi = model.lower[ia], model.upper[ia]
            k = np.round(np.log(pts[:, ia]) / coarse)
            k = np.clip(k, np.ceil(np.log(lo) / coarse - 1e-9), np.floor(np.log(hi) / coarse + 1e-9))
            snapped = np.exp(k * coarse)
            pts[:, ia] = np.where((snapped >= lo) & (snapped <= hi), snapped, pts[:, ia])
        ll = np.concatenate([model.log_likelihood(pts[i:i + 256], measurement) for i in range(0, len(pts), 256)])
        n_eval += len(pts)
        order = np.argsort(-ll)
        chosen: list[np.ndarray] = []
        for i in order:
            if not math.isfinite(ll[i]) or len(chosen) >= n_local:
                break
            if all(np.max(np.abs(pts[i] - c) / spacing) > 1.0 for c in chosen):
                chosen.append(pts[i])
        local += chosen
    step = 0.5 * spacing if n_glob > 0 else 0.05 * width
    result = _local_fits(model, measurement, local, algo, ftol, 1e-8 * width, int(maxeval), step)
    result.n_evaluations += n_eval
    if n_mirror > 0 and "rx" in model.names and "ry" in model.names:
        views = _mirror_starts(model, result.x)
        ll = model.log_likelihood(views, measurement)
        result.n_evaluations += len(views)
        chosen = []
        for i in np.argsort(-ll):
            if not math.isfinite(ll[i]) or len(chosen) >= n_mirror:
                break
            if all(np.max(np.abs(views[i] - c) / spacing) > 0.5 for c in chosen + [result.x]):
                chosen.append(views[i])
        if chosen:
            more = _local_fits(model, measurement, chosen, algo, ftol, 1e-8 * width, int(maxeval), step)
            result.n_evaluations += more.n_evaluations
            result.starts = list(result.starts) + list(more.starts)
            if more.log_likelihood > result.log_likelihood:
                result.x, result.log_likelihood = more.x, more.log_likelihood
                result.return_code, result.message = more.return_code, more.message
    result.seconds = time.perf_counter() - t0
    if diagnose:
        result = diagnose_fit(model, measurement, result, seed=seed)
        result.seconds = time.perf_counter() - t0
        _warn_untrustworthy(result, "maximum_likelihood")
    return result


# ---------------------------------------------------------------------- emcee


@dataclass
class ChainSummary:
    """An emcee chain's estimates and whether they can be trusted (:func:`chain_summary`).

    Attributes
    ----------
    names : tuple of str
        The parameters.
    mean, sd, median : numpy.ndarray
        (ndim,) posterior mean, standard deviation and median of the kept samples.
    tau : numpy.ndarray
        (ndim,) integrated autocorrelation times (steps), emcee's estimate.
    acceptance : float
        Mean acceptance fraction over the walkers.
    n_steps, discard : int
        Steps run, and steps discarded as burn-in.
    n_effective : float
        Independent samples, about ``walkers * (n_steps - discard) / max(tau)``.
    problems : list of str
        Why the estimates should not be trusted (empty when none was found).
    """

    names: tuple[str, ...]
    mean: np.ndarray
    sd: np.ndarray
    median: np.ndarray
    tau: np.ndarray
    acceptance: float
    n_steps: int
    discard: int
    n_effective: float
    problems: list[str] = field(default_factory=list)

    @property
    def converged(self) -> bool:
        """No problems found."""
        return not self.problems


#: A chain is long enough when it spans this many autocorrelation times (emcee's advice).
TAU_MULTIPLE = 50
#: Mean acceptance fractions outside this range mean a badly tuned ensemble (the stretch
#: move accepts about 0.7 of its proposals on a 2D Gaussian, less in more dimensions;
#: below 0.15 walkers are stuck or the posterior is multimodal).
ACCEPTANCE_RANGE = (0.15, 0.9)


def chain_summary(sampler: Any, names: Sequence[str] | None = None, discard: int | None = None) -> ChainSummary:
    """Posterior estimates of an emcee sampler (:func:`sample_emcee`) and its diagnosis.

    Problems reported: a chain shorter than :data:`TAU_MULTIPLE` autocorrelation times
    (its estimates, the sd most of all, are then unreliable), a mean acceptance fraction
    outside :data:`ACCEPTANCE_RANGE`, and stuck walkers (acceptance below 0.02).

    Parameters
    ----------
    sampler : emcee.EnsembleSampler
        The sampler after its run.
    names : sequence of str, optional
        Parameter names (default ``p0, p1, ...``).
    discard : int, optional
        Burn-in steps dropped, in [0, n_steps) (default ``3 * max(tau)`` of the whole chain,
        at most half of it).

    Returns
    -------
    ChainSummary
        Estimates, autocorrelation times, acceptance and problems.

    Raises
    ------
    pprender.Error
        For a sampler without steps, or a ``discard`` out of range.
    """
    import emcee

    chain = np.asarray(sampler.get_chain())
    if chain.ndim != 3 or chain.shape[0] < 1:
        raise Error("invalid sampler: it has run no steps")
    n_steps, n_walkers, d = chain.shape
    names_t = tuple(names) if names is not None else tuple(f"p{i}" for i in range(d))
    if len(names_t) != d:
        raise Error(f"invalid names: {len(names_t)} names for {d} parameters")
    with np.errstate(invalid="ignore", divide="ignore"):
        tau_all = emcee.autocorr.integrated_time(chain, tol=0, quiet=True)
    t_all = float(np.max(tau_all)) if np.all(np.isfinite(tau_all)) else math.inf
    if discard is None:
        disc = int(min(n_steps // 2, math.ceil(3 * t_all))) if math.isfinite(t_all) else n_steps // 2
    else:
        if isinstance(discard, (bool, np.bool_)) or not isinstance(discard, (int, np.integer)) or not 0 <= discard < n_steps:
            raise Error(f"invalid discard = {discard!r}: an integer in [0, {n_steps})")
        disc = int(discard)
    kept = chain[disc:]
    with np.errstate(invalid="ignore", divide="ignore"):
        tau = emcee.autocorr.integrated_time(kept, tol=0, quiet=True) if len(kept) > 1 else tau_all
    flat = kept.reshape(-1, d)
    acc = np.asarray(sampler.acceptance_fraction)
    problems = []
    tmax = float(np.max(tau)) if np.all(np.isfinite(tau)) else math.inf
    if not math.isfinite(tmax):
        problems.append("the autocorrelation time cannot be estimated (a parameter never moved): run longer")
    elif n_steps < TAU_MULTIPLE * tmax:
        problems.append(
            f"the chain is short: {n_steps} steps for autocorrelation times up to {tmax:.1f} steps (at least "
            f"{TAU_MULTIPLE} x that are needed; tau itself is then underestimated): run longer"
        )
    if not ACCEPTANCE_RANGE[0] <= acc.mean() <= ACCEPTANCE_RANGE[1]:
        problems.append(f"mean acceptance {acc.mean():.2f} outside {ACCEPTANCE_RANGE}: the ensemble is badly tuned")
    stuck = int(np.sum(acc < 0.02))
    if stuck:
        problems.append(f"{stuck} of {n_walkers} walkers accepted under 2% of their moves (stuck)")
    return ChainSummary(
        names=names_t, mean=flat.mean(axis=0), sd=flat.std(axis=0, ddof=1) if len(flat) > 1 else np.full(d, np.nan),
        median=np.median(flat, axis=0), tau=np.asarray(tau, dtype=np.float64), acceptance=float(acc.mean()),
        n_steps=int(n_steps), discard=disc,
        n_effective=float(n_walkers * (n_steps - disc) / max(tmax, 1.0)) if math.isfinite(tmax) else 0.0,
        problems=problems,
    )


def sample_emcee(
    model: ForwardModel,
    measurement: Any,
    x0: Any,
    n_walkers: int,
    n_steps: int,
    seed: int,
    *,
    spread: Any = 1e-3,
    progress: bool = False,
    moves: Any = None,
    check: bool = True,
) -> Any:
    """Sample the posterior (:meth:`ForwardModel.log_prob`) with ``emcee``.

    Walkers start at ``x0 + spread * (bound width) * N(0, 1)`` (clipped into the bounds),
    drawn with ``numpy.random.default_rng(seed)``; emcee's own generator is seeded with
    ``numpy.random.RandomState(seed)``, so equal seeds give equal chains. The sampler uses
    ``vectorize=True``: each call renders a whole set of walkers (:class:`ForwardModel`).

    Parameters
    ----------
    model : ForwardModel
        The forward model.
    measurement : Measurement or array_like
        The data: a :class:`Measurement` or counts (B, C).
    x0 : array_like
        (ndim,) centre of the initial walkers, inside the bounds.
    n_walkers : int
        Number of walkers, at least ``2 * ndim``.
    n_steps : int
        Number of steps, >= 1.
    seed : int
        Seed of both generators, in [0, 2**32).
    spread : float or array_like, optional
        Initial spread in units of the bound widths, one value or (ndim,), positive. Default
        1e-3.
    progress : bool, optional
        Show emcee's progress bar. Default False.
    moves : object, optional
        Passed to :class:`emcee.EnsembleSampler` (default None: emcee's default).
    check : bool, optional
        After the run, diagnose the chain (:func:`chain_summary`) and warn
        (:class:`FitWarning`) when it is too short for its autocorrelation time or its
        acceptance is off. Default True.

    Returns
    -------
    emcee.EnsembleSampler
        The sampler after ``n_steps`` steps (chains via ``get_chain(discard=..., flat=True)``).

    Warns
    -----
    FitWarning
        With ``check``, for a chain too short or badly tuned (:func:`chain_summary`).

    Raises
    ------
    pprender.Error
        For bad arguments, and where an initial walker does not have a finite log posterior:
        where the log-likelihood is ``-inf`` (counts where the model expects none, no
        material), saying for how many walkers; emcee would otherwise keep them stuck.
    """
    import emcee

    if not isinstance(model, ForwardModel):
        raise Error(f"invalid model of type {type(model).__name__}: expected ForwardModel")
    x0 = _x0(model, x0)
    if not isinstance(n_walkers, (int, np.integer)) or n_walkers < 2 * model.ndim:
        raise Error(f"invalid n_walkers = {n_walkers!r}: an integer >= 2 * ndim = {2 * model.ndim}")
    if not isinstance(n_steps, (int, np.integer)) or n_steps < 1:
        raise Error(f"invalid n_steps = {n_steps!r}: an integer >= 1")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise Error(f"invalid seed = {seed!r}: an integer in [0, 2**32)")
    sp = _per_parameter(spread, "spread", model)
    if not np.all(np.isfinite(sp) & (sp > 0)):
        raise Error(f"invalid spread = {spread!r}: positive, finite")
    model._counts(measurement)
    rng = np.random.default_rng(seed)
    width = model.upper - model.lower
    p0 = x0 + sp * width * rng.standard_normal((int(n_walkers), model.ndim))
    p0 = np.clip(p0, model.lower + 1e-12 * width, model.upper - 1e-12 * width)
    lp0 = model.log_prob(p0, measurement)
    bad = ~np.isfinite(lp0)
    if np.all(bad):
        raise Error(
            f"invalid x0 = {x0.tolist()}: the log-likelihood is -inf at every one of the {int(n_walkers)} "
            "initial walkers around it: the counts are impossible under the model there (counts recorded in "
            "bins where it expects none, with no background: check bin_edges cover the target's range "
            "window and the instrument's background_rate; or no material can be built at x0)"
        )
    if np.any(bad):
        raise Error(
            f"invalid x0 = {x0.tolist()}: the log-likelihood is -inf at {int(np.sum(bad))} of the "
            f"{int(n_walkers)} initial walkers (spread {sp.tolist()} of the bound widths around x0 reaches "
            "parameters where the counts are impossible or no material can be built); start elsewhere or "
            "reduce spread"
        )
    sampler = emcee.EnsembleSampler(int(n_walkers), model.ndim, model.log_prob, args=(measurement,),
                                    vectorize=True, moves=moves)
    state = emcee.State(p0, log_prob=lp0, random_state=np.random.RandomState(int(seed)).get_state())
    sampler.run_mcmc(state, int(n_steps), progress=progress)
    if check:
        summary = chain_summary(sampler, model.names)
        if summary.problems:
            warnings.warn("sample_emcee: " + "; ".join(summary.problems), FitWarning, stacklevel=2)
    return sampler
