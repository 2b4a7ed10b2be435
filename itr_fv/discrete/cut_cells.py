"""Cut cells: the faces whose centre-to-centre segment meets a sphere surface.

For the segment interface law (:class:`itr_fv.discrete.interface_law.SegmentLaw`) every face between
voxel centres x_p and x_p + h e_d takes its geometry from the analytic spheres along that
segment, not from the two voxel labels: the length of the segment inside each filler (the
rest is matrix) and, at every place the segment crosses a sphere surface, the interface
share that multiplies the resistance R there (a function of the surface normal n at the
crossing, see :data:`SHARES`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..rve.microstructure import Microstructure
from ..rve.sphere_geometry import particle_material_ids, segment_in_sphere, staircase_factor

__all__ = ["SHARES", "SurfaceCuts", "surface_cuts"]

#: Rows one ``np.add.at`` call of :func:`surface_cuts` adds (a call over all rows of a
#: 640^3 grid holds the interpreter for 0.6 s; signals are handled between calls).
ADD_ROWS = 1 << 21


def _add_at(target: np.ndarray, rows: np.ndarray, cols: np.ndarray,
            values: np.ndarray) -> None:
    """``np.add.at(target, (rows, cols), values)`` in calls of :data:`ADD_ROWS` values, in
    order (the same sums, bit for bit: every element adds its values in the same order)."""
    for k in range(0, values.size, ADD_ROWS):
        part = slice(k, k + ADD_ROWS)
        np.add.at(target, (rows[part], cols[part]), values[part])


def _staircase_share(n: np.ndarray, d: int) -> np.ndarray:
    return staircase_factor(n)


def _normal_share(n: np.ndarray, d: int) -> np.ndarray:
    unit_d = np.abs(n[:, d]) / np.sqrt((n * n).sum(axis=1))
    return 1.0 / np.maximum(unit_d, 1e-6)


#: Interface shares of one crossing of a face along e_d by a surface of normal n (any length). Both
#: make the total interface conductance of a sphere converge to area / R: faces along e_d
#: cut the surface with density |n_d| / h^2, so sum_d |n_d| / w_d = 1 for either.
#: ``"staircase"``: w = |n_x| + |n_y| + |n_z| (the staircase law's factor);
#: ``"normal"``: w = 1 / |n_d| (the ghost-fluid choice: for a flux normal to the surface
#: each face carries its component q.e_d).
SHARES: dict[str, Callable[[np.ndarray, int], np.ndarray]] = {
    "staircase": _staircase_share, "normal": _normal_share}


@dataclass(frozen=True)
class SurfaceCuts:
    """Faces cut by sphere surfaces, or partly inside a sphere.

    Attributes
    ----------
    index : tuple of 3 int64 arrays
        Flat index of the lower voxel p of every such face, per axis (sorted, unique).
    length : tuple of 3 float64 arrays, shape (m, n_materials)
        Length of the segment x_p -> x_p + h e_d inside spheres of each material id, m
        (column 0, the matrix, stays 0: the matrix holds the rest of h).
    share : tuple of 3 float64 arrays, shape (m, n_materials)
        Summed interface shares of the crossings of spheres of each material id.
    share_name : str
        The share rule (a key of :data:`SHARES`).
    """

    index: tuple[np.ndarray, np.ndarray, np.ndarray]
    length: tuple[np.ndarray, np.ndarray, np.ndarray]
    share: tuple[np.ndarray, np.ndarray, np.ndarray]
    share_name: str


def _image_shifts(centre: np.ndarray, radius: float, box: np.ndarray, h: float) -> list:
    """Periodic images of a sphere whose reach (radius + 2 h) meets the box."""
    out = []
    for sx in (-1, 0, 1):
        for sy in (-1, 0, 1):
            for sz in (-1, 0, 1):
                c = centre + np.array([sx, sy, sz]) * box
                if np.all(c + radius + 2 * h > 0) and np.all(c - radius - 2 * h < box):
                    out.append(c)
    return out


def surface_cuts(ms: Microstructure, share: str = "staircase") -> SurfaceCuts:
    """The cut faces of ``ms`` (with a particle table) and their segment geometry.

    Parameters
    ----------
    ms : Microstructure
        Voxel image with its particle table (spheres).
    share : {"staircase", "normal"}
        Interface share of a crossing (:data:`SHARES`).

    Returns
    -------
    SurfaceCuts
    """
    if ms.particles is None:
        raise ValueError("ms: the segment law needs the particle table (a Microstructure from "
                         "from_spheres or generate_rve), not a plain label image")
    if share not in SHARES:
        raise ValueError(f"share: expected one of {sorted(SHARES)}, got {share!r}")
    rule = SHARES[share]
    table = ms.particles
    n = np.array(ms.shape)
    h = ms.voxel_m
    box = n * h
    mat_of = particle_material_ids(ms)
    n_mat = len(ms.names)
    rows: list[list] = [[] for _ in range(3)]
    for pid, (c0, a) in enumerate(zip(np.mod(table.centers_m, box), table.radii_m), start=1):
        for c in _image_shifts(c0, float(a), box, h):
            lo = np.maximum(np.floor((c - a) / h - 1.5).astype(int), 0)
            hi = np.minimum(np.ceil((c + a) / h).astype(int), n - 1)
            if np.any(lo > hi):
                continue
            axes = [np.arange(lo[k], hi[k] + 1) for k in range(3)]
            cells = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
            x = (cells + 0.5) * h
            dist = np.sqrt(((x - c) ** 2).sum(axis=1))
            # a segment of length h from x can reach the surface (it starts within h of it;
            # one starting deeper lies wholly inside the convex sphere: the staircase law's face)
            near = np.abs(dist - a) < 1.01 * h
            cells, x = cells[near], x[near]
            for d in range(3):
                inside, w = segment_in_sphere(x, d, h, c, float(a), rule)
                keep = (inside > 0.0) & ((inside < h) | (w > 0.0))
                if keep.any():
                    flat = np.ravel_multi_index(tuple(cells[keep].T), ms.shape)
                    rows[d].append((flat, np.full(flat.size, mat_of[pid]), inside[keep], w[keep]))
    index, length, shares = [], [], []
    for d in range(3):
        if rows[d]:
            flat, mat, ln, w = (np.concatenate(col) for col in zip(*rows[d]))
        else:
            flat = mat = np.zeros(0, dtype=np.int64)
            ln = w = np.zeros(0)
        faces, inverse = np.unique(flat, return_inverse=True)
        L = np.zeros((faces.size, n_mat))
        W = np.zeros((faces.size, n_mat))
        _add_at(L, inverse, mat, ln)
        _add_at(W, inverse, mat, w)
        index.append(faces)
        length.append(L)
        shares.append(W)
    return SurfaceCuts(tuple(index), tuple(length), tuple(shares), share)
