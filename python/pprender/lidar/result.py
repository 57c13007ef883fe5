"""What :func:`pprender.render` returns (:class:`RenderResult`)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import _io
from .._core import Error
from .sensor import SPEED_OF_LIGHT

#: Version of the saved layout (:meth:`RenderResult.to_xarray`); files of a newer version
#: are refused.
FORMAT_VERSION = 1


@dataclass
class RenderResult:
    """What :func:`pprender.render` returns; arrays are NumPy, only the requested ones are set.

    Attributes
    ----------
    cross_section : numpy.ndarray
        (N, 4, 4) total Mueller lidar cross-section in m^2, or (N, 4) Stokes when the sensor
        has a ``polarization`` ((N,) intensity with ``intensity_only``).
    bin_edges : numpy.ndarray
        (B+1,) profile bin edges (m of range).
    pixel_size : float
        Side of an image pixel (m).
    extent : float
        Image half-width (m): images span ``[-extent, extent]`` in X and Y, ``extent`` the
        radius of the mesh's bounding sphere about the body origin (:mod:`pprender.lidar`).
    device : str
        What rendered: the adapter's name, or the f64 twin or reference renderer.
    profile : numpy.ndarray or None
        (N, B, 4, 4) or (N, B, 4) ((N, B) with ``intensity_only``), m^2 per bin, summing over
        bins to ``cross_section``.
    mueller : numpy.ndarray or None
        (N, H, W, 4, 4) Mueller images, m^2 per pixel.
    stokes : numpy.ndarray or None
        (N, H, W, 4) Stokes images, m^2 per pixel.
    intensity : numpy.ndarray or None
        (N, H, W) intensity images (``intensity_only``), m^2 per pixel.
    range : numpy.ndarray or None
        (N, H, W) metres, the mean over the pixel's covered visibility samples, NaN where
        nothing is seen.
    coverage : numpy.ndarray or None
        (N, H, W) the covered fraction of the pixel's samples (set with ``range``).
    illuminated_area : numpy.ndarray or None
        (N, B) m^2, output ``"illuminated_area"``: per range bin ``j`` the effective
        projected area of the directly lit surface that returns light in it, ``A_j =
        (sum_q w_jq I_q)^2 / sum_q (w_jq I_q)^2 / a_q`` over the shaded surface parts ``q``
        (a pixel, or the share of a pixel one surface covers), ``I_q`` the part's ``S0``
        cross-section (where positive), ``a_q`` its projected area and ``w_jq`` its pulse
        weight in the bin, the profile's own (footprint and pulse shape included). The
        renderer accumulates the denominator beside the profile (no images needed: a
        profile-only render gives it); the numerator is the single-bounce ``S0`` profile.
        Goodman's effective area ``(int I)^2 / int I^2``: a flat plate seen face-on gives
        its area in every bin its return reaches. Light reflected between parts
        (``bounces`` > 1) is not in it. 0 where nothing returns light;
        :func:`pprender.inverse.speckle.illuminated_area` uses it.
    table_seconds : float
        Time spent preparing the BRDF tables for this render (s; 0 for
        ``quality="reference"``).
    stage_seconds : dict
        Wall-clock seconds of this render's stages, in order, a diagnostic for benchmarks:
        ``tables``, ``device context`` (device creation on first use), ``plan``,
        ``pipeline and buffers`` (shader compilation on first use), ``encode and submit``,
        ``device`` (waiting for the GPU), ``readback`` (mapping and decoding the results)
        on a device; ``tables`` and ``render`` for ``arithmetic="f64"``, ``render`` for
        ``quality="reference"``; then ``paths`` (with ``bounces`` > 1) and ``to NumPy``.
        Empty for a result assembled by hand.
    by_bounce : dict or None
        With ``bounces`` > 1 (:class:`~pprender.lidar.settings.Settings`): the outputs split
        by the number of reflections, a bounce axis after the attitude's (index ``k - 1``
        for ``k`` bounces, summing to the totals): ``"cross_section"`` (N, K, ...) and, as
        requested, ``"profile"`` (N, K, B, ...) and ``"mueller"``/``"stokes"``/``"intensity"``
        (N, K, H, W, ...). Odd and even numbers of bounces are what radar polarimetry
        separates (even ones keep circular handedness). None with one bounce.
    extra : dict
        Free-form additions; empty as :func:`pprender.render` returns it.
    wavelength : float or None
        The sensor's wavelength (m) the render was made at (the materials' wavelength); None
        for a result assembled by hand.
    range_axis : numpy.ndarray
        (B,) bin centres (m).
    time_axis : numpy.ndarray
        (B,) round-trip delays ``2 r / c`` (s).
    mask : numpy.ndarray or None
        ``coverage > 0``: the pixels where something is seen (None without ``coverage``).

    Notes
    -----
    :meth:`save` and :meth:`load` keep a result in a Zarr v3 store (``.zarr``) or a
    netCDF file (``.nc``), exactly; :meth:`to_xarray` gives the same layout as an
    :class:`xarray.Dataset`.
    """

    cross_section: np.ndarray
    bin_edges: np.ndarray
    pixel_size: float
    extent: float
    device: str
    profile: np.ndarray | None = None
    mueller: np.ndarray | None = None
    stokes: np.ndarray | None = None
    intensity: np.ndarray | None = None
    range: np.ndarray | None = None
    coverage: np.ndarray | None = None
    illuminated_area: np.ndarray | None = None
    table_seconds: float = 0.0
    stage_seconds: dict[str, float] = field(default_factory=dict)
    by_bounce: dict[str, np.ndarray] | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    #: The sensor's wavelength (m) the render was made at (the materials' wavelength);
    #: None for a result assembled by hand.
    wavelength: float | None = None

    @property
    def range_axis(self) -> np.ndarray:
        return 0.5 * (self.bin_edges[1:] + self.bin_edges[:-1])

    @property
    def time_axis(self) -> np.ndarray:
        return 2.0 * self.range_axis / SPEED_OF_LIGHT

    @property
    def mask(self) -> np.ndarray | None:
        return None if self.coverage is None else self.coverage > 0

    # ------------------------------------------------------------------ saving

    def to_xarray(self) -> Any:
        """The result as an :class:`xarray.Dataset` with named dimensions, units and metadata.

        Layout (``N`` attitudes, ``B`` range bins, ``H x W`` pixels, ``K`` bounces):

        * dimensions ``attitude``, ``range`` (bin centres, m, with ``time`` ``2 r / c`` in
          s), ``range_edge`` (the ``bin_edges`` coordinate, ``B + 1``, m), ``row`` and
          ``col`` (image pixels, with ``y`` and ``x``: the pixel centres in the telescope
          frame, m; row 0 at the top), ``mueller_row``/``mueller_col`` (0..3), ``stokes``
          (``I Q U V``) and ``bounce`` (number of reflections, 1..K);
        * variables (m^2 unless said): ``cross_section`` (``attitude`` and the
          polarization dimensions: ``mueller_row, mueller_col``, ``stokes`` or none with
          ``intensity_only``), ``profile`` (``attitude, range``, polarization),
          ``coverage`` (``attitude, row, col``, dimensionless), ``illuminated_area``
          (``attitude, range``), and the image fields
          ``mueller``, ``stokes``, ``intensity`` and ``range`` (m) as ``mueller_image``,
          ``stokes_image``, ``intensity_image`` and ``range_image`` (``attitude, row,
          col``, ...: ``stokes`` and ``range`` are dimension names, as in
          :mod:`pprender.database`); ``by_bounce`` entries as ``by_bounce_<key>`` with
          ``bounce`` after ``attitude``. Fields that are None are left out.
        * attributes (a saved file adds ``created``, UTC): ``format``
          (``pprender.RenderResult/1``), ``pprender_version``,
          ``wavelength`` (m; absent when None), ``pixel_size`` and ``extent`` (m),
          ``device``, ``table_seconds`` (s), and as JSON text ``stage_seconds``, ``extra``
          and ``by_bounce`` (null, or the list of its keys).

        Each variable keeps its NumPy dtype (``pprender_dtype`` attribute), so that
        :meth:`from_xarray` gives back the same arrays bit for bit.

        Returns
        -------
        xarray.Dataset
            The dataset (in memory).

        Raises
        ------
        pprender.Error
            Naming the field, for arrays whose shapes do not follow the layout above, a
            non-finite ``pixel_size``, ``extent``, ``table_seconds`` or ``wavelength``, a
            ``stage_seconds`` that is not a dict of str to numbers, an ``extra`` value that
            cannot be stored as JSON (naming its key), or an unknown ``by_bounce`` key.
        """
        xr = _io._xarray()
        cs = np.asarray(self.cross_section)
        if cs.ndim == 3 and cs.shape[1:] == (4, 4):
            pol: tuple[str, ...] = ("mueller_row", "mueller_col")
        elif cs.ndim == 2 and cs.shape[1] == 4:
            pol = ("stokes",)
        elif cs.ndim == 1:
            pol = ()
        else:
            raise Error(f"invalid RenderResult.cross_section: shape {cs.shape}, expected (N, 4, 4), (N, 4) or (N,)")
        edges = np.asarray(self.bin_edges)
        if edges.ndim != 1 or len(edges) < 2:
            raise Error(f"invalid RenderResult.bin_edges: shape {edges.shape}, expected (B + 1,) with B >= 1")
        dims = _field_dims(pol)
        units = {"coverage": "1", "range": "m"}
        names = {
            "cross_section": "total lidar cross-section",
            "profile": "lidar cross-section per range bin",
            "mueller": "Mueller lidar cross-section per pixel",
            "stokes": "received Stokes lidar cross-section per pixel",
            "intensity": "lidar cross-section per pixel",
            "range": "range per pixel (mean over the covered samples; NaN where nothing is seen)",
            "coverage": "covered fraction of the pixel's samples",
            "illuminated_area": "effective illuminated area per range bin (Goodman)",
        }
        scalars: dict[str, Any] = {}
        for fname in ("pixel_size", "extent", "table_seconds"):
            scalars[fname] = _finite(getattr(self, fname), f"RenderResult.{fname}")
        if not isinstance(self.device, str):
            raise Error(f"invalid RenderResult.device = {self.device!r}: a str")
        b = len(edges) - 1
        sizes = {"range": b, "mueller_row": 4, "mueller_col": 4, "stokes": 4}
        data_vars: dict[str, Any] = {}
        for fname, d in dims.items():
            a = getattr(self, fname)
            if a is None:
                continue
            a = np.asarray(a)
            _check_dims(a, d, sizes, f"RenderResult.{fname}")
            data_vars[_VARIABLE.get(fname, fname)] = _io.variable(
                d, a, {"units": units.get(fname, "m2"), "long_name": names[fname]}
            )
        bounce_keys: list[str] | None = None
        if self.by_bounce is not None:
            if not isinstance(self.by_bounce, dict):
                raise Error(f"invalid RenderResult.by_bounce: a dict or None, got {type(self.by_bounce).__name__}")
            bounce_keys = []
            for key, a in self.by_bounce.items():
                if key not in ("cross_section", "profile", "mueller", "stokes", "intensity"):
                    raise Error(
                        f"invalid RenderResult.by_bounce key {key!r}: one of cross_section, profile, "
                        "mueller, stokes, intensity"
                    )
                d = dims[key][:1] + ("bounce",) + dims[key][1:]
                a = np.asarray(a)
                _check_dims(a, d, sizes, f"RenderResult.by_bounce[{key!r}]")
                data_vars[f"by_bounce_{key}"] = _io.variable(
                    d, a, {"units": "m2", "long_name": names[key] + ", by number of reflections"}
                )
                bounce_keys.append(key)
        stages = self.stage_seconds
        if type(stages) is not dict:
            raise Error(f"invalid RenderResult.stage_seconds: a dict of str to seconds, got {type(stages).__name__}")
        r = 0.5 * (edges[1:] + edges[:-1])
        coords: dict[str, Any] = {
            "bin_edges": _io.variable(("range_edge",), edges, {"units": "m", "long_name": "range bin edges"}),
            "range": ("range", r, {"units": "m", "long_name": "range bin centre relative to the body origin, positive away from the sensor"}),
            "time": ("range", 2.0 * r / SPEED_OF_LIGHT, {"units": "s", "long_name": "round-trip delay of the range bin centre, 2 range / c"}),
        }
        try:
            probe = xr.Dataset(data_vars)
        except ValueError as e:
            raise Error(f"invalid RenderResult: its arrays disagree on a size ({e})") from None
        if "mueller_row" in probe.dims:
            coords["mueller_row"] = ("mueller_row", np.arange(4), {"long_name": "Mueller row (output Stokes index)"})
            coords["mueller_col"] = ("mueller_col", np.arange(4), {"long_name": "Mueller column (input Stokes index)"})
        if "stokes" in probe.dims:
            coords["stokes"] = ("stokes", np.array(list("IQUV"), dtype=object), {"long_name": "received Stokes component"})
        if "attitude" in probe.dims:
            coords["attitude"] = ("attitude", np.arange(probe.sizes["attitude"]), {"long_name": "attitude index"})
        if "bounce" in probe.dims:
            coords["bounce"] = ("bounce", np.arange(1, probe.sizes["bounce"] + 1), {"long_name": "number of reflections"})
        if "row" in probe.dims:
            h, w = probe.sizes["row"], probe.sizes["col"]
            px, ext = scalars["pixel_size"], scalars["extent"]
            coords["row"] = ("row", np.arange(h), {"long_name": "image row, 0 at the top (+Y)"})
            coords["col"] = ("col", np.arange(w), {"long_name": "image column, 0 at the left (-X)"})
            coords["y"] = ("row", ext - (np.arange(h) + 0.5) * px, {"units": "m", "long_name": "telescope Y of the pixel centre"})
            coords["x"] = ("col", -ext + (np.arange(w) + 0.5) * px, {"units": "m", "long_name": "telescope X of the pixel centre"})
        attrs = _io.base_attrs(
            "RenderResult", FORMAT_VERSION, "pprender render result",
            "SI units; cross-sections in m^2; telescope frame and range as in pprender.lidar "
            "(src/render/mod.rs); Mueller M[i, j] maps input Stokes j to output i",
        )
        if self.wavelength is not None:
            attrs["wavelength"] = _finite(self.wavelength, "RenderResult.wavelength")
            attrs["wavelength_units"] = "m"
        attrs.update(
            pixel_size=scalars["pixel_size"],
            extent=scalars["extent"],
            length_units="m",
            device=self.device,
            table_seconds=scalars["table_seconds"],
            stage_seconds=_io.to_json(stages, "RenderResult.stage_seconds"),
            extra=_io.extra_json(self.extra, "RenderResult"),
            by_bounce=_io.to_json(bounce_keys, "RenderResult.by_bounce"),
        )
        return xr.Dataset(data_vars, coords=coords, attrs=attrs)

    @classmethod
    def from_xarray(cls, ds: Any) -> "RenderResult":
        """The result a dataset of :meth:`to_xarray` holds (exactly the one saved).

        Parameters
        ----------
        ds : xarray.Dataset
            A dataset made by :meth:`to_xarray` (or read from a file :meth:`save` wrote).

        Returns
        -------
        RenderResult
            The result.

        Raises
        ------
        pprender.Error
            For something that is not an :class:`xarray.Dataset` of a pprender
            RenderResult, one written by a newer pprender (a newer format version), or one
            missing a variable or attribute of the layout.
        """
        xr = _io._xarray()
        if not isinstance(ds, xr.Dataset):
            raise Error(f"invalid ds of type {type(ds).__name__}: expected an xarray.Dataset")
        where = "ds"
        _io.check_format(ds.attrs, "RenderResult", FORMAT_VERSION, where)
        a = ds.attrs
        cs = ds["cross_section"] if "cross_section" in ds.variables else None
        if cs is None:
            raise Error(f"invalid {where}: no variable 'cross_section'")
        pol = tuple(d for d in cs.dims if d != "attitude")
        dims = _field_dims(pol)
        fields: dict[str, Any] = {}
        for fname, d in dims.items():
            vname = _VARIABLE.get(fname, fname)
            fields[fname] = _io.array(ds, vname, d, where) if vname in ds.variables else None
        keys = _io.from_json(a, "by_bounce", where)
        by_bounce = None
        if keys is not None:
            by_bounce = {
                k: _io.array(ds, f"by_bounce_{k}", dims[k][:1] + ("bounce",) + dims[k][1:], where) for k in keys
            }
        for name in ("pixel_size", "extent", "device", "table_seconds"):
            if name not in a:
                raise Error(f"invalid {where}: attribute {name!r} missing")
        return cls(
            bin_edges=_io.array(ds, "bin_edges", ("range_edge",), where),
            pixel_size=float(a["pixel_size"]),
            extent=float(a["extent"]),
            device=str(a["device"]),
            table_seconds=float(a["table_seconds"]),
            stage_seconds=dict(_io.from_json(a, "stage_seconds", where)),
            by_bounce=by_bounce,
            extra=dict(_io.from_json(a, "extra", where)),
            wavelength=float(a["wavelength"]) if "wavelength" in a else None,
            **fields,
        )

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> None:
        """Save the result to ``path``: a Zarr v3 store (``.zarr``) or a netCDF file (``.nc``).

        The layout is :meth:`to_xarray`'s; :meth:`load` gives back an equal result (arrays
        bit for bit). The file is written beside ``path`` and renamed into place, so
        ``path`` never holds half a result. A netCDF file is read back and checked before
        it is put in place: data the installed netCDF engine cannot store exactly is
        refused (save as ``.zarr``).

        Parameters
        ----------
        path : str or os.PathLike
            Where to save; its suffix, ``.zarr`` or ``.nc``, picks the format.
        overwrite : bool, optional
            Replace a saved RenderResult or Measurement at ``path`` (default False: an
            existing ``path`` is refused). Anything else at ``path`` (a candidate database
            included) is never replaced.

        Raises
        ------
        pprender.Error
            For another suffix (naming ``path`` and the supported ones), an existing
            ``path`` without ``overwrite=True`` (or one that is not pprender's), a directory
            that does not exist, data the netCDF engine cannot store exactly, or what
            :meth:`to_xarray` refuses.
        """
        _io._suffix(path)
        _io.write(self.to_xarray(), path, overwrite)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> "RenderResult":
        """Load a result :meth:`save` wrote (read into memory; the file is closed).

        Parameters
        ----------
        path : str or os.PathLike
            A ``.zarr`` store or ``.nc`` file.

        Returns
        -------
        RenderResult
            The result, equal to the one saved.

        Raises
        ------
        pprender.Error
            For another suffix, nothing at ``path``, a file that is not a pprender
            RenderResult (a Measurement included), or one written in a newer format.
        """
        return cls.from_xarray(_io.read(path, "RenderResult"))


def _field_dims(pol: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
    """Each field's dimensions in the saved layout, ``pol`` the polarization dimensions."""
    img = ("attitude", "row", "col")
    return {
        "cross_section": ("attitude",) + pol,
        "profile": ("attitude", "range") + pol,
        "mueller": img + ("mueller_row", "mueller_col"),
        "stokes": img + ("stokes",),
        "intensity": img,
        "range": img,
        "coverage": img,
        "illuminated_area": ("attitude", "range"),
    }


# The image fields' variable names (``stokes`` and ``range`` are dimensions).
_VARIABLE = {f: f + "_image" for f in ("mueller", "stokes", "intensity", "range")}


def _finite(value: Any, name: str) -> float:
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    if not ok or not np.isfinite(float(value)):
        raise Error(f"invalid {name} = {value!r}: a finite number")
    return float(value)


def _check_dims(a: np.ndarray, dims: tuple[str, ...], sizes: dict[str, int], name: str) -> None:
    """Refuse an array whose shape does not fit ``dims`` (fixed sizes in ``sizes``)."""
    want = tuple(sizes.get(d, "*") for d in dims)
    if a.ndim != len(dims) or any(w != "*" and n != w for n, w in zip(a.shape, want)):
        shown = "(" + ", ".join(str(w) if w != "*" else d for d, w in zip(dims, want)) + ")"
        raise Error(f"invalid {name}: shape {a.shape}, expected {shown}")


_OUTPUTS = ("profile", "mueller", "stokes", "intensity", "range", "cross_section", "illuminated_area")
