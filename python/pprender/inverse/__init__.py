"""Inversion: from rendered profiles to what an instrument records and back.

* :mod:`~pprender.inverse.instrument`: the link budget, polarization channels, jitter,
  background and shot noise (:func:`~pprender.inverse.instrument.measure`);
* :mod:`~pprender.inverse.detector`: what the detector records: photon counting with dead
  time (Coates' pile-up statistics and correction) or a linear-mode APD (excess noise,
  saturation);
* :mod:`~pprender.inverse.atmosphere`: transmission by elevation (Kasten & Young air mass)
  and per-pulse scintillation (log-normal, gamma-gamma) with its effect on the counts;
* :mod:`~pprender.inverse.database`: candidate databases, shapes x materials x attitudes
  in a resumable Zarr store; :mod:`~pprender.inverse.distributed` builds them on Dask;
* :mod:`~pprender.inverse.so3`: rotation grids and distances;
* :mod:`~pprender.inverse.classify`: the vector classifier;
* :mod:`~pprender.inverse.speckle`: laser speckle statistics (degrees of freedom, Wishart
  sampling of correlated channels, the negative binomial likelihood);
* :mod:`~pprender.inverse.fit`: likelihood, nlopt and emcee fits (imported on first use:
  it loads scipy's spatial module);
* :mod:`~pprender.inverse.tumble`: tumbling targets: torque-free propagation, per-pulse
  light time and aberration, spin-state fits (imported on first use, like ``fit``).

The modules are also importable at their earlier paths (``pprender.instrument``, ...),
which are the same module objects.
"""

from __future__ import annotations

from . import atmosphere, classify, database, detector, distributed, instrument, so3, speckle

__all__ = [
    "atmosphere", "classify", "database", "detector", "distributed", "fit", "instrument", "so3", "speckle",
    "tumble",
]


def __getattr__(name: str) -> object:
    if name in ("fit", "tumble"):
        import importlib

        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
