"""Connectivity of the voxel graph: which voxels insulating faces cut off."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

__all__ = ["connected_components", "FloatingClusters"]


@dataclass(frozen=True)
class FloatingClusters:
    """Voxel clusters cut off from the rest by insulating (R = inf) interfaces.

    Their temperature level is undetermined (fixed to zero mean per cluster); they carry
    no flux across their boundary but still conduct inside themselves.

    Attributes
    ----------
    count : int
        Number of clusters besides the largest connected one.
    voxels : ndarray of int
        Size (voxels) of each floating cluster.
    volume_fraction : float
        Fraction of the grid in floating clusters.
    """

    count: int
    voxels: np.ndarray
    volume_fraction: float


def connected_components(g: np.ndarray) -> tuple[int, np.ndarray]:
    """Connected components of the voxel graph whose edges are faces with g > 0.

    Returns
    -------
    n : int
        Number of components (1 unless insulating interfaces cut off clusters).
    labels : ndarray of int32, shape (n1, n2, n3)
        Component of every voxel; component 0 is the largest.
    """
    shape = g.shape[1:]
    N = int(np.prod(shape))
    ids = np.arange(N).reshape(shape)
    rows, cols = [], []
    for d in range(3):
        mask = g[d] > 0
        rows.append(ids[mask])
        cols.append(np.roll(ids, -1, axis=d)[mask])
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    adj = scipy.sparse.coo_array((np.ones(r.size, dtype=np.int8), (r, c)), shape=(N, N)).tocsr()
    n, labels = scipy.sparse.csgraph.connected_components(adj, directed=False)
    if n > 1:
        sizes = np.bincount(labels, minlength=n)
        order = np.argsort(-sizes, kind="stable")
        remap = np.empty(n, dtype=np.int64)
        remap[order] = np.arange(n)
        labels = remap[labels]
    return int(n), labels.reshape(shape).astype(np.int32)
