"""Lidar rendering: Mueller/Stokes images, range maps and range-resolved pulse profiles.

Conventions (written once in ``src/render/mod.rs``; summary):

* Units: metres, seconds, radians; cross-sections in m^2.
* Telescope frame ``(X, Y, Z)``: ``Z`` from the target toward the receiver, ``X`` right,
  ``Y`` up in the images. Receiver direction ``wo = Z``; transmitter direction
  ``wi = (sin beta, 0, cos beta)`` for the bistatic angle ``beta``.
* Attitudes rotate the body into the telescope frame, ``p_tel = R p_body``: (N, 3, 3)
  rotation matrices, (N, 4) unit quaternions ``(w, x, y, z)`` (scalar first; scipy's
  ``as_quat()`` is scalar-last ``(x, y, z, w)``), or a ``scipy.spatial.transform.Rotation``
  (single or stacked), which is converted without ambiguity. The body
  origin is the range reference.
* Images: (N, H, W, ...) with row 0 at the top (``+Y``) and column 0 at the left
  (``-X``); they span ``[-extent, extent]`` in X and Y, ``extent`` the radius of the
  mesh's bounding sphere about the body origin.
* Range ``r = -p . (wi + wo) / 2`` relative to the body origin, positive away from the
  sensor; time axis ``t = 2 r / c``.
* Stokes bases: received beam ``(X, Y)``; transmitted beam (propagating along ``-wi``)
  ``x = normalize(-wi x Y)`` (``X`` monostatic), ``y = -wi x x`` (``-Y`` monostatic). A
  mirror facing the sensor is ``R diag(1, 1, -1, -1)``.
* Pixel values are differential lidar cross-sections ``4 pi f cos(theta_i) delta^2`` (m^2).
"""

import os

# Mesa's device-select layer complains when XDG_RUNTIME_DIR is unset (headless machines);
# it is not needed for compute. Must be set before the Vulkan loader starts.
os.environ.setdefault("NODEVICE_SELECT", "1")

from .dispatch import OffCentreWarning, _check_framing, _rotations, device_info, render  # noqa: E402
from .result import _OUTPUTS, RenderResult  # noqa: E402
from .scene import Scene, _mesh_arrays, _resolve_material  # noqa: E402
from .sensor import _FWHM_PER_SIGMA, SPEED_OF_LIGHT, Lidar, _is_int, _is_real  # noqa: E402
from .settings import _TABLE_KEYS, QUALITY, Settings  # noqa: E402

__all__ = ["Lidar", "OffCentreWarning", "QUALITY", "RenderResult", "Scene", "Settings", "device_info", "render",
           "SPEED_OF_LIGHT"]
