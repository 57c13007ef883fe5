"""pprender: polarized microfacet BRDFs and Pulse Polarization Ranging returns.

Conventions (the full statement is at the top of ``src/optics/mod.rs`` and in docs/physics.md):

* Local frame with the macro normal ``n = +z``. ``wi`` points from the surface toward the
  transmitter, ``wo`` toward the receiver; both unit vectors with ``z >= 0``.
* Stokes ``(I, Q, U, V)``; each beam has a transverse basis ``(x, y)`` with ``y = k x x``;
  ``V = 2 Im(Ex Ey*)`` with ``exp(-i omega t)`` fields and ``eta = n + i k``. Mueller
  matrices are ``(..., 4, 4)`` arrays, ``M[..., i, j]`` maps input Stokes ``j`` to output ``i``.
* ``frame="sp"``: the incident beam in the s/p basis of the plane (n, wi), the reflected beam
  in that of (n, wo) (``x = s``). ``frame="mitsuba"``: Mitsuba 3's ``stokes_basis``.
* A flat mirror at normal incidence is ``R diag(1, 1, -1, -1)``: linear states are kept,
  circular handedness flips.
* SI units: metres, seconds, radians; BRDFs in 1/sr without the cosine factor.
"""

from __future__ import annotations

import os
import pathlib
from dataclasses import dataclass

import numpy as np

from . import _core
from ._core import MODEL_VERSION, BrdfTable, Error, Material, __version__, brdf_table
from .lidar import SPEED_OF_LIGHT, Lidar, OffCentreWarning, RenderResult, Scene, Settings, device_info, render
from . import inverse  # noqa: E402  (its modules' heavy imports are lazy)
from .inverse import classify, database, distributed, instrument, so3  # noqa: E402
from .inverse.classify import Classifier, NoMatchWarning
from .inverse.instrument import Instrument, Measurement, PileUpWarning, expected_counts, measure
from .inverse.atmosphere import Atmosphere
from .inverse.detector import Detector
from .inverse.speckle import Speckle
from .inverse.database import build_database, open_database
from .inverse.distributed import build_database_distributed

__all__ = [
    "Atmosphere",
    "BrdfTable",
    "Detector",
    "Speckle",
    "Classifier",
    "Instrument",
    "Measurement",
    "expected_counts",
    "instrument",
    "measure",
    "build_database",
    "build_database_distributed",
    "distributed",
    "classify",
    "inverse",
    "database",
    "open_database",
    "so3",
    "Error",
    "Lidar",
    "Material",
    "MonostaticTable",
    "NoMatchWarning",
    "PileUpWarning",
    "OffCentreWarning",
    "RenderResult",
    "SPEED_OF_LIGHT",
    "Scene",
    "Settings",
    "device_info",
    "render",
    "__version__",
    "MODEL_VERSION",
    "albedo",
    "brdf",
    "brdf_table",
    "cache_dir",
    "monostatic_table",
    "prune_cache",
    "set_cache_dir",
    "specular",
    "white_furnace",
]


def _directions(x: object, name: str) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise Error(f"invalid {name}: cannot convert to a float64 array ({e})") from None
    if a.ndim == 0 or a.shape[-1] != 3:
        raise Error(f"invalid {name}: expected shape (..., 3), got {a.shape}")
    return a


def _check_frame(frame: str) -> str:
    if frame not in ("sp", "mitsuba"):
        raise Error(f'invalid frame = {frame!r}: expected "sp" or "mitsuba"')
    return frame


def brdf(material: Material, wi: object, wo: object, frame: str = "sp") -> np.ndarray:
    """Mueller BRDF ``f(wi, wo)`` of ``material``, shape ``(..., 4, 4)``, in 1/sr.

    The cosine factor is not included: the reflected radiance is ``f cos(theta_i)`` times
    the incident irradiance.

    Parameters
    ----------
    material : Material
        The material.
    wi : array_like, shape (..., 3)
        Directions toward the transmitter in the local frame (``n = +z``): ``z >= 0`` and
        unit length within 1e-6 (they are renormalized); broadcast against ``wo``.
    wo : array_like, shape (..., 3)
        Directions toward the receiver, as ``wi``; broadcast against ``wi``.
    frame : {"sp", "mitsuba"}, optional
        Stokes bases of the two beams (module docstring). Default ``"sp"``.

    Returns
    -------
    numpy.ndarray
        Shape ``(..., 4, 4)`` (the broadcast leading shape of ``wi`` and ``wo``), in 1/sr. A
        direction exactly on the horizon (``z == 0``) gives the zero matrix, as in Mitsuba.

    Raises
    ------
    pprender.Error
        For directions with ``z < 0``, non-finite values or other lengths; for ``wi`` and
        ``wo`` shapes that do not broadcast; for a ``frame`` other than ``"sp"`` or
        ``"mitsuba"``.
    """
    _check_frame(frame)
    a = _directions(wi, "wi")
    b = _directions(wo, "wo")
    try:
        a, b = np.broadcast_arrays(a, b)
    except ValueError:
        raise Error(f"wi and wo shapes {a.shape} and {b.shape} do not broadcast") from None
    shape = a.shape[:-1]
    out = _core.brdf(
        material,
        np.ascontiguousarray(a.reshape(-1, 3)),
        np.ascontiguousarray(b.reshape(-1, 3)),
        frame,
    )
    return out.reshape(shape + (4, 4))


