"""Representative volume elements: one RVE specification validated once, dense periodic
packings of polydisperse spheres, and their voxel images with particle ids.

Public API::

    from itr_fv.rve import FillerSpec, RVESpec, generate_rve, build_rve

    spec = RVESpec(box_um=12.0, voxel_um=0.25)            # every setting, checked once
    ms = generate_rve(spec, [FillerSpec.from_table1("Al2O3", 0.6)], seed=1)
    ms, report = generate_rve_with_report(spec, fillers, seed=1)  # with the quality report
    ms, seed = build_rve(spec, fillers, replica=0)         # the spec's seeds, with retries

Modules: ``spec`` (:class:`~itr_fv.rve.spec.RVESpec`), ``packing`` (sphere packing),
``generate`` (fillers, :func:`generate_rve`, :func:`generate_rve_with_report`,
:func:`build_rve`), ``microstructure`` (voxel images), ``sphere_geometry`` (analytic
sphere geometry on the grid), and for segmented scans ``volume_files`` (label volumes read
and written: TIFF, NumPy, VTK, raw), ``phase_table`` (label -> phase) and ``from_image``
(particles labelled, the image's Microstructure and Materials)::

    vol = read_volume("scan.tif", voxel_um=0.5)
    ms = microstructure_from_image(vol, PhaseTable.parse(["0=matrix", "1=Al2O3"], "silicone"))
"""

from .from_image import microstructure_from_image
from .generate import (
    FillerReport,
    FillerSpec,
    PackedRVE,
    RVEReport,
    SizeCut,
    build_rve,
    generate_rve,
    generate_rve_with_report,
    packing_limit,
    size_cut,
)
from .phase_table import PhaseTable
from .spec import RVESpec
from .volume_files import LabelVolume, read_volume, write_volume

__all__ = [
    "FillerReport",
    "FillerSpec",
    "LabelVolume",
    "PackedRVE",
    "PhaseTable",
    "RVEReport",
    "RVESpec",
    "SizeCut",
    "build_rve",
    "generate_rve",
    "generate_rve_with_report",
    "microstructure_from_image",
    "packing_limit",
    "read_volume",
    "size_cut",
    "write_volume",
]
