"""Warm starts for re-solving one geometry at new material parameters.

A campaign solves the same microstructure for many conductivity / resistance sets. The
best start in the span of already solved fields ``theta_1 .. theta_m`` (same load case) is
their Galerkin combination, the minimiser of the energy error over that span:

    x0 = V c,   (V^T A V) c = V^T b,   V = [theta_1 .. theta_m]

with the operator A and load b of the *new* parameters. One snapshot gives the optimally
scaled nearest solution; several snapshots (neighbours on both sides in log R, or along
several parameters) give a reduced-basis interpolation. Measured on a dense 60 % Al2O3
RVE (40^3, FFT solver, tol 1e-8, R_fp 1e-7 -> 5e-7): cold 74 iterations, nearest
snapshot 67, two snapshots 54, four snapshots 39.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..discrete.model import FaceGeometry, apply_operator, load_vector
from ..materials.properties import Materials

__all__ = ["galerkin_start"]


def galerkin_start(geometry: FaceGeometry, mat: Materials,
                   snapshots: Sequence[np.ndarray], directions: Sequence[int] = (0, 1, 2)
                   ) -> np.ndarray:
    """Energy-optimal warm start from solved fields of the same geometry.

    Parameters
    ----------
    geometry : FaceGeometry
        ``face_geometry(ms, staircase)`` of the microstructure.
    mat : Materials
        The new parameters (those of the solve to start).
    snapshots : sequence of ndarray
        Earlier solutions, each of shape (len(directions), n1, n2, n3) -- the ``theta`` of
        a :class:`~itr_fv.HomogenizationResult` solved with the same ``directions``.
    directions : sequence of int
        Load cases, in the order of the snapshots' first axis.

    Returns
    -------
    ndarray, shape (len(directions), n1, n2, n3)
        Pass as ``x0`` to ``itr_fv.homogenize``.
    """
    if not isinstance(geometry, FaceGeometry):
        raise ValueError("geometry: expected a FaceGeometry (itr_fv.discrete.model.face_geometry)")
    dirs = tuple(int(d) for d in directions)
    want = (len(dirs),) + tuple(geometry.shape)
    snaps = [np.asarray(s, dtype=np.float64) for s in snapshots]
    if not snaps:
        raise ValueError("snapshots: need at least one solved field")
    for s in snaps:
        if s.shape != want:
            raise ValueError(f"snapshots: expected arrays of shape {want}, got {s.shape}")
        if not np.all(np.isfinite(s)):
            raise ValueError("snapshots: contain NaN or inf")
    g = geometry.conductances(mat)
    x0 = np.zeros(want)
    for c, d in enumerate(dirs):
        b = load_vector(g, geometry.voxel_m, np.eye(3)[d]).ravel()
        V = np.stack([s[c].ravel() for s in snaps], axis=1)
        AV = np.stack([apply_operator(g, s[c]).ravel() for s in snaps], axis=1)
        G = V.T @ AV
        G = 0.5 * (G + G.T)
        coef = np.linalg.lstsq(G, V.T @ b, rcond=1e-12)[0]
        x0[c] = (V @ coef).reshape(geometry.shape)
    return x0
