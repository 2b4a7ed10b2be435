"""Face classes: the compact per-face data the interface laws read, in any array namespace.

Every face conductance is a series of resistances fixed by the face's *class* (its material
pair, staircase factor, film, segment lengths) and a few small parameter tables (k per
material, R per material pair, a spot conductance per contact pair). :class:`FaceClasses`
holds the class data of one :class:`~itr_fv.discrete.face_geometry.FaceGeometry`: built
once on the host (:func:`build_face_classes`) and moved once to any array namespace and
device (:meth:`FaceClasses.to`), so that a new parameter set costs one elementwise pass
over the grid (:meth:`itr_fv.discrete.interface_law.InterfaceLaw.conductances`).

Per axis d the *special* faces sit in one compact list: first the faces the law refines
(contact-zone segments, cut cells), then the other interface faces of ``index[d]`` in
their order. Every other face is a *bulk* face, ``1 / (h/(2 k_p) + h/(2 k_q))`` from the
two voxels' material ids. The conductances of the special faces go into the grid by an
integer scatter on NumPy, and elsewhere by functions of the array API standard only
(which has no integer-array assignment): a dense ``slot`` per axis (1 + the face's position
in the compact list, 0 at bulk faces), ``take`` and ``where``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

__all__ = ["ZoneSegments", "CutSegments", "AxisClasses", "FaceClasses",
           "build_face_classes", "host_namespace", "to_host"]


def host_namespace() -> Any:
    """The NumPy namespace of the array API standard (array_api_compat's wrapper: the same
    ndarrays, the standard's names on every supported NumPy)."""
    import array_api_compat.numpy as xp

    return xp


def _is_numpy(xp: Any) -> bool:
    import array_api_compat

    return array_api_compat.is_numpy_namespace(xp)


def to_host(x: Any) -> np.ndarray:
    """A NumPy copy (or view) of an array of NumPy, CuPy, PyTorch or array-api-strict."""
    if isinstance(x, np.ndarray):
        return x
    library = type(x).__module__.split(".")[0]
    if library == "cupy":
        return x.get()
    if library == "torch":
        return x.detach().cpu().numpy()
    return np.from_dlpack(x)


def _moved(obj: Any, xp: Any, device: Any) -> Any:
    """``obj`` (a dataclass of arrays) with every NumPy array field moved to ``xp``."""
    changes = {f.name: xp.asarray(getattr(obj, f.name), device=device)
               for f in fields(obj) if isinstance(getattr(obj, f.name), np.ndarray)}
    return replace(obj, **changes)


@dataclass(frozen=True)
class ZoneSegments:
    """Faces of the contact zones (staircase law, gap model), along the segment joining
    the two voxel centres through spheres a and b
    (:func:`itr_fv.discrete.contact_zones.zone_segments`).

    Attributes
    ----------
    la, lb : array of float64, shape (r,)
        Lengths of the segment inside sphere a and sphere b, m.
    sa, sb : array of float64, shape (r,)
        Summed interface shares of the crossings of a and of b.
    ma, mb : array of int32, shape (r,)
        Material ids of a and b.
    lm : array of float64, shape (r,)
        Length in the matrix, ``max(h - la - lb, 0)``, m.
    """

    la: Any
    lb: Any
    sa: Any
    sb: Any
    ma: Any
    mb: Any
    lm: Any

    @classmethod
    def from_segments(cls, segments: tuple, particle_mat: np.ndarray, voxel_m: float
                      ) -> tuple[np.ndarray, ZoneSegments]:
        """(flat face indices, segments) of one axis of ``FaceGeometry.segments``."""
        flat, la, lb, sa, sb, pa, pb = (np.asarray(a) for a in segments)
        la, lb, sa, sb = (np.asarray(a, dtype=np.float64) for a in (la, lb, sa, sb))
        ma = particle_mat[pa.astype(np.int64)].astype(np.int32)
        mb = particle_mat[pb.astype(np.int64)].astype(np.int32)
        lm = np.maximum(voxel_m - la - lb, 0.0)
        return flat.astype(np.int64), cls(la, lb, sa, sb, ma, mb, lm)


@dataclass(frozen=True)
class CutSegments:
    """Faces whose segment meets a sphere (segment law, :mod:`itr_fv.discrete.cut_cells`).

    Attributes
    ----------
    length : array of float64, shape (r, n_materials)
        Length of the segment inside spheres of each material id, m.
    share : array of float64, shape (r, n_materials)
        Summed interface shares of the crossings of spheres of each material id.
    lm : array of float64, shape (r,)
        Length in the matrix, ``max(h - sum of length, 0)``, m.
    """

    length: Any
    share: Any
    lm: Any

    @classmethod
    def from_cuts(cls, cuts: Any, d: int, voxel_m: float) -> tuple[np.ndarray, CutSegments]:
        """(flat face indices, segments) of axis ``d`` of a
        :class:`~itr_fv.discrete.cut_cells.SurfaceCuts`."""
        length, share = cuts.length[d], cuts.share[d]
        lm = np.maximum(voxel_m - length.sum(axis=1), 0.0)
        return np.asarray(cuts.index[d], dtype=np.int64), cls(length, share, lm)


@dataclass(frozen=True)
class AxisClasses:
    """The special faces of one axis: ``n_refined`` refined faces, then the other
    interface faces.

    Attributes
    ----------
    faces : ndarray of int64, shape (m,)
        Flat index of the lower voxel p of every special face (host NumPy in any namespace).
    n_refined : int
        Number of refined faces (the first ones of ``faces``).
    lo, hi : array of int32, shape (m - n_refined,)
        Material ids of p and of q = p + e_d at the other interface faces.
    code : array of int32, shape (m - n_refined,)
        ``lo * n_materials + hi``: the position of the pair in the flat resistance table.
    s : array of float64, shape (m - n_refined,)
        Staircase factors of those faces.
    contact : array of bool, shape (m - n_refined,)
        Faces between two different particles.
    film : array of float64, shape (m - n_refined,), or None
        Matrix film at contact faces, m (NaN elsewhere); None without a particle table.
    pair1 : array of int32, shape (m,), or None
        1 + the contact pair of a contact face, 0 at the other faces; None without pairs.
    refined : ZoneSegments or CutSegments or None
        Segment geometry of the refined faces.
    kinds : ndarray of int64, shape (c, 4)
        The distinct ``(lo, hi, contact, film is NaN)`` of all the interface faces of the
        axis (refined or not), in the order of their first face (host NumPy; the checks for
        missing resistances read them).
    slot : array of int32, shape (n1, n2, n3), or None
        1 + the position of every face in ``faces``, 0 at bulk faces (outside NumPy only).
    """

    faces: np.ndarray
    n_refined: int
    lo: Any
    hi: Any
    code: Any
    s: Any
    contact: Any
    film: Any
    pair1: Any
    refined: ZoneSegments | CutSegments | None
    kinds: np.ndarray
    slot: Any = None

    @property
    def size(self) -> int:
        """Number of special faces."""
        return int(self.faces.size)

    def to(self, xp: Any, device: Any, shape: tuple[int, int, int]) -> AxisClasses:
        """These classes in the namespace ``xp`` on ``device``, with the dense slots."""
        slot = np.zeros(int(np.prod(shape)), dtype=np.int32)
        slot[self.faces] = np.arange(1, self.faces.size + 1, dtype=np.int32)
        moved = _moved(replace(self, faces=None, kinds=None), xp, device)
        refined = None if self.refined is None else _moved(self.refined, xp, device)
        return replace(moved, faces=self.faces, kinds=self.kinds, refined=refined,
                       slot=xp.asarray(slot.reshape(shape), device=device))


@dataclass(frozen=True)
class FaceClasses:
    """The class arrays of a geometry in one array namespace, on one device.

    Attributes
    ----------
    shape : tuple of int
        Grid shape (n1, n2, n3).
    voxel_m : float
        Voxel edge h, m.
    n_materials : int
        Number of material ids.
    material_ids : array of int32, shape (n1, n2, n3)
        Material id of every voxel (the geometry's labels).
    axes : tuple of 3 AxisClasses
        The special faces of every axis.
    xp : namespace
        The array namespace of the arrays.
    device : object
        Their device (None: the namespace's default).
    """

    shape: tuple[int, int, int]
    voxel_m: float
    n_materials: int
    material_ids: Any
    axes: tuple[AxisClasses, AxisClasses, AxisClasses]
    xp: Any
    device: Any = None

    @property
    def scatter(self) -> bool:
        """Whether the special faces go into the grid by integer scatter (NumPy)."""
        return _is_numpy(self.xp)

    def to(self, xp: Any, device: Any = None) -> FaceClasses:
        """The same classes in the array namespace ``xp`` on ``device`` (built from the host
        classes; NumPy on the CPU returns them as they are).

        Parameters
        ----------
        xp : namespace
            An array API namespace (``array_api_strict``, ``array_api_compat.cupy``, ...).
        device : object, optional
            A device of ``xp`` (default: its default device).
        """
        if not _is_numpy(self.xp):
            raise ValueError("xp: classes move from the host (NumPy) classes only")
        if xp is None or not hasattr(xp, "asarray") or not hasattr(xp, "take"):
            raise ValueError(f"xp: expected an array API namespace, got {xp!r}")
        if _is_numpy(xp) and device in (None, "cpu"):
            return self
        return FaceClasses(self.shape, self.voxel_m, self.n_materials,
                           xp.asarray(self.material_ids, device=device),
                           tuple(a.to(xp, device, self.shape) for a in self.axes), xp, device)

    def empty_conductances(self) -> Any:
        """An uninitialised float64 array of shape (3, n1, n2, n3) for the conductances."""
        return self.xp.empty((3,) + tuple(self.shape), dtype=self.xp.float64,
                             device=self.device)

    def fill(self, g: Any, d: int, rc: Any, values: Any) -> None:
        """Axis ``d`` of ``g``: ``1 / (rc_p + rc_q)`` at bulk faces, ``values`` (one per
        special face, in the order of the compact list) at the special faces.

        Parameters
        ----------
        g : array, shape (3, n1, n2, n3)
            Conductances, W/(m^2 K), written in place.
        d : int
            Axis.
        rc : array, shape (n1, n2, n3)
            ``h / (2 k)`` of every voxel, m^2 K/W.
        values : array of shape (m,), or None
            Conductances of the special faces, W/(m^2 K) (None when there are none).
        """
        if self.scatter:
            np.add(rc, np.roll(rc, -1, axis=d), out=g[d])
            np.divide(1.0, g[d], out=g[d])
            if values is not None:
                g[d].reshape(-1)[self.axes[d].faces] = values
            return
        xp = self.xp
        bulk = 1.0 / (rc + xp.roll(rc, -1, axis=d))
        if values is None:
            g[d, ...] = bulk
            return
        slot = self.axes[d].slot
        table = xp.concat([xp.zeros(1, dtype=values.dtype, device=self.device), values])
        special = xp.reshape(xp.take(table, xp.reshape(slot, (-1,))), self.shape)
        g[d, ...] = xp.where(slot > 0, special, bulk)


def _first_kinds(lo: np.ndarray, hi: np.ndarray, contact: np.ndarray, film_nan: np.ndarray,
                 n_materials: int) -> np.ndarray:
    """The distinct (lo, hi, contact, film_nan) rows, in the order of their first face."""
    code = ((lo.astype(np.int64) * n_materials + hi) * 2 + contact) * 2 + film_nan
    present = np.flatnonzero(np.bincount(code, minlength=4 * n_materials ** 2))
    first = np.sort([int(np.argmax(code == c)) for c in present]).astype(np.int64)
    return np.stack([lo[first], hi[first], contact[first], film_nan[first]],
                    axis=1).astype(np.int64)


def _positions(index: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Position of every face of ``faces`` in ``index`` (unique flat indices), -1 where
    absent."""
    if index.size == 0 or faces.size == 0:
        return np.full(faces.size, -1, dtype=np.int64)
    if np.all(index[1:] > index[:-1]):  # sorted (as face_geometry lists them)
        pos = np.minimum(np.searchsorted(index, faces), index.size - 1)
    else:
        order = np.argsort(index, kind="stable")
        pos = order[np.minimum(np.searchsorted(index, faces, sorter=order), index.size - 1)]
    return np.where(index[pos] == faces, pos, -1)


def _axis_classes(geometry: Any, d: int, refined: tuple[np.ndarray, Any] | None
                  ) -> AxisClasses:
    n_mat = len(geometry.names)
    idx = np.asarray(geometry.index[d], dtype=np.int64)
    lo_all = np.asarray(geometry.mat_lo[d], dtype=np.int32)
    hi_all = np.asarray(geometry.mat_hi[d], dtype=np.int32)
    contact_all = np.asarray(geometry.contact[d], dtype=bool)
    film_all = None if geometry.film is None else np.asarray(geometry.film[d], np.float64)
    film_nan = (np.zeros(idx.size, dtype=bool) if film_all is None
                else np.isnan(film_all) & contact_all)
    kinds = _first_kinds(lo_all, hi_all, contact_all, film_nan, n_mat)
    ref_faces, segments = refined if refined is not None else (np.zeros(0, np.int64), None)
    at = _positions(idx, ref_faces)
    keep = np.ones(idx.size, dtype=bool)
    keep[at[at >= 0]] = False
    pair1 = None
    if geometry.pair is not None:
        pair_all = np.where(contact_all, np.asarray(geometry.pair[d]) + 1, 0).astype(np.int32)
        ref_pair = np.where(at >= 0, pair_all[np.maximum(at, 0)] if idx.size else 0, 0)
        pair1 = np.concatenate([ref_pair.astype(np.int32), pair_all[keep]])
    lo, hi = lo_all[keep], hi_all[keep]
    return AxisClasses(
        faces=np.concatenate([ref_faces, idx[keep]]), n_refined=int(ref_faces.size),
        lo=lo, hi=hi, code=(lo * n_mat + hi).astype(np.int32),
        s=np.asarray(geometry.s[d], dtype=np.float64)[keep], contact=contact_all[keep],
        film=None if film_all is None else film_all[keep], pair1=pair1, refined=segments,
        kinds=kinds)


def build_face_classes(geometry: Any, refinement: tuple | None = None) -> FaceClasses:
    """The host (NumPy) class arrays of ``geometry``.

    Parameters
    ----------
    geometry : FaceGeometry
        The interface faces of a microstructure.
    refinement : tuple of 3 (faces, ZoneSegments or CutSegments), optional
        Per axis the faces the law refines (flat indices, unique) and their segments
        (:meth:`itr_fv.discrete.interface_law.InterfaceLaw.refinement`).

    Returns
    -------
    FaceClasses
    """
    if refinement is not None and len(refinement) != 3:
        raise ValueError(f"refinement: expected one entry per axis, got {len(refinement)}")
    axes = tuple(_axis_classes(geometry, d, None if refinement is None else refinement[d])
                 for d in range(3))
    return FaceClasses(tuple(geometry.shape), float(geometry.voxel_m), len(geometry.names),
                       np.asarray(geometry.material_ids, dtype=np.int32), axes,
                       host_namespace())
