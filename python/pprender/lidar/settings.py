"""Render settings: the accuracy dial's presets (:data:`QUALITY`) and the BRDF table
keywords a :class:`~pprender.lidar.sensor.Lidar` may override. Their cost and error are
measured in docs/tradeoff.md."""

from __future__ import annotations

from typing import Any

_TABLE_KEYS = ("n_z", "n_psi", "n_z_lambertian", "n_psi_lambertian", "n_z_double", "n_psi_double",
               "double_order")

#: The quality presets of :class:`Lidar` (``quality=``): BRDF table grids (keywords of
#: :func:`pprender.brdf_table`; absent keys take its defaults: single n_z 256 / n_psi 32,
#: multiple + diffuse 256 / 8, double 32 / 8 at order 48) and the default image
#: resolution (pixels across one range FWHM) and visibility samples per pixel.
#: ``"reference"`` renders on the CPU in f64
#: with exact BRDFs (no tables). Their cost and error are measured in docs/tradeoff.md.
QUALITY: dict[str, dict[str, Any]] = {
    "fast": {"table": {"n_z": 64, "n_psi": 16, "n_z_lambertian": 64, "n_psi_lambertian": 4,
                       "n_z_double": 16, "n_psi_double": 4, "double_order": 32},
             "pixels_per_fwhm": 2.0, "min_resolution": 32, "pixel_samples": 1},
    "balanced": {"table": {}, "pixels_per_fwhm": 4.0, "min_resolution": 64, "pixel_samples": 8},
    "accurate": {"table": {"n_z": 1024, "n_psi": 64, "n_z_lambertian": 512,
                           "n_psi_lambertian": 16, "n_z_double": 64, "n_psi_double": 16,
                           "double_order": 96},
                 "pixels_per_fwhm": 8.0, "min_resolution": 64, "pixel_samples": 16},
    "reference": {"table": {}, "pixels_per_fwhm": 4.0, "min_resolution": 64, "pixel_samples": 16},
}
