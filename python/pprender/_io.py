"""Saving and loading results through xarray: Zarr v3 directories and netCDF files.

What :meth:`pprender.RenderResult.save` and :meth:`pprender.Measurement.save` share (each
class's own layout is in its ``to_xarray`` docstring):

* The suffix picks the format: ``.zarr`` a Zarr v3 directory (``zarr_format=3``,
  ``consolidated=False``, as :mod:`pprender.database`), ``.nc`` a netCDF file written by
  whichever netCDF engine xarray finds (netCDF4, h5netcdf, else scipy's netCDF3). A netCDF
  file is read back and compared with what was meant before it is put in place: what the
  engine cannot store exactly (netCDF3 has no int64: counts above 2**31 - 1) is refused,
  naming ``.zarr``, which stores everything.
* Round trips are exact: arrays bit for bit with their dtypes (each variable records its
  NumPy dtype in ``pprender_dtype``; netCDF3 stores int64 as int32 and it is cast back),
  scalars equal, None stays None. Nothing is masked or decoded on reading (no
  ``_FillValue``, no time decoding).
* Writes are atomic: the file or store is written beside ``path`` under a temporary name
  and renamed into place. An existing ``path`` is refused unless ``overwrite=True``, and
  even then only a saved RenderResult or Measurement is replaced (never a candidate
  database or anything else).
* Attributes: ``format`` (``"pprender.<Kind>/<version>"``; a newer version than this
  pprender reads is refused), ``pprender_version``, ``created`` (UTC, ISO 8601),
  ``title``, ``conventions``; nested metadata as JSON text, so that every format stores
  it the same way.
"""

from __future__ import annotations

import datetime
import json
import os
import shutil
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ._core import Error, __version__

#: Suffix -> format name, the formats :func:`write` and :func:`read` know.
SUFFIXES = {".zarr": "Zarr v3 directory", ".nc": "netCDF file"}

#: dtype attribute of each saved variable (restores int64 counts stored as netCDF3 int32).
DTYPE_ATTR = "pprender_dtype"


def _xarray() -> Any:
    try:
        import xarray as xr
    except ImportError as e:  # pragma: no cover - xarray is a test dependency
        raise ImportError("saving and loading need xarray (pip install 'pprender[inverse]')") from e
    return xr


def _suffix(path: str | os.PathLike[str]) -> str:
    """The format suffix of ``path``; :class:`Error` naming it and the supported ones."""
    p = Path(path)
    s = p.suffix.lower()
    if s not in SUFFIXES:
        known = ", ".join(f"{k!r} ({v})" for k, v in SUFFIXES.items())
        raise Error(f"invalid path {str(path)!r}: its suffix picks the format; supported: {known}")
    return s


def format_name(kind: str, version: int) -> str:
    return f"pprender.{kind}/{version}"


def check_format(attrs: Mapping[str, Any], kind: str, version: int, where: str) -> None:
    """Refuse attributes that are not those of a pprender ``kind`` of at most ``version``."""
    fmt = attrs.get("format")
    if not isinstance(fmt, str) or not fmt.startswith("pprender.") or "/" not in fmt:
        raise Error(f"invalid {where}: not a pprender {kind} (format attribute {fmt!r})")
    name, _, ver = fmt[len("pprender."):].partition("/")
    if name != kind:
        how = {"RenderResult": "pprender.RenderResult.load", "Measurement": "pprender.Measurement.load",
               "database": "pprender.open_database"}.get(name, "the pprender function that wrote it")
        raise Error(f"invalid {where}: it holds a pprender {name}, not a {kind} (open it with {how})")
    try:
        v = int(ver)
    except ValueError:
        raise Error(f"invalid {where}: unreadable format version {fmt!r}") from None
    if v > version:
        raise Error(
            f"invalid {where}: format {fmt!r} was written by a newer pprender "
            f"({attrs.get('pprender_version')!r}); this one ({__version__}) reads {kind} formats up "
            f"to version {version}: upgrade pprender"
        )


def base_attrs(kind: str, version: int, title: str, conventions: str) -> dict[str, Any]:
    return {
        "format": format_name(kind, version),
        "pprender_version": __version__,
        "title": title,
        "conventions": conventions,
    }


# ----------------------------------------------------------------------------- JSON


