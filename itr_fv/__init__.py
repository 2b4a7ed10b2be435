"""itr_fv: the discrete model of heat conduction with interface resistance and its reference
finite-volume solver (sparse assembly + pyamg-preconditioned CG).

Public API::

    from itr_fv import Materials, Microstructure, homogenize
    from itr_fv.rve import FillerSpec, generate_rve      # dense periodic packings
    from itr_fv import analytic                          # exact / reference formulas
    from itr_fv import read_volume, PhaseTable, microstructure_from_image  # segmented volumes

Subpackages, by job (each imports only those before it): ``materials`` (phases, interface
resistances, parameter names, size distributions, the paper's tables), ``rve`` (RVE
specification, packing, voxel images), ``discrete`` (the discrete model both solvers solve:
face geometry, interface laws, operator, problem), ``output`` (VTK, renders) and
``solvers`` (the driver, the backend registry, CG, the pyamg backend, the memory guard,
warm starts, the result). Beside them: ``analytic`` (exact and reference formulas),
``io`` (atomic writes, run manifests), ``checks`` (argument checks) and ``numba_cache``
(where compiled kernels are cached: never inside the installed package). The module paths
before this layout still import, with a DeprecationWarning (:mod:`itr_fv._moved`).
"""

from . import _moved
from .checks import PhysicalScaleWarning
from .materials.properties import Materials
from .rve.from_image import microstructure_from_image
from .rve.microstructure import Microstructure, ParticleTable
from .rve.phase_table import PhaseTable
from .rve.volume_files import LabelVolume, read_volume, write_volume
from .solvers.choice import Solver, resolve_solver
from .solvers.driver import homogenize
from .solvers.resources import InsufficientMemoryError
from .solvers.result import ConvergenceError, HomogenizationResult

__all__ = ["Materials", "Microstructure", "ParticleTable", "homogenize", "Solver", "resolve_solver",
           "HomogenizationResult", "ConvergenceError", "InsufficientMemoryError",
           "PhysicalScaleWarning", "LabelVolume", "read_volume", "write_volume", "PhaseTable",
           "microstructure_from_image"]
__version__ = "0.1.0"

_moved.install()
