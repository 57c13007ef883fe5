"""Moved to :mod:`pprender.inverse.database`; this import path is kept and is that module."""

import sys

from .inverse import database as _moved
from .inverse.database import *  # noqa: F401,F403  (for static analysis; the module below is the same)

sys.modules[__name__] = _moved
