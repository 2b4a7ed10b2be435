"""itr_fv: the discrete model of heat conduction with interface resistance and its reference
finite-volume solver (sparse assembly + pyamg-preconditioned CG).

Public API::

    from itr_fv import Materials, Microstructure, homogenize
"""

from .materials import Materials
from .microstructure import Microstructure, ParticleTable
from .result import ConvergenceError, HomogenizationResult
from .solver import homogenize

__all__ = ["Materials", "Microstructure", "ParticleTable", "homogenize",
           "HomogenizationResult", "ConvergenceError"]
__version__ = "0.1.0"
