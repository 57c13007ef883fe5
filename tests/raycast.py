"""trimesh/embree ray casting through the renderer's pixel centres (conventions of
src/render/mod.rs), shared by the render tests as an independent reference."""

from __future__ import annotations

import numpy as np
import trimesh


def pixel_rays(ext: float, n: int, offsets: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Origins at z = 2 ext above the pixel centres (n*n, 3; row-major, row 0 at +Y), or
    above each pixel's sample points ``offsets`` (k, 2) ``(u, v)`` from its top-left corner,
    ``v`` down the rows ((n*n*k, 3), pixel-major), and directions along -Z: the receiver's
    orthographic rays."""
    pix = 2 * ext / n
    uv = np.array([[0.5, 0.5]]) if offsets is None else np.asarray(offsets, float)
    shape = (n, n, len(uv))  # (row, column, sample)
    X = np.broadcast_to(-ext + (np.arange(n)[None, :, None] + uv[None, None, :, 0]) * pix, shape)
    Y = np.broadcast_to(ext - (np.arange(n)[:, None, None] + uv[None, None, :, 1]) * pix, shape)
    origins = np.stack([X.ravel(), Y.ravel(), np.full(X.size, 2 * ext)], axis=1)
    return origins, np.tile([0.0, 0.0, -1.0], (X.size, 1))


def rotated(mesh: trimesh.Trimesh, rot: np.ndarray) -> trimesh.Trimesh:
    """A copy of ``mesh`` in the telescope frame, ``p_tel = rot p_body``."""
    m = mesh.copy()
    t = np.eye(4)
    t[:3, :3] = rot
    m.apply_transform(t)
    return m
