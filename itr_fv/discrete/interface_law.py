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

The conductances are written once against the Python array API standard: the law turns a
parameter set into small host tables (:class:`LawTables`: ``h / (2 k)`` per material, R
per material pair, a spot conductance per contact pair; the checks for missing
resistances run on them), and one elementwise pass (``take``, ``where``, ``roll``,
arithmetic) combines them with the geometry's class arrays
(:class:`~itr_fv.discrete.face_classes.FaceClasses`) in their namespace and on their
device: NumPy on the host by default, CuPy on a GPU, ``array_api_strict`` in the tests.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..materials.parameters import KINDS
from .contact_zones import fill_thin_films, zone_segments
from .cut_cells import SHARES, surface_cuts
from .face_classes import (
    AxisClasses,
    CutSegments,
    FaceClasses,
    ZoneSegments,
    build_face_classes,
)

#: A :class:`itr_fv.discrete.face_geometry.FaceGeometry` and a
#: :class:`itr_fv.materials.Materials` (not imported here: face_geometry imports this module).
GeometryLike = Any
MaterialsLike = Any

__all__ = ["InterfaceLaw", "StaircaseLaw", "SegmentLaw", "LawTables", "LAW_NAMES",
           "SHARE_NAMES", "PARAMETER_KINDS", "interface_law"]

#: Interface shares of a surface crossing under the segment law (the keys of
#: :data:`itr_fv.discrete.cut_cells.SHARES`).
SHARE_NAMES = tuple(SHARES)


