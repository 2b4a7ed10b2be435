"""Interface laws: how the conductance of a face follows from its geometry and the materials.

Every law gives one conductance per unit area (W/(m^2 K)) per face of the 7-point stencil
(:mod:`itr_fv.discrete.model`), so both solvers and the reduced basis take any law unchanged. A face
is a series of resistances (m^2 K/W)::

    r_f = sum over phases of (length in the phase) / k  +  sum over crossings of  w R

and the laws differ in how they measure the lengths and the crossings:

- :class:`StaircaseLaw` (``"staircase"``): half a voxel ``h / (2 k)`` in each of the two
  voxels' phases (centre labels), ``R`` with the staircase factor
  ``w = |n_x| + |n_y| + |n_z|`` where the labels differ. Contacts between two particles
  follow the contact model: ``"gap"`` (the two particle-matrix resistances and the matrix
  film ``d(x_f) / k_m`` between the analytic spheres; the faces of thin films along their
  segments) or ``"area"`` (the paper's per-area ``R_ff``).
- :class:`SegmentLaw` (``"segment"``, gap contacts only): every face whose centre-to-centre
  segment meets a sphere takes its lengths from the analytic spheres along that segment and
  one ``w R`` per surface crossing (:mod:`itr_fv.discrete.cut_cells`); the bulk parts have
  their exact lengths at every h.

A law declares the parameter kinds it reads (:data:`itr_fv.materials.parameters.KINDS` is
their union), the geometry it needs (:meth:`InterfaceLaw.labels`,
:meth:`InterfaceLaw.law_geometry`, :attr:`InterfaceLaw.needs_particles`) and how its face
resistances depend on each (:attr:`InterfaceLaw.affine_in`): affine in ``1 / k`` and in
``R`` for all the laws here, not in a contact-spot conductance ``Gc`` (added in parallel).
The reduced basis asks the law instead of assuming it.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ..materials.parameters import KINDS
from .contact_zones import fill_thin_films, zone_segments
from .cut_cells import SHARES, surface_cuts

#: A :class:`itr_fv.discrete.face_geometry.FaceGeometry` and a
#: :class:`itr_fv.materials.Materials` (not imported here: face_geometry imports this module).
GeometryLike = Any
MaterialsLike = Any

__all__ = ["InterfaceLaw", "StaircaseLaw", "SegmentLaw", "LAW_NAMES", "SHARE_NAMES",
           "PARAMETER_KINDS", "interface_law"]

#: Interface shares of a surface crossing under the segment law (the keys of
#: :data:`itr_fv.discrete.cut_cells.SHARES`).
SHARE_NAMES = tuple(SHARES)


class InterfaceLaw:
    """Base of the interface laws.

    Attributes
    ----------
    name : str
        The law's name (``"staircase"`` or ``"segment"``).
    contact : str
        Contact model between two particles (``"gap"`` or ``"area"``).
    affine_in : dict of str to str or None
        Per parameter kind: ``"inverse"`` (face resistances affine in 1/value), ``"linear"``
        (affine in the value) or None (not affine).
    """

    name: ClassVar[str]
    #: Whether the law needs the particle table (the analytic spheres), not only labels.
    needs_particles: ClassVar[bool] = False
    contact: str
    affine_in: dict[str, str | None]

    def labels(self, ms: Any) -> tuple[np.ndarray, np.ndarray, int]:
        """``(particle_ids, material_ids, filled)``: the labels the law's faces are read
        from (by default the microstructure's own; ``filled`` voxels changed)."""
        return ms.particle_ids, ms.material_ids, 0

    def law_geometry(self, ms: Any, *, staircase: bool) -> dict[str, Any]:
        """The geometry this law needs beyond the faces' labels, as fields of
        :class:`~itr_fv.discrete.face_geometry.FaceGeometry` (asked for only where the
        particle table is known)."""
        return {}

    @property
    def parameter_kinds(self) -> tuple[str, ...]:
        """The parameter kinds this law reads."""
        return tuple(self.affine_in)

    def conductances(self, geometry: GeometryLike, materials: MaterialsLike) -> np.ndarray:
        """Face conductances per unit area, W/(m^2 K), shape (3, n1, n2, n3)."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}(contact={self.contact!r})"


class StaircaseLaw(InterfaceLaw):
    """Centre labels, half voxels and the staircase factor (first order in h).

    Parameters
    ----------
    contact : {"gap", "area"}
        Contact model between two particles.
    """

    name = "staircase"

    def __init__(self, contact: str = "gap") -> None:
        if contact not in ("gap", "area"):
            raise ValueError(f"contact: expected 'gap' or 'area', got {contact!r}")
        self.contact = contact
        third = {"Gc": None} if contact == "gap" else {"Rff": "linear"}
        self.affine_in = {"k": "inverse", "R": "linear", **third}

    def labels(self, ms: Any) -> tuple[np.ndarray, np.ndarray, int]:
        """Under the gap model with the particle table, matrix wedges thinner than a voxel
        between nearly touching spheres go to the spheres (:func:`fill_thin_films`)."""
        if self.contact == "gap" and ms.particles is not None:
            return fill_thin_films(ms)
        return super().labels(ms)

    def law_geometry(self, ms: Any, *, staircase: bool) -> dict[str, Any]:
        """Under the gap model: the segments of the contact zones (:func:`zone_segments`)."""
        if self.contact != "gap":
            return {"segments": None}
        return {"segments": zone_segments(ms, SHARES["staircase"] if staircase else None)}

    def conductances(self, geometry: GeometryLike, materials: MaterialsLike) -> np.ndarray:
        k, R = materials.tables(geometry.names)
        gap_model = self.contact == "gap"
        if gap_model and geometry.film is None and geometry.n_contact_faces:
            raise ValueError("contact: the gap model needs the particle geometry (a "
                             "Microstructure from from_spheres or generate_rve); this label "
                             "image has faces between different particles: pass "
                             "Materials(..., contact='area') for a per-area contact resistance")
        h = geometry.voxel_m
        half_r = (0.5 * h) / k  # h / (2 k) per material id, m^2 K / W
        rc = half_r[geometry.material_ids]
        spots = self._spots(geometry, materials)
        g = np.empty((3,) + geometry.shape, dtype=np.float64)
        for d in range(3):
            np.add(rc, np.roll(rc, -1, axis=d), out=g[d])
            np.divide(1.0, g[d], out=g[d])
            idx = geometry.index[d]
            if idx.size == 0:
                continue
            lo, hi = geometry.mat_lo[d], geometry.mat_hi[d]
            r_face = R[lo, hi]
            cont = geometry.contact[d]
            if gap_model and cont.any():
                # two particle-matrix resistances (material id 0 is the matrix) + the film
                r_face[cont] = R[lo[cont], 0] + R[hi[cont], 0] + geometry.film[d][cont] / k[0]
            if np.isnan(r_face).any():
                j = int(np.flatnonzero(np.isnan(r_face))[0])
                if gap_model and cont[j]:
                    m = lo[j] if np.isnan(R[lo[j], 0]) else hi[j]
                    materials.resistance_between(geometry.names[m], geometry.names[0])  # raises
                materials.resistance_between(geometry.names[lo[j]], geometry.names[hi[j]])
            with np.errstate(invalid="ignore"):
                series = half_r[lo] + half_r[hi] + np.where(np.isinf(r_face), np.inf,
                                                            r_face * geometry.s[d])
            g[d].reshape(-1)[idx] = 1.0 / series
            self._refine(geometry, g[d], d, k, R)
            if spots is not None and cont.any():
                g[d].reshape(-1)[idx[cont]] += spots[geometry.pair[d][cont]]
        return g

    def _spots(self, geometry: GeometryLike, materials: MaterialsLike) -> np.ndarray | None:
        """Contact-spot conductance per unit area of each pair's faces, W/(m^2 K)."""
        if (self.contact != "gap" or geometry.pair_material_ids is None
                or not materials.contact_conductance):
            return None
        names = geometry.names
        spots = np.array([materials.spot_conductance(names[a], names[b])
                          for a, b in geometry.pair_material_ids])
        spots[geometry.pair_gap_m > geometry.touch_gap_m] = 0.0
        h = geometry.voxel_m
        return spots / (geometry.pair_faces * h * h)

    def _refine(self, geometry: GeometryLike, gd: np.ndarray, d: int, k: np.ndarray,
                R: np.ndarray) -> None:
        """Overwrite the faces of the contact zones with their segment conductances:
        ``1 / (l_a/k_a + l_b/k_b + l_m/k_m + s_a R_b,a + s_b R_b,b)`` (W/(m^2 K)), the
        lengths along the segment joining the two voxel centres."""
        if self.contact != "gap" or geometry.segments is None or not geometry.segments[d][0].size:
            return
        flat, la, lb, sa, sb, pa, pb = geometry.segments[d]
        ma = geometry.particle_mat[pa]
        mb = geometry.particle_mat[pb]
        lm = np.maximum(geometry.voxel_m - la - lb, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            ra = np.where(sa > 0, sa * R[ma, 0], 0.0)
            rb = np.where(sb > 0, sb * R[mb, 0], 0.0)
            series = la / k[ma] + lb / k[mb] + lm / k[0] + ra + rb
        gd.reshape(-1)[flat] = np.where(np.isinf(series), 0.0, 1.0 / series)


class SegmentLaw(StaircaseLaw):
    """Cut cells: every face that meets a sphere takes its geometry along its segment.

    ``g = 1 / (sum_i l_i / k_i + l_m / k_m + sum_c w_c R_c)`` with l_i the length of the
    centre-to-centre segment inside spheres of filler i, l_m = h - sum_i l_i, and one
    share w_c of the particle-matrix resistance R_c per crossing of a sphere surface
    (:data:`itr_fv.discrete.cut_cells.SHARES`). A contact between two particles is the same
    formula (the film between the spheres is the matrix length of the segment), so the
    law is the gap model at contacts; contact spots add as in the staircase law. Faces that
    meet no sphere keep the staircase law of their labels (no thin films are filled).

    Parameters
    ----------
    share : {"staircase", "normal"}
        Interface share of a crossing.
    """

    name = "segment"
    needs_particles = True

    def __init__(self, share: str = "staircase") -> None:
        super().__init__("gap")
        if share not in SHARE_NAMES:
            raise ValueError(f"share: expected one of {SHARE_NAMES}, got {share!r}")
        self.share = share

    def labels(self, ms: Any) -> tuple[np.ndarray, np.ndarray, int]:
        """The microstructure's own labels: the segments resolve thin films themselves."""
        return ms.particle_ids, ms.material_ids, 0

    def law_geometry(self, ms: Any, *, staircase: bool) -> dict[str, Any]:
        """The sphere-surface crossings of every face that meets a sphere
        (:func:`surface_cuts`)."""
        return {"segments": None, "cuts": surface_cuts(ms, self.share)}

    def conductances(self, geometry: GeometryLike, materials: MaterialsLike) -> np.ndarray:
        if geometry.particle_mat is not None:
            for m in np.unique(geometry.particle_mat[1:]):
                materials.resistance_between(geometry.names[m], geometry.names[0])  # or raise
        return super().conductances(geometry, materials)

    def _refine(self, geometry: GeometryLike, gd: np.ndarray, d: int, k: np.ndarray,
                R: np.ndarray) -> None:
        cuts = geometry.cuts
        if cuts is None or not cuts.index[d].size:
            return
        L, W = cuts.length[d], cuts.share[d]
        lm = np.maximum(geometry.voxel_m - L.sum(axis=1), 0.0)
        Rb = R[:, 0].copy()
        Rb[0] = 0.0
        with np.errstate(invalid="ignore", divide="ignore"):
            r_int = np.where(W > 0, W * Rb[None, :], 0.0)
            series = (L @ (1.0 / k)) + lm / k[0] + r_int.sum(axis=1)
        gd.reshape(-1)[cuts.index[d]] = np.where(np.isinf(series), 0.0, 1.0 / series)

    def __repr__(self) -> str:
        return f"SegmentLaw(share={self.share!r})"


#: Names accepted by :func:`interface_law`.
LAW_NAMES = ("staircase", "segment")


def _parameter_kinds() -> dict[str, int]:
    kinds: dict[str, int] = {}
    for law in (StaircaseLaw("gap"), StaircaseLaw("area"), SegmentLaw()):
        for kind in law.parameter_kinds:
            if kind not in KINDS:
                raise ImportError(f"{law!r} reads the parameter kind {kind!r}, which the flat "
                                  f"naming (itr_fv.materials.parameters.KINDS) lacks")
            kinds[kind] = KINDS[kind]
    if set(kinds) != set(KINDS):
        raise ImportError(f"no interface law reads the parameter kinds "
                          f"{sorted(set(KINDS) - set(kinds))} of the flat naming")
    return kinds


#: Every parameter kind some law reads, and the number of phase names each takes (equal to
#: :data:`itr_fv.materials.parameters.KINDS`, checked here on import).
PARAMETER_KINDS = _parameter_kinds()


def interface_law(name: "str | InterfaceLaw", contact: str) -> InterfaceLaw:
    """The law ``name`` (``"staircase"`` or ``"segment"``, or a law object, returned as it is
    when its contact model is ``contact``) under the contact model ``contact``."""
    if isinstance(name, InterfaceLaw):
        if name.contact != contact:
            raise ValueError(f"interface: {name!r} models contacts as {name.contact!r}, but "
                             f"contact={contact!r}")
        return name
    if name == "staircase":
        return StaircaseLaw(contact)
    if name == "segment":
        if contact != "gap":
            raise ValueError("interface: the segment law models contacts by the matrix film "
                             "along each segment (the gap model); it has no per-area contact "
                             f"resistance: use contact='gap', got {contact!r}")
        return SegmentLaw()
    raise ValueError(f"interface: expected one of {LAW_NAMES}, got {name!r}")
