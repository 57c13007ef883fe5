"""The laser and receiver (:class:`Lidar`): wavelength, pulse, polarization, geometry, and
the render settings chosen with them (presets in :mod:`pprender.lidar.settings`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .._core import Error
from .settings import Settings, _is_int

SPEED_OF_LIGHT = 299_792_458.0
_FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))


def _is_real(x: Any) -> bool:
    """An int or float (NumPy's included), not a bool or a string."""
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


@dataclass(frozen=True)
class Lidar:
    """The laser and receiver: wavelength, pulse, polarization and geometry.

    The render settings (quality, resolution, samples, tables, arithmetic) are a
    :class:`~pprender.lidar.settings.Settings`, :attr:`settings`; for compatibility they are
    also given here, as keywords, and :func:`pprender.render` takes a ``settings=`` that
    overrides them.

    Parameters
    ----------
    wavelength : float, optional
        Laser wavelength (m). It must match the materials' wavelength (their refractive
        indices are for one wavelength). Default 1064e-9.
    pulse_fwhm : float, optional
        Gaussian pulse full width at half maximum (s): the received pulse, a range FWHM of
        ``c pulse_fwhm / 2``. Ignored when ``pulse_samples`` is given. Default 100e-12.
    bin_width : float, optional
        Profile bin width (m of range). Default (None): a quarter of the range FWHM.
    resolution : int, optional
        A render setting: see :class:`~pprender.lidar.settings.Settings` (it is validated
        there; ``render(settings=...)`` overrides the Lidar's).
    bistatic_angle : float, optional
        Bistatic angle (rad) in [0, pi/2). Default 0.
    polarization : sequence of float, optional
        Transmitted Stokes vector (4,) in the transmit basis (``S0 > 0``, physical), or None
        (default) for full Mueller output.
    supersampling : int, optional
        A render setting: see :class:`~pprender.lidar.settings.Settings` (it is validated
        there; ``render(settings=...)`` overrides the Lidar's).
    pixel_samples : int, optional
        A render setting: see :class:`~pprender.lidar.settings.Settings` (it is validated
        there; ``render(settings=...)`` overrides the Lidar's).
    coverage : {"sampled", "analytic"}, optional
        A render setting: see :class:`~pprender.lidar.settings.Settings` (it is validated
        there; ``render(settings=...)`` overrides the Lidar's).
    pulse_samples : sequence of float, optional
        A measured or modelled pulse shape instead of the Gaussian: received power, any
        scale, >= 0 (1 to 100000 finite values with a positive sum), sampled every
        ``pulse_sample_spacing`` seconds. The samples are joined linearly (going to zero one
        spacing beyond each end) and the shape is placed with its centroid at range 0, as the
        Gaussian's centre. Its profile is exact in f64 but accumulated on the host from the
        kernel's per-pixel range footprints, several times slower than the Gaussian's
        on-device accumulation (docs/render-benchmark.md). ``pulse_fwhm`` is then ignored and
        the defaults of ``bin_width`` and ``resolution`` use the FWHM of the Gaussian with the
        sampled shape's variance.
    pulse_sample_spacing : float, optional
        Spacing of ``pulse_samples`` (s), positive; given together with them.
    quality : {"fast", "balanced", "accurate", "reference"}, optional
        A render setting: see :class:`~pprender.lidar.settings.Settings` (it is validated
        there; ``render(settings=...)`` overrides the Lidar's).
    table : mapping of str to int, optional
        A render setting: see :class:`~pprender.lidar.settings.Settings` (it is validated
        there; ``render(settings=...)`` overrides the Lidar's).
    intensity_only : bool, optional
        With a ``polarization``, compute only the received intensity ``S0`` (``"intensity"``
        images (N, H, W), profiles (N, B), cross-sections (N,)); the kernel then looks up only
        the Mueller elements it needs (``M00`` alone for an unpolarized transmitter). Default
        False.
    arithmetic : {"f32", "f64"}, optional
        A render setting: see :class:`~pprender.lidar.settings.Settings` (it is validated
        there; ``render(settings=...)`` overrides the Lidar's).
    brdf : {"table", "shader"}, optional
        A render setting: see :class:`~pprender.lidar.settings.Settings` (it is validated
        there; ``render(settings=...)`` overrides the Lidar's).
    bounces, path_samples, path_seed : int, optional
        Render settings (inter-reflections): see :class:`~pprender.lidar.settings.Settings`
        (validated there; ``render(settings=...)`` overrides the Lidar's).

    Raises
    ------
    pprender.Error
        For an invalid field, named in the message: a value out of the ranges above,
        ``brdf="shader"`` or ``arithmetic="f32"`` with ``quality="reference"``,
        ``intensity_only`` without a ``polarization``, ``coverage="analytic"`` with
        ``pixel_samples`` other than 1, a non-physical ``polarization``
        (``sqrt(S1^2 + S2^2 + S3^2) > S0``), or only one of ``pulse_samples`` and
        ``pulse_sample_spacing``.

    See Also
    --------
    pprender.brdf_table : The per-material BRDF tables and their grid keywords.
    """

    wavelength: float = 1064e-9
    pulse_fwhm: float = 100e-12
    bin_width: float | None = None
    resolution: int | None = None
    bistatic_angle: float = 0.0
    polarization: Sequence[float] | None = None
    supersampling: int = 1
    pixel_samples: int | None = None
    coverage: str = "sampled"
    pulse_samples: Sequence[float] | None = None
    pulse_sample_spacing: float | None = None
    quality: str = "balanced"
    table: Any = None
    intensity_only: bool = False
    arithmetic: str | None = None
    brdf: str = "table"
    bounces: int = 1
    path_samples: int | None = None
    path_seed: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.intensity_only, (bool, np.bool_)):
            raise Error(f"invalid intensity_only = {self.intensity_only!r}: True or False")
        if self.intensity_only and self.polarization is None:
            raise Error("invalid intensity_only = True: needs a transmitted polarization (a Stokes vector); "
                        "without one the output is the Mueller matrix")
        for name in ("wavelength", "pulse_fwhm"):
            v = getattr(self, name)
            if not (_is_real(v) and math.isfinite(v) and v > 0):
                raise Error(f"invalid {name} = {v!r}: a positive, finite number (SI units)")
        if self.bin_width is not None and not (
            _is_real(self.bin_width) and math.isfinite(self.bin_width) and self.bin_width > 0
        ):
            raise Error(f"invalid bin_width = {self.bin_width!r}: a positive length in metres")
        settings = Settings(resolution=self.resolution, supersampling=self.supersampling,
                            pixel_samples=self.pixel_samples, coverage=self.coverage,
                            quality=self.quality, table=self.table, arithmetic=self.arithmetic,
                            brdf=self.brdf, bounces=self.bounces, path_samples=self.path_samples,
                            path_seed=self.path_seed)
        object.__setattr__(self, "table", settings.table)
        object.__setattr__(self, "_settings", settings)
        b = self.bistatic_angle
        if not (_is_real(b) and 0.0 <= b < math.pi / 2):
            raise Error(f"invalid bistatic_angle = {b!r}: radians in [0, pi/2)")
        if self.polarization is not None:
            try:
                p = np.asarray(self.polarization, dtype=np.float64)
            except (TypeError, ValueError):
                p = np.full(1, np.nan)
            if isinstance(self.polarization, (str, bytes)) or p.shape != (4,) or not np.all(np.isfinite(p)) or p[0] <= 0:
                raise Error(
                    f"invalid polarization = {self.polarization!r}: a Stokes vector (4,) with S0 > 0"
                )
            if np.linalg.norm(p[1:]) > p[0] * (1 + 1e-9):
                raise Error(
                    f"invalid polarization = {self.polarization!r}: not physical "
                    "(sqrt(S1^2 + S2^2 + S3^2) > S0)"
                )

        if self.pulse_samples is not None or self.pulse_sample_spacing is not None:
            if self.pulse_samples is None or self.pulse_sample_spacing is None:
                raise Error(
                    "invalid pulse: pulse_samples and pulse_sample_spacing go together "
                    "(samples of the received power every pulse_sample_spacing seconds)"
                )
            dt = self.pulse_sample_spacing
            if not (_is_real(dt) and math.isfinite(dt) and dt > 0):
                raise Error(f"invalid pulse_sample_spacing = {dt!r}: a positive, finite time in seconds")
            try:
                ps = np.asarray(self.pulse_samples, dtype=np.float64)
            except (TypeError, ValueError):
                raise Error("invalid pulse_samples: not an array of numbers") from None
            if ps.ndim != 1 or not 1 <= len(ps) <= 100_000:
                raise Error(f"invalid pulse_samples: shape {ps.shape}, expected (n,) with 1 <= n <= 100000")
            if not np.all(np.isfinite(ps)) or np.any(ps < 0) or not ps.sum() > 0:
                raise Error("invalid pulse_samples: finite values >= 0 with a positive sum")
            object.__setattr__(self, "pulse_samples", tuple(float(x) for x in ps))

    @property
    def sampled(self) -> bool:
        """Whether the pulse is a sampled shape (``pulse_samples``) rather than a Gaussian."""
        return self.pulse_samples is not None

    @property
    def pulse_spacing_range(self) -> float:
        """Sample spacing of a sampled pulse in range units, ``c pulse_sample_spacing / 2`` (m)."""
        if self.pulse_sample_spacing is None:
            raise Error("this Lidar has a Gaussian pulse (no pulse_samples)")
        return SPEED_OF_LIGHT * self.pulse_sample_spacing / 2.0

    @property
    def pulse_variance_range(self) -> float:
        """Variance of the pulse in range units (m^2): sigma^2 for the Gaussian; for a
        sampled shape that of its piecewise-linear interpolation (each hat adds dt^2/6)."""
        if self.pulse_samples is None:
            return self.sigma_range**2
        p = np.asarray(self.pulse_samples)
        dt = self.pulse_spacing_range
        r = dt * np.arange(len(p))
        w = p / p.sum()
        mu = float((w * r).sum())
        return float((w * (r - mu) ** 2).sum()) + dt * dt / 6.0

    @property
    def range_fwhm(self) -> float:
        """Range FWHM of the pulse, ``c pulse_fwhm / 2`` (m); for a sampled shape, the FWHM
        of the Gaussian with its variance."""
        if self.pulse_samples is not None:
            return _FWHM_PER_SIGMA * math.sqrt(self.pulse_variance_range)
        return SPEED_OF_LIGHT * self.pulse_fwhm / 2.0

    @property
    def sigma_range(self) -> float:
        return self.range_fwhm / _FWHM_PER_SIGMA

    def effective_bin_width(self) -> float:
        return self.bin_width if self.bin_width is not None else self.range_fwhm / 4.0

    @property
    def settings(self) -> Settings:
        """The render settings given with this sensor (:class:`~pprender.lidar.settings.Settings`)."""
        return self._settings  # type: ignore[attr-defined, no-any-return]

    def effective_resolution(self, radius: float) -> int:
        """Image side in pixels for an object of bounding ``radius`` (m):
        :meth:`Settings.effective_resolution` with this pulse's range FWHM."""
        return self.settings.effective_resolution(radius, self.range_fwhm)

    def effective_pixel_samples(self) -> int:
        """Visibility samples per pixel (:meth:`Settings.effective_pixel_samples`)."""
        return self.settings.effective_pixel_samples()

    def effective_arithmetic(self) -> str:
        """``"f64"`` for the twin or the reference, else ``"f32"`` (:meth:`Settings.effective_arithmetic`)."""
        return self.settings.effective_arithmetic()

    def table_options(self) -> dict[str, int]:
        """The BRDF table grid the renderer uses (:meth:`Settings.table_options`)."""
        return self.settings.table_options()
