"""Connectivity of the voxel graph: which voxels insulating faces cut off, and the projection
that removes the mean of every connected cluster (the null space of the operator)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from array_api_compat import array_namespace
from array_api_compat import device as device_of

__all__ = ["connected_components", "FloatingClusters", "ClusterProjection"]


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


class ClusterProjection:
    """Removes the mean of every connected cluster from a voxel field, in place, where the
    field lives: the orthogonal projection onto range(A), the gauge fix of theta.

    Written once against the array API standard (``sum``, ``take``, ``cumulative_sum``,
    ``astype``, arithmetic; sums in float64) for the driver's gauge and for the
    preconditioners of the array backends; the numba backend keeps a fused kernel of it.
    The sum of the largest cluster is the total minus the sums of the floating clusters,
    which are segment sums (a cumulative sum) over the floating voxels sorted by cluster
    (an order found once, on the host): one pass over the field, one over the floating
    voxels and the subtraction.

    Parameters
    ----------
    labels : ndarray of int, shape (n1, n2, n3), or None
        Connected component of every voxel (host NumPy, as :func:`connected_components`
        returns it: 0 the largest), or None for a connected grid (the mean is removed).
    like : array, optional
        An array whose namespace and device the projection's index arrays take, and so
        the fields it projects (default: host NumPy).

    Attributes
    ----------
    n_clusters : int
        Number of connected clusters.
    """

    def __init__(self, labels: np.ndarray | None, *, like: Any = None) -> None:
        xp = array_namespace(np.zeros(0) if like is None else like)
        dev = None if like is None else device_of(like)
        self.xp = xp
        self.n_clusters = 1
        if labels is None:
            return
        labels = np.asarray(labels)
        if labels.ndim != 3 or not np.issubdtype(labels.dtype, np.integer) or \
                (labels.size and labels.min() < 0):
            raise ValueError("labels: expected a 3-D array of non-negative cluster numbers, "
                             f"got dtype {labels.dtype} and shape {labels.shape}")
        flat = labels.ravel()
        counts = np.bincount(flat)
        if np.any(counts == 0):
            raise ValueError("labels: cluster numbers must be 0 .. n-1 without gaps")
        self.n_clusters = int(counts.size)
        if self.n_clusters == 1:
            return
        floating = np.flatnonzero(flat)
        order = floating[np.argsort(flat[floating], kind="stable")]
        ends = np.cumsum(counts[1:])

        def put(a: np.ndarray) -> Any:
            return xp.asarray(a, device=dev)

        self._order = put(order.astype(np.int64))
        self._starts = put(np.concatenate([[0], ends[:-1]]).astype(np.int64))
        self._ends = put(ends.astype(np.int64))
        self._labels = put(flat.astype(np.int64))
        self._counts = put(counts.astype(np.float64))

    def project(self, v: Any) -> Any:
        """Remove the mean of every cluster from ``v`` (shape (n1, n2, n3)) in place.

        Returns
        -------
        The same array ``v``.
        """
        xp = self.xp
        flat = xp.reshape(v, (-1,))
        total = xp.sum(flat, dtype=xp.float64)
        if self.n_clusters == 1:
            v -= float(total) / math.prod(v.shape)
            return v
        values = xp.astype(xp.take(flat, self._order), xp.float64)
        running = xp.cumulative_sum(values, include_initial=True)
        floating = xp.take(running, self._ends) - xp.take(running, self._starts)
        main = xp.reshape(total - xp.sum(floating), (1,))
        means = xp.concat([main, floating]) / self._counts
        v -= xp.reshape(xp.take(xp.astype(means, v.dtype), self._labels), v.shape)
        return v
