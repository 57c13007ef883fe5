"""Moved to :mod:`pprender.inverse.so3`; this import path is kept and is that module."""

import sys

from .inverse import so3 as _moved
from .inverse.so3 import *  # noqa: F401,F403  (for static analysis; the module below is the same)

sys.modules[__name__] = _moved
