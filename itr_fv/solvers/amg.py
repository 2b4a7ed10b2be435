"""The reference backend ``"itr_fv"``: sparse 7-point assembly, a pyamg hierarchy as the
preconditioner of :func:`itr_fv.solvers.krylov.conjugate_gradients`.

The singular periodic operator is made definite by pinning one voxel per connected cluster
(:func:`pin`); the hierarchy (Ruge-Stueben classical AMG by default, or smoothed
aggregation) is built once per system and reused for every load case.

Memory: measured peak 1109-1236 bytes per voxel (64^3 to 192^3, classical AMG, three load
cases, fields not kept; ``validation/results/memory.md``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyamg
import scipy.sparse

from ..discrete.problem import DiscreteSystem
from .backends import Backend, LoadCaseSolution, PreparedSystem, register_backend
from .krylov import conjugate_gradients

__all__ = ["AMGBackend", "assemble_operator", "pin", "AMG_BYTES_PER_VOXEL"]

#: Measured peak bytes per voxel (see the module docstring), rounded up.
AMG_BYTES_PER_VOXEL = 1250


def assemble_operator(g: np.ndarray) -> scipy.sparse.csr_array:
    """Sparse matrix A of the periodic 7-point operator (W/(m^2 K)), no Python voxel loop.

    ``(A theta)_p = sum over faces of g (theta_p - theta_q)``; symmetric, positive
    semi-definite, constants in its null space (one per connected cluster).

    Parameters
    ----------
    g : ndarray, shape (3, n1, n2, n3)
        Face conductances from :mod:`itr_fv.discrete.model`.

    Returns
    -------
    scipy.sparse.csr_array, shape (N, N), N = n1 n2 n3 (C order)
    """
    shape = g.shape[1:]
    N = int(np.prod(shape))
    ids = np.arange(N, dtype=np.int64).reshape(shape)
    diag = np.zeros(shape)
    rows, cols, vals = [], [], []
    for d in range(3):
        if shape[d] == 1:  # a face between a voxel and its own image carries no theta coupling
            continue
        diag += g[d]
        diag += np.roll(g[d], 1, axis=d)
        nb = np.roll(ids, -1, axis=d).ravel()
        gd = g[d].ravel()
        rows += [ids.ravel(), nb]
        cols += [nb, ids.ravel()]
        vals += [-gd, -gd]
    rows.append(ids.ravel())
    cols.append(ids.ravel())
    vals.append(diag.ravel())
    A = scipy.sparse.coo_array((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                               shape=(N, N)).tocsr()
    A.sum_duplicates()
    A.eliminate_zeros()
    return A


def pin(A: scipy.sparse.csr_array, pins: np.ndarray) -> scipy.sparse.csr_array:
    """Replace row and column of each pinned voxel by the identity (exact gauge fix).

    Each cluster's equations sum to zero, so one equation per cluster is redundant; fixing
    theta = 0 there and dropping that equation leaves the other values unchanged and makes
    the matrix symmetric positive definite.
    """
    keep = np.ones(A.shape[0])
    keep[pins] = 0.0
    P = scipy.sparse.diags_array(keep)
    Ap = (P @ A @ P).tocsr()
    # the pinned row keeps its own diagonal (not 1): a drift of theta there then weighs in
    # the residual as it would in the original equations
    diag = A.diagonal()
    scale = np.where(diag[pins] > 0, diag[pins], 1.0)
    fix = np.zeros(A.shape[0])
    fix[pins] = scale
    Ap = Ap + scipy.sparse.diags_array(fix)
    Ap = scipy.sparse.csr_array(Ap)
    Ap.eliminate_zeros()
    return Ap


_AMG = ("classical", "smoothed_aggregation")


def _amg_hierarchy(A: scipy.sparse.csr_array, amg: str) -> pyamg.multilevel.MultilevelSolver:
    """pyamg hierarchy of the pinned (SPD) operator."""
    if amg == "classical":
        return pyamg.ruge_stuben_solver(scipy.sparse.csr_matrix(A), max_coarse=400)
    return pyamg.smoothed_aggregation_solver(scipy.sparse.csr_matrix(A), B=np.ones((A.shape[0], 1)),
                                             symmetry="symmetric", max_coarse=400)




class _SparseOperator:
    """The pinned sparse operator on flat vectors."""

    def __init__(self, A: scipy.sparse.csr_array) -> None:
        self.A = A

    def apply(self, x: np.ndarray, out: np.ndarray) -> None:
        out[...] = self.A @ x


class _AMGPreconditioner:
    """One V-cycle of the hierarchy."""

    def __init__(self, ml: pyamg.multilevel.MultilevelSolver) -> None:
        self.M = ml.aspreconditioner(cycle="V")

    def apply(self, r: np.ndarray) -> np.ndarray:
        return self.M.matvec(r)


class _PreparedAMG(PreparedSystem):
    def __init__(self, system: DiscreteSystem, amg: str) -> None:
        labels = system.labels
        self.shape = system.g.shape[1:]
        self.pins = np.array([0]) if labels is None else \
            np.unique(labels.ravel(), return_index=True)[1]
        A = assemble_operator(system.g)
        self.operator = _SparseOperator(pin(A, self.pins))
        ml = _amg_hierarchy(self.operator.A, amg)
        self.preconditioner = _AMGPreconditioner(ml)
        self.info = {"amg": amg, "amg_levels": len(ml.levels),
                     "operator_complexity": float(ml.operator_complexity())}

    def solve(self, b, x0, tol, maxiter, callback=None) -> LoadCaseSolution:
        rhs = np.array(b, dtype=np.float64).ravel()
        rhs[self.pins] = 0.0
        x = np.zeros_like(rhs) if x0 is None else np.array(x0, dtype=np.float64).ravel()
        x[self.pins] = 0.0
        out = conjugate_gradients(self.operator, rhs, x, tol=tol, maxiter=maxiter,
                                  preconditioner=self.preconditioner, callback=callback)
        return LoadCaseSolution(x.reshape(self.shape), out.iterations, out.history,
                                out.residual, out.restarts)


@register_backend
class AMGBackend(Backend):
    """Sparse assembly + pyamg-preconditioned CG: the reference backend.

    Parameters
    ----------
    amg : {"classical", "smoothed_aggregation"}
        pyamg hierarchy used as the preconditioner: Ruge-Stueben classical AMG (default;
        on these M-matrices with jumping conductances it needs 3-4x fewer CG iterations
        than smoothed aggregation, see validation/results/bench_fv.md) or smoothed
        aggregation.
    """

    name = "itr_fv"
    default_maxiter = 500

    def __init__(self, amg: str = "classical") -> None:
        if amg not in _AMG:
            raise ValueError(f"amg: expected one of {sorted(_AMG)}, got {amg!r}")
        self.amg = amg

    def bytes_per_voxel(self) -> int:
        return AMG_BYTES_PER_VOXEL

    def options(self) -> dict[str, Any]:
        return {"amg": self.amg}

    def prepare(self, system: DiscreteSystem, voxel_m: float) -> PreparedSystem:
        return _PreparedAMG(system, self.amg)
