"""Voxel microstructures: material id and particle id per voxel, plus the particle table."""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..checks import finite_number, phase_name
from .contact_film import ContactFilm

__all__ = ["Microstructure", "ParticleTable", "grid_slabs", "label_counts", "periodic_components"]

#: Voxels one NumPy call of a whole-grid pass handles (tens of milliseconds): a 640^3 grid
#: in one call would hold the interpreter, and its signal handlers, for seconds.
SLAB_VOXELS = 1 << 22


def grid_slabs(shape: tuple[int, ...]) -> list[slice]:
    """Consecutive ranges of the first axis of about :data:`SLAB_VOXELS` voxels each."""
    rows = max(1, SLAB_VOXELS // max(1, math.prod(shape[1:])))
    return [slice(i, min(i + rows, shape[0])) for i in range(0, shape[0], rows)]


def label_counts(labels: np.ndarray, minlength: int = 0) -> np.ndarray:
    """``np.bincount(labels.ravel(), minlength=minlength)`` of a voxel array of labels >= 0,
    counted slab by slab (:data:`SLAB_VOXELS`)."""
    flat = labels.reshape(-1)
    counts = np.zeros(int(minlength), dtype=np.intp)
    for k in range(0, flat.size, SLAB_VOXELS):
        part = np.bincount(flat[k:k + SLAB_VOXELS], minlength=counts.size)
        part[:counts.size] += counts
        counts = part
    return counts


@dataclass(frozen=True)
class ParticleTable:
    """Analytic geometry of the spheres behind a voxel image.

    Attributes
    ----------
    centers_m : ndarray, shape (P, 3)
        Sphere centres, m, inside the periodic box ``[0, box_m)``.
    radii_m : ndarray, shape (P,)
        Sphere radii, m.
    material : ndarray of str, shape (P,)
        Phase name of each sphere. Row ``i`` is particle id ``i + 1``.
    contact : ContactFilm
        Which pairs touch and the film they meet at (the packer's, from
        :func:`itr_fv.rve.generate_rve`; default: no stated film, every gap as it lies).
    """

    centers_m: np.ndarray
    radii_m: np.ndarray
    material: np.ndarray
    contact: ContactFilm = ContactFilm()

    def __len__(self) -> int:
        return int(self.radii_m.shape[0])


def _shape3(shape: int | Sequence[int], argument: str = "shape") -> tuple[int, int, int]:
    if isinstance(shape, (int, np.integer)):
        shape = (int(shape),) * 3
    try:
        out = tuple(int(s) for s in shape)
    except (TypeError, ValueError):
        raise ValueError(f"{argument}: expected an int or three ints, got {shape!r}") from None
    if len(out) != 3 or any(s != t for s, t in zip(out, shape)):
        raise ValueError(f"{argument}: expected three integers, got {shape!r}")
    if any(s < 1 for s in out):
        raise ValueError(f"{argument}: every dimension must hold at least one voxel, got {out}")
    return out  # type: ignore[return-value]


def _positive_length(value: float, argument: str) -> float:
    v = finite_number(value, argument)
    if v <= 0.0:
        raise ValueError(f"{argument} must be finite and > 0 (m), got {v!r}")
    return v


def _cubic_grid(box_m: float | Sequence[float], n: tuple[int, int, int]
                ) -> tuple[np.ndarray, float]:
    """The box edges (3,), m, and the voxel edge h, m, of a grid of ``n`` cubic voxels
    (ValueError naming ``box_m`` or ``box_m/shape``)."""
    box = np.broadcast_to(np.asarray(box_m, dtype=np.float64), (3,)).copy() \
        if np.ndim(box_m) <= 1 and np.size(box_m) in (1, 3) else None
    if box is None:
        raise ValueError(f"box_m: expected a length or three lengths (m), got {box_m!r}")
    for d in range(3):
        _positive_length(box[d], "box_m")
    hs = box / np.array(n)
    h = float(hs[0])
    if not np.allclose(hs, h, rtol=1e-9, atol=0.0):
        raise ValueError(f"box_m/shape: voxels must be cubic, box {box.tolist()} m over "
                         f"shape {n} gives edges {hs.tolist()}")
    return box, h


def _sphere_table(centers_m: np.ndarray, radii_m: np.ndarray, box: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Centres (P, 3) and radii (P,), m, as float arrays, checked: finite, radii > 0 and
    every sphere smaller than the periodic box (ValueError naming the argument)."""
    c = np.asarray(centers_m, dtype=np.float64)
    r = np.asarray(radii_m, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 3:
        raise ValueError(f"centers_m: expected shape (P, 3), got {c.shape}")
    if r.shape != (c.shape[0],):
        raise ValueError(f"radii_m: expected shape ({c.shape[0]},), got {r.shape}")
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(r))):
        raise ValueError("centers_m/radii_m: NaN or inf in the sphere table")
    if np.any(r <= 0):
        raise ValueError("radii_m: every radius must be > 0 (m)")
    if r.size and np.any(2 * r >= box.min()):
        raise ValueError(f"radii_m: a sphere of diameter {2 * r.max():.4g} m does not fit the "
                         f"periodic box {box.min():.4g} m")
    return c, r


def _sphere_phases(materials: Sequence[str] | str, matrix: str, count: int
                   ) -> tuple[np.ndarray, list[str], np.ndarray]:
    """The phase of each of ``count`` spheres (object array), the phase names (the matrix
    first, then the fillers in order of appearance) and each sphere's material id."""
    if isinstance(materials, str):
        mats = np.array([materials] * count, dtype=object)
    else:
        mats = np.asarray(list(materials), dtype=object)
        if mats.shape != (count,):
            raise ValueError(f"materials: expected {count} names, got {mats.shape}")
    phase_name(matrix, "matrix")
    phase_names = [matrix]
    for m in mats:
        phase_name(m, "materials")
        if m == matrix:
            raise ValueError(f"materials: a sphere cannot be of the matrix phase {matrix!r}")
        if m not in phase_names:
            phase_names.append(m)
    mat_index = np.array([phase_names.index(m) for m in mats], dtype=np.int32)
    return mats, phase_names, mat_index


def _join_periodic(labels: np.ndarray, n: int) -> tuple[np.ndarray, int]:
    """``labels`` (1..n, 0 background) with the labels that face each other across the
    three pairs of opposite box faces joined, renumbered 1..m in order of first label."""
    if n < 1:
        return labels.astype(np.int32, copy=False), 0
    parent = np.arange(n + 1)

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for axis in range(3):
        a = np.take(labels, 0, axis=axis).ravel()
        b = np.take(labels, -1, axis=axis).ravel()
        both = (a > 0) & (b > 0)
        for i, j in set(zip(a[both].tolist(), b[both].tolist())):
            ri, rj = root(i), root(j)
            if ri != rj:
                parent[max(ri, rj)] = min(ri, rj)
    roots = np.array([root(i) for i in range(n + 1)])
    kept = np.unique(roots[1:])
    renumber = np.zeros(n + 1, dtype=np.int32)
    renumber[1:] = np.searchsorted(kept, roots[1:]) + 1
    return renumber[labels], int(kept.size)


def periodic_components(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """Face-connected pieces of ``mask`` in the periodic box: labels 1..n (0 outside the
    mask), int32, and n."""
    from scipy import ndimage

    labels, n = ndimage.label(mask)  # the default structure: face connectivity
    return _join_periodic(labels, int(n))


def periodic_pieces(mask: np.ndarray) -> int:
    """Face-connected pieces of the voxels ``mask`` in the periodic box (a piece that leaves
    the box on one face and enters on the opposite one counts once)."""
    return periodic_components(mask)[1]


def _warn_phase_ids_as_particles(mid: np.ndarray, pid: np.ndarray) -> None:
    """Warn when the particle ids are the phase ids and a 'particle' is several pieces."""
    if pid.max() == 0 or not np.array_equal(mid, pid):
        return
    for p in range(1, int(pid.max()) + 1):
        pieces = periodic_pieces(pid == p)
        if pieces > 1:
            warnings.warn(f"particle_ids: they equal material_ids, and particle {p} is "
                          f"{pieces} separate pieces: each phase is taken as one particle, so "
                          "the contacts between its particles are not seen (the gap contact "
                          "model and the contact resistances act only between particle ids); "
                          "label each particle (e.g. scipy.ndimage.label per phase)",
                          UserWarning, stacklevel=3)
            return


def _int_labels(a: object, argument: str) -> np.ndarray:
    arr = np.asarray(a)
    if arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"{argument}: expected an integer array, got dtype {arr.dtype}")
    if arr.ndim != 3:
        raise ValueError(f"{argument}: expected a 3-D array (n1, n2, n3), got shape {arr.shape}")
    if arr.size == 0:
        raise ValueError(f"{argument}: the grid holds zero voxels (shape {arr.shape})")
    if arr.min() < 0:
        raise ValueError(f"{argument}: labels must be >= 0")
    return np.ascontiguousarray(arr, dtype=np.int32)


class Microstructure:
    """Periodic voxel image of a composite with per-voxel particle identity.

    Use :meth:`from_spheres` or :meth:`from_labels` to build one.

    Attributes
    ----------
    material_ids : ndarray of int32, shape (n1, n2, n3)
        0 = matrix, ``i`` = phase ``names[i]``.
    particle_ids : ndarray of int32, shape (n1, n2, n3)
        0 = matrix, ``p`` = particle ``p`` (row ``p - 1`` of :attr:`particles`).
    voxel_m : float
        Voxel edge h, m.
    names : tuple of str
        Phase name per material id; ``names[0]`` is the matrix.
    particles : ParticleTable or None
        Analytic sphere geometry when known (used by the staircase correction).
    """

    def __init__(self, material_ids: np.ndarray, particle_ids: np.ndarray, voxel_m: float,
                 names: Sequence[str], particles: ParticleTable | None = None) -> None:
        self.material_ids = material_ids
        self.particle_ids = particle_ids
        self.voxel_m = voxel_m
        self.names = tuple(names)
        self.particles = particles

    # ----------------------------------------------------------------- builders
    @classmethod
    def from_labels(cls, material_ids: np.ndarray, particle_ids: np.ndarray, voxel_m: float,
                    names: Sequence[str], particles: ParticleTable | None = None
                    ) -> Microstructure:
        """Build from plain label arrays.

        Parameters
        ----------
        material_ids : int array, shape (n1, n2, n3)
            0 = matrix, ``i`` = ``names[i]``.
        particle_ids : int array, shape (n1, n2, n3)
            0 = matrix, 1.. = particle index. A voxel is matrix in both arrays or in neither,
            and every particle has a single material. Particle ids equal to the material ids
            where a phase falls into several pieces are warned about: each phase would be one
            particle, without contacts inside it.
        voxel_m : float
            Voxel edge, m.
        names : sequence of str
            Phase per material id, ``names[0]`` the matrix.
        particles : ParticleTable, optional
            Sphere geometry if known. Without it the staircase correction is estimated
            from the image (see :func:`itr_fv.discrete.model.face_geometry`).
        """
        mid = _int_labels(material_ids, "material_ids")
        pid = _int_labels(particle_ids, "particle_ids")
        if mid.shape != pid.shape:
            raise ValueError(f"particle_ids: shape {pid.shape} differs from material_ids "
                             f"{mid.shape}")
        h = _positive_length(voxel_m, "voxel_m")
        if isinstance(names, str) or not isinstance(names, Sequence) or len(names) < 1:
            raise ValueError("names: expected a sequence of phase names, names[0] the matrix")
        names = tuple(names)
        for n in names:
            phase_name(n, "names")
        if len(set(names)) != len(names):
            raise ValueError(f"names: expected distinct phase names, got {names!r}")
        if mid.max() >= len(names):
            raise ValueError(f"material_ids: id {int(mid.max())} has no entry in names {names!r}")
        if np.any((mid == 0) != (pid == 0)):
            raise ValueError("particle_ids: a voxel must be matrix (0) in both material_ids and "
                             "particle_ids or in neither")
        n_particles = int(pid.max())
        if n_particles:
            # every particle one material: min and max of material id per particle agree
            flat_p = pid.ravel()
            flat_m = mid.ravel()
            lo = np.full(n_particles + 1, np.iinfo(np.int32).max, dtype=np.int64)
            hi = np.full(n_particles + 1, -1, dtype=np.int64)
            np.minimum.at(lo, flat_p, flat_m)
            np.maximum.at(hi, flat_p, flat_m)
            present = hi[1:] >= 0
            if np.any(lo[1:][present] != hi[1:][present]):
                bad = int(np.flatnonzero(present & (lo[1:] != hi[1:]))[0]) + 1
                raise ValueError(f"particle_ids: particle {bad} spans several material ids")
            _warn_phase_ids_as_particles(mid, pid)
        if particles is not None:
            if not isinstance(particles, ParticleTable):
                raise ValueError("particles: expected a ParticleTable")
            if len(particles) < n_particles:
                raise ValueError(f"particles: table has {len(particles)} rows, labels need "
                                 f"{n_particles}")
        return cls(mid, pid, h, names, particles)

    @classmethod
    def from_spheres(cls, centers_m: np.ndarray, radii_m: np.ndarray,
                     materials: Sequence[str] | str, box_m: float | Sequence[float],
                     shape: int | Sequence[int], matrix: str = "matrix", *,
                     contact: ContactFilm | None = None,
                     progress: Callable[[float], object] | None = None) -> Microstructure:
        """Voxelize periodic spheres (minimum image) on a grid of cubic voxels.

        A voxel belongs to a sphere when its centre lies inside it; where spheres
        overlap, the voxel goes to the sphere with the smallest ``distance / radius``.

        Parameters
        ----------
        centers_m : array, shape (P, 3)
            Sphere centres, m (wrapped into the box).
        radii_m : array, shape (P,)
            Radii, m, > 0 and smaller than half the box.
        materials : str or sequence of str, length P
            Phase name of each sphere (one name for all).
        box_m : float or 3 floats
            Edge lengths of the periodic box, m.
        shape : int or 3 ints
            Voxels per axis; ``box_m / shape`` must be the same h on every axis.
        matrix : str
            Name of the matrix phase.
        contact : ContactFilm, optional
            Which pairs touch and their stated film (default: none stated, every gap as it
            lies).
        progress : callable, optional
            Called with the fraction of the spheres voxelized (rising to 1), a few hundred
            times at most; for a progress bar.
        """
        n = _shape3(shape)
        box, h = _cubic_grid(box_m, n)
        c, r = _sphere_table(centers_m, radii_m, box)
        mats, phase_names, mat_index = _sphere_phases(materials, matrix, c.shape[0])
        if contact is None:
            contact = ContactFilm()
        elif not isinstance(contact, ContactFilm):
            raise ValueError(f"contact: expected a ContactFilm, got {type(contact).__name__}")
        c = np.mod(c, box)
        pid = _voxelize_spheres(c, r, n, h, progress=progress)
        lut = np.concatenate([[0], mat_index]).astype(np.int32)
        mid = np.empty_like(pid)
        for rows in grid_slabs(pid.shape):
            mid[rows] = lut[pid[rows]]
        table = ParticleTable(c, r, np.asarray(mats, dtype=str), contact)
        return cls(mid, pid, h, tuple(phase_names), table)

    def with_film(self, film_m: float) -> Microstructure:
        """The same voxels and spheres, touching pairs meeting at the film ``film_m`` (m).

        The pairs that touch are the packer's (:attr:`ParticleTable.contact`); the voxel
        arrays are shared, not copied.
        """
        if self.particles is None:
            raise ValueError("film_m: a stated film needs the particle table (a "
                             "Microstructure from from_spheres or generate_rve)")
        v = finite_number(film_m, "film_m")
        if v < 0:
            raise ValueError(f"film_m: expected a film >= 0 (m), got {film_m!r}")
        c = self.particles.contact
        table = dataclasses.replace(self.particles, contact=ContactFilm(
            film_m=v, packing_gap_m=c.packing_gap_m, tolerance=c.tolerance))
        return type(self)(self.material_ids, self.particle_ids, self.voxel_m, self.names,
                          table)

    # --------------------------------------------------------------- properties
    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.material_ids.shape)  # type: ignore[return-value]

    @property
    def box_m(self) -> np.ndarray:
        """Edge lengths of the periodic box, m."""
        return np.array(self.shape, dtype=np.float64) * self.voxel_m

    @property
    def n_particles(self) -> int:
        return int(self.particle_ids.max())

    def volume_fractions(self) -> dict[str, float]:
        """Voxel volume fraction of every phase."""
        counts = label_counts(self.material_ids, len(self.names))
        return {n: float(cnt) / self.material_ids.size for n, cnt in zip(self.names, counts)}

    def __repr__(self) -> str:
        fr = ", ".join(f"{k}={v:.3f}" for k, v in self.volume_fractions().items())
        return (f"Microstructure(shape={self.shape}, voxel_m={self.voxel_m:.4g}, "
                f"particles={self.n_particles}, fractions: {fr})")


#: :func:`_voxelize_spheres` reports its progress this many times at most.
_PROGRESS_REPORTS = 200


def _voxelize_spheres(c: np.ndarray, r: np.ndarray, n: tuple[int, int, int], h: float, *,
                      progress: Callable[[float], object] | None = None) -> np.ndarray:
    """Particle id per voxel (0 = matrix) for periodic spheres; voxel centres at (i + 1/2) h.

    One sphere at a time in NumPy (returns to Python between spheres, so signal handlers
    run); ``progress`` gets the fraction of the spheres done.
    """
    pid = np.zeros(n, dtype=np.int32)
    best = np.empty(n, dtype=np.float64)
    for rows in grid_slabs(n):
        best[rows] = np.inf
    every = max(1, c.shape[0] // _PROGRESS_REPORTS)
    for p in range(c.shape[0]):
        if progress is not None and p % every == 0:
            progress(p / c.shape[0])
        ranges = []
        for d in range(3):
            lo = math.ceil((c[p, d] - r[p]) / h - 0.5)
            hi = math.floor((c[p, d] + r[p]) / h - 0.5)
            ranges.append(np.arange(lo, hi + 1))
        if any(len(a) == 0 for a in ranges):
            continue
        dx = [((a + 0.5) * h - c[p, d]) / r[p] for d, a in enumerate(ranges)]
        q = dx[0][:, None, None] ** 2 + dx[1][None, :, None] ** 2 + dx[2][None, None, :] ** 2
        ii = np.ix_(*(np.mod(a, n[d]) for d, a in enumerate(ranges)))
        sub = best[ii]
        take = (q <= 1.0) & (q < sub)
        if not take.any():
            continue
        sub = np.where(take, q, sub)
        best[ii] = sub
        cur = pid[ii]
        pid[ii] = np.where(take, p + 1, cur)
    if progress is not None:
        progress(1.0)
    return pid