def _check_json(value: Any, where: str) -> None:
    """Refuse what would not come back equal, of the same types, from JSON text."""
    if value is None or type(value) in (bool, int, float, str):
        return
    if type(value) is list:
        for i, v in enumerate(value):
            _check_json(v, f"{where}[{i}]")
        return
    if type(value) is dict:
        for k, v in value.items():
            if type(k) is not str:
                raise Error(f"invalid {where}: key {k!r} is not a str (JSON keys are text)")
            _check_json(v, f"{where}[{k!r}]")
        return
    hint = ""
    if isinstance(value, tuple):
        hint = " (a tuple would come back as a list: pass a list)"
    elif isinstance(value, (np.generic, np.ndarray)):
        hint = " (convert NumPy values with float(), int() or .tolist())"
    raise Error(
        f"invalid {where}: a {type(value).__name__} cannot be saved{hint}; values must be None, bool, "
        "int, float, str, or lists and str-keyed dicts of them"
    )


def to_json(value: Any, where: str) -> str:
    """``value`` as JSON text, refusing what would not round-trip exactly (naming ``where``)."""
    _check_json(value, where)
    return json.dumps(value)  # floats as repr: exact; nan/inf as NaN/Infinity


def extra_json(extra: Any, owner: str) -> str:
    """The ``extra`` dict as JSON text; :class:`Error` naming the first key whose value cannot be saved."""
    if type(extra) is not dict:
        raise Error(f"invalid {owner}.extra: a dict, got {type(extra).__name__}")
    for k, v in extra.items():
        if type(k) is not str:
            raise Error(f"invalid {owner}.extra key {k!r}: keys must be str")
        _check_json(v, f"{owner}.extra[{k!r}]")
    return json.dumps(extra)


def from_json(attrs: Mapping[str, Any], name: str, where: str) -> Any:
    text = attrs.get(name)
    if not isinstance(text, str):
        raise Error(f"invalid {where}: attribute {name!r} missing or not JSON text")
    try:
        return json.loads(text)
    except ValueError:
        raise Error(f"invalid {where}: attribute {name!r} is not valid JSON") from None


# ----------------------------------------------------------------------------- variables


def variable(dims: tuple[str, ...], data: Any, attrs: Mapping[str, Any] | None = None) -> tuple[Any, ...]:
    """An xarray variable tuple recording the array's dtype (:data:`DTYPE_ATTR`)."""
    a = np.asarray(data)
    return (dims, a, {**(attrs or {}), DTYPE_ATTR: a.dtype.str})


def array(ds: Any, name: str, dims: tuple[str, ...], where: str) -> np.ndarray:
    """Variable ``name`` of ``ds`` as a NumPy array in the order ``dims`` (a ``...`` first
    keeps leading dimensions in their order), cast back to its recorded dtype (exactly)."""
    if name not in ds.variables:
        raise Error(f"invalid {where}: no variable {name!r}")
    v = ds[name]
    try:
        v = v.transpose(*dims)
    except ValueError:
        raise Error(f"invalid {where}: variable {name!r} has dimensions {v.dims}, expected {dims}") from None
    a = np.asarray(v.values)
    want = v.attrs.get(DTYPE_ATTR)
    if isinstance(want, str) and a.dtype.str != want:
        b = a.astype(np.dtype(want))
        if not np.array_equal(b, a, equal_nan=b.dtype.kind in "fc"):
            raise Error(f"invalid {where}: variable {name!r} does not convert exactly to {want}")
        a = b
    return a


# ----------------------------------------------------------------------------- files


#: What ``overwrite=True`` may replace (never a candidate database, nor anything else).
REPLACEABLE = ("RenderResult", "Measurement")


def _existing_kind(path: Path) -> str | None:
    """The ``format`` attribute of a saved RenderResult or Measurement at ``path``, else None."""
    try:
        if path.is_dir():
            with open(path / "zarr.json") as f:
                fmt = json.load(f).get("attributes", {}).get("format")
        else:
            xr = _xarray()
            with xr.open_dataset(path, decode_cf=False) as ds:
                fmt = ds.attrs.get("format")
    except Exception:  # anything unreadable is not ours
        return None
    ok = isinstance(fmt, str) and any(fmt.startswith(f"pprender.{k}/") for k in REPLACEABLE)
    return fmt if ok else None


