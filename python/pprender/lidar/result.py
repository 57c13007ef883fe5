"""What :func:`pprender.render` returns (:class:`RenderResult`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .sensor import SPEED_OF_LIGHT


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


_OUTPUTS = ("profile", "mueller", "stokes", "intensity", "range", "cross_section")
