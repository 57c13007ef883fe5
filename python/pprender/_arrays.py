"""Return conventions shared by the array functions of pprender.microfacet and
pprender.validation.seed."""

from __future__ import annotations

from typing import Union

import numpy as np
from numpy.typing import NDArray

FloatOrArray = Union[np.float64, NDArray[np.float64]]


def _out(x: NDArray[np.float64]) -> FloatOrArray:
    """0-d results as NumPy floats, others unchanged."""
    return x[()] if x.ndim == 0 else x
