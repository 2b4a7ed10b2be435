"""itr_fft: FFT-preconditioned CG solver of the discrete model of :mod:`itr_fv.model`.

Public API::

    import itr_fft
    res = itr_fft.homogenize(ms, mat, tol=1e-8)       # same signature/result as itr_fv

Solver choice lives in the campaign layer (:mod:`surrogate.solver_choice`): this package
imports the discrete problem from ``itr_fv``, never its solver.

Importing the package sets ``OMP_WAIT_POLICY=PASSIVE`` unless the caller set it: numba's
OpenMP threads otherwise spin at every barrier, and on a machine shared with other jobs
(2 cores, load 4-6) that made two threads 5-10x slower than one; passive waiting made
them ~2x faster than one. It has to be in place before numba starts its thread pool.
"""

import os as _os

_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from .solver import FLOAT32_MIN_TOL, float32_min_tol, homogenize, reference_conductance

__all__ = ["homogenize", "reference_conductance", "FLOAT32_MIN_TOL", "float32_min_tol"]
