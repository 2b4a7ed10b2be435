"""Interface faces of a voxel image: where the labels change, their staircase factors,
the particle pairs in contact and their films, and (segment law) the cut cells.

The scans over the grid, the faces and the contact zones run in numba kernels on a pool of
threads (:mod:`itr_fv.discrete._geometry_kernels`); the arrays are those of the NumPy code
they replaced (``tests/test_geometry_build.py`` keeps a frozen copy of it).

:func:`face_geometry` computes everything that does not depend on material values once; a
parameter change only needs :meth:`FaceGeometry.conductances` again, which hands the
geometry to its interface law (:mod:`itr_fv.discrete.interface_law`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.ndimage

from ..materials.properties import Materials
from ..rve.microstructure import Microstructure
from ..rve.sphere_geometry import min_image, particle_material_ids, staircase_factor
from . import _geometry_kernels as K
from .contact_zones import DEFAULT_TOUCH_GAP_M
from .cut_cells import SurfaceCuts
from .face_classes import FaceClasses
from .interface_law import InterfaceLaw, StaircaseLaw, interface_law

__all__ = ["FaceGeometry", "face_geometry", "face_conductances", "self_image_faces"]

@dataclass(frozen=True)
class FaceGeometry:
    """Interface faces of a microstructure, independent of material values.

    A parameter change (conductivities, resistances) only needs :meth:`conductances`
    again; the geometry is computed once.

    Attributes
    ----------
    shape : tuple of int
        Grid shape (n1, n2, n3).
    voxel_m : float
        Voxel edge h, m.
    material_ids : ndarray of int32
        Material id per voxel (shared with the microstructure, not copied).
    index : tuple of 3 int64 arrays
        Flat index of the lower voxel p of every interface face, per axis.
    mat_lo, mat_hi : tuple of 3 int32 arrays
        Material ids of p and of q = p + e_d at those faces.
    contact : tuple of 3 bool arrays
        True at faces between two different particles (contact faces).
    s : tuple of 3 float64 arrays
        Staircase factor of those faces (1 when the correction is off).
    staircase : str
        How s was obtained: ``"off"``, ``"spheres"`` (analytic normals) or ``"image"``.
    film : tuple of 3 float64 arrays, or None
        Matrix film thickness d(x_f) at the contact faces, m (NaN at other faces); None
        without a particle table.
    pair : tuple of 3 int64 arrays, or None
        Index of the particle pair of each contact face (-1 at other faces).
    pair_particles : ndarray of int64, shape (P, 2), or None
        Particle ids (1-based) of every pair that shares faces.
    pair_gap_m : ndarray, or None
        Closest-approach gap |c_q - c_p| - a_p - a_q of every pair, m.
    pair_faces : ndarray of int64, or None
        Number of faces of every pair.
    pair_material_ids : ndarray of int32, shape (P, 2), or None
        Material ids of the two particles of every pair.
    touch_gap_m : float
        Pairs with a closest gap at or below this touch (they get contact spots), m.
    contact_model : str
        The contact model the geometry was built for (``"gap"`` or ``"area"``).
    filled_voxels : int
        Matrix voxels of thin wedges given to particles (gap model, see
        :func:`itr_fv.discrete.contact_zones.fill_thin_films`).
    segments : tuple, or None
        Faces of the contact zones and their segment geometry
        (:func:`itr_fv.discrete.contact_zones.zone_segments`; staircase law, gap model).
    particle_mat : ndarray of int64, or None
        Material id of every particle id (index 0: the matrix).
    law : InterfaceLaw
        The interface law that turns this geometry and a :class:`Materials` into face
        conductances (:mod:`itr_fv.discrete.interface_law`).
    cuts : SurfaceCuts, or None
        Faces that meet a sphere, with their segment geometry (segment law).

    The host class arrays of the law (:meth:`face_classes`) are built on first use and
    kept with the geometry (not pickled).
    """

    shape: tuple[int, int, int]
    voxel_m: float
    names: tuple[str, ...]
    material_ids: np.ndarray
    index: tuple[np.ndarray, np.ndarray, np.ndarray]
    mat_lo: tuple[np.ndarray, np.ndarray, np.ndarray]
    mat_hi: tuple[np.ndarray, np.ndarray, np.ndarray]
    contact: tuple[np.ndarray, np.ndarray, np.ndarray]
    s: tuple[np.ndarray, np.ndarray, np.ndarray]
    staircase: str
    film: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    pair: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    pair_particles: np.ndarray | None = None
    pair_gap_m: np.ndarray | None = None
    pair_faces: np.ndarray | None = None
    pair_material_ids: np.ndarray | None = None
    touch_gap_m: float = DEFAULT_TOUCH_GAP_M
    contact_model: str = "area"
    filled_voxels: int = 0
    segments: tuple | None = None
    particle_mat: np.ndarray | None = None
    law: InterfaceLaw | None = None
    cuts: SurfaceCuts | None = None

    def __post_init__(self) -> None:
        if self.law is None:
            object.__setattr__(self, "law", StaircaseLaw(self.contact_model))

    @property
    def n_interface_faces(self) -> int:
        return int(sum(a.size for a in self.index))

    @property
    def n_contact_faces(self) -> int:
        """Faces between two different particles."""
        return int(sum(int(c.sum()) for c in self.contact))

    def touching_pairs(self) -> np.ndarray:
        """Indices of the pairs whose closest gap is at most ``touch_gap_m``."""
        if self.pair_gap_m is None:
            return np.zeros(0, dtype=np.int64)
        return np.flatnonzero(self.pair_gap_m <= self.touch_gap_m)

    def total_spot_conductance(self, materials: Materials) -> float:
        """Sum of the contact-spot conductances the grid carries, W/K.

        Each touching pair that shares voxel faces carries its G_c (spread over its faces);
        a touching pair that shares no face at this resolution carries none.
        """
        if self.pair_particles is None or materials.contact != "gap":
            return 0.0
        return float(sum(materials.spot_conductance(self.names[self.pair_material_ids[i, 0]],
                                                    self.names[self.pair_material_ids[i, 1]])
                         for i in self.touching_pairs()))

    def face_classes(self) -> FaceClasses:
        """The host (NumPy) class arrays of this geometry under its law, built once
        (:mod:`itr_fv.discrete.face_classes`); ``.to(xp, device)`` moves them."""
        classes = self.__dict__.get("_face_classes")
        if classes is None:
            classes = self.law.face_classes(self)
            object.__setattr__(self, "_face_classes", classes)
        return classes

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state.pop("_face_classes", None)  # derived, rebuilt on first use
        return state

    def conductances(self, materials: Materials, *, classes: FaceClasses | None = None) -> Any:
        """Face conductances per unit area, W/(m^2 K).

        Parameters
        ----------
        materials : Materials
            Conductivities and resistances; every phase of the microstructure and every
            interface pair it holds must be present.
        classes : FaceClasses, optional
            This geometry's class arrays in the namespace and on the device the result
            should be in (``self.face_classes().to(xp, device)``); default the host ones.

        Returns
        -------
        g : array of float64, shape (3, n1, n2, n3)
            ``g[d][p]`` is the conductance of the face between p and p + e_d (a NumPy
            ndarray by default, else an array of the namespace of ``classes``).
        """
        if not isinstance(materials, Materials):
            raise ValueError(f"mat: expected a Materials object, got {type(materials).__name__}")
        if materials.contact != self.contact_model:
            raise ValueError(f"geometry: built for contact={self.contact_model!r}, but the "
                             f"materials use contact={materials.contact!r}; build it with "
                             f"face_geometry(ms, contact={materials.contact!r})")
        return self.law.conductances(self, materials, classes=classes)


def self_image_faces(table, pid: np.ndarray, pq: np.ndarray, d: int,
                      shape: tuple[int, int, int], h: float) -> np.ndarray:
    """Flat indices of axis-d faces where a sphere meets its own periodic image.

    Both voxels carry the same particle id, but they lie in different periodic images of
    the sphere (their minimum-image offsets from its centre differ by the box length, not
    by h). Only spheres whose diameter comes within two voxels of the box edge can do this.
    """
    L = shape[d] * h
    big = np.flatnonzero(2.0 * table.radii_m > L - 2.0 * h) + 1
    if big.size == 0:
        return np.zeros(0, dtype=np.int64)
    cand = np.flatnonzero((np.isin(pid, big) & (pid == pq)).ravel())
    if cand.size == 0:
        return cand
    i_d = np.unravel_index(cand, shape)[d]
    c = table.centers_m[pid.ravel()[cand] - 1, d]
    u_p = min_image((i_d + 0.5) * h - c, np.array(L))
    u_q = min_image((i_d + 1.5) * h - c, np.array(L))
    return cand[np.abs(u_q - u_p - h) > 0.5 * h]


def _gather(pid: np.ndarray, mid: np.ndarray, idx: np.ndarray, d: int
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Particle and material ids of p and q = p + e_d at the faces ``idx`` (flat, of p)."""
    shape = pid.shape
    ijk = list(np.unravel_index(idx, shape))
    ijk[d] = (ijk[d] + 1) % shape[d]
    q = np.ravel_multi_index(tuple(ijk), shape)
    return pid.ravel()[idx], pid.ravel()[q], mid.ravel()[idx], mid.ravel()[q]