@dataclass(frozen=True)
class LawTables:
    """The parameter tables of one parameter set, indexed by material id or contact pair.

    Built on the host (NumPy) by :meth:`StaircaseLaw.tables`, after the checks for missing
    values; :meth:`to` moves them (a few numbers) to the namespace of the class arrays.

    Attributes
    ----------
    half_r : array, shape (m,)
        ``h / (2 k)`` per material id, m^2 K/W.
    k, inv_k : array, shape (m,)
        Conductivity, W/(m K), and its inverse.
    R : array, shape (m * m,)
        Resistance of every material pair, row-major (``R[lo * m + hi]``), m^2 K/W; NaN where
        the table has none.
    Rm : array, shape (m,)
        Resistance of every material with the matrix (material id 0), m^2 K/W.
    Rb : array, shape (m,)
        ``Rm`` with 0 at the matrix itself.
    spots1 : array, shape (P + 1,), or None
        0, then the contact-spot conductance per unit area of every contact pair's faces,
        W/(m^2 K) (None without spots).
    k_matrix : float
        Conductivity of the matrix, W/(m K).
    """

    half_r: Any
    k: Any
    inv_k: Any
    R: Any
    Rm: Any
    Rb: Any
    spots1: Any
    k_matrix: float

    def to(self, xp: Any, device: Any = None) -> LawTables:
        """The tables as arrays of ``xp`` on ``device``."""
        def move(a: Any) -> Any:
            return None if a is None else xp.asarray(a, device=device)

        return LawTables(move(self.half_r), move(self.k), move(self.inv_k), move(self.R),
                         move(self.Rm), move(self.Rb), move(self.spots1), self.k_matrix)


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

    def refinement(self, geometry: GeometryLike) -> tuple | None:
        """Per axis the faces whose conductance the law takes from segment geometry, and
        that geometry (:class:`~itr_fv.discrete.face_classes.ZoneSegments` or
        :class:`~itr_fv.discrete.face_classes.CutSegments`); None when there are none."""
        return None

    def face_classes(self, geometry: GeometryLike) -> FaceClasses:
        """The host class arrays of ``geometry`` under this law (build once per geometry:
        :meth:`~itr_fv.discrete.face_geometry.FaceGeometry.face_classes` keeps them)."""
        return build_face_classes(geometry, self.refinement(geometry))

    def conductances(self, geometry: GeometryLike, materials: MaterialsLike, *,
                     classes: FaceClasses | None = None) -> Any:
        """Face conductances per unit area, W/(m^2 K), shape (3, n1, n2, n3).

        Parameters
        ----------
        geometry : FaceGeometry
            The interface faces (built with this law).
        materials : Materials
            Conductivities, resistances and contact spots.
        classes : FaceClasses, optional
            The geometry's class arrays in the namespace and on the device the result
            should be in (default: the host ones, ``geometry.face_classes()``: NumPy).

        Returns
        -------
        g : array of float64, shape (3, n1, n2, n3)
            In the namespace of ``classes``.
        """
        if classes is None:
            classes = geometry.face_classes()
        tables = self.tables(geometry, materials, classes)
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.evaluate(classes, tables)

    def tables(self, geometry: GeometryLike, materials: MaterialsLike,
               classes: FaceClasses) -> LawTables:
        """The host parameter tables of ``materials`` (raises for missing values)."""
        raise NotImplementedError

    def evaluate(self, classes: FaceClasses, tables: LawTables) -> Any:
        """The elementwise pass: conductances from class arrays and parameter tables."""
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

    def refinement(self, geometry: GeometryLike) -> tuple | None:
        """Under the gap model: the faces of the contact zones and their segments
        (:meth:`ZoneSegments.from_segments`)."""
        if self.contact != "gap" or geometry.segments is None:
            return None
        return tuple(ZoneSegments.from_segments(geometry.segments[d], geometry.particle_mat,
                                                geometry.voxel_m) for d in range(3))

    def tables(self, geometry: GeometryLike, materials: MaterialsLike,
               classes: FaceClasses) -> LawTables:
        """The host tables of ``materials``; raises ValueError where a face needs a value
        the materials lack (the first such face of each axis names its pair)."""
        k, R = materials.tables(geometry.names)
        has_contact = any(bool(ax.kinds[:, 2].any()) for ax in classes.axes)
        if self.contact == "gap" and geometry.film is None and has_contact:
            raise ValueError("contact: the gap model needs the particle geometry (a "
                             "Microstructure from from_spheres or generate_rve); this label "
                             "image has faces between different particles: pass "
                             "Materials(..., contact='area') for a per-area contact resistance")
        spots = self._spots(geometry, materials)
        for ax in classes.axes:
            self._check_resistances(geometry, materials, ax, R)
        h = geometry.voxel_m
        Rb = R[:, 0].copy()
        Rb[0] = 0.0
        return LawTables(half_r=(0.5 * h) / k, k=k, inv_k=1.0 / k, R=R.reshape(-1),
                         Rm=R[:, 0].copy(), Rb=Rb,
                         spots1=None if spots is None else np.concatenate([[0.0], spots]),
                         k_matrix=float(k[0]))

    def _check_resistances(self, geometry: GeometryLike, materials: MaterialsLike,
                           ax: AxisClasses, R: np.ndarray) -> None:
        """Raise (``materials.resistance_between``) for the first face class of the axis
        whose series resistance the table leaves undefined (NaN)."""
        lo, hi, contact, film_nan = (ax.kinds[:, i] for i in range(4))
        r = R[lo, hi]
        gap_model = self.contact == "gap"
        if gap_model and geometry.film is not None:
            film = np.where(film_nan > 0, np.nan, 0.0)
            r = np.where(contact > 0, R[lo, 0] + R[hi, 0] + film, r)
        bad = np.flatnonzero(np.isnan(r))
        if not bad.size:
            return
        j = int(bad[0])
        names = geometry.names
        if gap_model and contact[j]:
            m = lo[j] if np.isnan(R[lo[j], 0]) else hi[j]
            materials.resistance_between(names[m], names[0])  # raises
        materials.resistance_between(names[lo[j]], names[hi[j]])

    def evaluate(self, classes: FaceClasses, tables: LawTables) -> Any:
        xp = classes.xp
        t = tables if classes.scatter else tables.to(xp, classes.device)
        ids = xp.reshape(classes.material_ids, (-1,))
        rc = xp.reshape(xp.take(t.half_r, ids), classes.shape)  # h / (2 k) per voxel
        g = classes.empty_conductances()
        for d, ax in enumerate(classes.axes):
            classes.fill(g, d, rc, self._special_values(xp, ax, t))
        return g

    def _special_values(self, xp: Any, ax: AxisClasses, t: LawTables) -> Any:
        """Conductances of the special faces of one axis, in their compact order, W/(m^2 K)."""
        if ax.size == 0:
            return None
        parts = []
        if ax.n_refined:
            parts.append(self._refined_values(xp, ax.refined, t))
        if ax.size > ax.n_refined:
            parts.append(self._interface_values(xp, ax, t))
        values = parts[0] if len(parts) == 1 else xp.concat(parts)
        if t.spots1 is not None and ax.pair1 is not None:
            # contact spots in parallel with the film (also at refined contact faces)
            values = xp.where(ax.pair1 > 0, values + xp.take(t.spots1, ax.pair1), values)
        return values

    def _interface_values(self, xp: Any, ax: AxisClasses, t: LawTables) -> Any:
        """``1 / (h/(2 k_lo) + h/(2 k_hi) + s R)`` at the interface faces; under the gap
        model ``R = R_b,lo + R_b,hi + film / k_m`` at contact faces."""
        r = xp.take(t.R, ax.code)
        if self.contact == "gap" and ax.film is not None:
            film_r = xp.take(t.Rm, ax.lo) + xp.take(t.Rm, ax.hi) + ax.film / t.k_matrix
            r = xp.where(ax.contact, film_r, r)
        series = (xp.take(t.half_r, ax.lo) + xp.take(t.half_r, ax.hi)
                  + xp.where(xp.isinf(r), xp.inf, r * ax.s))
        return 1.0 / series

    def _refined_values(self, xp: Any, seg: ZoneSegments, t: LawTables) -> Any:
        """The faces of the contact zones take their segment conductances:
        ``1 / (l_a/k_a + l_b/k_b + l_m/k_m + s_a R_b,a + s_b R_b,b)`` (W/(m^2 K)), the
        lengths along the segment joining the two voxel centres."""
        ra = xp.where(seg.sa > 0, seg.sa * xp.take(t.Rm, seg.ma), 0.0)
        rb = xp.where(seg.sb > 0, seg.sb * xp.take(t.Rm, seg.mb), 0.0)
        series = (seg.la / xp.take(t.k, seg.ma) + seg.lb / xp.take(t.k, seg.mb)
                  + seg.lm / t.k_matrix + ra + rb)
        return xp.where(xp.isinf(series), 0.0, 1.0 / series)

    def _spots(self, geometry: GeometryLike, materials: MaterialsLike) -> np.ndarray | None:
        """Contact-spot conductance per unit area of each pair's faces, W/(m^2 K)."""
        if (self.contact != "gap" or geometry.pair_material_ids is None
                or not materials.contact_conductance):
            return None
        names = geometry.names
        spots = np.array([materials.spot_conductance(names[a], names[b])
                          for a, b in geometry.pair_material_ids], dtype=np.float64)
        spots[geometry.pair_gap_m > geometry.touch_gap_m] = 0.0
        h = geometry.voxel_m
        return spots / (geometry.pair_faces * h * h)


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

    def refinement(self, geometry: GeometryLike) -> tuple | None:
        """The cut faces and their segments (:meth:`CutSegments.from_cuts`)."""
        if geometry.cuts is None:
            return None
        return tuple(CutSegments.from_cuts(geometry.cuts, d, geometry.voxel_m)
                     for d in range(3))

    def tables(self, geometry: GeometryLike, materials: MaterialsLike,
               classes: FaceClasses) -> LawTables:
        """As the staircase law's, after checking that every filler of the particle table
        has its resistance with the matrix (every cut face may need it)."""
        if geometry.particle_mat is not None:
            for m in np.unique(geometry.particle_mat[1:]):
                materials.resistance_between(geometry.names[m], geometry.names[0])  # or raise
        return super().tables(geometry, materials, classes)

    def _refined_values(self, xp: Any, seg: CutSegments, t: LawTables) -> Any:
        """``1 / (sum_i l_i / k_i + l_m / k_m + sum_c w_c R_c)`` at the cut faces."""
        rb = xp.reshape(t.Rb, (1, -1))
        r_int = xp.where(seg.share > 0, seg.share * rb, 0.0)
        series = (seg.length @ t.inv_k) + seg.lm / t.k_matrix + xp.sum(r_int, axis=1)
        return xp.where(xp.isinf(series), 0.0, 1.0 / series)

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
