"""Analytic sphere geometry on the periodic voxel grid, shared by the face geometry, the
contact zones and the cut cells: minimum images, staircase factors, segments through spheres.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .microstructure import Microstructure

__all__ = ["min_image", "staircase_factor", "segment_in_sphere", "particle_material_ids"]


def min_image(dx: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Minimum-image form of the displacement ``dx`` (m) in a periodic box of edges ``box``."""
    return dx - box * np.round(dx / box)


def staircase_factor(n: np.ndarray) -> np.ndarray:
    """s = |n_x| + |n_y| + |n_z| for unnormalised normals n (shape (m, 3)); 1 where n = 0."""
    norm = np.sqrt((n * n).sum(axis=1))
    s = np.ones(n.shape[0])
    ok = norm > 0
    s[ok] = np.abs(n[ok]).sum(axis=1) / norm[ok]
    return s


def particle_material_ids(ms: Microstructure) -> np.ndarray:
    """Material id of every particle id (index 0: the matrix), from the particle table."""
    return np.concatenate([[0], [ms.names.index(m) for m in ms.particles.material]]
                          ).astype(np.int64)


def segment_in_sphere(x0: np.ndarray, d: int, h: float, centre: np.ndarray, radius: float,
                      share: Callable[[np.ndarray, int], np.ndarray] | None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Length (m) of the segments x0 -> x0 + h e_d inside a sphere, and the summed interface
    shares of the surface crossings strictly inside the segments.

    Parameters
    ----------
    x0 : ndarray, shape (m, 3)
        Segment starts (voxel centres), m.
    d : int
        Axis of the segments.
    h : float
        Segment length (the voxel edge), m.
    centre : ndarray, shape (3,)
        Sphere centre (the image nearest to the segments), m.
    radius : float
        Sphere radius, m.
    share : callable or None
        ``share(n, d)`` -> the factor that multiplies the interface resistance R at each
        crossing, from the outward surface normals n there (shape (c, 3), not normalised);
        None counts 1 per crossing.
    """
    w = x0 - centre
    wd = w[:, d]
    disc = radius * radius - ((w * w).sum(axis=1) - wd * wd)
    root = np.sqrt(np.maximum(disc, 0.0))
    t1 = (-wd - root) / h
    t2 = (-wd + root) / h
    inside = np.where(disc > 0, np.clip(np.minimum(t2, 1.0) - np.maximum(t1, 0.0), 0.0, None),
                      0.0) * h
    w_sum = np.zeros(len(x0))
    for t in (t1, t2):
        cross = (disc > 0) & (t > 0.0) & (t < 1.0)
        if cross.any():
            n = w[cross]  # outward normal at the crossing, of length ~radius
            n[:, d] += t[cross] * h
            w_sum[cross] += 1.0 if share is None else share(n, d)
    return inside, w_sum
