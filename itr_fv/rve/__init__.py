"""Representative volume elements: one RVE specification validated once, dense periodic
packings of polydisperse spheres, and their voxel images with particle ids.

Public API::

    from itr_fv.rve import FillerSpec, generate_rve, build_rve

Modules: ``spec`` (:class:`~itr_fv.rve.spec.RVESpec`), ``packing`` (sphere packing),
``generate`` (fillers, :func:`generate_rve`, :func:`build_rve`), ``microstructure`` (voxel
images) and ``sphere_geometry`` (analytic sphere geometry on the grid).
"""

from .generate import (
    FillerReport,
    FillerSpec,
    PackedRVE,
    RVEReport,
    SizeCut,
    build_rve,
    generate_rve,
    packing_limit,
    size_cut,
)

__all__ = ["FillerSpec", "FillerReport", "RVEReport", "generate_rve", "packing_limit",
           "build_rve", "PackedRVE", "SizeCut", "size_cut"]
