"""What :func:`pprender.render` returns (:class:`RenderResult`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .sensor import SPEED_OF_LIGHT


@dataclass
class RenderResult:
    """What :func:`render` returns; arrays are NumPy, only the requested ones are set.

    ``cross_section``: (N, 4, 4) total Mueller lidar cross-section in m^2, or (N, 4) Stokes
    when the sensor has a ``polarization``. ``profile``: (N, B, 4, 4) or (N, B, 4), m^2 per
    bin, summing over bins to ``cross_section``; ``range_axis`` (B,) bin centres (m),
    ``bin_edges`` (B+1,), ``time_axis`` (B,) round-trip delays ``2 r / c`` (s).
    ``mueller`` (N, H, W, 4, 4) / ``stokes`` (N, H, W, 4) / ``intensity`` (N, H, W): m^2 per pixel. ``range``
    (N, H, W) metres, the mean over the pixel's covered visibility samples, NaN where
    nothing is seen; ``coverage`` (N, H, W) the covered fraction of its samples.
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
