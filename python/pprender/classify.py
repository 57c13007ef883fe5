"""Moved to :mod:`pprender.inverse.classify`; this import path is kept and is that module."""

import sys

from .inverse import classify as _moved
from .inverse.classify import *  # noqa: F401,F403  (for static analysis; the module below is the same)

sys.modules[__name__] = _moved
