"""itr_fv: the discrete model of heat conduction with interface resistance and its reference
finite-volume solver (sparse assembly + pyamg-preconditioned CG).

Public API::

    from itr_fv import Materials, Microstructure, homogenize
    from itr_fv.rve import FillerSpec, generate_rve      # dense periodic packings
    from itr_fv import analytic                          # exact / reference formulas

Modules: ``materials`` (phases, resistances), ``microstructure`` (voxel images),
``psd`` (lognormal size distributions), ``packing`` and ``rve`` (RVE generation),
``model`` (the discrete model both solvers solve; its parts: ``face_geometry``,
``contact_zones``, ``cut_cells``, ``sphere_geometry``, ``interface_law`` (the staircase and
segment laws), ``operator``, ``connectivity``), ``solver`` (this reference solver),
``solve`` and ``result`` (shared by both solvers), ``warm_start``, ``analytic``,
``vtk_output`` and ``particle_render`` (pyvista output), ``resources`` (the memory guard),
``io`` (atomic writes, run manifests), ``checks`` (argument checks), ``numba_cache`` (where
compiled kernels are cached: never inside the installed package).
"""

from .checks import PhysicalScaleWarning
from .materials import Materials
from .microstructure import Microstructure, ParticleTable
from .resources import InsufficientMemoryError
from .result import ConvergenceError, HomogenizationResult
from .solver import homogenize

__all__ = ["Materials", "Microstructure", "ParticleTable", "homogenize",
           "HomogenizationResult", "ConvergenceError", "InsufficientMemoryError",
           "PhysicalScaleWarning"]
__version__ = "0.1.0"
