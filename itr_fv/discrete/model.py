"""The discrete model: face conductances with interface resistance, load vectors, fluxes.

Every solver of ``itr_fv.homogenize`` (pyamg, FFT, multigrid, array API) solves exactly the
system defined here. Cell-centred finite volumes on an n1 x n2 x n3 periodic grid of cubic voxels
of edge h. The face between voxel p and its neighbour q = p + e_d carries the conductance
per unit area (W/(m^2 K))::

    g = 1 / (h / (2 k_p) + R_pq * s_pq + h / (2 k_q))

with R_pq = 0 inside one particle or inside the matrix, R_pq = R(material_p, material_q)
at a particle-matrix face, and s_pq the staircase factor |n_x| + |n_y| + |n_z| of the true
surface normal n. At a face between two *different* particles p and q (a contact face) the
resistance depends on the contact model of :class:`~itr_fv.materials.Materials`:

- ``contact="gap"``: ``R_pq = R_b(p) + R_b(q) + d(x_f) / k_m`` (m^2 K/W), the paper's Eq. 6
  applied locally: the two particle-matrix resistances and the matrix film between the two
  analytic spheres, of thickness ``d = |c_q - c_p| - sqrt(a_p^2 - rho^2) - sqrt(a_q^2 - rho^2)``
  (m) at the face centre's distance rho from the line of centres, never below the pair's
  closest-approach gap. Its h -> 0 limit is the continuum problem of spheres with interface
  resistance separated by matrix films. An optional contact spot of conductance G_c (W/K)
  per touching pair (closest gap <= ``touch_gap_m``) adds ``G_c / (n_faces h^2)`` to the
  conductance per unit area of each of that pair's faces, so the pair's total spot
  conductance is G_c at every h.
- ``contact="area"``: ``R_pq = R(material_p, material_q)`` per unit face area, the paper's
  per-area R_ff (a property of the voxel, not of the material).

This is the staircase law (:class:`~itr_fv.discrete.interface_law.StaircaseLaw`, the default). The
segment law (:class:`~itr_fv.discrete.interface_law.SegmentLaw`, ``interface="segment"``) replaces
the
half voxels and ``s R`` at every face whose centre-to-centre segment meets a sphere by the
exact lengths along that segment and one share ``w R`` per surface crossing::

    g = 1 / (sum_i l_i / k_i + l_m / k_m + sum_c w_c R_c)

Either way the operator is the same 7-point stencil with one conductance per face.

The model is split by job: :mod:`itr_fv.discrete.face_geometry` (interface faces, staircase
factors, contact pairs), :mod:`itr_fv.discrete.contact_zones` (films between nearly touching
spheres), :mod:`itr_fv.discrete.cut_cells` (segments through spheres),
:mod:`itr_fv.discrete.interface_law`
(geometry + materials -> conductances), :mod:`itr_fv.discrete.operator` (load, ``A theta``, fluxes,
energy) and :mod:`itr_fv.discrete.connectivity`; this module gathers their public names.

Layout convention: ``g[d][i, j, k]`` is the face between voxel (i, j, k) and its periodic
neighbour (i, j, k) + e_d. With the periodic split T = -E.x + theta, conservation in
every voxel reads ``A theta = b(E)`` (see :func:`apply_operator`, :func:`load_vector`).
"""

from __future__ import annotations

from .connectivity import connected_components
from .contact_zones import DEFAULT_TOUCH_GAP_M, fill_thin_films
from .face_geometry import FaceGeometry, face_conductances, face_geometry
from .interface_law import InterfaceLaw, SegmentLaw, StaircaseLaw, interface_law
from .operator import (
    apply_operator,
    cell_centres,
    energy_tensor,
    face_fluxes,
    load_vector,
    mean_flux,
)

__all__ = [
    "DEFAULT_TOUCH_GAP_M", "FaceGeometry", "face_geometry", "fill_thin_films",
    "face_conductances", "load_vector", "apply_operator",
    "face_fluxes", "mean_flux", "energy_tensor", "connected_components", "cell_centres",
    "InterfaceLaw", "StaircaseLaw", "SegmentLaw", "interface_law",
]