def _same(a: Any, b: Any) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind in "OUS" or b.dtype.kind in "OUS":
        return a.shape == b.shape and [str(x) for x in a.flat] == [str(x) for x in b.flat]
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _open(path: Path, suffix: str) -> Any:
    xr = _xarray()
    kw = dict(decode_times=False, decode_timedelta=False, mask_and_scale=False)
    if suffix == ".zarr":
        return xr.open_dataset(path, engine="zarr", consolidated=False, zarr_format=3, chunks=None, **kw)
    return xr.open_dataset(path, **kw)


def write(ds: Any, path: str | os.PathLike[str], overwrite: bool) -> None:
    """Write ``ds`` to ``path`` atomically (module docstring)."""
    suffix = _suffix(path)
    p = Path(path)
    if not isinstance(overwrite, (bool, np.bool_)):
        raise Error(f"invalid overwrite = {overwrite!r}: True or False")
    if p.exists() or p.is_symlink():
        if not overwrite:
            raise Error(f"invalid path {str(path)!r}: it exists; pass overwrite=True to replace it or choose another path")
        if _existing_kind(p) is None:
            raise Error(
                f"invalid path {str(path)!r}: overwrite=True replaces only saved pprender RenderResults "
                "and Measurements, and this is something else"
            )
    if not p.parent.is_dir():
        raise Error(f"invalid path {str(path)!r}: its directory {str(p.parent)!r} does not exist")
    ds = ds.copy()
    ds.attrs["created"] = datetime.datetime.now(datetime.timezone.utc).isoformat()
    encoding = {name: {"_FillValue": None} for name in ds.variables}
    tmp = p.parent / f".{p.name}.{uuid.uuid4().hex}.partial{suffix}"
    try:
        if suffix == ".zarr":
            ds.to_zarr(tmp, mode="w-", zarr_format=3, consolidated=False, encoding=encoding,
                       write_empty_chunks=True)
        else:
            try:
                ds.to_netcdf(tmp, encoding=encoding)
            except (ValueError, TypeError, OverflowError) as e:
                raise Error(
                    f"invalid path {str(path)!r}: this netCDF engine cannot store the data exactly ({e}); "
                    "save as '.zarr' instead"
                ) from None
            _verify(ds, tmp, suffix, path)
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        elif p.exists() and tmp.is_dir():
            p.unlink()
        os.replace(tmp, p)
    finally:
        if tmp.is_dir():
            shutil.rmtree(tmp)
        elif tmp.exists():
            tmp.unlink()


def _verify(ds: Any, tmp: Path, suffix: str, path: str | os.PathLike[str]) -> None:
    """Read ``tmp`` back and refuse it unless every variable and attribute is what was meant."""
    with _open(tmp, suffix) as back:
        back.load()
        for name, v in ds.variables.items():
            w = back.variables.get(name)
            ok = w is not None and w.dims == v.dims
            if ok:
                want = np.asarray(v.values)
                got = np.asarray(w.values)
                if got.dtype != want.dtype and want.dtype.kind in "biuf":
                    got = got.astype(want.dtype)
                ok = _same(want, got)
            if not ok:
                raise Error(
                    f"invalid path {str(path)!r}: the netCDF engine does not store variable {name!r} "
                    "exactly; save as '.zarr' instead"
                )
        for k, a in ds.attrs.items():
            b = back.attrs.get(k)
            if isinstance(a, str):
                same = isinstance(b, str) and b == a
            else:  # numbers: pprender writes only finite floats as plain attributes
                same = b is not None and np.ndim(b) == 0 and float(b) == float(a)
            if not same:
                raise Error(
                    f"invalid path {str(path)!r}: the netCDF engine does not store attribute {k!r} "
                    "exactly; save as '.zarr' instead"
                )


def read(path: str | os.PathLike[str], kind: str) -> Any:
    """The dataset at ``path``, loaded into memory and closed."""
    suffix = _suffix(path)
    p = Path(path)
    if not p.exists():
        raise Error(f"invalid path {str(path)!r}: nothing there")
    try:
        ds = _open(p, suffix)
    except Error:
        raise
    except Exception as e:
        raise Error(f"invalid path {str(path)!r}: not a pprender {kind} ({type(e).__name__}: {e})") from None
    with ds:
        return ds.load()
