"""The laser and receiver (:class:`Lidar`): wavelength, pulse, polarization, geometry, and
the render settings chosen with them (presets in :mod:`pprender.lidar.settings`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .._core import Error
from .settings import _TABLE_KEYS, QUALITY

SPEED_OF_LIGHT = 299_792_458.0
_FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))


def _is_real(x: Any) -> bool:
    """An int or float (NumPy's included), not a bool or a string."""
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def _is_int(x: Any) -> bool:
    return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))


@dataclass(frozen=True)
class Lidar:
    """The laser and receiver: wavelength, pulse, polarization, geometry and render settings.

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
        Image side in pixels, in [1, 8192]; given explicitly, it overrides the ``quality``
        preset's. Default (None): the preset's; with the default ``"balanced"``, such that a
        pixel is a quarter of the range FWHM across (clamped to [64, 1024]): about 1e-3
        relative error of cross-sections for generic orientations (edges aligned with the
        pixel grid alias more; docs/render-accuracy.md). See :meth:`effective_resolution`.
    bistatic_angle : float, optional
        Bistatic angle (rad) in [0, pi/2). Default 0.
    polarization : sequence of float, optional
        Transmitted Stokes vector (4,) in the transmit basis (``S0 > 0``, physical), or None
        (default) for full Mueller output.
    supersampling : int, optional
        Sub-pixels per pixel side for visibility and the profile, in [1, 64]. It refines
        everything at ``supersampling^2`` times the cost. Default 1.
    pixel_samples : int, optional
        Visibility samples per (sub-)pixel: 1, 2, 4, 8 or 16; given explicitly, it overrides
        the ``quality`` preset's. Default (None): the preset's. The pixel's area is shared
        among the surfaces its samples see, each shaded once at the mean of its samples (a
        (0, m, 2)-net: one sample in each of the ``K`` rows and columns of the pixel, so an
        edge's coverage is resolved to ``1/K`` of a pixel, and a sliver thinner than a pixel
        is still seen); pixels that see one surface cost one shading as with ``1``. This is
        what makes silhouettes, panel edges and thin parts area-correct
        (docs/render-accuracy.md).
    coverage : {"sampled", "analytic"}, optional
        ``"sampled"`` (default): the ``pixel_samples`` above. ``"analytic"``: one raster
        sample per pixel finds the triangles around it (those seen at the centres of the
        pixel's 3x3 neighbourhood, and their edge neighbours on the mesh), and each one's
        visible part of the pixel is computed exactly by clipping the triangles to the pixel
        in depth order; each is shaded once at the centroid of its part. Edges then cost no
        more samples: coverage is exact to f32 rounding wherever at most 32 triangles overlap
        a pixel (else, at a vertex shared by dozens of triangles, the pixel falls back to its
        centre sample). Needs ``pixel_samples`` 1 (or unset).
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
        The speed/accuracy dial (:data:`QUALITY`; docs/tradeoff.md measures each):
        ``"fast"`` (coarse BRDF tables, pixels half the range FWHM across), ``"balanced"``
        (default: the default grids and resolution), ``"accurate"`` (fine tables, double
        bounce at order 96, pixels an eighth of the range FWHM) or ``"reference"`` (the exact
        f64 CPU renderer: every pixel's BRDF evaluated by the core, no tables; slow).
    table : mapping of str to int, optional
        Individual overrides of the preset's BRDF table grid, with any of ``n_z``, ``n_psi``
        (single term), ``n_z_lambertian``, ``n_psi_lambertian`` (multiple + diffuse),
        ``n_z_double``, ``n_psi_double``, ``double_order`` (:func:`pprender.brdf_table`),
        each an integer in [2, 65536]. Stored as a sorted tuple of ``(key, value)`` pairs.
    intensity_only : bool, optional
        With a ``polarization``, compute only the received intensity ``S0`` (``"intensity"``
        images (N, H, W), profiles (N, B), cross-sections (N,)); the kernel then looks up only
        the Mueller elements it needs (``M00`` alone for an unpolarized transmitter). Default
        False.
    arithmetic : {"f32", "f64"}, optional
        ``"f32"`` (the device kernel, default) or ``"f64"``: the kernel's f64 CPU twin, the
        same tables, visibility samples and pulse integration in double precision (with
        rayon, on the CPU whatever ``device``; bistatic cast shadows by exact rays instead of
        the kernel's shadow map). It isolates what f32 arithmetic costs in accuracy: about
        3e-5 of a pixel's M00, half the tables' own interpolation error, and 1e-6 to 1e-4 of a
        profile, growing with the pixel's range footprint (docs/tradeoff.md measures both).
        It is also a native CPU renderer: on a machine without a GPU it can be faster than
        lavapipe (1.3x for profiles, 4x to 5x for images on 2 cores here,
        docs/render-benchmark.md, docs/equal-error.md); on a GPU ``"f32"`` is the choice.
        ``quality="reference"`` is f64 already (``arithmetic`` unset or ``"f64"``).
    brdf : {"table", "shader"}, optional
        ``"table"`` (default) looks every term up in the per-material tables of
        :func:`pprender.brdf_table`; ``"shader"`` evaluates the single, multiple and diffuse
        terms per pixel in the kernel instead (and in its twin for ``arithmetic="f64"``): the
        microfacet distribution, the complex Fresnel amplitudes and their Mueller matrix, the
        masking correlation, the masking excess and the albedos from the material's own 1D
        tables. That is the core's model for the default ``masking="table"`` (the Smith and
        seed closed forms and ``"exact"`` go through a 512-node table of theirs, within 1e-6
        and 5e-6 of M00), so only f32 arithmetic remains: the tables' grids (``n_z``,
        ``n_psi``, ``n_z_lambertian``, ``n_psi_lambertian``) and their interpolation error
        drop out, and no such tables are built. The double bounce stays tabulated (it is an
        integral per pixel). What it costs and gains is in docs/tradeoff.md. Not with
        ``quality="reference"``.

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

    def __post_init__(self) -> None:
        if self.brdf not in ("table", "shader"):
            raise Error(f'invalid brdf = {self.brdf!r}: "table" (per-material tables) or "shader" '
                        "(the single, multiple and diffuse terms evaluated per pixel)")
        if self.quality == "reference" and self.brdf == "shader":
            raise Error('invalid brdf = "shader" with quality = "reference": the reference evaluates '
                        'every term exactly per pixel already (leave brdf = "table")')
        if self.arithmetic not in (None, "f32", "f64"):
            raise Error(f'invalid arithmetic = {self.arithmetic!r}: "f32" (the device kernel) or "f64" '
                        "(its CPU twin in double precision)")
        if self.quality == "reference" and self.arithmetic == "f32":
            raise Error('invalid arithmetic = "f32" with quality = "reference": the reference is the '
                        'exact f64 renderer (leave arithmetic unset)')
        if not isinstance(self.intensity_only, (bool, np.bool_)):
            raise Error(f"invalid intensity_only = {self.intensity_only!r}: True or False")
        if self.intensity_only and self.polarization is None:
            raise Error("invalid intensity_only = True: needs a transmitted polarization (a Stokes vector); "
                        "without one the output is the Mueller matrix")
        if self.quality not in QUALITY:
            raise Error(f"invalid quality = {self.quality!r}: one of {tuple(QUALITY)}")
        if self.table is not None:
            try:
                items = dict(self.table).items()
            except (TypeError, ValueError):
                raise Error(f"invalid table = {self.table!r}: a mapping of grid keywords to integers") from None
            bad = [k for k, _ in items if k not in _TABLE_KEYS]
            if bad:
                raise Error(f"invalid table keys {bad}: choose from {_TABLE_KEYS}")
            for k, v in items:
                if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or not 2 <= v <= 65536:
                    raise Error(f"invalid table[{k!r}] = {v!r}: an integer in [2, 65536]")
            object.__setattr__(self, "table", tuple(sorted((k, int(v)) for k, v in items)))
        for name in ("wavelength", "pulse_fwhm"):
            v = getattr(self, name)
            if not (_is_real(v) and math.isfinite(v) and v > 0):
                raise Error(f"invalid {name} = {v!r}: a positive, finite number (SI units)")
        if self.bin_width is not None and not (
            _is_real(self.bin_width) and math.isfinite(self.bin_width) and self.bin_width > 0
        ):
            raise Error(f"invalid bin_width = {self.bin_width!r}: a positive length in metres")
        if self.resolution is not None and (
            not _is_int(self.resolution) or not 1 <= self.resolution <= 8192
        ):
            raise Error(f"invalid resolution = {self.resolution!r}: an integer in [1, 8192]")
        if not _is_int(self.supersampling) or not 1 <= self.supersampling <= 64:
            raise Error(f"invalid supersampling = {self.supersampling!r}: an integer in [1, 64]")
        k = self.pixel_samples
        if k is not None and (
            not isinstance(k, (int, np.integer)) or isinstance(k, bool) or k not in (1, 2, 4, 8, 16)
        ):
            raise Error(f"invalid pixel_samples = {k!r}: visibility samples per pixel, one of 1, 2, 4, 8, 16")
        if self.coverage not in ("sampled", "analytic"):
            raise Error(f"invalid coverage = {self.coverage!r}: \"sampled\" or \"analytic\"")
        if self.coverage == "analytic" and k is not None and k != 1:
            raise Error(f"invalid pixel_samples = {k!r} with coverage=\"analytic\": 1 (or None); "
                        "analytic coverage samples each pixel once to find its triangles")
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

    def effective_resolution(self, radius: float) -> int:
        """Image side in pixels: ``resolution``, or the quality preset's default for an
        object of bounding ``radius`` (m): a pixel ``range_fwhm / pixels_per_fwhm`` across,
        clamped to [64, 1024] (``"fast"``: [32, 1024])."""
        if self.resolution is not None:
            return int(self.resolution)
        q = QUALITY[self.quality]
        n = math.ceil(2.0 * radius / (self.range_fwhm / q["pixels_per_fwhm"]))
        return int(min(1024, max(q["min_resolution"], n)))

    def effective_pixel_samples(self) -> int:
        """Visibility samples per pixel: ``pixel_samples``, or the quality preset's (1 with
        analytic ``coverage``)."""
        if self.coverage == "analytic":
            return 1
        if self.pixel_samples is not None:
            return int(self.pixel_samples)
        return int(QUALITY[self.quality]["pixel_samples"])

    def effective_arithmetic(self) -> str:
        """``"f64"`` for the twin or the reference, else ``"f32"`` (the device kernel)."""
        if self.quality == "reference":
            return "f64"
        return self.arithmetic or "f32"

    def table_options(self) -> dict[str, int]:
        """The BRDF table grid the renderer uses: the preset's, then ``table``'s overrides
        (keys absent: the defaults of :func:`pprender.brdf_table`)."""
        d = dict(QUALITY[self.quality]["table"])
        d.update(dict(self.table or ()))
        return d
