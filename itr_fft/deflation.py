"""Particle deflation: a coarse space of one constant per particle around any preconditioner.

With resistive interfaces, a particle's temperature can move as a whole against the matrix
at little energy: every particle gives one small eigenvalue of A, and neither the FFT
Laplacian nor a box-aggregation multigrid (whose coarse cells straddle particle surfaces)
sees these modes. :class:`ParticleDeflation` adds them back as an exact coarse solve on the
space Z of group indicators (one group per particle, one for the matrix) and combines it
with an inner preconditioner M multiplicatively and symmetrically:

    c1 = E^+ Z^T r,  r1 = r - A Z c1,  y = M r1,  c2 = E^+ Z^T (r1 - A y),
    z  = y + Z (c1 + c2),                 E = Z^T A Z  (the group-to-group conductances, W/K per h)

(the two-level "balancing" form, which is symmetric positive when M is, so CG may use it).
Per application: two stencil passes (the second with its group sums fused), one group-sum
pass and one combining pass on top of M. E is sparse (a particle couples to its neighbours)
and factorised once (SuperLU) with a shift of 1e-9 of its mean diagonal, which fixes its null
space (the constant, and any group cut off by insulating faces) without touching the rest.
The stencil passes use the float64 conductances: r - A Z c1 cancels to a small remainder, and
E is float64, so float32 conductances there stall CG near 1e-9 (measured on a sphere array
with R = 5e-5).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import _mg_kernels as MG

__all__ = ["ParticleDeflation", "group_operator"]


def group_operator(g: np.ndarray, groups: np.ndarray, n_groups: int) -> sp.csc_matrix:
    """E = Z^T A Z, the Galerkin operator on group constants (sparse, n_groups^2).

    Parameters
    ----------
    g : ndarray, shape (3, n1, n2, n3)
        Face conductances, W/(m^2 K).
    groups : int32 ndarray, shape (n1, n2, n3)
        Group of every cell, in [0, n_groups).
    n_groups : int
        Number of groups.
    """
    rows, cols, vals = MG.group_operator_entries(g, groups)
    r = np.concatenate([rows, cols, rows, cols])
    c = np.concatenate([rows, cols, cols, rows])
    v = np.concatenate([vals, vals, -vals, -vals])
    return sp.coo_matrix((v, (r, c)), shape=(n_groups, n_groups)).tocsc()


class ParticleDeflation:
    """Two-level preconditioner: particle constants exactly, the rest by ``inner``.

    Parameters
    ----------
    g : ndarray, shape (3, n1, n2, n3)
        Face conductances, W/(m^2 K).
    groups : int ndarray, shape (n1, n2, n3)
        Group of every cell (particle ids, 0 = matrix).
    inner : object with ``apply(r)``
        Symmetric positive preconditioner of the same operator (returns an array of r's
        shape).
    """

    def __init__(self, g: np.ndarray, groups: np.ndarray, inner: Any) -> None:
        if groups.shape != g.shape[1:]:
            raise ValueError(f"groups: expected shape {g.shape[1:]}, got {groups.shape}")
        self.g = g
        self.groups = np.ascontiguousarray(groups, dtype=np.int32)
        self.n_groups = int(self.groups.max()) + 1 if self.groups.size else 1
        e = group_operator(g, self.groups, self.n_groups)
        diag = e.diagonal()
        shift = 1e-9 * float(diag.mean()) if diag.any() else 1.0
        self._lu = spla.splu((e + shift * sp.identity(self.n_groups, format="csc")).tocsc())
        self.inner = inner
        # cells per group: the weights that keep Z c free of the (null-space) constant
        self._weights = np.bincount(self.groups.ravel(), minlength=self.n_groups) / \
            self.groups.size
        # float64: r - A Z c1 cancels to a small remainder that float32 would not hold
        self._r1 = np.empty(g.shape[1:])
        self._z = np.empty(g.shape[1:])

    def _solve_groups(self, sums: np.ndarray) -> np.ndarray:
        """E^-1 sums without its constant: the shift makes E invertible, and the round-off
        sum of a residual (which is ~0 in exact arithmetic) would otherwise come back as a
        large constant in z that pollutes r . z near convergence."""
        c = self._lu.solve(sums)
        c -= float(self._weights @ c)
        return c

    def _coarse(self, v: np.ndarray) -> np.ndarray:
        return self._solve_groups(MG.group_sums(v, self.groups, self.n_groups))

    def apply_dot(self, r: np.ndarray) -> tuple[np.ndarray, float]:
        """z = M_2 r (float64, the same array every call) and r . z."""
        c1 = self._coarse(r)
        r1 = self._r1
        MG.minus_operator_of_groups(self.g, self.groups, c1, r, r1)
        y = self.inner.apply(r1)
        # r2 = r1 - A y in place, and its group sums in the same pass
        c = c1 + self._solve_groups(MG.minus_operator_group_sums(self.g, y, r1, r1,
                                                                 self.groups, self.n_groups))
        rz = MG.add_groups_dot(y, self.groups, c, r, self._z)
        return self._z, rz

    def apply(self, r: np.ndarray) -> np.ndarray:
        """z = M_2 r (the same array every call)."""
        return self.apply_dot(r)[0]
