"""Whether the filler percolates: clusters of filler voxels, joined through faces (inside a
particle and at contacts between particles), that reach from one face of the box to the
opposite one (:func:`itr_fv.discrete.connectivity.connected_components` on the filler's
faces, the periodic wrap cut: the image as a sample, not as a periodic cell)."""

from __future__ import annotations

import numpy as np

from ..rve.microstructure import Microstructure
from .connectivity import connected_components

__all__ = ["spanning_clusters"]


def spanning_clusters(ms: Microstructure) -> dict:
    """Per axis whether a filler cluster spans the box, and the clusters.

    Returns
    -------
    dict
        ``spans`` (three bools, axes 0, 1, 2), ``clusters`` (filler clusters),
        ``largest_fraction`` (the largest cluster's share of the filler voxels) and
        ``spanning_fraction`` (the share of the filler voxels in clusters that span any
        axis).
    """
    solid = ms.material_ids > 0
    if not solid.any():
        return {"spans": [False, False, False], "clusters": 0, "largest_fraction": 0.0,
                "spanning_fraction": 0.0}
    faces = np.zeros((3, *ms.shape), dtype=np.int8)
    for d in range(3):
        faces[d] = solid & np.roll(solid, -1, axis=d)
        np.moveaxis(faces[d], d, 0)[-1] = 0  # the wrap faces across the box's boundary
    _, labels = connected_components(faces)
    sizes = np.bincount(labels[solid])
    spans, spanning = [], set()
    for d in range(3):
        first = np.take(labels, 0, axis=d)[np.take(solid, 0, axis=d)]
        last = np.take(labels, -1, axis=d)[np.take(solid, -1, axis=d)]
        both = np.intersect1d(first, last)
        spans.append(bool(both.size))
        spanning.update(both.tolist())
    total = int(solid.sum())
    filled = sizes[sizes > 0]
    return {"spans": spans, "clusters": int(filled.size),
            "largest_fraction": float(filled.max() / total),
            "spanning_fraction": float(sum(int(sizes[c]) for c in spanning) / total)}
