"""The backend ``"scipy_fft"``: FFT-preconditioned CG in plain numpy/scipy (no numba).

The same preconditioner as ``"itr_fft"`` (the exact inverse of the periodic 7-point
Laplacian with face conductance ``g_ref``, the geometric mean of the positive face
conductances, applied with real FFTs in float64) and the same CG
(:func:`itr_fv.solvers.krylov.conjugate_gradients`), but the operator is
:func:`itr_fv.discrete.operator.apply_operator` (array expressions), the cluster projection
:class:`itr_fv.discrete.connectivity.ClusterProjection` and the vector operations are
numpy's. It needs no compiler and is the template of a new backend: one module, one
registration. Slower than ``"itr_fft"`` (unfused array passes, one thread).

Memory: float64 conductances (3 N), load vector (N), CG vectors x, r, p, q (4 N), the
half spectrum (~N complex) and the operator's temporaries (~3 N).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import scipy.fft

from itr_fv.discrete.connectivity import ClusterProjection
from itr_fv.discrete.operator import apply_operator
from itr_fv.discrete.problem import DiscreteSystem
from itr_fv.solvers.backends import Backend, LoadCaseSolution, PreparedSystem, register_backend
from itr_fv.solvers.krylov import conjugate_gradients

from .spectral import inverse_laplacian, reference_conductance

__all__ = ["ScipyFFTBackend"]


class _Operator:
    def __init__(self, g: np.ndarray) -> None:
        self.g = g

    def apply(self, x: np.ndarray, out: np.ndarray) -> None:
        apply_operator(self.g, x, out)


class _Preconditioner:
    """z = (g_ref L)^+ r, zero mode removed; cluster means removed when there are several."""

    def __init__(self, g: np.ndarray, clusters: ClusterProjection | None) -> None:
        shape = g.shape[1:]
        g_ref = reference_conductance(g)
        self.inverse = inverse_laplacian(shape, g_ref)
        self.shape = shape
        self.g_ref = g_ref
        self.clusters = clusters

    def apply(self, r: np.ndarray) -> np.ndarray:
        z = scipy.fft.irfftn(scipy.fft.rfftn(r) * self.inverse, s=self.shape)
        if self.clusters is not None:
            self.clusters.project(z)
        return z


class _Prepared(PreparedSystem):
    def __init__(self, system: DiscreteSystem, voxel_m: float) -> None:
        self.clusters = ClusterProjection(system.labels)
        several = self.clusters if self.clusters.n_clusters > 1 else None
        self.operator = _Operator(system.g)
        self.preconditioner = _Preconditioner(system.g, several)
        self._project = None if several is None else several.project
        self.info = {"g_ref": self.preconditioner.g_ref,
                     "k_ref": self.preconditioner.g_ref * voxel_m}

    def solve(self, b, x0, tol, maxiter, callback=None) -> LoadCaseSolution:
        x = np.zeros(b.shape) if x0 is None else np.array(x0, dtype=np.float64, copy=True)
        out = conjugate_gradients(self.operator, b, x, tol=tol, maxiter=maxiter,
                                  preconditioner=self.preconditioner, callback=callback,
                                  project=self._project)
        return LoadCaseSolution(x, out.iterations, out.history, out.residual, out.restarts)


@register_backend
class ScipyFFTBackend(Backend):
    """FFT-preconditioned CG in numpy/scipy, float64, one thread; no options."""

    name = "scipy_fft"
    default_maxiter = 3000

    def bytes_per_voxel(self) -> int:
        # 8 float64 arrays of N, the complex half spectrum and 3 N of temporaries, plus
        # the geometry's set-up peak shared with the other backends
        return int(math.ceil(8 * (8 + 1 + 3) + 40))

    def options(self) -> dict[str, Any]:
        return {}

    def prepare(self, system: DiscreteSystem, voxel_m: float) -> PreparedSystem:
        return _Prepared(system, voxel_m)
