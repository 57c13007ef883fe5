"""Plots of renders, profiles, measurements and fits (matplotlib, imported on first use).

Conventions (written once here):

* Every function returns the :class:`matplotlib.figure.Figure` it drew on (made with
  ``matplotlib.pyplot``, so it shows inline in notebooks; close it with ``plt.close(fig)``
  in loops). Functions with ``ax`` draw into that axes' figure instead.
* Images follow :mod:`pprender.lidar`: row 0 at the top (``+Y``), column 0 at the left
  (``-X``), spanning ``[-extent, extent]`` metres; pixels where nothing is seen (zero
  intensity) are blank.
* Stokes images and profiles from a Mueller render are for the transmitted state
  ``input_state`` (default H, ``(1, 1, 0, 0)``, in the transmit basis): ``S = M s_in``.
* Ranges in metres (positive away from the sensor), angles in degrees unless stated.
* Range profiles (:func:`profile`) zoom by default to where the signal is: a render's bins
  cover the target's bounding sphere and the pulse, and a compact return fills a small
  part of them.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from . import polarimetry
from ._core import Error
from .lidar import RenderResult

__all__ = [
    "attitude_errors",
    "confusion_matrix",
    "corner",
    "polarization_images",
    "profile",
    "range_image",
    "stokes_images",
]

_H = (1.0, 1.0, 0.0, 0.0)

# range_window="signal": bins whose signal exceeds this fraction of the peak are "lit".
_SIGNAL_FRACTION = 1e-3
# range_window="signal": the lit span is padded on each side by this many bins (one pulse
# FWHM at the Lidar default bin width, range_fwhm / 4), or by _SIGNAL_PAD_SPAN
# of the span where that is more.
_SIGNAL_PAD_BINS = 4
_SIGNAL_PAD_SPAN = 0.1


def _plt() -> Any:
    import matplotlib.pyplot as plt

    return plt


def _state(input_state: Any) -> np.ndarray:
    s = np.asarray(input_state, dtype=np.float64)
    if s.shape != (4,) or not np.all(np.isfinite(s)) or s[0] <= 0 or np.linalg.norm(s[1:]) > s[0] * (1 + 1e-9):
        raise Error(f"invalid input_state = {input_state!r}: a physical Stokes vector (4,) with S0 > 0")
    return s


def _check_index(index: Any, n: int) -> None:
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or not -n <= index < n:
        raise Error(f"invalid index = {index!r}: an integer in [-{n}, {n}) (negative counts from the end)")


def _stokes_image(result: Any, index: int, input_state: Any) -> tuple[np.ndarray, np.ndarray | None, float]:
    """(H, W, 4) Stokes image, (H, W, 4, 4) Mueller image or None, extent."""
    if not isinstance(result, RenderResult):
        raise Error(f"invalid result of type {type(result).__name__}: expected a pprender.RenderResult")
    if result.mueller is not None:
        n = len(result.mueller)
        m = result.mueller
    elif result.stokes is not None:
        n = len(result.stokes)
        m = None
    else:
        raise Error('invalid result: no image; render with outputs=("mueller",) or ("stokes",)')
    _check_index(index, n)
    if m is not None:
        mi = m[index]
        s = mi @ _state(input_state)
        return s, mi, result.extent
    return result.stokes[index], None, result.extent  # type: ignore[index]


def _image(fig: Any, ax: Any, data: np.ndarray, extent: float, title: str, cmap: str, vmin: Any = None,
           vmax: Any = None, label: str = "", log: bool = False) -> None:
    """imshow ``data`` (NaN or masked pixels blank) with the image conventions, and a colorbar."""
    norm = None
    if log:
        from matplotlib.colors import LogNorm

        pos = data[np.isfinite(data) & (data > 0)]
        if pos.size:
            norm = LogNorm(vmin=max(float(pos.min()), float(pos.max()) * 1e-6), vmax=float(pos.max()))
            vmin = vmax = None
    im = ax.imshow(data, origin="upper", extent=(-extent, extent, -extent, extent), cmap=cmap,
                   vmin=vmin, vmax=vmax, norm=norm, interpolation="nearest")
    ax.set_title(title)
    ax.set_xlabel("X (m)")
    ax.set_ylabel("Y (m)")
    cb = fig.colorbar(im, ax=ax, shrink=0.85)
    if label:
        cb.set_label(label)


def stokes_images(result: RenderResult, index: int = 0, input_state: Sequence[float] = _H, *,
                  normalized: bool = True, log_intensity: bool = True,
                  figsize: tuple[float, float] = (11.0, 9.0)) -> Any:
    """Four Stokes images ``I, Q, U, V`` of one attitude of a render.

    2 x 2 image axes, each with a colorbar (8 axes).

    Parameters
    ----------
    result : RenderResult
        A render with ``"mueller"`` or ``"stokes"`` output.
    index : int, optional
        The attitude. Default 0.
    input_state : sequence of float, optional
        Transmitted Stokes state (4,) in the transmit basis, for a Mueller render (default H,
        ``(1, 1, 0, 0)``; module docstring).
    normalized : bool, optional
        Show ``Q, U, V`` divided by ``I``, in [-1, 1] (default True); else in m^2 per pixel.
    log_intensity : bool, optional
        ``I`` (m^2 per pixel) in logarithmic colours over 6 decades (default True), as glints
        outshine the rest.
    figsize : tuple of float, optional
        Figure size (inches). Default (11, 9).

    Returns
    -------
    matplotlib.figure.Figure
        The figure.

    Raises
    ------
    pprender.Error
        For a result without images, an ``index`` out of range or a non-physical
        ``input_state``.
    """
    s, _, extent = _stokes_image(result, index, input_state)
    i = s[..., 0]
    seen = i > 0
    plt = _plt()
    fig, axes = plt.subplots(2, 2, figsize=figsize)
    _image(fig, axes[0, 0], np.where(seen, i, np.nan), extent, "I", "viridis", label="m$^2$ per pixel",
           log=log_intensity)
    for ax, k, name in zip(axes.flat[1:], (1, 2, 3), "QUV"):
        if normalized:
            v = np.where(seen, s[..., k] / np.where(seen, i, 1.0), np.nan)
            _image(fig, ax, v, extent, f"{name} / I", "RdBu_r", -1.0, 1.0)
        else:
            v = np.where(seen, s[..., k], np.nan)
            lim = float(np.nanmax(np.abs(v))) if np.any(seen) else 1.0
            _image(fig, ax, v, extent, name, "RdBu_r", -lim, lim, "m$^2$ per pixel")
    fig.tight_layout()
    return fig


def polarization_images(result: RenderResult, index: int = 0, input_state: Sequence[float] = _H, *,
                        figsize: tuple[float, float] | None = None) -> Any:
    """Degree of polarization ``DoP``, linear ``DoLP`` and circular ``DoCP`` of the returned light.

    Computed by :func:`pprender.polarimetry.dop` etc. and, for a Mueller render, with the
    Gil-Bernabeu depolarization index of each pixel's Mueller matrix
    (:func:`pprender.polarimetry.depolarization_index`; 1 non-depolarizing, 0 an ideal
    depolarizer). One row of 3 (Stokes) or 4 (Mueller) image axes with colorbars.

    Parameters
    ----------
    result : RenderResult
        A render with ``"mueller"`` or ``"stokes"`` output.
    index : int, optional
        The attitude. Default 0.
    input_state : sequence of float, optional
        Transmitted Stokes state (4,) in the transmit basis, for a Mueller render (default H,
        ``(1, 1, 0, 0)``; module docstring).
    figsize : tuple of float, optional
        Figure size (inches); default 4.2 by 3.8 per image.

    Returns
    -------
    matplotlib.figure.Figure
        The figure.

    Raises
    ------
    pprender.Error
        For a result without images, an ``index`` out of range or a non-physical
        ``input_state``.
    """
    s, m, extent = _stokes_image(result, index, input_state)
    seen = s[..., 0] > 0
    panels = [
        ("DoP", polarimetry.dop(s)),
        ("DoLP", polarimetry.dolp(s)),
        ("DoCP", polarimetry.docp(s)),
    ]
    if m is not None:
        panels.append(("depolarization index", polarimetry.depolarization_index(m)))
    plt = _plt()
    fig, axes = plt.subplots(1, len(panels), figsize=figsize or (4.2 * len(panels), 3.8), squeeze=False)
    for ax, (title, v) in zip(axes[0], panels):
        _image(fig, ax, np.where(seen, v, np.nan), extent, title, "magma", 0.0, 1.0)
    fig.tight_layout()
    return fig


def _range_window(range_window: Any) -> str | tuple[float, float]:
    """The checked ``range_window`` option: ``"signal"``, ``"all"`` or ``(lo, hi)`` metres."""
    if isinstance(range_window, str):
        if range_window in ("signal", "all"):
            return range_window
    elif isinstance(range_window, (tuple, list, np.ndarray)) and len(range_window) == 2:
        try:
            lo, hi = (float(v) for v in range_window)
        except (TypeError, ValueError):
            pass
        else:
            if math.isfinite(lo) and math.isfinite(hi) and lo < hi:
                return lo, hi
    raise Error(f"invalid range_window = {range_window!r}: \"signal\" (zoom to the signal), \"all\" (the "
                "whole window) or (lo, hi), finite metres with lo < hi")


def _signal_limits(strength: np.ndarray, edges: np.ndarray) -> tuple[float, float]:
    """Range limits (m) around the bins where ``strength`` (B,) exceeds a small fraction of its
    peak (:func:`profile`'s ``range_window="signal"``); the whole window if there is none."""
    peak = float(np.max(strength, initial=0.0))
    lit = np.flatnonzero(strength > _SIGNAL_FRACTION * peak) if peak > 0 else np.empty(0, dtype=np.int64)
    if lit.size == 0:
        return float(edges[0]), float(edges[-1])
    lo, hi = float(edges[lit[0]]), float(edges[lit[-1] + 1])
    pad = max(_SIGNAL_PAD_BINS * float(np.median(np.diff(edges))), _SIGNAL_PAD_SPAN * (hi - lo))
    return max(lo - pad, float(edges[0])), min(hi + pad, float(edges[-1]))


def profile(data: Any, *, bin_edges: Any = None, index: int = 0, input_state: Sequence[float] = _H,
            instrument: Any = None, ax: Any = None, log: bool = False,
            range_window: str | tuple[float, float] = "signal") -> Any:
    """Range profile with its polarization channels, on one axes.

    By default the range axis is zoomed to where the signal is: a render's bins cover the
    target's bounding sphere and the pulse, and a compact return fills a small part of them.

    Parameters
    ----------
    data : Measurement, RenderResult or array_like
        * a :class:`pprender.instrument.Measurement`: recorded counts per channel (thin
          steps) and, drawn on top of them, their expectation (``signal + background``;
          thick lines through the bin centres, in the same colour with a white outline, one
          line style per channel);
        * a :class:`RenderResult` with a profile, or an array ``(..., B, 4, 4)`` Mueller /
          ``(..., B, 4)`` Stokes with ``bin_edges``: the Stokes components ``I, Q, U, V``
          (m^2 per bin; from a Mueller profile for ``input_state``), or, with an
          ``instrument``, the cross-section seen by each of its channels.
    bin_edges : array_like, optional
        (B + 1,) range bin edges (m) of an array ``data``.
    index : int, optional
        Selects the attitude (leading axis) if there is one. Default 0.
    input_state : sequence of float, optional
        Transmitted Stokes state (4,) for a Mueller profile (default H, ``(1, 1, 0, 0)``).
    instrument : Instrument, optional
        Show the cross-section seen by each of its channels instead of ``I, Q, U, V``.
    ax : matplotlib.axes.Axes, optional
        Draw into this axes (and its figure).
    log : bool, optional
        Log y axis. Default False.
    range_window : {"signal", "all"} or tuple of float, optional
        The range axis limits:

        * ``"signal"`` (default): the bins where the signal exceeds 1e-3 of its peak (the
          largest ``|value|`` of the lines drawn; for a measurement its expected signal
          counts, background excluded), padded on each side by 4 bins (one pulse FWHM at
          :class:`pprender.Lidar`'s default bin width, ``range_fwhm / 4``) or a tenth of
          that span, whichever is more, within the bins; the whole window if there is no
          signal;
        * ``"all"``: the whole window, ``bin_edges[0]`` to ``bin_edges[-1]``;
        * ``(lo, hi)``: these limits (m, finite, ``lo < hi``).

    Returns
    -------
    matplotlib.figure.Figure
        The figure.

    Raises
    ------
    pprender.Error
        For invalid data, ``index``, ``instrument``, ``input_state`` or ``range_window``.
    """
    from matplotlib import patheffects

    from .inverse.instrument import Instrument, Measurement, _channel_cross_sections, _profile_and_edges

    window = _range_window(range_window)

    def pick(a: np.ndarray, core: int) -> np.ndarray:
        if a.ndim == core:
            return a
        flat = a.reshape((-1,) + a.shape[-core:])
        _check_index(index, len(flat))
        return flat[index]

    # what to draw: (B, C) values and names, checked before a figure is made
    if isinstance(data, Measurement):
        edges = data.bin_edges
        counts = pick(data.counts, 2)
        expected = pick(data.expected, 2)
        strength = pick(data.signal, 2).max(axis=1)
        names = list(data.channel_names)
    else:
        p, edges, mueller = _profile_and_edges(data, bin_edges)
        if instrument is not None:
            if not isinstance(instrument, Instrument):
                raise Error(f"invalid instrument of type {type(instrument).__name__}: expected Instrument")
            values = pick(_channel_cross_sections(p, mueller, instrument.channels), 2)  # type: ignore[arg-type]
            names = list(instrument.channel_names)
        else:
            values = pick(p, 3) @ _state(input_state) if mueller else pick(p, 2)
            names = list("IQUV")
        strength = np.abs(values).max(axis=1)

    plt = _plt()
    if ax is None:
        fig, ax = plt.subplots(figsize=(8.0, 4.5), layout="constrained")
    else:
        fig = ax.figure
    if isinstance(data, Measurement):
        halo = [patheffects.withStroke(linewidth=3.5, foreground="white")]
        centres = 0.5 * (edges[1:] + edges[:-1])
        for c, name in enumerate(names):
            colour = f"C{c}"
            ax.stairs(counts[:, c], edges, color=colour, linewidth=0.8, alpha=0.55, zorder=2,
                      label=f"{name} counts")
            # a line style per channel, so nearly equal expectations stay told apart
            ax.plot(centres, expected[:, c], color=colour, linestyle=("-", "--", "-.", ":")[c % 4], linewidth=2.0,
                    zorder=3, path_effects=halo, label=f"{name} expected")
        ax.set_ylabel("counts per bin")
    else:
        for k, name in enumerate(names):
            ax.stairs(values[:, k], edges, label=name)
        ax.set_ylabel("cross-section per bin (m$^2$)")
    ax.set_xlabel("range (m)")
    if window == "signal":
        ax.set_xlim(*_signal_limits(strength, edges))
    elif window == "all":
        ax.set_xlim(float(edges[0]), float(edges[-1]))
    else:
        ax.set_xlim(*window)
    if log:
        ax.set_yscale("symlog" if not isinstance(data, Measurement) else "log")
    ax.legend(fontsize="small", ncol=2)
    return fig


def range_image(result: RenderResult, index: int = 0, *, ax: Any = None, cmap: str = "viridis",
                figsize: tuple[float, float] = (5.5, 4.5)) -> Any:
    """The range map of one attitude of a render: the mean range of what each pixel sees.

    One image axes (the image conventions of the module docstring) and a colorbar in
    metres; pixels where nothing is seen (NaN in ``result.range``) are masked, blank.

    Parameters
    ----------
    result : RenderResult
        A render with ``"range"`` output.
    index : int, optional
        The attitude. Default 0.
    ax : matplotlib.axes.Axes, optional
        Draw into this axes (and its figure).
    cmap : str, optional
        Colour map. Default ``"viridis"`` (dark is near).
    figsize : tuple of float, optional
        Figure size (inches) of a new figure. Default (5.5, 4.5).

    Returns
    -------
    matplotlib.figure.Figure
        The figure.

    Raises
    ------
    pprender.Error
        For a result without a range map or an ``index`` out of range.
    """
    if not isinstance(result, RenderResult):
        raise Error(f"invalid result of type {type(result).__name__}: expected a pprender.RenderResult")
    if result.range is None:
        raise Error('invalid result: no range map; render with outputs=("range",)')
    _check_index(index, len(result.range))
    plt = _plt()
    if ax is None:
        fig, ax = plt.subplots(figsize=figsize, layout="constrained")
    else:
        fig = ax.figure
    _image(fig, ax, np.ma.masked_invalid(result.range[index]), result.extent, "range (away from the sensor)", cmap,
           label="range (m)")
    return fig


def confusion_matrix(matrix: Any, labels: Sequence[str], *, normalize: bool = True, ax: Any = None,
                     cmap: str = "Blues") -> Any:
    """A confusion matrix: ``matrix[i, j]`` counts cases of true class ``i`` classified as ``j``.

    Rows are true, columns predicted; each cell is annotated with its count. One axes and a
    colorbar.

    Parameters
    ----------
    matrix : array_like
        (K, K) counts, finite and >= 0.
    labels : sequence of str
        (K,) class names.
    normalize : bool, optional
        Colours are row fractions (each true class sums to 1) when True (default), else
        counts.
    ax : matplotlib.axes.Axes, optional
        Draw into this axes (and its figure).
    cmap : str, optional
        Colour map. Default ``"Blues"``.

    Returns
    -------
    matplotlib.figure.Figure
        The figure.

    Raises
    ------
    pprender.Error
        For a matrix that is not square counts, or a wrong number of labels.
    """
    try:
        m = np.asarray(matrix, dtype=np.float64)
    except (TypeError, ValueError):
        raise Error("invalid matrix: not an array of numbers") from None
    if m.ndim != 2 or m.shape[0] != m.shape[1] or m.shape[0] == 0:
        raise Error(f"invalid matrix: shape {m.shape}, expected a square (K, K) count matrix")
    if not np.all(np.isfinite(m)) or np.any(m < 0):
        raise Error("invalid matrix: counts must be finite and >= 0")
    labels = [str(x) for x in labels]
    if len(labels) != m.shape[0]:
        raise Error(f"invalid labels: {len(labels)} labels for a {m.shape[0]} x {m.shape[0]} matrix")
    plt = _plt()
    if ax is None:
        k = m.shape[0]
        fig, ax = plt.subplots(figsize=(3.5 + 0.8 * k, 2.5 + 0.8 * k), layout="constrained")
    else:
        fig = ax.figure
    rows = m.sum(axis=1, keepdims=True)
    shown = np.divide(m, rows, out=np.zeros_like(m), where=rows > 0) if normalize else m
    im = ax.imshow(shown, cmap=cmap, vmin=0.0, vmax=1.0 if normalize else None)
    fig.colorbar(im, ax=ax, label="fraction of true class" if normalize else "count")
    ticks = np.arange(len(labels))
    ax.set_xticks(ticks, labels, rotation=45, ha="right")
    ax.set_yticks(ticks, labels)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    top = float(shown.max()) if shown.size else 1.0
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            txt = f"{int(m[i, j])}" if float(m[i, j]).is_integer() else f"{m[i, j]:.3g}"
            ax.text(j, i, txt, ha="center", va="center", fontsize="small",
                    color="white" if shown[i, j] > 0.6 * top else "black")
    return fig


def attitude_errors(errors: Any, *, bins: int = 30, degrees: bool = True, ax: Any = None) -> Any:
    """Histogram of attitude errors, with the median and 90th percentile marked.

    One axes.

    Parameters
    ----------
    errors : array_like
        Angles in radians, in [0, pi], e.g. from :func:`pprender.fit.attitude_error`.
    bins : int, optional
        Histogram bins. Default 30.
    degrees : bool, optional
        Show degrees (default True) or radians.
    ax : matplotlib.axes.Axes, optional
        Draw into this axes (and its figure).

    Returns
    -------
    matplotlib.figure.Figure
        The figure.

    Raises
    ------
    pprender.Error
        For an empty array, or values that are not angles in [0, pi].
    """
    try:
        e = np.asarray(errors, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise Error("invalid errors: not an array of numbers") from None
    if e.size == 0 or not np.all(np.isfinite(e)) or np.any(e < 0) or np.any(e > math.pi + 1e-12):
        raise Error("invalid errors: a non-empty array of angles in [0, pi] radians")
    v = np.degrees(e) if degrees else e
    unit = "deg" if degrees else "rad"
    plt = _plt()
    if ax is None:
        fig, ax = plt.subplots(figsize=(6.0, 4.0))
    else:
        fig = ax.figure
    ax.hist(v, bins=bins, color="0.6", edgecolor="0.3")
    for q, style in ((50, "-"), (90, "--")):
        x = float(np.percentile(v, q))
        ax.axvline(x, color="C3", linestyle=style, label=f"{q}th percentile {x:.3g} {unit}")
    ax.set_xlabel(f"attitude error ({unit})")
    ax.set_ylabel("count")
    ax.legend(fontsize="small")
    return fig


def corner(samples: Any, names: Sequence[str] | None = None, truths: Any = None, **kwargs: Any) -> Any:
    """Corner plot of posterior samples (the ``corner`` package).

    Quantiles 16/50/84 % are marked and titled. A p x p grid of axes.

    Parameters
    ----------
    samples : array_like
        (n, p) samples, n >= 2, e.g. ``sampler.get_chain(discard=..., flat=True)``.
    names : sequence of str, optional
        (p,) axis labels (e.g. ``model.names``).
    truths : array_like, optional
        (p,) reference values.
    **kwargs
        Further keyword arguments, passed to ``corner.corner``.

    Returns
    -------
    matplotlib.figure.Figure
        The figure.

    Raises
    ------
    pprender.Error
        For samples that are not finite (n, p) numbers with n >= 2, or ``names`` or
        ``truths`` of the wrong length.
    """
    import corner as _corner

    try:
        x = np.asarray(samples, dtype=np.float64)
    except (TypeError, ValueError):
        raise Error("invalid samples: not an array of numbers") from None
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] < 2:
        raise Error(f"invalid samples: shape {x.shape}, expected (n, p) with n >= 2")
    if not np.all(np.isfinite(x)):
        raise Error("invalid samples: not finite")
    p = x.shape[1]
    if names is not None and len(names) != p:
        raise Error(f"invalid names: {len(names)} for {p} parameters")
    if truths is not None and np.shape(truths) != (p,):
        raise Error(f"invalid truths: shape {np.shape(truths)}, expected ({p},)")
    opts = dict(labels=list(names) if names is not None else None, truths=truths,
                quantiles=[0.16, 0.5, 0.84], show_titles=True)
    opts.update(kwargs)
    return _corner.corner(x, **opts)
