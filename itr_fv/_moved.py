"""Old module paths of ``itr_fv`` (before its layout by job) as aliases of the new ones.

``import itr_fv.psd`` or ``from itr_fv.model import face_geometry`` keep working: the module
imported is the new one (``itr_fv.materials.psd``, ``itr_fv.discrete.model``), the same
object under both names, with a :class:`DeprecationWarning` that names the new path.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings

__all__ = ["MOVED", "install"]

#: Old module name (under ``itr_fv``) -> its new dotted path.
MOVED = {
    "parameters": "materials.parameters", "material_system": "materials.material_system",
    "paper_data": "materials.paper_data", "psd": "materials.psd",
    "formulation_names": "materials.formulation_names",
    "rve_spec": "rve.spec", "packing": "rve.packing", "microstructure": "rve.microstructure",
    "sphere_geometry": "rve.sphere_geometry",
    "face_geometry": "discrete.face_geometry", "contact_zones": "discrete.contact_zones",
    "cut_cells": "discrete.cut_cells", "interface_law": "discrete.interface_law",
    "operator": "discrete.operator", "connectivity": "discrete.connectivity",
    "problem": "discrete.problem", "model": "discrete.model",
    "vtk_output": "output.vtk", "offscreen": "output.offscreen",
    "particle_render": "output.particle_render",
    "solve": "solvers.driver", "solver": "solvers.driver", "backends": "solvers.backends",
    "krylov": "solvers.krylov", "amg_backend": "solvers.amg", "resources": "solvers.resources",
    "warm_start": "solvers.warm_start", "result": "solvers.result",
}


class _AliasFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds ``itr_fv.<old>`` and loads it as the module at its new path."""

    def find_spec(self, fullname, path=None, target=None):  # noqa: D102
        package, _, leaf = fullname.partition(".")
        if package != "itr_fv" or leaf not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec):  # noqa: D102
        return None  # a placeholder; exec_module puts the real module in its place

    def exec_module(self, module):  # noqa: D102
        old = module.__name__
        new = "itr_fv." + MOVED[old.partition(".")[2]]
        warnings.warn(f"{old} moved to {new}; import it from there", DeprecationWarning,
                      stacklevel=3)
        # the import system returns what sys.modules holds after exec_module: the real one
        sys.modules[old] = importlib.import_module(new)


def install() -> None:
    """Put the alias finder on :data:`sys.meta_path` (once)."""
    if not any(isinstance(f, _AliasFinder) for f in sys.meta_path):
        sys.meta_path.append(_AliasFinder())
