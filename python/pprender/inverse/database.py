"""Candidate databases: range-resolved profiles of every shape x material x attitude.

A database is a Zarr (v3) store on the local file system, read with xarray
(:func:`open_database`). It is written chunk by chunk, can be resumed after an
interruption, and records everything needed to know (and redo) how it was made.

Conventions (every function in this module):

* Units: metres, seconds, radians; profiles in m^2 per range bin (:func:`pprender.render`).
  Attitudes are unit quaternions ``(w, x, y, z)`` rotating the body into the telescope
  frame, as in :func:`pprender.render`.
* Store layout (``ds = open_database(path)``):

  - ``profile``: ``(shape, material, attitude, range, mueller_row, mueller_col)`` Mueller
    profiles for ``Lidar(polarization=None)``, or ``(shape, material, attitude, range,
    stokes)`` Stokes profiles when the sensor transmits a polarization. Stored as
    ``dtype`` (default float32: 6e-8 relative rounding, far below the renderer's ~1e-3
    accuracy). Attitudes not yet rendered read as NaN.
  - ``complete``: ``(shape, material, attitude_chunk)`` bool, True once that chunk's
    profiles are written (the flag is written after the data).
  - coordinates: ``shape`` and ``material`` (names), ``attitude`` (index 0..M-1),
    ``quaternion`` ``(attitude, quaternion_component)`` with components ``w x y z``,
    ``range`` (bin centres, m), ``time`` (round-trip delay ``2 range / c`` of each bin,
    s), ``mueller_row``/``mueller_col`` (0..3) or ``stokes`` (``I Q U V``), and per
    shape ``bounding_radius`` (m) and ``n_faces``.
  - attributes: ``sensor`` (every :class:`pprender.Lidar` field), ``materials`` (every
    constructor parameter of every :class:`pprender.Material`, per part for per-part
    assignments), ``shapes`` (vertex/face counts, parts, bounds, SHA-256 of the mesh
    arrays), ``attitudes`` (count, SHA-256 of the float64 quaternions, the user's grid
    description), ``chunk_attitudes``, ``range_window``, ``range_grid``, ``dtype``,
    ``pprender_version``, ``model_version`` (:data:`pprender.MODEL_VERSION`, bumped with
    every change that moves rendered numbers: a store built by another model is not
    resumed), ``created`` (UTC, ISO 8601) and ``fingerprint``, the SHA-256 of all of
    these but ``created`` and ``range_grid``.
  - ``_build/``: a Zarr group (invisible to xarray) with each mesh's vertices, faces
    and per-face part indices, so that any process can render any chunk from the store
    alone (:func:`write_chunk`).

* Common range window. The renderer's bin edges are integer multiples of the bin width
  ``w`` (:meth:`pprender.Lidar.effective_bin_width`), symmetric about range 0 (the body
  origin): shape ``s`` gets ``2 K_s`` bins over ``[-K_s w, K_s w]`` with ``K_s`` set by
  its bounding radius and the pulse. The database uses one grid for all shapes,
  ``2 K`` bins over ``[-K w, K w]`` with ``K = max_s K_s`` (found by rendering one
  attitude of each shape when the store is created), or ``K = ceil(range_window / w)``
  when ``range_window`` (m) is given (it must cover every shape's window). Each shape's
  profile is placed at its own ranges and padded with zeros, so profiles of different
  shapes are directly comparable bin by bin.
* Chunks: one Zarr chunk per ``(shape, material, attitude chunk)``; attitude chunk ``c``
  holds attitudes ``[c * chunk_attitudes, (c + 1) * chunk_attitudes)``. Each chunk is
  rendered and written independently (:func:`write_chunk`), so chunks can be written by
  separate processes (each writes its own Zarr chunk files; local writes are atomic).

Shapes are meshes, not :class:`pprender.Scene` objects (a Scene binds its materials, while
the database renders every shape with every entry of ``materials``); they are shaded flat.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import json
import math
import os
import shutil
import uuid
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, NamedTuple, cast

import numpy as np

from .._core import Error, Material
from ..lidar import SPEED_OF_LIGHT, Lidar, Scene, _mesh_arrays

__all__ = [
    "Chunk",
    "build_database",
    "create_database",
    "list_chunks",
    "open_database",
    "pad_profile",
    "write_chunk",
]

FORMAT = "pprender.database/1"
#: Default number of attitudes per chunk: about 3 MB of float32 Mueller profiles at 200 bins.
DEFAULT_CHUNK_ATTITUDES = 256

RenderFn = Callable[[Scene, Lidar, np.ndarray], Any]


class Chunk(NamedTuple):
    """One unit of work: attitudes ``start:stop`` of one shape with one material.

    Parameters
    ----------
    shape : int
        Index into the database's ``shape`` coordinate.
    material : int
        Index into the database's ``material`` coordinate.
    attitude_chunk : int
        Index of the attitude chunk: attitudes ``[c * chunk_attitudes, (c + 1) *
        chunk_attitudes)`` (module docstring).
    start, stop : int
        The chunk's attitudes, ``start:stop``.
    done : bool
        True when written.
    """

    shape: int
    material: int
    attitude_chunk: int
    start: int
    stop: int
    done: bool


def _render_profiles(scene: Scene, sensor: Lidar, attitudes: np.ndarray) -> Any:
    """The default render: :func:`pprender.render` with ``outputs=("profile",)``."""
    from ..lidar import render

    return render(scene, sensor, attitudes, outputs=("profile",))


# --------------------------------------------------------------------------- serialization


def _num(x: float) -> float | str:
    """A float for JSON attributes: itself when finite (exact round trip), else a string."""
    x = float(x)
    return x if math.isfinite(x) else repr(x)


def _material_params(m: Material) -> dict[str, Any]:
    """Every constructor parameter of ``m`` (``Material(**params)`` rebuilds it)."""
    d: dict[str, Any] = {
        "distribution": m.distribution,
        "eta": [_num(m.eta.real), _num(m.eta.imag)],
        "shadowing": m.shadowing,
        "correlation": m.correlation,
        "smith_g1": m.smith_g1,
        "masking": m.masking,
        "terms": list(m.terms),
        "diffuse_albedo": _num(m.diffuse_albedo),
        "name": m.name,
        "double_order": int(m.double_order),
        "coherent_backscatter": bool(m.coherent_backscatter),
        "double_masking": m.double_masking,
        "wavelength": _num(m.wavelength),
        "correlation_length": _num(m.correlation_length),
        "orders": m.orders,
        "bank_rays": int(m.bank_rays),
    }
    if m.alpha_step is not None:  # (absent otherwise: databases written before it stay valid)
        d["alpha_step"] = _num(m.alpha_step)
    if m.distribution == "blinn_phong":
        d["m"] = _num(m.m)  # type: ignore[arg-type]
    else:
        d["alpha"] = _num(m.alpha)  # type: ignore[arg-type]
    return d


def _material_from_params(d: Mapping[str, Any]) -> Material:
    kw = dict(d)
    kw["eta"] = complex(float(kw["eta"][0]), float(kw["eta"][1]))
    for k in ("m", "alpha", "diffuse_albedo", "wavelength", "correlation_length", "alpha_step"):
        if k in kw:
            kw[k] = float(kw[k])
    return Material(**kw)


def _sensor_params(sensor: Lidar) -> dict[str, Any]:
    d = dataclasses.asdict(sensor)
    for k, v in d.items():
        if isinstance(v, tuple):
            d[k] = [float(x) for x in v]
    if d["polarization"] is not None:
        d["polarization"] = [float(x) for x in d["polarization"]]
    return d


def _sensor_from_params(d: Mapping[str, Any]) -> Lidar:
    return Lidar(**dict(d))


def _sha256(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype.str).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


# --------------------------------------------------------------------------- input validation


@dataclasses.dataclass
class _Mesh:
    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int64
    face_part: np.ndarray  # (F,) int32 indices into parts
    parts: list[str] | None

    def summary(self) -> dict[str, Any]:
        lo = self.vertices.min(axis=0) if len(self.vertices) else np.zeros(3)
        hi = self.vertices.max(axis=0) if len(self.vertices) else np.zeros(3)
        return {
            "n_vertices": int(len(self.vertices)),
            "n_faces": int(len(self.faces)),
            "parts": self.parts,
            "bounds": [[_num(x) for x in lo], [_num(x) for x in hi]],
            "sha256": _sha256(self.vertices, self.faces, self.face_part),
        }


def _as_mesh(name: str, shape: Any) -> _Mesh:
    if isinstance(shape, Scene):
        raise Error(
            f"invalid shape {name!r}: a pprender.Scene binds its materials; pass its mesh (a "
            "trimesh.Trimesh or (vertices, faces)) and give the materials in `materials`"
        )
    v, f, meta, _ = _mesh_arrays(shape)
    if len(f) == 0:
        raise Error(f"invalid shape {name!r}: the mesh has no faces")
    if not np.all(np.isfinite(v)):
        raise Error(f"invalid shape {name!r}: non-finite vertices")
    parts = meta.get("pprender_parts") if meta else None
    fm = meta.get("pprender_material") if (meta and parts is not None) else None
    fp = np.zeros(len(f), dtype=np.int32) if fm is None else np.asarray(fm, dtype=np.int32)
    return _Mesh(
        np.ascontiguousarray(v, dtype=np.float64),
        np.ascontiguousarray(f, dtype=np.int64),
        np.ascontiguousarray(fp),
        None if parts is None else [str(p) for p in parts],
    )


def _resolve(m: Any, wavelength: float, what: str) -> Material:
    if isinstance(m, Material):
        return m
    if isinstance(m, str):
        from .. import materials

        return materials.get(m, wavelength=wavelength)
    raise Error(f"invalid {what}: {m!r}; expected a pprender.Material or a material name")


def _material_spec(name: str, value: Any, wavelength: float) -> tuple[dict[str, Any], Material | dict[str, Material]]:
    """The JSON spec ``{"name", "kind": "uniform", "material": params}`` or ``{"name",
    "kind": "parts", "parts": {part: params}}`` of a Material, a material name, or a
    mapping part -> material, and the resolved Material(s)."""
    if isinstance(value, Mapping):
        if not value:
            raise Error(f"invalid material {name!r}: an empty part mapping")
        mats = {str(p): _resolve(v, wavelength, f"material {name!r} part {p!r}") for p, v in value.items()}
        return {"name": name, "kind": "parts", "parts": {p: _material_params(m) for p, m in mats.items()}}, mats
    m = _resolve(value, wavelength, f"material {name!r}")
    return {"name": name, "kind": "uniform", "material": _material_params(m)}, m


def _names(kind: str, mapping: Any) -> list[str]:
    if not isinstance(mapping, Mapping) or len(mapping) == 0:
        raise Error(f"invalid {kind}: expected a non-empty mapping from name to {kind[:-1]}")
    names = list(mapping)
    for n in names:
        if not isinstance(n, str) or not n:
            raise Error(f"invalid {kind} name {n!r}: a non-empty string")
    return names


def _attitudes(attitudes: Any) -> np.ndarray:
    """(M, 4) float64 quaternions, checked (unit within 1e-6) but stored as given: the
    renderer normalizes them itself."""
    from .so3 import _quaternions, scipy_quaternions

    r = scipy_quaternions(attitudes)
    if r is not None:
        attitudes = r.reshape(-1, 4)
    q = _quaternions(attitudes, "attitudes")
    if q.ndim != 2 or len(q) == 0:
        raise Error(f"invalid attitudes: shape {q.shape}, expected (M, 4) with M >= 1")
    return np.ascontiguousarray(np.asarray(attitudes, dtype=np.float64))


_MATERIAL_CACHE: dict[str, Material] = {}
_MATERIAL_CACHE_SIZE = 32


def _cached_material(params: Mapping[str, Any]) -> Material:
    """``Material(**params)``, cached per process (building a material's tables takes
    ~0.5 s; chunk writers in one worker process reuse them)."""
    key = json.dumps(params, sort_keys=True)
    m = _MATERIAL_CACHE.get(key)
    if m is None:
        m = _material_from_params(params)
        if len(_MATERIAL_CACHE) >= _MATERIAL_CACHE_SIZE:
            _MATERIAL_CACHE.pop(next(iter(_MATERIAL_CACHE)))
        _MATERIAL_CACHE[key] = m
    return m


def _materials_of(spec: Mapping[str, Any]) -> Material | dict[str, Material]:
    """The Material (uniform) or part -> Material mapping a material spec describes."""
    if spec["kind"] == "uniform":
        return _cached_material(spec["material"])
    return {p: _cached_material(d) for p, d in spec["parts"].items()}


def _scene(mesh: _Mesh, mats: Material | Mapping[str, Material], shape_name: str, material_name: str) -> Scene:
    vf = (mesh.vertices, mesh.faces)
    if isinstance(mats, Material):
        return Scene(vf, mats)
    parts = mesh.parts
    if parts is None:
        raise Error(
            f"invalid material {material_name!r}: it assigns materials per part, but shape "
            f"{shape_name!r} has no parts (metadata['pprender_parts'], pprender.models)"
        )
    missing = [p for p in parts if p not in mats]
    if missing:
        raise Error(
            f"invalid material {material_name!r}: no material for part(s) {missing} of shape "
            f"{shape_name!r} (parts {parts})"
        )
    return Scene(vf, [mats[p] for p in parts], face_material=mesh.face_part)


# --------------------------------------------------------------------------- store access


class _Store:
    """An open database: its recipe, arrays and a one-entry scene cache."""

    def __init__(self, path: str | os.PathLike[str], materials: list[Any] | None = None) -> None:
        import zarr

        self.path = Path(path)
        if not (self.path / "zarr.json").is_file():
            raise Error(f"invalid path {str(path)!r}: no Zarr store there (create it with build_database)")
        self.group: Any = zarr.open_group(str(self.path), mode="r+")
        attrs: dict[str, Any] = dict(self.group.attrs)
        if attrs.get("format") != FORMAT:
            raise Error(f"invalid path {str(path)!r}: not a pprender database (format {attrs.get('format')!r})")
        self.attrs = attrs
        self.sensor = _sensor_from_params(attrs["sensor"])
        self.shape_names: list[str] = [s["name"] for s in attrs["shapes"]]
        self.material_specs: list[dict[str, Any]] = list(attrs["materials"])
        self.chunk_attitudes = int(attrs["chunk_attitudes"])
        grid = attrs["range_grid"]
        self.half_bins = int(grid["half_bins"])
        self.bin_width = float(grid["bin_width"])
        self.profile: Any = cast(Any, self.group["profile"])
        self.complete: Any = cast(Any, self.group["complete"])
        self.n_attitudes = int(self.profile.shape[2])
        self.n_chunks = int(self.complete.shape[2])
        self._attitudes: np.ndarray | None = None
        # Materials are slow to build (tables): built once per process, on first use.
        self._materials: list[Any] = list(materials) if materials is not None else [None] * len(self.material_specs)
        self._scene_key: tuple[int, int] | None = None
        self._scene_value: Scene | None = None

    @property
    def attitudes(self) -> np.ndarray:
        if self._attitudes is None:
            self._attitudes = np.asarray(self.group["quaternion"][...], dtype=np.float64)
        return self._attitudes

    def mesh(self, i: int) -> _Mesh:
        b = self.group["_build"]
        parts = self.attrs["shapes"][i]["parts"]
        return _Mesh(
            np.asarray(b[f"shape_{i}_vertices"][...]),
            np.asarray(b[f"shape_{i}_faces"][...]),
            np.asarray(b[f"shape_{i}_face_part"][...]),
            parts,
        )

    def scene(self, s: int, m: int) -> Scene:
        if self._scene_key != (s, m):
            if self._materials[m] is None:
                self._materials[m] = _materials_of(self.material_specs[m])
            self._scene_value = _scene(
                self.mesh(s), self._materials[m], self.shape_names[s], self.material_specs[m]["name"]
            )
            self._scene_key = (s, m)
        assert self._scene_value is not None
        return self._scene_value

    def done(self) -> np.ndarray:
        return np.asarray(self.complete[...], dtype=bool)

    def chunk(self, c: Any) -> Chunk:
        n_s, n_m, n_c = self.complete.shape
        if isinstance(c, (int, np.integer)) and not isinstance(c, (bool, np.bool_)):
            if not 0 <= int(c) < n_s * n_m * n_c:
                raise Error(f"invalid chunk = {c!r}: a flat index in [0, {n_s * n_m * n_c})")
            s, rest = divmod(int(c), n_m * n_c)
            m, k = divmod(rest, n_c)
        else:
            try:
                s, m, k = (int(x) for x in tuple(c)[:3])
            except (TypeError, ValueError):
                raise Error(f"invalid chunk = {c!r}: a Chunk, a (shape, material, attitude_chunk) triple or a flat index") from None
            if not (0 <= s < n_s and 0 <= m < n_m and 0 <= k < n_c):
                raise Error(f"invalid chunk = {c!r}: indices out of range for chunk grid {(n_s, n_m, n_c)}")
        start = k * self.chunk_attitudes
        stop = min(start + self.chunk_attitudes, self.n_attitudes)
        return Chunk(s, m, k, start, stop, bool(self.complete[s, m, k]))


def _pad(prof: np.ndarray, edges: np.ndarray, w: float, K: int, what: str) -> np.ndarray:
    """A profile ``(n, 2 K_s, ...)`` on the renderer's bins ``edges`` padded with zeros to
    the common grid ``(n, 2 K, ...)`` of bin width ``w`` (float64)."""
    if prof.ndim < 2:
        raise Error(f"invalid profile for {what}: shape {prof.shape}, expected (N, B, ...)")
    nb = prof.shape[1]
    k_s = int(round(-edges[0] / w)) if len(edges) else -1
    if (
        edges.shape != (nb + 1,)
        or nb != 2 * k_s
        or abs(edges[0] + k_s * w) > 1e-6 * w
        or abs((edges[-1] - edges[0]) / nb - w) > 1e-9 * w
    ):
        raise Error(
            f"invalid bin edges for {what}: {edges[:1]}..{edges[-1:]} ({len(edges)} edges for {nb} bins) "
            f"are not the renderer's symmetric grid of bin width {w} m"
        )
    if k_s > K:
        raise Error(
            f"invalid range_window: {what} needs +-{k_s * w} m, the database covers +-{K * w} m; "
            "rebuild with a larger range_window (or None)"
        )
    if not np.all(np.isfinite(prof)):
        raise Error(f"invalid profile for {what}: non-finite values")
    out = np.zeros((prof.shape[0], 2 * K) + prof.shape[2:], dtype=np.float64)
    out[:, K - k_s : K + k_s] = prof
    return out


def _place(store: _Store, result: Any, n: int, s: int) -> np.ndarray:
    """The rendered chunk padded into the store's grid, in the store's dtype."""
    prof = np.asarray(result.profile)
    channels = (4, 4) if store.sensor.polarization is None else (4,)
    if prof.ndim != 2 + len(channels) or prof.shape[0] != n or prof.shape[2:] != channels:
        raise Error(f"render returned a profile of shape {prof.shape}, expected ({n}, B, {', '.join(map(str, channels))})")
    edges = np.asarray(result.bin_edges, dtype=np.float64)
    out = _pad(prof, edges, store.bin_width, store.half_bins, f"shape {store.shape_names[s]!r}")
    return out.astype(store.profile.dtype, copy=False)


def pad_profile(profile: Any, bin_edges: Any, database: Any) -> np.ndarray:
    """Put profiles rendered by :func:`pprender.render` onto a database's range grid.

    Parameters
    ----------
    profile : array_like
        (N, B, ...) profiles (m^2 per bin), e.g. ``RenderResult.profile``, rendered with
        the database's bin width.
    bin_edges : array_like
        (B + 1,) their bin edges (m), ``RenderResult.bin_edges``.
    database : xarray.Dataset or path
        The database (:func:`open_database`) or its path.

    Returns
    -------
    numpy.ndarray
        (N, 2 K, ...) float64, zero outside the profile's own bins (module docstring).

    Raises
    ------
    pprender.Error
        For something that is not a pprender database, bin edges that are not the renderer's
        symmetric grid of the database's bin width, a profile wider than the database's range
        window, or non-finite profiles.
    """
    if isinstance(database, (str, os.PathLike)):
        database = open_database(database)
    try:
        grid = database.attrs["range_grid"]
        w, K = float(grid["bin_width"]), int(grid["half_bins"])
    except (AttributeError, KeyError, TypeError):
        raise Error("invalid database: expected an open pprender database or its path") from None
    prof = np.asarray(profile, dtype=np.float64)
    return _pad(prof, np.asarray(bin_edges, dtype=np.float64), w, K, "the profile")


# --------------------------------------------------------------------------- public API


def list_chunks(path: str | os.PathLike[str]) -> list[Chunk]:
    """Every chunk of the database at ``path``, in build order.

    Parameters
    ----------
    path : str or os.PathLike
        The database's directory.

    Returns
    -------
    list of Chunk
        In build order (shape, then material, then attitude chunk), each with ``done`` read
        from the store's ``complete`` flags.

    Raises
    ------
    pprender.Error
        When ``path`` holds no pprender database.
    """
    st = _Store(path)
    done = st.done()
    out = []
    for s in range(done.shape[0]):
        for m in range(done.shape[1]):
            for k in range(done.shape[2]):
                start = k * st.chunk_attitudes
                out.append(Chunk(s, m, k, start, min(start + st.chunk_attitudes, st.n_attitudes), bool(done[s, m, k])))
    return out


def write_chunk(
    path: str | os.PathLike[str],
    chunk: Chunk | tuple[int, int, int] | int,
    *,
    render: RenderFn | None = None,
) -> bool:
    """Render one chunk and write it, unless it is already complete (idempotent).

    Everything needed (meshes, materials, sensor, attitudes, range grid) is read from the
    store, so this can run in any process, e.g. as a Dask task per pending chunk of
    :func:`list_chunks`; chunks are independent Zarr chunk files. The ``complete`` flag is
    written after the data, so a chunk interrupted before it is redone.

    Parameters
    ----------
    path : str or os.PathLike
        A store made by :func:`create_database` (or :func:`build_database`).
    chunk : Chunk, (shape, material, attitude_chunk) or int
        Which chunk: a :class:`Chunk`, an index triple, or a flat index in build order.
    render : callable, optional
        ``render(scene, sensor, attitudes) -> result`` with ``result.profile`` and
        ``result.bin_edges`` as from :func:`pprender.render` (default: that, with
        ``outputs=("profile",)``).

    Returns
    -------
    bool
        True if the chunk was rendered and written, False if it was already complete.

    Raises
    ------
    pprender.Error
        For a path without a pprender database, a chunk out of range, or a render whose
        profile does not fit the store (shape, bin grid, range window).
    """
    return _write_chunk(_Store(path), chunk, render)


def _write_chunk(st: _Store, chunk: Chunk | tuple[int, int, int] | int, render: RenderFn | None) -> bool:
    """:func:`write_chunk` into an open store (the builders reuse theirs)."""
    c = st.chunk(chunk)
    if c.done:
        return False
    fn = render if render is not None else _render_profiles
    n = c.stop - c.start
    result = fn(st.scene(c.shape, c.material), st.sensor, st.attitudes[c.start : c.stop])
    st.profile[c.shape, c.material, c.start : c.stop] = _place(st, result, n, c.shape)
    # The flag goes in after the data: a chunk interrupted before this line is redone.
    st.complete[c.shape, c.material, c.attitude_chunk] = True
    return True


def create_database(
    path: str | os.PathLike[str],
    shapes: Mapping[str, Any],
    materials: Mapping[str, Any],
    attitudes: Any,
    sensor: Lidar,
    *,
    chunk_attitudes: int = DEFAULT_CHUNK_ATTITUDES,
    range_window: float | None = None,
    dtype: str = "float32",
    attitude_grid: Any = None,
    render: RenderFn | None = None,
    overwrite: bool = False,
) -> bool:
    """Create an empty database at ``path`` (all chunks pending), or accept an identical one.

    An existing database made with the same parameters is accepted as is. The store is
    assembled in a sibling directory and renamed into place, so ``path`` either holds a
    complete empty database or nothing. The range grid is found by rendering one attitude of
    each shape (module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        Directory of the Zarr store (local file system).
    shapes : Mapping[str, mesh]
        As :func:`build_database`.
    materials : Mapping[str, material]
        As :func:`build_database`.
    attitudes : array_like
        As :func:`build_database`.
    sensor : pprender.Lidar
        As :func:`build_database`.
    chunk_attitudes : int, optional
        As :func:`build_database`.
    range_window : float, optional
        As :func:`build_database`.
    dtype : {"float32", "float64"}, optional
        As :func:`build_database`.
    attitude_grid : JSON-serializable, optional
        As :func:`build_database`.
    render : callable, optional
        As :func:`build_database`; used for the probe renders.
    overwrite : bool, optional
        As :func:`build_database`.

    Returns
    -------
    bool
        True if a new store was created, False if an identical one was already there.

    Raises
    ------
    pprender.Error
        As :func:`build_database`.

    See Also
    --------
    build_database : Create and fill a database.
    write_chunk : Fill one chunk.
    """
    return _create(
        path, shapes, materials, attitudes, sensor,
        chunk_attitudes=chunk_attitudes, range_window=range_window, dtype=dtype,
        attitude_grid=attitude_grid, render=render, overwrite=overwrite,
    )[0]


def _create(
    path: str | os.PathLike[str],
    shapes: Mapping[str, Any],
    materials: Mapping[str, Any],
    attitudes: Any,
    sensor: Lidar,
    *,
    chunk_attitudes: int = DEFAULT_CHUNK_ATTITUDES,
    range_window: float | None = None,
    dtype: str = "float32",
    attitude_grid: Any = None,
    render: RenderFn | None = None,
    overwrite: bool = False,
) -> tuple[bool, list[Any]]:
    if not isinstance(sensor, Lidar):
        raise Error(f"invalid sensor of type {type(sensor).__name__}: expected pprender.Lidar")
    shape_names = _names("shapes", shapes)
    material_names = _names("materials", materials)
    meshes = [_as_mesh(n, shapes[n]) for n in shape_names]
    resolved = [_material_spec(n, materials[n], sensor.wavelength) for n in material_names]
    specs = [r[0] for r in resolved]
    q = _attitudes(attitudes)
    if isinstance(chunk_attitudes, (bool, np.bool_)) or not isinstance(chunk_attitudes, (int, np.integer)) or not 1 <= chunk_attitudes <= 1_000_000:
        raise Error(f"invalid chunk_attitudes = {chunk_attitudes!r}: an integer in [1, 1000000]")
    if range_window is not None and not (
        isinstance(range_window, (int, float, np.floating)) and math.isfinite(range_window) and range_window > 0
    ):
        raise Error(f"invalid range_window = {range_window!r}: a positive half-width in metres, or None")
    if dtype not in ("float32", "float64"):
        raise Error(f'invalid dtype = {dtype!r}: "float32" or "float64"')
    try:
        grid_desc = json.loads(json.dumps(attitude_grid))
    except (TypeError, ValueError):
        raise Error("invalid attitude_grid: a JSON-serializable description (str, dict, ...)") from None

    from .. import MODEL_VERSION, __version__

    inputs: dict[str, Any] = {
        "format": FORMAT,
        "pprender_version": __version__,
        "model_version": MODEL_VERSION,
        "sensor": _sensor_params(sensor),
        "shapes": [dict(name=n, **m.summary()) for n, m in zip(shape_names, meshes)],
        "materials": specs,
        "attitudes": {"count": int(len(q)), "sha256": _sha256(q), "grid": grid_desc},
        "chunk_attitudes": int(chunk_attitudes),
        "range_window": None if range_window is None else float(range_window),
        "dtype": dtype,
    }
    fingerprint = hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()

    path = Path(path)
    if path.exists() and not (path.is_dir() and not any(path.iterdir())):  # an empty directory is fine
        existing = _existing_fingerprint(path)
        if not overwrite:
            if existing is None:
                raise Error(
                    f"invalid path {str(path)!r}: it exists and is not a pprender database; "
                    "choose another path"
                )
            if existing[0] == fingerprint:
                return False, [r[1] for r in resolved]
            diff = sorted(k for k in inputs if existing[1].get(k) != inputs[k])
            raise Error(
                f"invalid path {str(path)!r}: a database made with different parameters "
                f"({', '.join(diff) or 'fingerprint'}) is there; pass overwrite=True to replace it "
                "or choose another path"
            )
        if existing is None:
            raise Error(
                f"invalid path {str(path)!r}: overwrite=True replaces only pprender databases, "
                "and this is something else"
            )

    # Range grid: each shape's half-width in bins from one probe render.
    fn = render if render is not None else _render_profiles
    w = sensor.effective_bin_width()
    half: list[int] = []
    radii: list[float] = []
    for i, (n, mesh) in enumerate(zip(shape_names, meshes)):
        scene = _scene(mesh, resolved[0][1], n, specs[0]["name"])
        radii.append(scene.radius)
        edges = np.asarray(fn(scene, sensor, q[:1]).bin_edges, dtype=np.float64)
        half.append(int(round(-edges[0] / w)))
    K = max(half)
    if range_window is not None:
        K_win = int(math.ceil(range_window / w - 1e-9))
        if K_win < K:
            raise Error(
                f"invalid range_window = {range_window!r}: shape {shape_names[half.index(K)]!r} "
                f"needs a half-width of {K * w} m (bins of {w} m); use at least that, or None"
            )
        K = K_win
    n_chunks = -(-len(q) // int(chunk_attitudes))

    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex}.partial"
    try:
        _write_empty(
            tmp, inputs, fingerprint, shape_names, material_names, meshes, radii, half, K, w, q,
            int(chunk_attitudes), n_chunks, sensor,
        )
        if path.exists():
            shutil.rmtree(path)
        os.rename(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    return True, [r[1] for r in resolved]


def _existing_fingerprint(path: Path) -> tuple[str, dict[str, Any]] | None:
    if not (path / "zarr.json").is_file():
        return None
    try:
        with open(path / "zarr.json") as f:
            attrs = json.load(f).get("attributes", {})
    except (OSError, ValueError):
        return None
    if attrs.get("format") != FORMAT or "fingerprint" not in attrs:
        return None
    return attrs["fingerprint"], attrs


def _write_empty(
    tmp: Path,
    inputs: dict[str, Any],
    fingerprint: str,
    shape_names: list[str],
    material_names: list[str],
    meshes: list[_Mesh],
    radii: list[float],
    half: list[int],
    K: int,
    w: float,
    q: np.ndarray,
    chunk_attitudes: int,
    n_chunks: int,
    sensor: Lidar,
) -> None:
    import xarray as xr
    import zarr

    r = (np.arange(2 * K, dtype=np.float64) - K + 0.5) * w
    mueller = sensor.polarization is None
    coords: dict[str, Any] = {
        "shape": ("shape", np.array(shape_names, dtype=object), {"long_name": "shape name"}),
        "material": ("material", np.array(material_names, dtype=object), {"long_name": "material name"}),
        "attitude": ("attitude", np.arange(len(q)), {"long_name": "attitude index"}),
        "quaternion_component": ("quaternion_component", np.array(list("wxyz"), dtype=object)),
        "quaternion": (
            ("attitude", "quaternion_component"),
            q,
            {"long_name": "attitude: unit quaternion (w, x, y, z) rotating the body into the telescope frame"},
        ),
        "range": ("range", r, {"units": "m", "long_name": "range bin centre relative to the body origin, positive away from the sensor", "bin_width": w}),
        "time": ("range", 2.0 * r / SPEED_OF_LIGHT, {"units": "s", "long_name": "round-trip delay of the range bin centre, 2 range / c"}),
        "bounding_radius": ("shape", np.array(radii), {"units": "m", "long_name": "bounding-sphere radius about the body origin"}),
        "n_faces": ("shape", np.array([len(m.faces) for m in meshes]), {"long_name": "number of triangles"}),
    }
    if mueller:
        coords["mueller_row"] = ("mueller_row", np.arange(4), {"long_name": "Mueller row (output Stokes index)"})
        coords["mueller_col"] = ("mueller_col", np.arange(4), {"long_name": "Mueller column (input Stokes index)"})
        channel_dims: tuple[str, ...] = ("mueller_row", "mueller_col")
        channel_shape: tuple[int, ...] = (4, 4)
    else:
        coords["stokes"] = ("stokes", np.array(list("IQUV"), dtype=object), {"long_name": "received Stokes component"})
        channel_dims, channel_shape = ("stokes",), (4,)
    xr.Dataset(coords=coords).to_zarr(str(tmp), mode="w-", zarr_format=3, consolidated=False)

    g: Any = zarr.open_group(str(tmp), mode="r+")
    n_s, n_m = len(shape_names), len(material_names)
    g.create_array(
        "profile",
        shape=(n_s, n_m, len(q), 2 * K) + channel_shape,
        chunks=(1, 1, chunk_attitudes, 2 * K) + channel_shape,
        dtype=inputs["dtype"],
        fill_value=np.nan,
        dimension_names=("shape", "material", "attitude", "range") + channel_dims,
        attributes={
            "units": "m2",
            "long_name": (
                "range-resolved Mueller lidar cross-section per range bin" if mueller
                else "range-resolved received Stokes lidar cross-section per range bin"
            ),
            "coordinates": "quaternion time bounding_radius n_faces",
        },
    )
    g.create_array(
        "complete",
        shape=(n_s, n_m, n_chunks),
        chunks=(1, 1, 1),
        dtype="bool",
        fill_value=False,
        dimension_names=("shape", "material", "attitude_chunk"),
        attributes={"long_name": f"chunk written (attitudes [c * {chunk_attitudes}, (c + 1) * {chunk_attitudes}))"},
    )
    b = g.create_group("_build")
    for i, m in enumerate(meshes):
        b.create_array(f"shape_{i}_vertices", data=m.vertices)
        b.create_array(f"shape_{i}_faces", data=m.faces)
        b.create_array(f"shape_{i}_face_part", data=m.face_part)
    g.attrs.update(
        {
            **inputs,
            "title": "pprender candidate database",
            "range_grid": {
                "bin_width": w,
                "half_bins": K,
                "n_bins": 2 * K,
                "r_min": -K * w,
                "r_max": K * w,
                "shape_half_bins": dict(zip(shape_names, half)),
                "shape_resolution": {n: sensor.effective_resolution(rad) for n, rad in zip(shape_names, radii)},
            },
            "created": datetime.datetime.now(datetime.timezone.utc).isoformat(),
            "conventions": (
                "SI units; profile in m^2 per range bin; quaternions (w, x, y, z) rotate the body "
                "into the telescope frame; range relative to the body origin, positive away from "
                "the sensor (see pprender.lidar and pprender.database)"
            ),
            "fingerprint": fingerprint,
        }
    )


def build_database(
    path: str | os.PathLike[str],
    shapes: Mapping[str, Any],
    materials: Mapping[str, Any],
    attitudes: Any,
    sensor: Lidar,
    *,
    chunk_attitudes: int = DEFAULT_CHUNK_ATTITUDES,
    range_window: float | None = None,
    dtype: str = "float32",
    attitude_grid: Any = None,
    render: RenderFn | None = None,
    progress: bool = True,
    overwrite: bool = False,
) -> Any:
    """Render every shape x material x attitude into a Zarr database at ``path``.

    Chunks are rendered and written one at a time (memory: one chunk, about
    ``chunk_attitudes x bins x 16 x 8`` bytes, whatever the number of attitudes). An
    existing database made with the same parameters is resumed: its complete chunks are
    skipped and the result is bit for bit that of an uninterrupted build.

    Parameters
    ----------
    path : str or os.PathLike
        Directory of the Zarr store (local file system).
    shapes : Mapping[str, mesh]
        Name -> ``trimesh.Trimesh``, ``trimesh.Scene`` or ``(vertices, faces)`` (m, body
        frame), e.g. from :mod:`pprender.models`.
    materials : Mapping[str, material]
        Name -> a :class:`pprender.Material` or material name (:mod:`pprender.materials`,
        built at the sensor's wavelength) for the whole mesh, or a mapping part name ->
        material for meshes with parts (every shape must then have those parts).
    attitudes : array_like
        (M, 4) unit quaternions ``(w, x, y, z)`` (scalar first; norm within 1e-6; stored as
        given), e.g. :func:`pprender.so3.grid`, or a stacked
        ``scipy.spatial.transform.Rotation`` (stored as its ``(w, x, y, z)``).
    sensor : pprender.Lidar
        The sensor; ``polarization=None`` stores Mueller profiles, a Stokes vector stores
        Stokes profiles.
    chunk_attitudes : int, optional
        Attitudes per chunk, in [1, 1e6]. Default 256 (about 3 MB of float32 Mueller profiles
        at 200 bins).
    range_window : float, optional
        Half-width (m) of the common range window; default: the largest shape's.
    dtype : {"float32", "float64"}, optional
        Storage type of the profiles. Default ``"float32"``.
    attitude_grid : JSON-serializable, optional
        A description of how the attitudes were made (e.g. ``{"method":
        "so3.grid", "n": 5000}``), recorded in the attributes.
    render : callable, optional
        ``render(scene, sensor, attitudes) -> result`` with ``.profile`` and
        ``.bin_edges`` (default :func:`pprender.render` with ``outputs=("profile",)``).
    progress : bool, optional
        Show a tqdm progress bar (one step per chunk). Default True.
    overwrite : bool, optional
        Replace an existing database made with other parameters (only a pprender
        database is ever removed; an empty directory is used as is). Default False.

    Returns
    -------
    xarray.Dataset
        :func:`open_database` ``(path)``.

    Raises
    ------
    pprender.Error
        For a database made with different parameters at ``path`` unless
        ``overwrite=True``, a ``path`` that exists and is not a pprender database (even with
        ``overwrite=True``), a ``range_window`` smaller than a shape's window, or other
        invalid arguments.
    """
    _, mats = _create(
        path, shapes, materials, attitudes, sensor,
        chunk_attitudes=chunk_attitudes, range_window=range_window, dtype=dtype,
        attitude_grid=attitude_grid, render=render, overwrite=overwrite,
    )
    st = _Store(path, mats)
    chunks = list_chunks(path)
    pending = [c for c in chunks if not c.done]
    bar = _progress(progress, total=len(chunks), initial=len(chunks) - len(pending), desc=Path(path).name)
    try:
        for c in pending:
            _write_chunk(st, c, render)
            bar.update(1)
    finally:
        bar.close()
    return open_database(path)


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(enabled: bool, **kw: Any) -> Any:
    if not enabled:
        return _NoBar()
    from tqdm.auto import tqdm

    return tqdm(unit="chunk", **kw)


def open_database(path: str | os.PathLike[str], chunks: Any = None) -> Any:
    """Open a database lazily as an :class:`xarray.Dataset` (nothing is read until used).

    Layout: module docstring. Incomplete chunks read as NaN (see ``complete``).

    Parameters
    ----------
    path : str or os.PathLike
        The database's directory.
    chunks : object, optional
        Passed to :func:`xarray.open_zarr` (None: lazy NumPy-backed arrays without Dask;
        ``{}``: Dask arrays with the store's chunks).

    Returns
    -------
    xarray.Dataset
        The database.

    Raises
    ------
    pprender.Error
        When ``path`` holds no pprender database.
    """
    import xarray as xr

    p = Path(path)
    if _existing_fingerprint(p) is None:
        raise Error(f"invalid path {str(path)!r}: not a pprender database")
    return xr.open_zarr(str(p), consolidated=False, chunks=chunks)
