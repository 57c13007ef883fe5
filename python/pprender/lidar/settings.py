"""Render settings, apart from the sensor's optics: how finely and how exactly a render is
computed (:class:`Settings`), and the accuracy dial's presets (:data:`QUALITY`). Their
cost and error are measured in docs/tradeoff.md."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._core import Error


def _is_int(x: Any) -> bool:
    return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))

_TABLE_KEYS = ("n_z", "n_psi", "n_z_lambertian", "n_psi_lambertian", "n_z_double", "n_psi_double",
               "double_order")

#: The quality presets of :class:`Lidar` (``quality=``): BRDF table grids (keywords of
#: :func:`pprender.brdf_table`; absent keys take its defaults: single n_z 256 / n_psi 32,
#: multiple + diffuse 256 / 8, double 32 / 8 at order 48) and the default image
#: resolution (pixels across one range FWHM), visibility samples per pixel and paths per
#: pixel of inter-reflections (with ``bounces`` > 1).
#: ``"reference"`` renders on the CPU in f64
#: with exact BRDFs (no tables). Their cost and error are measured in docs/tradeoff.md.
QUALITY: dict[str, dict[str, Any]] = {
    "fast": {"table": {"n_z": 64, "n_psi": 16, "n_z_lambertian": 64, "n_psi_lambertian": 4,
                       "n_z_double": 16, "n_psi_double": 4, "double_order": 32},
             "pixels_per_fwhm": 2.0, "min_resolution": 32, "pixel_samples": 1, "path_samples": 4},
    "balanced": {"table": {}, "pixels_per_fwhm": 4.0, "min_resolution": 64, "pixel_samples": 8,
                 "path_samples": 16},
    "accurate": {"table": {"n_z": 1024, "n_psi": 64, "n_z_lambertian": 512,
                           "n_psi_lambertian": 16, "n_z_double": 64, "n_psi_double": 16,
                           "double_order": 96},
                 "pixels_per_fwhm": 8.0, "min_resolution": 64, "pixel_samples": 16, "path_samples": 64},
    "reference": {"table": {}, "pixels_per_fwhm": 4.0, "min_resolution": 64, "pixel_samples": 16,
                  "path_samples": 256},
}


@dataclass(frozen=True)
class Settings:
    """How a render is computed: sampling, BRDF tables, arithmetic, the accuracy preset.

    Give them to :func:`pprender.render` (``settings=``) to render one sensor at several
    settings, or as keywords of :class:`~pprender.lidar.sensor.Lidar` (its
    :attr:`~pprender.lidar.sensor.Lidar.settings`).

    Parameters
    ----------
    resolution : int, optional
        Image side in pixels, in [1, 8192]; given explicitly, it overrides the ``quality``
        preset's. Default (None): the preset's; with the default ``"balanced"``, such that a
        pixel is a quarter of the range FWHM across (clamped to [64, 1024]): about 1e-3
        relative error of cross-sections for generic orientations (edges aligned with the
        pixel grid alias more; docs/render-accuracy.md). See :meth:`effective_resolution`.
    supersampling : int, optional
        Sub-pixels per pixel side for visibility and the profile, in [1, 64]. It refines
        everything at ``supersampling^2`` times the cost. Default 1.
    pixel_samples : int, optional
        Visibility samples per (sub-)pixel: 1, 2, 4, 8 or 16; given explicitly, it overrides
        the ``quality`` preset's. Default (None): the preset's. The pixel's area is shared
        among the surfaces its samples see, each shaded once at the mean of its samples (a
        (0, m, 2)-net: one sample in each of the ``K`` rows and columns of the pixel, so an
        edge's coverage is resolved to ``1/K`` of a pixel); pixels that see one surface cost
        one shading as with ``1``. With ``K > 1`` a pixel that a face narrower than a pixel
        overlaps (a wire, a panel's rim) takes that face's visible area by exact clipping
        instead (shaded on the CPU for every device), so thin parts are area-correct at any
        angle to the pixel grid (docs/thin-parts.md; paid for only where there are such
        parts). This is what makes silhouettes, panel edges and thin parts area-correct
        (docs/render-accuracy.md). With ``1`` a part thinner than a pixel is seen where a
        pixel centre falls on it.
    coverage : {"sampled", "analytic"}, optional
        ``"sampled"`` (default): the ``pixel_samples`` above. ``"analytic"``: one raster
        sample per pixel finds the triangles around it (those seen at the centres of the
        pixel's 3x3 neighbourhood, and their edge neighbours on the mesh), and each one's
        visible part of the pixel is computed exactly by clipping the triangles to the pixel
        in depth order; each is shaded once at the centroid of its part. Edges then cost no
        more samples: coverage is exact to f32 rounding for the triangles found, wherever at
        most 32 triangles overlap a pixel (else, at a vertex shared by dozens of triangles,
        the pixel falls back to its centre sample). Faces narrower than a pixel are listed
        for the pixels they overlap (as with ``pixel_samples`` above), so a wire between the
        pixel centres is not missed. Needs ``pixel_samples`` 1 (or unset).
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
    bounces : {1, 2, 3}, optional
        The most reflections a path of light may make on the mesh (default 1: each pixel's
        surface reflects straight back). 2 and 3 add the light that reaches the surface a
        pixel sees after one or two reflections off other parts (a panel against the bus, a
        dish against its mount: concave corners return light as retro-reflectors, and even
        bounces keep circular handedness while odd ones flip it). They are traced by Monte
        Carlo paths in f64 on the CPU for every backend, with ray casting against the mesh
        (pprender.render module docs; ``RenderResult.by_bounce`` splits the outputs by
        bounces). A convex or flat mesh traces nothing. The surfaces met along a path are
        evaluated without the double-bounce term.
    path_samples : int, optional
        Paths per pixel with ``bounces`` > 1, in [1, 65536], on average over the pixels the
        mesh may cover: they are drawn only in the pixels of surfaces that face another part
        of the mesh (the others have no inter-reflections), so a satellite whose corners fill
        a few pixels draws many paths there; pixels of parts thinner than a pixel in the
        view (a wire, a panel's rim seen edge-on) get 8 times as many, on top. Given
        explicitly, it overrides the ``quality`` preset's (4, 16, 64, 256 for fast,
        balanced, accurate, reference). The noise falls about as ``1 / sqrt(path_samples)``.
    path_seed : int, optional
        Seed of the paths' random numbers, in [0, 2**32 - 1] (default 0). They depend on the
        seed, the pixel and its number of paths only: the same seed gives the same bits, in
        a batch or one attitude at a time, and a fit sees common random numbers from step to
        step (a pixel's number of paths, ``path_samples`` times a power of two, changes only
        where the share of the mesh's pixels facing other parts crosses a power of
        sqrt(2), or where a part turns thinner or wider than a pixel).

    Raises
    ------
    pprender.Error
        For an invalid field, named in the message: a value out of the ranges above,
        ``brdf="shader"`` or ``arithmetic="f32"`` with ``quality="reference"``, or
        ``coverage="analytic"`` with ``pixel_samples`` other than 1.
    """

    resolution: int | None = None
    supersampling: int = 1
    pixel_samples: int | None = None
    coverage: str = "sampled"
    quality: str = "balanced"
    table: Any = None
    arithmetic: str | None = None
    brdf: str = "table"
    bounces: int = 1
    path_samples: int | None = None
    path_seed: int = 0

    def __post_init__(self) -> None:
        if not _is_int(self.bounces) or not 1 <= self.bounces <= 3:
            raise Error(f"invalid bounces = {self.bounces!r}: 1, 2 or 3 (the most reflections of a path)")
        if self.path_samples is not None and (
            not _is_int(self.path_samples) or not 1 <= self.path_samples <= 65536
        ):
            raise Error(f"invalid path_samples = {self.path_samples!r}: paths per pixel, an integer in [1, 65536]")
        if not _is_int(self.path_seed) or not 0 <= self.path_seed <= 2**32 - 1:
            raise Error(f"invalid path_seed = {self.path_seed!r}: an integer in [0, 2**32 - 1]")
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

    def effective_resolution(self, radius: float, range_fwhm: float) -> int:
        """Image side in pixels: ``resolution``, or the quality preset's default for an
        object of bounding ``radius`` (m) and a pulse of range FWHM ``range_fwhm`` (m): a pixel
        ``range_fwhm / pixels_per_fwhm`` across, clamped to [64, 1024] (``"fast"``:
        [32, 1024])."""
        if self.resolution is not None:
            return int(self.resolution)
        q = QUALITY[self.quality]
        n = math.ceil(2.0 * radius / (range_fwhm / q["pixels_per_fwhm"]))
        return int(min(1024, max(q["min_resolution"], n)))

    def effective_pixel_samples(self) -> int:
        """Visibility samples per pixel: ``pixel_samples``, or the quality preset's (1 with
        analytic ``coverage``)."""
        if self.coverage == "analytic":
            return 1
        if self.pixel_samples is not None:
            return int(self.pixel_samples)
        return int(QUALITY[self.quality]["pixel_samples"])

    def effective_path_samples(self) -> int:
        """Paths per pixel with ``bounces`` > 1: ``path_samples``, or the quality preset's."""
        if self.path_samples is not None:
            return int(self.path_samples)
        return int(QUALITY[self.quality]["path_samples"])

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
