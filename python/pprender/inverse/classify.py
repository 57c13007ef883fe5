"""Vector classification of measured PPR profiles against a candidate database.

Conventions (every function and class in this module):

* A profile is a ``(B, C)`` array: ``B`` range bins on the database's common range grid
  (:mod:`pprender.database`), ``C`` channels. Its feature vector is the profile
  flattened bin-major, ``f[b * C + c] = profile[b, c]``, of length ``F = B C``.
* Channels come from a *projection* of the database's Mueller profiles
  ``(..., B, 4, 4) -> (..., B, C)`` (:func:`stokes_projection`,
  :func:`co_cross_projection`, :func:`mueller_projection`), or are the stored Stokes
  profiles of a database rendered with a transmitted polarization. Measurements are
  given as ``(B, C)`` or ``(M, B, C)`` in the same channels (apply
  ``classifier.projection`` to simulated Mueller profiles).
* Score of a measurement ``x`` against a candidate ``y`` with a weight matrix ``W``:
  ``s = <W x, W y> / (|W x| |W y|)`` in ``[-1, 1]``, 1 exactly when ``W x`` is a positive
  multiple of ``W y``: insensitive to the overall intensity (range, aperture, gain).
  A candidate with ``W y = 0`` scores 0.
* Nothing is scored against nothing (:class:`pprender.Error` instead): a measurement
  must have at least one positive value (counts cannot be negative: one that is all
  zero, or zero and negative everywhere, e.g. a background-subtracted measurement with
  no signal, has nothing to classify) and must not vanish under the weights
  (``W x_o = 0`` at every range offset); and the candidates must not all vanish
  (``W y = 0`` for every candidate). Channels are therefore intensities or include one
  (``I`` of the Stokes channels, ``M00`` of the Mueller ones).
* No match is not a match: :meth:`Classifier.top_k` warns (:class:`NoMatchWarning`)
  for measurements whose best score is at most ``1e-9`` (zero up to rounding, or
  negative: not even positively correlated with any candidate), and
  :attr:`Matches.matched` is False for them; their "best" candidates are arbitrary.
* Range offsets: measurements are not registered in absolute range. The score is the
  maximum over integer offsets ``|o| <= max_shift`` of the score of ``x_o[b] = x[b + o]``
  (zero beyond the ends). ``o > 0`` means the measurement lies ``o`` bins farther in range
  than the candidate. Ties go to the smallest ``|o|`` (then the negative one).
* Weights ``W`` (``F' x F``), learned from the candidates with labels of a ``target``
  (``"shape"``, ``"material"`` or ``"attitude"``) and from the measurements' count level;
  candidates are first scaled to unit norm (the score ignores intensity), and covariances
  are of these unit vectors:

  - ``None``: ``W = I``, the plain cosine similarity (the default). On held-out
    measurements (``docs/classifier-weights.md``) ``"whiten"`` given the measurements'
    ``counts`` was never worse than it by more than one standard error and at best 0.01
    better; where the count level is unknown, keep ``None``.
  - ``"whiten"``: ``W = (S_r + (tau + lambda) I)^(-1/2)``, the inverse square root of the
    covariance of what a nearest-candidate search leaves unexplained:

    * ``S_r``, the spread of a candidate about its nearest neighbour of the same target
      class: half the mean ``R`` of ``r r^T`` over the residuals ``r = y_k - y_j`` of each
      candidate ``k`` to the candidate ``j != k`` of its class with the highest cosine
      (from at most 2048 candidates ``k``, evenly spaced in index; classes of one candidate
      have none), shrunk toward ``(trace(R) / F) I`` with Ledoit and Wolf's weight (2004,
      J. Multivar. Anal. 88, 365: estimated from the residuals themselves, large when they
      are few against ``F``). Variation between classes, and variation along the candidate
      grid that the search resolves (attitude), is not in it;
    * ``tau``, the Poisson noise of a measurement with ``counts`` expected signal and
      ``background`` expected background counts (:class:`Classifier`), per unit-norm
      feature: ``tau = 1 / counts + (background / F) * mean_k (sum_f |y_kf|)^2 / counts^2``.
      A unit-norm profile ``u`` measured with ``N`` signal counts has variance ``u_f / a``
      in feature ``f`` (``a = N / sum_f u_f`` the counts per unit norm), ``1 / N`` on average
      over its effective support of ``(sum_f u_f)^2`` features, plus the background's
      ``b_f / a^2``; ``tau`` takes that as the same in every direction. It assumes the
      channels are counted intensities (co/cross, analyzer channels);
    * ``lambda = regularization * trace(S_r) / F``, a small ridge (``trace(S_r)`` replaced by
      ``F tau``, or by ``F``, where it is 0).

    Directions in which a measurement varies more than the noise, beyond the nearest
    candidate (nuisance: for ``target="material"``, shape and attitude detail finer than
    the grid), are damped; no direction is weighted more than ``1 / sqrt(tau)``, so with few
    counts ``W`` tends to a multiple of ``I`` (plain cosine).

    Changed in issue 25: ``"whiten"`` was ``(S_w + lambda I)^(-1/2)`` (``S_w`` as for
    ``"lda"`` below) with no noise. ``S_w`` holds the attitude variation of a class, which
    the search over the grid resolves, and it is nearly singular (rank 192 of 528 features
    with 256 candidates); the small ridge left most directions, where the candidates of a
    class do not vary but measurements and their noise do, weighted most. At 3000 counts
    the margin of the right material over the best wrong one fell from 7.0 to 0.75 noise
    standard deviations, and on held-out measurements it lost up to 0.45 of the accuracy
    to ``None`` (``docs/classifier-weights.md``).
  - ``"lda"``: Fisher discriminant weighting, for classes that are clusters about their
    means. ``W0 = (S_w + (tau + lambda) I)^(-1/2)`` with ``S_w`` the pooled within-class
    covariance (scatter of candidates about the mean of their target class, divided by
    ``K - n_classes``), ``tau`` as above and ``lambda = regularization * trace(S_w) / F``.
    In the space of ``W0``, the between-class covariance ``S_b`` (class means about the
    overall mean, weighted by class size) becomes ``W0 S_b W0 = V diag(mu) V^T`` with
    ``mu`` the Fisher ratios (between- over within-class variance) of the directions
    ``V``; ``W = diag(sqrt(1 + mu)) V^T W0`` keeps every direction but stretches the
    discriminant ones. With ``n_components`` only the top ``n_components`` directions are
    kept (classical LDA, at most ``n_classes - 1`` informative ones; with few of them many
    candidates tie). On a candidate grid (attitudes) ``S_w`` holds variation the search
    resolves, as the old ``"whiten"`` did, and with few counts ``"lda"`` does worse than
    ``None`` (``docs/classifier-weights.md``); issue 25 added ``tau`` to it.
  - an array: ``(C,)`` per-channel or ``(B, C)`` per-feature weights (a diagonal ``W``),
    or a matrix ``(F', F)``.

  Learned weights without ``counts`` assume noise-free measurements (``tau = 0``) and warn
  (:class:`NoiseFreeWeightsWarning`): give ``counts`` (``math.inf`` for truly noise-free
  data). They need ``F <= 4096`` (an ``F x F`` eigen-decomposition); use a projection
  with fewer channels otherwise.
* Numbers are numbers: text, None or complex values in candidates, measurements,
  weights or numeric parameters raise :class:`pprender.Error` naming the parameter.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from .._core import Error
from .instrument import _numeric_array

__all__ = [
    "Classifier",
    "Matches",
    "NoMatchWarning",
    "NoiseFreeWeightsWarning",
    "Projection",
    "co_cross_projection",
    "mueller_projection",
    "stokes_projection",
]

_TARGETS = ("shape", "material", "attitude")
_MAX_LEARNED_FEATURES = 4096
#: Best scores at or below this are no match (module docstring).
_NO_MATCH_SCORE = 1e-9
#: Most candidates whose nearest-neighbour residuals estimate ``S_r`` (module docstring).
_MAX_RESIDUALS = 2048


class NoMatchWarning(UserWarning):
    """:meth:`Classifier.top_k`: some measurement matches no candidate (best score ``<= 1e-9``).

    See :attr:`Matches.matched`.
    """


class NoiseFreeWeightsWarning(UserWarning):
    """:class:`Classifier`: learned weights (``"whiten"``, ``"lda"``) built without ``counts``.

    They then assume noise-free measurements and, at a finite count level, can do far
    worse than no weights (module docstring, ``docs/classifier-weights.md``). Pass the
    measurements' expected signal counts as ``counts`` (``math.inf`` for noise-free data).
    """


# --------------------------------------------------------------------------- projections


@dataclasses.dataclass(frozen=True)
class Projection:
    """A map from Mueller profiles ``(..., B, 4, 4)`` to channels ``(..., B, C)``.

    Applied with ``projection(mueller)``, which raises :class:`pprender.Error` for an array
    that is not ``(..., B, 4, 4)``.

    Parameters
    ----------
    fn : callable
        The map, applied to a float64 array ``(..., B, 4, 4)``.
    channels : tuple of str
        The channels' names.
    description : str
        What the projection is (shown in error messages).
    """

    fn: Callable[[np.ndarray], np.ndarray]
    channels: tuple[str, ...]
    description: str

    def __call__(self, mueller: Any) -> np.ndarray:
        m = np.asarray(mueller, dtype=np.float64)
        if m.ndim < 3 or m.shape[-2:] != (4, 4):
            raise Error(f"invalid profile for projection {self.description!r}: shape {m.shape}, expected (..., B, 4, 4)")
        return self.fn(m)


def stokes_projection(stokes_in: Sequence[float]) -> Projection:
    """Received Stokes profiles for a transmitted Stokes vector ``stokes_in``.

    ``S[..., b, :] = M[..., b, :, :] @ stokes_in``, channels ``I Q U V`` in the receiver
    basis: what :func:`pprender.render` returns with ``Lidar(polarization=stokes_in)``.

    Parameters
    ----------
    stokes_in : sequence of float
        The transmitted Stokes vector (4,), finite, in the transmit basis
        (:mod:`pprender.lidar`).

    Returns
    -------
    Projection
        Channels ``("I", "Q", "U", "V")``.

    Raises
    ------
    pprender.Error
        For a ``stokes_in`` that is not a finite vector (4,).
    """
    s = _numeric_array(stokes_in, "stokes_in", "a Stokes vector (4,)")
    if s.shape != (4,) or not np.all(np.isfinite(s)):
        raise Error(f"invalid stokes_in = {stokes_in!r}: a finite Stokes vector (4,)")
    return Projection(lambda m: m @ s, ("I", "Q", "U", "V"), f"stokes({s.tolist()})")


def co_cross_projection(angle: float = 0.0) -> Projection:
    """Co- and cross-polarized received intensities for linear transmission at ``angle``.

    The transmitted state is ``s = (1, cos 2a, sin 2a, 0)``. The transmit basis is
    ``(x, y) = (X, -Y)`` monostatically (in general ``y = -Y`` and ``x`` tilted in the ``XZ``
    plane; :mod:`pprender.lidar`), so the same physical polarization is at ``-a`` in the
    receiver basis ``(X, Y)``: ``co = (S0 + cos 2a S1 - sin 2a S2) / 2`` and
    ``cross = (S0 - cos 2a S1 + sin 2a S2) / 2`` with ``S = M s``. A mirror facing the sensor
    (``diag(1, 1, -1, -1)``) gives ``co = 1``, ``cross = 0`` at every angle.

    Parameters
    ----------
    angle : float, optional
        Angle ``a`` (rad) of the transmitted linear polarization from the transmit basis'
        ``x`` axis, finite. Default 0.

    Returns
    -------
    Projection
        Channels ``("co", "cross")``.

    Raises
    ------
    pprender.Error
        For a non-finite ``angle``.
    """
    if not (isinstance(angle, (int, float, np.floating)) and np.isfinite(angle)):
        raise Error(f"invalid angle = {angle!r}: a finite angle in radians")
    c, s = np.cos(2.0 * angle), np.sin(2.0 * angle)
    s_in = np.array([1.0, c, s, 0.0])
    analyzers = 0.5 * np.array([[1.0, c, -s, 0.0], [1.0, -c, s, 0.0]])  # (2, 4)
    return Projection(lambda m: (m @ s_in) @ analyzers.T, ("co", "cross"), f"co_cross(angle={float(angle)})")


def mueller_projection() -> Projection:
    """All 16 Mueller elements as channels (a full Mueller polarimeter).

    Returns
    -------
    Projection
        ``M_ij`` at channel ``4 i + j``, named ``"Mij"``.
    """
    names = tuple(f"M{i}{j}" for i in range(4) for j in range(4))
    return Projection(lambda m: m.reshape(m.shape[:-2] + (16,)), names, "mueller")


# --------------------------------------------------------------------------- results


@dataclasses.dataclass
class Matches:
    """The best ``k`` candidates per measurement (best first), arrays of shape (M, k).

    Made by :meth:`Classifier.top_k`. Label arrays are None when the classifier has no such
    labels.

    Attributes
    ----------
    index : numpy.ndarray
        (M, k) indices into the classifier's candidates.
    score : numpy.ndarray
        (M, k) scores.
    offset : numpy.ndarray
        (M, k) range offsets of the measurement in bins (module docstring).
    shape : numpy.ndarray or None
        (M, k) the candidates' shape names.
    material : numpy.ndarray or None
        (M, k) the candidates' material names.
    attitude_index : numpy.ndarray or None
        (M, k) the candidates' attitude indices.
    attitude : numpy.ndarray or None
        (M, k, 4) the candidates' attitudes, quaternions.
    matched : numpy.ndarray
        (M,) bool: which measurements match anything at all (best score above ``1e-9``); the
        others' rows are no match (module docstring).
    """

    index: np.ndarray
    score: np.ndarray
    offset: np.ndarray
    shape: np.ndarray | None
    material: np.ndarray | None
    attitude_index: np.ndarray | None
    attitude: np.ndarray | None

    @property
    def matched(self) -> np.ndarray:
        """(M,) bool: whether the best candidate scores above ``1e-9`` (a match at all)."""
        return np.asarray(self.score)[:, 0] > _NO_MATCH_SCORE


# --------------------------------------------------------------------------- classifier


def _finite_array(x: Any, name: str) -> np.ndarray:
    a = _numeric_array(x, name)
    if not np.all(np.isfinite(a)):
        raise Error(f"invalid {name}: NaN or infinite values")
    return a


def _inv_sqrt(s: np.ndarray) -> np.ndarray:
    e, u = np.linalg.eigh(s)
    return (u / np.sqrt(e)) @ u.T


class Classifier:
    """Scores measured profiles against every candidate of a database (module docstring).

    Parameters
    ----------
    candidates : xarray.Dataset or array_like
        A database from :func:`pprender.database.open_database` (every chunk complete;
        candidates ordered shape, material, attitude, i.e. index
        ``(i_shape * n_material + i_material) * n_attitude + i_attitude``), or an array of
        candidate profiles ``(K, B, C)`` (or anything ``projection`` maps to that).
    labels : Mapping[str, array_like], optional
        For array candidates: ``"shape"`` (K,), ``"material"`` (K,), ``"attitude"``
        (K, 4) quaternions, any subset (needed for learned weights' ``target``).
    projection : Projection or callable, optional
        Maps the candidates' profiles to channels. Default: for a database,
        :func:`mueller_projection` (Mueller) or the stored Stokes channels; for arrays,
        none.
    weights : None, "whiten", "lda" or array_like, optional
        The weight matrix ``W`` (module docstring). Default None, the plain cosine. Learned
        weights need ``counts`` (``docs/classifier-weights.md``).
    target : {"shape", "material", "attitude"}, optional
        The label whose classes define learned weights. Default ``"material"``.
    max_shift : int, optional
        Largest range offset searched, in bins (>= 0, below ``B``). Default 0.
    regularization : float, optional
        Relative ridge ``lambda / (trace(S_r) / F)`` for learned weights, > 0 (module
        docstring). Default 1e-2.
    n_components : int, optional
        For ``"lda"``: keep only this many discriminant directions.
    counts : float, optional
        For learned weights: the expected signal counts of a measurement (summed over bins
        and channels), > 0, or ``math.inf`` for noise-free measurements; sets the noise
        variance ``tau`` (module docstring). With measurements at several count levels give
        the lowest: weights made for too many counts amplify noise, weights made for too few
        only tend to the plain cosine. Without it, learned weights assume noise-free
        measurements and warn (:class:`NoiseFreeWeightsWarning`).
    background : float, optional
        For learned weights with ``counts``: the expected background counts of a
        measurement (summed over bins and channels, taken as spread evenly over the ``F``
        features; the expectation is subtracted before scoring, its noise stays), >= 0.
        Default 0.

    Raises
    ------
    pprender.Error
        For an incomplete or empty database, candidates that are all zero or vanish under
        the weights (module docstring), labels with a database, ``n_components`` without
        ``weights="lda"``, ``counts`` or ``background`` without learned weights, or other
        invalid arguments.

    Warns
    -----
    NoiseFreeWeightsWarning
        For learned weights without ``counts``.
    """

    def __init__(
        self,
        candidates: Any,
        *,
        labels: Mapping[str, Any] | None = None,
        projection: Projection | Callable[[np.ndarray], np.ndarray] | None = None,
        weights: Any = None,
        target: str = "material",
        max_shift: int = 0,
        regularization: float = 1e-2,
        n_components: int | None = None,
        counts: float | None = None,
        background: float = 0.0,
    ) -> None:
        self.projection = projection
        self.labels: dict[str, np.ndarray] = {}
        #: (B,) range bin centres (m) for a database, else None.
        self.range: np.ndarray | None = None
        if _is_dataset(candidates):
            if labels is not None:
                raise Error("invalid labels: a database's labels come from its coordinates; pass labels only with arrays")
            feats = self._from_database(candidates, projection)
        else:
            if projection is not None:
                feats = np.asarray(projection(_finite_array(candidates, "candidates")))
            else:
                feats = np.asarray(candidates)
            feats = _finite_array(feats, "candidates")
            self._set_labels(labels, len(feats) if feats.ndim else 0)
        if feats.ndim != 3 or feats.shape[0] == 0 or feats.shape[1] == 0 or feats.shape[2] == 0:
            raise Error(f"invalid candidates: shape {feats.shape}, expected (K, B, C) with K, B, C >= 1 (an empty database?)")
        if not np.any(feats != 0):
            raise Error("invalid candidates: every candidate profile is all zero (nothing to match against)")
        self.features = feats  # (K, B, C)
        K, B, C = feats.shape
        if isinstance(max_shift, (bool, np.bool_)) or not isinstance(max_shift, (int, np.integer)) or not 0 <= max_shift < B:
            raise Error(f"invalid max_shift = {max_shift!r}: an integer in [0, {B - 1}] (bins)")
        self.max_shift = int(max_shift)
        if not (isinstance(regularization, (int, float, np.floating)) and np.isfinite(regularization) and regularization > 0):
            raise Error(f"invalid regularization = {regularization!r}: a positive number")
        if target not in _TARGETS:
            raise Error(f"invalid target = {target!r}: one of {_TARGETS}")
        if n_components is not None and not (isinstance(weights, str) and weights == "lda"):
            raise Error(
                f"invalid n_components = {n_components!r}: it applies only to weights=\"lda\" (weights = {weights!r})"
            )
        learned = isinstance(weights, str) and weights in ("whiten", "lda")
        noise = _noise_level(counts, background, learned, weights)
        self.target = target
        self.weights = self._weights(weights, target, float(regularization), n_components, noise)
        y = self._apply(feats.reshape(K, B * C))
        norm = np.linalg.norm(y, axis=1, keepdims=True)
        if not np.any(norm > 0):
            raise Error(
                "invalid candidates/weights: W y = 0 for every candidate (the weights give zero weight to "
                "everything the candidates contain), so every score would be 0"
            )
        self._y = np.divide(y, norm, out=np.zeros_like(y), where=norm > 0)  # (K, F'), unit rows

    # ------------------------------------------------------------------ construction

    def _from_database(self, ds: Any, projection: Any) -> np.ndarray:
        if "profile" not in ds or "complete" not in ds:
            raise Error("invalid candidates: not a pprender database (no profile/complete variables)")
        if ds.sizes.get("shape", 0) * ds.sizes.get("material", 0) * ds.sizes.get("attitude", 0) == 0:
            raise Error("invalid candidates: the database is empty")
        done = np.asarray(ds["complete"].values, dtype=bool)
        if not done.all():
            raise Error(
                f"invalid candidates: the database is incomplete ({int((~done).sum())} of {done.size} "
                "chunks pending); finish it with build_database or write_chunk"
            )
        stokes = "stokes" in ds["profile"].dims
        if projection is None:
            projection = (lambda p: p) if stokes else mueller_projection()
            self.projection = None if stokes else projection
        elif stokes:
            raise Error("invalid projection: this database stores Stokes profiles (no Mueller matrices to project)")
        n_s, n_m, n_a = ds.sizes["shape"], ds.sizes["material"], ds.sizes["attitude"]
        blocks = []
        for i in range(n_s):
            for j in range(n_m):
                p = np.asarray(ds["profile"].isel(shape=i, material=j).values, dtype=np.float64)
                blocks.append(np.asarray(projection(p), dtype=np.float64))
        feats = np.concatenate(blocks)
        self.labels = {
            "shape": np.repeat(np.asarray(ds["shape"].values, dtype=object), n_m * n_a),
            "material": np.tile(np.repeat(np.asarray(ds["material"].values, dtype=object), n_a), n_s),
            "attitude_index": np.tile(np.arange(n_a), n_s * n_m),
            "attitude": np.tile(np.asarray(ds["quaternion"].values, dtype=np.float64), (n_s * n_m, 1)),
        }
        self.range = np.asarray(ds["range"].values)
        return _finite_array(feats, "database profiles")

    def _set_labels(self, labels: Mapping[str, Any] | None, K: int) -> None:
        if labels is None:
            return
        for key, v in labels.items():
            if key not in ("shape", "material", "attitude"):
                raise Error(f"invalid labels key {key!r}: one of 'shape', 'material', 'attitude'")
            a = np.asarray(v, dtype=np.float64 if key == "attitude" else object)
            want = (K, 4) if key == "attitude" else (K,)
            if a.shape != want:
                raise Error(f"invalid labels[{key!r}]: shape {a.shape}, expected {want}")
            self.labels[key] = a
        if "attitude" in self.labels:
            _, inv = np.unique(self.labels["attitude"], axis=0, return_inverse=True)
            self.labels["attitude_index"] = inv.ravel()

    def _classes(self, target: str) -> np.ndarray:
        key = "attitude_index" if target == "attitude" else target
        if key not in self.labels:
            raise Error(f"invalid target = {target!r}: the candidates have no {target} labels (pass labels=...)")
        _, inv = np.unique(np.asarray(self.labels[key]).astype(str), return_inverse=True)
        return inv.ravel()

    def _weights(
        self, weights: Any, target: str, reg: float, n_components: int | None, noise: tuple[float, float] | None
    ) -> np.ndarray | None:
        K, B, C = self.features.shape
        F = B * C
        if weights is None:
            return None
        if isinstance(weights, str):
            if weights not in ("whiten", "lda"):
                raise Error(f'invalid weights = {weights!r}: None, "whiten", "lda" or an array')
            if F > _MAX_LEARNED_FEATURES:
                raise Error(
                    f"invalid weights = {weights!r}: {F} features (B = {B} bins x C = {C} channels) is "
                    f"more than {_MAX_LEARNED_FEATURES}; use a projection with fewer channels"
                )
            if n_components is not None and (
                isinstance(n_components, (bool, np.bool_)) or not isinstance(n_components, (int, np.integer))
                or not 1 <= n_components <= F
            ):
                raise Error(f"invalid n_components = {n_components!r}: an integer in [1, {F}]")
            cls = self._classes(target)
            x = self.features.reshape(K, F)
            n = np.linalg.norm(x, axis=1, keepdims=True)
            x = np.divide(x, n, out=np.zeros_like(x), where=n > 0)
            if noise is None:
                warnings.warn(
                    f"weights={weights!r} without counts= assume noise-free measurements: at a finite count "
                    "level they can do far worse than weights=None (docs/classifier-weights.md). Pass the "
                    "measurements' expected signal counts as counts= (math.inf for noise-free data)",
                    NoiseFreeWeightsWarning,
                    stacklevel=3,
                )
                tau = 0.0
            else:
                n_sig, n_bg = noise
                # Poisson variance per unit-norm feature (module docstring)
                tau = 1.0 / n_sig + (n_bg / F) * float(np.mean(np.abs(x).sum(axis=1) ** 2)) / n_sig**2
            if weights == "whiten":
                return _ridge_inv_sqrt(_residual_covariance(x, cls), tau, reg)
            n_cls = int(cls.max()) + 1
            sizes = np.bincount(cls, minlength=n_cls).astype(np.float64)
            means = np.zeros((n_cls, F))
            np.add.at(means, cls, x)
            means /= sizes[:, None]
            r = x - means[cls]
            w0 = _ridge_inv_sqrt(r.T @ r / max(K - n_cls, 1), tau, reg)  # S_w
            d = means - (sizes @ means) / K
            s_b = (d.T * sizes) @ d / K
            mu, v = np.linalg.eigh(w0 @ s_b @ w0)
            mu, v = np.clip(mu[::-1], 0.0, None), v[:, ::-1]
            if n_components is not None:
                mu, v = mu[:n_components], v[:, :n_components]
            return (np.sqrt(1.0 + mu)[:, None] * v.T) @ w0
        w = _finite_array(weights, "weights")
        if w.shape == (C,):
            return np.tile(w, B)
        if w.shape == (B, C):
            return w.reshape(F)
        if w.ndim == 2 and w.shape[1] == F and w.shape[0] >= 1:
            return w
        raise Error(f"invalid weights: shape {w.shape}, expected ({C},), ({B}, {C}) or (F', {F})")

    def _apply(self, x: np.ndarray) -> np.ndarray:
        if self.weights is None:
            return x
        if self.weights.ndim == 1:
            return x * self.weights
        return x @ self.weights.T

    # ------------------------------------------------------------------ scoring

    @property
    def n_candidates(self) -> int:
        return int(self.features.shape[0])

    def _registered(self, m: Any) -> np.ndarray:
        """A :class:`pprender.Measurement`'s background-subtracted counts placed on the
        database's range grid (its bins must have the database's width and lie on the same
        grid of multiples of it: those of :func:`pprender.render`)."""
        if self.range is None:
            raise Error("invalid measurements: a Measurement needs a classifier built from a database "
                        "(its range grid); pass (M, B, C) arrays otherwise")
        counts = np.asarray(m.counts, dtype=np.float64) - np.asarray(m.background, dtype=np.float64)
        edges = np.asarray(m.bin_edges, dtype=np.float64)
        w = float(self.range[1] - self.range[0])
        lo = float(self.range[0] - 0.5 * w)
        nb = counts.shape[-2]
        start = (edges[0] - lo) / w
        k = int(round(start))
        if (abs(start - k) > 1e-6 or edges.shape != (nb + 1,)
                or abs((edges[-1] - edges[0]) / nb - w) > 1e-9 * w):
            raise Error(f"invalid measurements: bin edges {edges[0]:.6g}..{edges[-1]:.6g} m ({nb} bins) are "
                        f"not on the database's grid of {w:.6g} m bins starting at {lo:.6g} m")
        B = len(self.range)
        out = np.zeros(counts.shape[:-2] + (B, counts.shape[-1]))
        a, b = max(k, 0), min(k + nb, B)
        if a >= b:
            raise Error("invalid measurements: no bin inside the database's range window")
        out[..., a:b, :] = counts[..., a - k:b - k, :]
        return out

    def _measurements(self, measurements: Any) -> tuple[np.ndarray, bool]:
        if hasattr(measurements, "counts") and hasattr(measurements, "bin_edges"):
            measurements = self._registered(measurements)
        x = _finite_array(measurements, "measurements")
        single = x.ndim == 2
        if single:
            x = x[None]
        _, B, C = self.features.shape
        if x.ndim != 3 or x.shape[1:] != (B, C):
            raise Error(
                f"invalid measurements: shape {x.shape}, expected (M, {B}, {C}) or ({B}, {C}): "
                f"{B} range bins on the database grid and {C} channels"
            )
        if len(x) == 0:
            raise Error("invalid measurements: none given (M = 0)")
        zero = ~np.any(x != 0, axis=(1, 2))
        if zero.any():
            raise Error(f"invalid measurements: measurement(s) {np.flatnonzero(zero)[:10].tolist()} are all zero")
        nonpositive = ~np.any(x > 0, axis=(1, 2))
        if nonpositive.any():
            raise Error(
                f"invalid measurements: measurement(s) {np.flatnonzero(nonpositive)[:10].tolist()} have no "
                "positive value (zero or negative everywhere): photon counts cannot be negative, so there is "
                "no signal to classify (a background-subtracted measurement with no signal above the background?)"
            )
        return x, single

    def _offsets(self) -> list[int]:
        out = [0]
        for o in range(1, self.max_shift + 1):
            out += [o, -o]
        return out

    def _scores(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Best scores and offsets (M, K), and whether ``W x_o != 0`` at some offset (M,)."""
        M, B, C = x.shape
        K = self.n_candidates
        best = np.full((M, K), -np.inf)
        offset = np.zeros((M, K), dtype=np.int64)
        seen = np.zeros(M, dtype=bool)
        for o in self._offsets():
            xo = np.zeros_like(x)
            if o >= 0:
                xo[:, : B - o] = x[:, o:]
            else:
                xo[:, -o:] = x[:, : B + o]
            z = self._apply(xo.reshape(M, B * C))
            nz = np.linalg.norm(z, axis=1, keepdims=True)
            seen |= nz[:, 0] > 0
            z = np.divide(z, nz, out=np.zeros_like(z), where=nz > 0)
            s = z @ self._y.T
            better = s > best
            best[better] = s[better]
            offset[better] = o
        return best, offset, seen

    def scores(self, measurements: Any, *, return_offsets: bool = False) -> Any:
        """Scores of every measurement against every candidate.

        Parameters
        ----------
        measurements : array_like or pprender.Measurement
            (M, B, C) or (B, C) profiles in the candidates' channels and range grid, or a
            :class:`pprender.Measurement` (its counts less the expected background, placed on
            the database's range grid; the classifier must come from a database).
        return_offsets : bool
            Also return the best range offset (bins) per pair.

        Returns
        -------
        numpy.ndarray
            (M, K) scores in [-1, 1] ((K,) for one measurement); with ``return_offsets``
            a pair (scores, offsets).

        Raises
        ------
        pprender.Error
            For a measurement with no positive value or one that vanishes under the
            weights (module docstring).
        """
        x, single = self._measurements(measurements)
        out_s = np.empty((len(x), self.n_candidates))
        out_o = np.empty((len(x), self.n_candidates), dtype=np.int64)
        seen = np.empty(len(x), dtype=bool)
        step = max(1, int(4e6 // max(self.n_candidates, 1)))  # bound the (M, K) temporaries
        for i in range(0, len(x), step):
            out_s[i : i + step], out_o[i : i + step], seen[i : i + step] = self._scores(x[i : i + step])
        if not seen.all():
            raise Error(
                f"invalid measurements: measurement(s) {np.flatnonzero(~seen)[:10].tolist()} vanish under the "
                "weights (W x = 0 at every range offset): their signal lies only in features the weights "
                "ignore, so every score would be 0"
            )
        if single:
            out_s, out_o = out_s[0], out_o[0]
        return (out_s, out_o) if return_offsets else out_s

    def top_k(self, measurements: Any, k: int = 5) -> Matches:
        """The ``k`` best candidates per measurement, best first (ties: lower index first).

        A measurement whose best score is at most ``1e-9`` matches nothing: a
        :class:`NoMatchWarning` names it and ``Matches.matched`` is False for it (its rows are
        still filled, by score then index, but are not matches).

        Parameters
        ----------
        measurements : array_like or pprender.Measurement
            As :meth:`scores`.
        k : int, optional
            Number of candidates, in [1, K]. Default 5.

        Returns
        -------
        Matches
            Their scores, range offsets and labels; arrays (M, k), also for a single (B, C)
            measurement.

        Raises
        ------
        pprender.Error
            As :meth:`scores` does, and for ``k`` out of range.

        Warns
        -----
        NoMatchWarning
            For measurements that match no candidate.
        """
        x, _ = self._measurements(measurements)
        K = self.n_candidates
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)) or not 1 <= k <= K:
            raise Error(f"invalid k = {k!r}: an integer in [1, {K}]")
        s, o = self.scores(x, return_offsets=True)
        idx = np.empty((len(x), k), dtype=np.int64)
        for m in range(len(x)):
            part = np.argpartition(-s[m], k - 1)[:k] if k < K else np.arange(K)
            # every candidate scoring as well as the k-th is eligible; order by score, index
            cut = s[m, part].min()
            cand = np.flatnonzero(s[m] >= cut)
            order = np.lexsort((cand, -s[m, cand]))
            idx[m] = cand[order[:k]]
        rows = np.arange(len(x))[:, None]
        none = np.flatnonzero(s[rows[:, 0], idx[:, 0]] <= _NO_MATCH_SCORE)
        if len(none):
            warnings.warn(
                f"top_k: measurement(s) {none[:10].tolist()}{' ...' if len(none) > 10 else ''} match no "
                f"candidate: best score {float(s[none[0], idx[none[0], 0]]):.3g} <= {_NO_MATCH_SCORE:g} "
                "(not even positively correlated with any candidate; signal outside the candidates' "
                "range window or channels?). Their rows are not matches: see Matches.matched",
                NoMatchWarning,
                stacklevel=2,
            )
        lab = self.labels
        return Matches(
            index=idx,
            score=s[rows, idx],
            offset=o[rows, idx],
            shape=lab["shape"][idx] if "shape" in lab else None,
            material=lab["material"][idx] if "material" in lab else None,
            attitude_index=lab["attitude_index"][idx] if "attitude_index" in lab else None,
            attitude=lab["attitude"][idx] if "attitude" in lab else None,
        )