def specular(material: Material, wi: object, frame: str = "sp") -> np.ndarray:
    """Dimensionless Mueller reflectance of the flat interface of ``material`` (the mirror limit).

    Roughness is ignored: incidence ``wi`` reflects into ``wo = (-wi.x, -wi.y, wi.z)``.

    Parameters
    ----------
    material : Material
        The material.
    wi : array_like, shape (..., 3)
        Unit vectors toward the transmitter in the local frame (``n = +z``).
    frame : {"sp", "mitsuba"}, optional
        Stokes bases of the two beams (module docstring). Default ``"sp"``.

    Returns
    -------
    numpy.ndarray
        Shape ``(..., 4, 4)``, dimensionless.

    Raises
    ------
    pprender.Error
        For a ``wi`` that is not an array of shape ``(..., 3)``, or a ``frame`` other than
        ``"sp"`` or ``"mitsuba"``.
    """
    _check_frame(frame)
    a = _directions(wi, "wi")
    shape = a.shape[:-1]
    return _core.specular(material, np.ascontiguousarray(a.reshape(-1, 3)), frame).reshape(shape + (4, 4))


def albedo(material: Material, wi: object, order: int = 128) -> np.ndarray:
    """Directional albedo for unpolarized incident light, ``int M00(wi, wo) cos(theta_o) dwo``.

    Parameters
    ----------
    material : Material
        The material.
    wi : array_like, shape (..., 3)
        Incident directions in the local frame (``n = +z``): unit vectors (``|w| - 1``
        within 1e-6) with ``z >= 0``.
    order : int, optional
        Order of the Gauss-Legendre rule of the single-bounce term, an integer in [8, 4096].
        Default 128.

    Returns
    -------
    numpy.ndarray
        Shape ``(...)`` for ``wi`` of shape ``(..., 3)``.

    Raises
    ------
    pprender.Error
        For a ``wi`` that is not finite, not made of unit vectors or below the horizon
        (``z < 0``), or an ``order`` that is not an integer in [8, 4096].

    Notes
    -----
    The single-bounce term is integrated numerically over the half vector with an
    ``order x order`` Gauss-Legendre rule (split at the horizon and at the masking switch;
    see ``src/brdf/albedo.rs``), independently of the per-material tables; the multiple and
    diffuse terms are integrated analytically. With ``F = 1`` (``eta=inf``) and
    ``terms=("single", "multiple")`` the result is 1 to within the table error (below 1e-5,
    see ``tests/test_energy.py``).
    """
    a = _directions(wi, "wi")
    shape = a.shape[:-1]
    if not isinstance(order, (int, np.integer)):
        raise Error(f"invalid order = {order!r}: must be an integer in [8, 4096]")
    norms = np.linalg.norm(a, axis=-1)
    if not np.all(np.isfinite(a)):
        raise Error("invalid wi: not finite")
    if np.any(np.abs(norms - 1.0) > 1e-6):
        raise Error("invalid wi: directions must be unit vectors (|w| - 1 within 1e-6)")
    if np.any(a[..., 2] < 0):
        raise Error("invalid wi: below the horizon (z < 0)")
    cos_i = np.clip(a[..., 2] / norms, 0.0, 1.0)
    return _core.albedo(material, np.ascontiguousarray(cos_i.reshape(-1)), int(order)).reshape(shape)


def set_cache_dir(path: str | os.PathLike[str] | None) -> None:
    """Set where path banks (``Material(..., orders="surface")``) are cached on disk.

    A path bank (one per alpha node and ``bank_rays``) takes about a minute per node to
    trace on 2 cores at the default rays, and 0.1-0.3 GB on disk at alpha 0.3-1 (147 MB
    at alpha 0.5, about 1.5 GB for those eight nodes; the six nodes below 0.3 are
    smaller and faster); it is traced once per
    machine, on first use, with a progress line on stderr (none when the environment
    variable ``PPRENDER_PROGRESS`` is ``0``), and read back by later processes. An entry
    that is missing, corrupt, or made by another pprender version or for other
    parameters is traced again and replaced, never trusted (entries another version wrote
    stay on disk until :func:`prune_cache` removes them); processes building the same
    entry at once each write a whole file and rename it into place. If the directory
    cannot be created or written, a warning is printed once and banks stay in memory.

    Without a call the directory is the environment variable ``PPRENDER_CACHE_DIR``
    (empty or ``"off"``: no disk cache), else ``$XDG_CACHE_HOME/pprender``, else
    ``~/.cache/pprender``. The setting holds for the rest of the process; banks already
    in memory stay there.

    Parameters
    ----------
    path : str or os.PathLike or None
        The directory (created when a bank is first written; a relative path is taken
        from the current directory now), or None to keep path banks in memory only.

    Raises
    ------
    pprender.Error
        Naming ``cache_dir``, for an empty string, a path that exists but is not a
        directory, or something that is not a path or None.
    """
    _core.set_cache_dir(path)


