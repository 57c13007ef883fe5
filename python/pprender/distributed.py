"""Moved to :mod:`pprender.inverse.distributed`; this import path is kept and is that module."""

import sys

from .inverse import distributed as _moved
from .inverse.distributed import *  # noqa: F401,F403  (for static analysis; the module below is the same)

sys.modules[__name__] = _moved