def _noise_level(counts: Any, background: Any, learned: bool, weights: Any) -> tuple[float, float] | None:
    """``(counts, background)`` checked, or None without ``counts`` (learned weights only)."""
    if counts is None:
        if not (isinstance(background, (int, float, np.integer, np.floating)) and not isinstance(background, bool)
                and background == 0):
            raise Error(f"invalid background = {background!r}: it applies only with counts= (counts = None)")
        return None
    if not learned:
        raise Error(f"invalid counts = {counts!r}: it applies only to learned weights, \"whiten\" or \"lda\" "
                    f"(weights = {weights!r})")
    ok = isinstance(counts, (int, float, np.integer, np.floating)) and not isinstance(counts, (bool, np.bool_))
    if not (ok and float(counts) > 0 and not np.isnan(counts)):
        raise Error(f"invalid counts = {counts!r}: expected signal counts per measurement, > 0 (math.inf: noise-free)")
    ok = isinstance(background, (int, float, np.integer, np.floating)) and not isinstance(background, (bool, np.bool_))
    if not (ok and np.isfinite(background) and background >= 0):
        raise Error(f"invalid background = {background!r}: expected background counts per measurement, a finite "
                    "number >= 0")
    return float(counts), float(background)


def _ridge_inv_sqrt(s: np.ndarray, tau: float, reg: float) -> np.ndarray:
    """``(s + (tau + lambda) I)^(-1/2)``, ``lambda = reg * trace(s) / F`` (module docstring)."""
    F = len(s)
    tr = float(np.trace(s))
    lam = reg * (tr / F if tr > 0 else (tau if tau > 0 else 1.0))
    return _inv_sqrt(s + (tau + lam) * np.eye(F))


