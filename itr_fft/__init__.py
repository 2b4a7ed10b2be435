"""itr_fft: FFT-preconditioned CG solver of the discrete model of :mod:`itr_fv.model`.

Public API::

    import itr_fft
    res = itr_fft.homogenize(ms, mat, tol=1e-8)       # same signature/result as itr_fv
    itr_fft.choose_solver(ms.shape)                    # "itr_fv" or "itr_fft"
"""

from .auto import choose_solver, homogenize_auto
from .solver import FLOAT32_MIN_TOL, homogenize, reference_conductance

__all__ = ["homogenize", "choose_solver", "homogenize_auto", "reference_conductance",
           "FLOAT32_MIN_TOL"]
