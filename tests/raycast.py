"""trimesh/embree ray casting through the renderer's pixel centres (conventions of
src/render/mod.rs), shared by the render tests as an independent reference."""

from __future__ import annotations

import numpy as np
import trimesh


def pixel_rays(ext: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Origins (n*n, 3) at z = 2 ext above the pixel centres (row-major, row 0 at +Y) and
    directions along -Z: the receiver's orthographic rays."""
    pix = 2 * ext / n
    x = -ext + (np.arange(n) + 0.5) * pix
    y = ext - (np.arange(n) + 0.5) * pix
    X, Y = np.meshgrid(x, y)
    origins = np.stack([X.ravel(), Y.ravel(), np.full(X.size, 2 * ext)], axis=1)
    return origins, np.tile([0.0, 0.0, -1.0], (X.size, 1))


def rotated(mesh: trimesh.Trimesh, rot: np.ndarray) -> trimesh.Trimesh:
    """A copy of ``mesh`` in the telescope frame, ``p_tel = rot p_body``."""
    m = mesh.copy()
    t = np.eye(4)
    t[:3, :3] = rot
    m.apply_transform(t)
    return m
