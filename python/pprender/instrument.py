"""Moved to :mod:`pprender.inverse.instrument`; this import path is kept and is that module."""

import sys

from .inverse import instrument as _moved
from .inverse.instrument import *  # noqa: F401,F403  (for static analysis; the module below is the same)

sys.modules[__name__] = _moved