def _residual_covariance(x: np.ndarray, cls: np.ndarray, shrink: bool = True) -> np.ndarray:
    """``S_r`` (module docstring) of unit rows ``x`` (K, F) with class indices ``cls`` (K,),
    shrunk toward ``(trace / F) I`` by Ledoit and Wolf's weight unless ``shrink`` is False."""
    K, F = x.shape
    rows = np.unique(np.linspace(0, K - 1, min(K, _MAX_RESIDUALS)).round().astype(np.int64))
    sampled = np.zeros(K, dtype=bool)
    sampled[rows] = True
    res = []
    for c in np.unique(cls):
        members = np.flatnonzero(cls == c)
        if len(members) < 2:
            continue
        own = np.flatnonzero(sampled[members])  # positions in members of the sampled candidates
        for i in range(0, len(own), 256):  # bound the (rows, members) cosine block
            pos = own[i : i + 256]
            g = x[members[pos]] @ x[members].T
            g[np.arange(len(pos)), pos] = -np.inf  # not itself
            res.append(x[members[pos]] - x[members[g.argmax(axis=1)]])
    if not res:
        return np.zeros((F, F))
    r = np.concatenate(res)
    n = len(r)
    s = r.T @ r / n
    if shrink:
        rho = _ledoit_wolf(r, s)
        s = (1.0 - rho) * s + rho * np.trace(s) / F * np.eye(F)
    return s / 2.0


def _ledoit_wolf(r: np.ndarray, s: np.ndarray) -> float:
    """Ledoit and Wolf's (2004, J. Multivar. Anal. 88, 365, Lemma 3.2 and eq. 14) shrinkage
    weight toward ``(trace(s) / F) I`` for the covariance ``s = r^T r / n`` of the rows ``r``
    (n, F) (taken as zero-mean): ``min(b2, d2) / d2`` with ``d2 = |s - mu I|_F^2`` and
    ``b2 = sum_i |r_i r_i^T - s|_F^2 / n^2``."""
    n, F = r.shape
    mu = np.trace(s) / F
    d2 = float(np.sum(s * s) - 2.0 * mu * np.trace(s) + mu * mu * F)
    if d2 <= 0:
        return 0.0
    sq = np.sum(r * r, axis=1)
    b2 = float(np.sum(sq**2) - 2.0 * np.sum((r @ s) * r) + n * np.sum(s * s)) / n**2
    return min(b2, d2) / d2


def _is_dataset(x: Any) -> bool:
    try:
        import xarray as xr
    except ImportError:  # pragma: no cover - xarray is needed for databases anyway
        return False
    return isinstance(x, xr.Dataset)