def _axis_faces(pid: np.ndarray, mid: np.ndarray, d: int, table, h: float, threads: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The interface faces of axis d (flat index of p, sorted): where the particle id changes,
    and (with a particle table) where a sphere meets its own periodic image; with the
    particle and material ids of p and q."""
    idx, p_lo, p_hi, m_lo, m_hi = K.interface_faces(pid, mid, d, threads)
    if table is None:
        return idx, p_lo, p_hi, m_lo, m_hi
    shape = pid.shape
    if not np.any(2.0 * table.radii_m > shape[d] * h - 2.0 * h):
        return idx, p_lo, p_hi, m_lo, m_hi  # no sphere can meet its own image
    extra = self_image_faces(table, pid, np.roll(pid, -1, axis=d), d, shape, h)
    if extra.size == 0:
        return idx, p_lo, p_hi, m_lo, m_hi
    idx = np.union1d(idx, extra)
    return (idx, *_gather(pid, mid, idx, d))


def _image_staircase(pid: np.ndarray, image_smoothing: float) -> list[np.ndarray]:
    """Central-difference gradient of the Gaussian-smoothed solid indicator, per axis."""
    solid = scipy.ndimage.gaussian_filter((pid > 0).astype(np.float64), image_smoothing,
                                          mode="wrap")
    return [0.5 * (np.roll(solid, -1, axis=a) - np.roll(solid, 1, axis=a)) for a in range(3)]


def _unique_contacts(rows: np.ndarray) -> tuple[np.ndarray, ...]:
    """``np.unique(rows, axis=0, return_index=True, return_inverse=True,
    return_counts=True)`` of the contact rows (p, q, shift), through one int64 key per row
    where the rows fit one (the same lexicographic order, first occurrences and counts)."""
    if rows.shape[0]:
        lo, hi = rows.min(axis=0), rows.max(axis=0)
        span = [int(hi[0]) + 1, int(hi[1]) + 1] + [int(hi[k] - lo[k]) + 1 for k in (2, 3, 4)]
        if min(int(lo[0]), int(lo[1])) >= 0 and math.prod(span) < 2 ** 62:
            key = rows[:, 0].copy()
            for k in range(1, 5):
                key *= span[k]
                key += rows[:, k] - (lo[k] if k >= 2 else 0)
            _, first, inverse, counts = np.unique(key, return_index=True, return_inverse=True,
                                                  return_counts=True)
            return rows[first], first, inverse.reshape(-1), counts
    uniq, first, inverse, counts = np.unique(rows, axis=0, return_index=True,
                                             return_inverse=True, return_counts=True)
    return uniq, first, inverse.reshape(-1), counts


def _contact_pairs(rows: list[np.ndarray], gaps: list[np.ndarray], at: list[np.ndarray],
                   index: list[np.ndarray]) -> dict[str, Any]:
    """The contacts of the contact faces: one contact = (particle p, particle q, image shift
    of q), from the rows ``(p, q, shift)`` and closest gaps of every axis's contact faces
    ``at[d]`` (positions in ``index[d]``); each face's contact index (-1 off contacts)."""
    uniq, first, inverse, counts = _unique_contacts(np.concatenate(rows))
    face_pair, start = [], 0
    for d in range(3):
        fp = np.full(index[d].size, -1, dtype=np.int64)
        fp[at[d]] = inverse[start:start + at[d].size]
        start += at[d].size
        face_pair.append(fp)
    return dict(pair=tuple(face_pair), pair_particles=uniq[:, :2],
                pair_gap_m=np.concatenate(gaps)[first], pair_faces=counts)


def face_geometry(ms: Microstructure, staircase: bool = True,
                  image_smoothing: float = 1.5,
                  touch_gap_m: float = DEFAULT_TOUCH_GAP_M,
                  contact: str = "gap", interface: str | InterfaceLaw = "staircase",
                  workers: int | None = None) -> FaceGeometry:
    """Find the interface faces of ``ms`` and their staircase factors.

    Parameters
    ----------
    ms : Microstructure
        The voxel image.
    staircase : bool
        Apply the staircase correction s = |n_x| + |n_y| + |n_z|. With a particle table,
        n is analytic: from the particle centre to the face centre at a particle-matrix
        face, along the (minimum-image) line of centres at a particle-particle face. For
        a plain label image (no table) n is estimated from the gradient of the solid
        indicator smoothed by a periodic Gaussian of ``image_smoothing`` voxels at
        particle-matrix faces, and s = 1 is kept at particle-particle faces. With a
        particle table, a sphere that meets its own periodic image (diameter within two
        voxels of the box) gets contact resistance there too, with s = 1; a plain label
        image cannot tell this apart from the inside of the particle.
    image_smoothing : float
        Gaussian width (voxels) of the image-based normal estimate.
    touch_gap_m : float
        Pairs whose closest surface gap is at most this (m) count as touching: they carry
        the contact spots of ``Materials(contact_conductance=...)``.
    contact : {"area", "gap"}
        The contact model the geometry is for (``Materials.contact``; the default is the
        same as there). With ``"gap"`` and a particle table, matrix wedges thinner than a voxel
        between nearly touching spheres are given to the spheres (:func:`fill_thin_films`);
        the geometry's own ``material_ids`` then differ from the microstructure's there
        (staircase law only).
    interface : {"staircase", "segment"} or InterfaceLaw
        The interface law (:func:`itr_fv.discrete.interface_law.interface_law`), by name or as an
        object (e.g. ``SegmentLaw(share="normal")``). The segment law needs the particle
        table and ``contact="gap"``; it fills no thin films.
    workers : int, optional
        Threads that run the build's numba kernels (default: 1 below 40^3 voxels, else
        numba's thread count ``NUMBA_NUM_THREADS``; at most the machine's cores). The result
        does not depend on it.

    Returns
    -------
    FaceGeometry
    """
    if not isinstance(ms, Microstructure):
        raise ValueError(f"ms: expected a Microstructure, got {type(ms).__name__}")
    law = interface_law(interface, contact)
    if law.needs_particles and ms.particles is None:
        raise ValueError(f"interface: the {law.name} law needs the particle table (a "
                         "Microstructure from from_spheres or generate_rve)")
    threads = K.threads_for(math.prod(ms.shape), workers)
    with K.using_threads(threads):
        return _face_geometry(ms, staircase, image_smoothing, touch_gap_m, contact, law,
                              threads)


def _face_geometry(ms: Microstructure, staircase: bool, image_smoothing: float,
                   touch_gap_m: float, contact: str, law: InterfaceLaw, threads: int
                   ) -> FaceGeometry:
    """:func:`face_geometry` once its arguments are checked."""
    shape, h = ms.shape, ms.voxel_m
    pid, mid, filled = law.labels(ms)
    pid, mid = np.ascontiguousarray(pid), np.ascontiguousarray(mid)
    index, lo, hi, is_contact_all, s_all = [], [], [], [], []
    films, pair_rows, gaps, contact_at = [], [], [], []
    table = ms.particles
    mode = "off" if not staircase else ("spheres" if table is not None else "image")
    grad = _image_staircase(pid, image_smoothing) if mode == "image" and ms.n_particles \
        else None
    if table is not None:
        centers = np.ascontiguousarray(table.centers_m, dtype=np.float64)
        radii = np.ascontiguousarray(table.radii_m, dtype=np.float64)
    for d in range(3):
        idx, p_lo, p_hi, m_lo, m_hi = _axis_faces(pid, mid, d, table, h, threads)
        index.append(idx)
        lo.append(m_lo)
        hi.append(m_hi)
        if table is not None:
            is_contact, s, film, at, gap, shift = K.sphere_faces(
                idx, p_lo, p_hi, d, shape, float(h), centers, radii, mode == "spheres", threads,
                table.contact.args)
            pair_rows.append(np.column_stack([np.minimum(p_lo[at], p_hi[at]).astype(np.int64),
                                              np.maximum(p_lo[at], p_hi[at]).astype(np.int64),
                                              shift]))
            films.append(film)
            gaps.append(gap)
            contact_at.append(at)
        else:
            is_contact = (p_lo > 0) & (p_hi > 0)
            s = np.ones(idx.size)
        if mode == "image" and idx.size:
            pm = np.flatnonzero(~is_contact)
            p_flat = idx[pm]
            q_flat = np.ravel_multi_index(
                tuple(np.mod(c + (1 if a == d else 0), shape[a])
                      for a, c in enumerate(np.unravel_index(p_flat, shape))), shape)
            n_est = np.stack([0.5 * (grad[a].ravel()[p_flat] + grad[a].ravel()[q_flat])
                              for a in range(3)], axis=1)
            s[pm] = staircase_factor(n_est)
        is_contact_all.append(is_contact)
        s_all.append(s)
    extra = {}
    if table is not None:
        mat_of_particle = particle_material_ids(ms)
        extra = dict(film=tuple(films), **_contact_pairs(pair_rows, gaps, contact_at, index),
                     touch_gap_m=float(touch_gap_m), filled_voxels=filled,
                     particle_mat=mat_of_particle, **law.law_geometry(ms, staircase=staircase))
        extra["pair_material_ids"] = mat_of_particle[extra["pair_particles"]].astype(np.int32)
    return FaceGeometry(tuple(shape), float(h), tuple(ms.names), mid, tuple(index), tuple(lo),
                        tuple(hi), tuple(is_contact_all), tuple(s_all), mode,
                        contact_model=contact, law=law, **extra)


def face_conductances(ms: Microstructure, mat: Materials, staircase: bool = True) -> np.ndarray:
    """Face conductances per unit area g, W/(m^2 K), shape (3, n1, n2, n3).

    Shorthand for ``face_geometry(ms, staircase, contact=mat.contact).conductances(mat)``.
    """
    return face_geometry(ms, staircase, contact=mat.contact).conductances(mat)