def cache_dir() -> pathlib.Path | None:
    """The directory path banks are cached in (:func:`set_cache_dir`), or None.

    Returns
    -------
    pathlib.Path or None
        The absolute directory, or None when path banks are kept in memory only.
    """
    return _core.cache_dir()


def prune_cache(all: bool = False, path: str | os.PathLike[str] | None = None) -> dict[str, int]:
    """Remove path banks from the disk cache that this pprender can never read.

    Banks are keyed on the pprender version and the code that traces them, so after an
    upgrade the old entries (0.1-0.3 GB each at alpha 0.3-1) are never read again, but
    stay on disk until removed. This removes them: entries written by another version or
    layout, or whose header cannot be read, and temporary files left by processes that
    died while writing. This version's entries (for any alpha, rays or autocorrelation)
    are kept; with ``all=True`` they are removed too (each is traced again on next use).
    Files that are not path-bank entries are never touched.

    Another pprender version that shares the directory will trace its banks again; a
    process reading a removed entry keeps its open copy (POSIX).

    Parameters
    ----------
    all : bool
        Remove every entry, not only those this version cannot read.
    path : str or os.PathLike or None
        The cache directory to prune; None (default): :func:`cache_dir` (nothing to do
        when the disk cache is off).

    Returns
    -------
    dict
        ``removed`` (entries removed), ``bytes`` (their size), ``kept`` (entries left).

    Raises
    ------
    pprender.Error
        Naming ``all`` (not a bool) or ``path`` (not a path, or not a directory).
    OSError
        An entry could not be removed (e.g. no permission).
    """
    removed, nbytes, kept = _core.prune_cache(all, path)
    return {"removed": removed, "bytes": nbytes, "kept": kept}


def white_furnace(distribution: str = "blinn_phong", **kwargs: object) -> Material:
    """The white-furnace test material: ``F = 1`` (a perfect conductor, ``eta=inf``).

    Parameters
    ----------
    distribution : str, optional
        The microfacet distribution, passed to :class:`Material`. Default ``"blinn_phong"``.
    **kwargs
        Further keyword arguments, passed to :class:`Material`.

    Returns
    -------
    Material
        ``Material(distribution, eta=complex(inf, 0), **kwargs)``.
    """
    return Material(distribution, eta=complex(np.inf, 0.0), **kwargs)  # type: ignore[arg-type]


@dataclass(frozen=True)
class MonostaticTable:
    """The monostatic double-bounce Mueller BRDF of a material against incidence angle.

    Made by :func:`monostatic_table`. The single term at backscatter and the multiple term
    are closed forms and are not in the table.

    Attributes
    ----------
    theta : numpy.ndarray, shape (n,)
        Incidence angles in radians: nodes uniform in the material's table coordinate,
        densest near normal incidence on the lobe's scale.
    mueller : numpy.ndarray, shape (n, 4, 4)
        The double-bounce Mueller BRDF in 1/sr, sp frame (plane of incidence), coherent
        backscatter included as configured on the material.
    build_seconds : float
        Time to build the table (s).
    max_error : float or None
        Largest error of the interpolated table at the midpoints between nodes against the
        material's own evaluation, relative to the total monostatic M00 there (None if not
        measured).
    """

    theta: np.ndarray
    mueller: np.ndarray
    build_seconds: float
    max_error: float | None


def monostatic_table(
    material: Material, nodes: int = 64, double_order: int = 48, measure: bool = True
) -> MonostaticTable:
    """Tabulate the monostatic double-bounce BRDF of ``material`` at ``nodes + 1`` angles.

    Parameters
    ----------
    material : Material
        The material.
    nodes : int, optional
        Number of intervals of the table, in [4, 100000]: ``nodes + 1`` angles. Default 64.
    double_order : int, optional
        Order of the double-bounce quadrature, in [4, 1024]. Default 48.
    measure : bool, optional
        Measure the table's interpolation error (``MonostaticTable.max_error``; None
        otherwise). Default True.

    Returns
    -------
    MonostaticTable
        The table (see :class:`MonostaticTable`).

    Raises
    ------
    pprender.Error
        For ``nodes`` or ``double_order`` out of range.

    Notes
    -----
    Interpolation: ``ln M00`` (bounded by its neighbours) and ``M_ij / M00`` by Catmull-Rom
    in the table coordinate, as in ``src/brdf/table.rs``.
    """
    theta, mueller, secs, err = _core.monostatic_table(material, int(nodes), int(double_order), bool(measure))
    return MonostaticTable(theta=theta, mueller=mueller, build_seconds=secs, max_error=err)


def __getattr__(name: str) -> object:
    # pprender.models imports trimesh (about 0.5 s), fit scipy's spatial module, plot
    # matplotlib: load them on first use (materials and mesh too, so that
    # ``pprender.materials.get`` works without importing the submodule first).
    if name in ("models", "fit", "plot", "materials", "mesh"):
        import importlib

        # "fit" is pprender/fit.py, which makes itself pprender.inverse.fit
        return importlib.import_module("." + name, __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
