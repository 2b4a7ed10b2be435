"""The discrete model: face conductances with interface resistance, load vectors, fluxes.

Both solvers (``itr_fv.homogenize`` and ``itr_fft.homogenize``) solve exactly the system
defined here. Cell-centred finite volumes on an n1 x n2 x n3 periodic grid of cubic voxels
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

Layout convention: ``g[d][i, j, k]`` is the face between voxel (i, j, k) and its periodic
neighbour (i, j, k) + e_d. With the periodic split T = -E.x + theta, conservation in
every voxel reads ``A theta = b(E)`` (see :func:`apply_operator`, :func:`load_vector`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.ndimage
import scipy.sparse
import scipy.sparse.csgraph

from .materials import Materials
from .microstructure import Microstructure

#: Particle pairs whose closest surface gap is at most this touch (m): they carry contact
#: spots. The packer leaves ~1 nm between touching particles; nearly touching pairs in a
#: dense packing sit at 10-200 nm.
DEFAULT_TOUCH_GAP_M = 5e-9

__all__ = [
    "DEFAULT_TOUCH_GAP_M", "FaceGeometry", "face_geometry", "fill_thin_films",
    "face_conductances", "load_vector",
    "apply_operator",
    "face_fluxes", "mean_flux", "energy_tensor", "connected_components", "cell_centres",
]


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
        :func:`fill_thin_films`).
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

    @property
    def _particle_mat(self) -> np.ndarray:
        return self.particle_mat

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

    def conductances(self, materials: Materials) -> np.ndarray:
        """Face conductances per unit area, W/(m^2 K).

        Parameters
        ----------
        materials : Materials
            Conductivities and resistances; every phase of the microstructure and every
            interface pair it holds must be present.

        Returns
        -------
        g : ndarray, shape (3, n1, n2, n3)
            ``g[d][p]`` is the conductance of the face between p and p + e_d.
        """
        if not isinstance(materials, Materials):
            raise ValueError(f"mat: expected a Materials object, got {type(materials).__name__}")
        if materials.contact != self.contact_model:
            raise ValueError(f"geometry: built for contact={self.contact_model!r}, but the "
                             f"materials use contact={materials.contact!r}; build it with "
                             f"face_geometry(ms, contact={materials.contact!r})")
        k, R = materials.tables(self.names)
        gap_model = materials.contact == "gap"
        if gap_model and self.film is None and self.n_contact_faces:
            raise ValueError("contact: the gap model needs the particle geometry (a "
                             "Microstructure from from_spheres or generate_rve); this label "
                             "image has faces between different particles: pass "
                             "Materials(..., contact='area') for a per-area contact resistance")
        h = self.voxel_m
        half_r = (0.5 * h) / k  # h / (2 k) per material id, m^2 K / W
        rc = half_r[self.material_ids]
        spots = None
        if gap_model and self.pair_material_ids is not None and materials.contact_conductance:
            spots = np.array([materials.spot_conductance(self.names[a], self.names[b])
                              for a, b in self.pair_material_ids])
            spots[self.pair_gap_m > self.touch_gap_m] = 0.0
            spots /= self.pair_faces * h * h  # W/(m^2 K) on each face of the pair
        g = np.empty((3,) + self.shape, dtype=np.float64)
        for d in range(3):
            np.add(rc, np.roll(rc, -1, axis=d), out=g[d])
            np.divide(1.0, g[d], out=g[d])
            idx = self.index[d]
            if idx.size == 0:
                continue
            lo, hi = self.mat_lo[d], self.mat_hi[d]
            r_face = R[lo, hi]
            cont = self.contact[d]
            if gap_model and cont.any():
                # two particle-matrix resistances (material id 0 is the matrix) + the film
                r_face[cont] = R[lo[cont], 0] + R[hi[cont], 0] + self.film[d][cont] / k[0]
            if np.isnan(r_face).any():
                j = int(np.flatnonzero(np.isnan(r_face))[0])
                if gap_model and cont[j]:
                    m = lo[j] if np.isnan(R[lo[j], 0]) else hi[j]
                    materials.resistance_between(self.names[m], self.names[0])  # raises
                materials.resistance_between(self.names[lo[j]], self.names[hi[j]])  # raises
            with np.errstate(invalid="ignore"):
                series = half_r[lo] + half_r[hi] + np.where(np.isinf(r_face), np.inf,
                                                            r_face * self.s[d])
            g[d].reshape(-1)[idx] = 1.0 / series
            if gap_model and self.segments is not None and self.segments[d][0].size:
                self._segment_conductances(g[d], d, k, R)
            if spots is not None and cont.any():
                g[d].reshape(-1)[idx[cont]] += spots[self.pair[d][cont]]
        return g

    def _segment_conductances(self, gd: np.ndarray, d: int, k: np.ndarray,
                              R: np.ndarray) -> None:
        """Overwrite the faces of the contact zones with their segment conductances:
        ``1 / (l_a/k_a + l_b/k_b + l_m/k_m + s_a R_b,a + s_b R_b,b)`` (W/(m^2 K)), the
        lengths along the segment joining the two voxel centres."""
        flat, la, lb, sa, sb, pa, pb = self.segments[d]
        ma = self._particle_mat[pa]
        mb = self._particle_mat[pb]
        lm = np.maximum(self.voxel_m - la - lb, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            ra = np.where(sa > 0, sa * R[ma, 0], 0.0)
            rb = np.where(sb > 0, sb * R[mb, 0], 0.0)
            series = la / k[ma] + lb / k[mb] + lm / k[0] + ra + rb
        gd.reshape(-1)[flat] = np.where(np.isinf(series), 0.0, 1.0 / series)


def cell_centres(shape: tuple[int, int, int], voxel_m: float, axis: int) -> np.ndarray:
    """Coordinate (m) of the voxel centres along ``axis``, broadcastable to ``shape``."""
    x = (np.arange(shape[axis]) + 0.5) * voxel_m
    view = [1, 1, 1]
    view[axis] = shape[axis]
    return x.reshape(view)


def _min_image(dx: np.ndarray, box: np.ndarray) -> np.ndarray:
    return dx - box * np.round(dx / box)


def _staircase_factor(n: np.ndarray) -> np.ndarray:
    """s = |n_x| + |n_y| + |n_z| for unnormalised normals n (shape (m, 3)); 1 where n = 0."""
    norm = np.sqrt((n * n).sum(axis=1))
    s = np.ones(n.shape[0])
    ok = norm > 0
    s[ok] = np.abs(n[ok]).sum(axis=1) / norm[ok]
    return s


def _self_image_faces(table, pid: np.ndarray, pq: np.ndarray, d: int,
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
    u_p = _min_image((i_d + 0.5) * h - c, np.array(L))
    u_q = _min_image((i_d + 1.5) * h - c, np.array(L))
    return cand[np.abs(u_q - u_p - h) > 0.5 * h]


def _contact_films(table, p_lo: np.ndarray, p_hi: np.ndarray, x_face: np.ndarray, d: int,
                   box: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Film thickness d(x_f) at contact faces, the contacts' closest gaps and image shifts.

    The two spheres are taken in their periodic images nearest to the face (in a small
    periodic cell one pair can touch through several images: each is its own contact).
    ``d = |c_q - c_p| - sqrt(a_p^2 - rho^2) - sqrt(a_q^2 - rho^2)`` with rho the distance of
    the face centre from the line of centres, clipped below at the closest gap
    ``|c_q - c_p| - a_p - a_q`` (and at 0). A sphere meeting its own periodic image (p == q)
    faces that image one box length along e_d.

    Returns
    -------
    film, gap0 : ndarray, m
    shift : ndarray of int64, shape (m, 3)
        Image of q relative to p (in box lengths): with p, q and the shift it names one
        contact.
    """
    a = p_lo - 1
    b = p_hi - 1
    ca = x_face + _min_image(table.centers_m[a] - x_face, box)
    cb = x_face + _min_image(table.centers_m[b] - x_face, box)
    own = a == b
    if own.any():  # the other image lies on the other side of the face along e_d
        side = np.where(x_face[own, d] >= ca[own, d], 1.0, -1.0)
        cb[own, d] = ca[own, d] + side * box[d]
    D = cb - ca
    shift = np.rint((D - (table.centers_m[b] - table.centers_m[a])) / box).astype(np.int64)
    dist = np.sqrt((D * D).sum(axis=1))
    u = D / dist[:, None]
    w = x_face - ca
    along = (w * u).sum(axis=1)
    rho2 = np.maximum((w * w).sum(axis=1) - along * along, 0.0)
    ra = table.radii_m[a]
    rb = table.radii_m[b]
    gap0 = dist - ra - rb
    film = (dist - np.sqrt(np.maximum(ra * ra - rho2, 0.0))
            - np.sqrt(np.maximum(rb * rb - rho2, 0.0)))
    return np.maximum(film, np.maximum(gap0, 0.0)), gap0, shift


def _particle_material_ids(ms: Microstructure) -> np.ndarray:
    """Material id of every particle id (index 0: the matrix), from the particle table."""
    return np.concatenate([[0], [ms.names.index(m) for m in ms.particles.material]]
                          ).astype(np.int64)


def _wedge_radius(dist: float, ra: float, rb: float, h: float) -> float:
    """Largest distance rho from the line of centres at which the film is at most h."""
    def film(rho: float) -> float:
        return dist - math.sqrt(max(ra * ra - rho * rho, 0.0)) - \
            math.sqrt(max(rb * rb - rho * rho, 0.0))
    lo, hi = 0.0, min(ra, rb)
    if film(hi) <= h:
        return hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if film(mid) <= h else (lo, mid)
    return lo


def _near_contacts(ms: Microstructure, max_gap: float) -> list[tuple[int, int, np.ndarray]]:
    """Pairs of spheres (0-based indices a, b and the vector D from a to the image of b)
    whose closest gap is below ``max_gap`` (m); in small periodic cells every image counts."""
    import scipy.spatial

    table = ms.particles
    box = np.array(ms.shape, dtype=np.float64) * ms.voxel_m
    c = np.mod(table.centers_m, box)
    r = table.radii_m
    reach = 2.0 * float(r.max()) + max_gap
    todo = []
    if reach < 0.5 * float(box.min()):
        # large box: a pair within reach touches through its minimum image only
        if len(table) > 1:
            tree = scipy.spatial.cKDTree(c, boxsize=box * (1 + 1e-12))
            pairs = tree.query_pairs(reach, output_type="ndarray")
            D = _min_image(c[pairs[:, 1]] - c[pairs[:, 0]], box)
            near = np.sqrt((D * D).sum(axis=1)) < r[pairs[:, 0]] + r[pairs[:, 1]] + max_gap
            todo = [(int(i), int(j), dv) for (i, j), dv in zip(pairs[near], D[near])]
    else:
        # small periodic cell: a pair (or a sphere and itself) may touch through any image
        shifts = np.array([(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1)
                           for z in (-1, 0, 1)])
        for i in range(len(r)):
            for j in range(i, len(r)):
                for sh in shifts:
                    if i == j and tuple(sh) <= (0, 0, 0):
                        continue  # itself, and each self-image contact once
                    D = c[j] + sh * box - c[i]
                    if np.sqrt(D @ D) < r[i] + r[j] + max_gap:
                        todo.append((i, j, D))
    return todo


def fill_thin_films(ms: Microstructure) -> tuple[np.ndarray, np.ndarray, int]:
    """Particle and material ids with matrix wedges thinner than a voxel given to a particle.

    Between two nearly touching spheres the matrix forms a wedge that is thinner than the
    voxel h near the contact. Centre-based voxelization keeps some of its voxels as matrix
    (mostly particle by volume) and, for contacts not along a grid axis, leaves the two
    particles without a shared voxel face, so the contact conducts through a whole matrix
    voxel. The gap model carries films thinner than h at particle-particle faces (d(x_f)
    / k_m), so here every matrix voxel whose centre lies between two spheres, within the
    distance from their line of centres where the film is at most h, goes to the sphere
    whose surface is nearer. Films thicker than h stay resolved by matrix voxels.

    Returns
    -------
    particle_ids, material_ids : ndarray
        Copies with the wedge voxels filled.
    filled : int
        Number of voxels that changed.
    """
    table = ms.particles
    pid = ms.particle_ids.copy()
    mid = ms.material_ids.copy()
    if table is None or len(table) < 1:
        return pid, mid, 0
    shape, h = ms.shape, ms.voxel_m
    box = np.array(shape, dtype=np.float64) * h
    c = np.mod(table.centers_m, box)
    r = table.radii_m
    mat_of = _particle_material_ids(ms).astype(mid.dtype)
    todo = _near_contacts(ms, h)
    filled = 0
    for a, b, D in todo:
        dist = float(np.sqrt(D @ D))
        gap0 = dist - r[a] - r[b]
        if gap0 >= h or dist <= 0.0:
            continue
        u = D / dist
        rho_max = _wedge_radius(dist, r[a], r[b], h)
        x0 = c[a] + u * (r[a] + 0.5 * gap0)  # closest approach, unwrapped near c[a]
        half = rho_max + h
        lo_i = np.floor((x0 - half) / h - 0.5).astype(int)
        hi_i = np.ceil((x0 + half) / h - 0.5).astype(int)
        ii = [np.arange(lo_i[k], hi_i[k] + 1) for k in range(3)]
        grid = np.stack(np.meshgrid(*ii, indexing="ij"), axis=-1).reshape(-1, 3)
        x = (grid + 0.5) * h
        w = x - c[a]
        t = w @ u
        rho2 = (w * w).sum(axis=1) - t * t
        wrapped = tuple(np.mod(grid[:, k], shape[k]) for k in range(3))
        free = pid[wrapped] == 0
        da = np.sqrt((w * w).sum(axis=1)) - r[a]
        wb = x - (c[a] + D)
        db = np.sqrt((wb * wb).sum(axis=1)) - r[b]
        sel = free & (rho2 <= rho_max * rho_max) & (t > 0.0) & (t < dist) & (da > 0) & (db > 0)
        if not sel.any():
            continue
        owner = np.where(da[sel] <= db[sel], a, b) + 1
        target = tuple(w_[sel] for w_ in wrapped)
        pid[target] = owner
        mid[target] = mat_of[owner]
        filled += int(sel.sum())
    return pid, mid, filled


#: Contact zones whose film is at most this many voxels get segment conductances.
SEGMENT_ZONE_VOXELS = 3.0


def _segment_in_sphere(x0: np.ndarray, d: int, h: float, centre: np.ndarray, radius: float,
                       staircase: bool) -> tuple[np.ndarray, np.ndarray]:
    """Length (m) of the segments x0 -> x0 + h e_d inside a sphere, and the sum of the
    staircase factors of the surface crossings strictly inside the segments."""
    w = x0 - centre
    wd = w[:, d]
    disc = radius * radius - ((w * w).sum(axis=1) - wd * wd)
    root = np.sqrt(np.maximum(disc, 0.0))
    t1 = (-wd - root) / h
    t2 = (-wd + root) / h
    inside = np.where(disc > 0, np.clip(np.minimum(t2, 1.0) - np.maximum(t1, 0.0), 0.0, None),
                      0.0) * h
    s_sum = np.zeros(len(x0))
    for t in (t1, t2):
        cross = (disc > 0) & (t > 0.0) & (t < 1.0)
        if cross.any():
            p = x0[cross] - centre
            p[:, d] += t[cross] * h
            s_sum[cross] += _staircase_factor(p) if staircase else 1.0
    return inside, s_sum


def _segment_faces(ms: Microstructure, staircase: bool) -> tuple[list, ...]:
    """Faces in the contact zones, with the geometry along their centre-to-centre segments.

    Around every pair of spheres whose matrix film is thinner than SEGMENT_ZONE_VOXELS
    voxels somewhere, the faces whose centre lies in that thin part of the film (and within
    a voxel of its two surfaces) get their conductance from the analytic spheres along the
    segment joining the two voxel centres, not from the voxel labels: a film resolved by
    voxels conducts as its voxelized thickness, which along a diagonal normal comes in
    layers of h max|n_i| (``validation/results/thin_film.md``).

    Returns
    -------
    per axis: flat face index, length in sphere a, length in sphere b (m), summed staircase
    factors of the crossings of a and of b, particle ids (1-based) of a and b.
    """
    table = ms.particles
    shape, h = ms.shape, ms.voxel_m
    c = np.mod(table.centers_m, np.array(shape, dtype=np.float64) * h)
    r = table.radii_m
    zone = SEGMENT_ZONE_VOXELS * h
    out = [[[] for _ in range(7)] for _ in range(3)]
    seen = [set() for _ in range(3)]
    for a, b, D in _near_contacts(ms, zone):
        dist = float(np.sqrt(D @ D))
        gap0 = dist - r[a] - r[b]
        if gap0 >= zone or dist <= 0.0:
            continue
        u = D / dist
        rho_max = _wedge_radius(dist, r[a], r[b], zone)
        x_mid = c[a] + u * (r[a] + 0.5 * gap0)
        half = rho_max + 2 * h
        lo_i = np.floor((x_mid - half) / h - 0.5).astype(int)
        hi_i = np.ceil((x_mid + half) / h - 0.5).astype(int)
        ii = [np.arange(lo_i[k], hi_i[k] + 1) for k in range(3)]
        grid = np.stack(np.meshgrid(*ii, indexing="ij"), axis=-1).reshape(-1, 3)
        x = (grid + 0.5) * h
        cb = c[a] + D
        for d in range(3):
            xf = x.copy()
            xf[:, d] += 0.5 * h
            w = xf - c[a]
            t = w @ u
            rho2 = np.maximum((w * w).sum(axis=1) - t * t, 0.0)
            surf_a = np.sqrt(np.maximum(r[a] ** 2 - rho2, 0.0))
            surf_b = dist - np.sqrt(np.maximum(r[b] ** 2 - rho2, 0.0))
            sel = (rho2 <= rho_max ** 2) & (t > surf_a - h) & (t < surf_b + h)
            if not sel.any():
                continue
            la, sa = _segment_in_sphere(x[sel], d, h, c[a], r[a], staircase)
            lb, sb = _segment_in_sphere(x[sel], d, h, cb, r[b], staircase)
            flat = np.ravel_multi_index(tuple(np.mod(grid[sel, k], shape[k]) for k in range(3)),
                                        shape)
            for f, la_, lb_, sa_, sb_ in zip(flat, la, lb, sa, sb):
                if f in seen[d]:
                    continue  # a face in two contact zones keeps the first
                seen[d].add(f)
                for k, v in enumerate((f, la_, lb_, sa_, sb_, a + 1, b + 1)):
                    out[d][k].append(v)
    return tuple(tuple(np.asarray(col) for col in axis) for axis in out)


def face_geometry(ms: Microstructure, staircase: bool = True,
                  image_smoothing: float = 1.5,
                  touch_gap_m: float = DEFAULT_TOUCH_GAP_M,
                  contact: str = "gap") -> FaceGeometry:
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
        the geometry's own ``material_ids`` then differ from the microstructure's there.

    Returns
    -------
    FaceGeometry
    """
    if not isinstance(ms, Microstructure):
        raise ValueError(f"ms: expected a Microstructure, got {type(ms).__name__}")
    if contact not in ("gap", "area"):
        raise ValueError(f"contact: expected 'gap' or 'area', got {contact!r}")
    shape, h = ms.shape, ms.voxel_m
    pid, mid = ms.particle_ids, ms.material_ids
    filled = 0
    if contact == "gap" and ms.particles is not None:
        pid, mid, filled = fill_thin_films(ms)
    box = np.array(shape, dtype=np.float64) * h
    index, lo, hi, is_contact_all, s_all = [], [], [], [], []
    films, pair_keys, gaps, keys_seen = [], [], [], []
    table = ms.particles
    mode = "off" if not staircase else ("spheres" if table is not None else "image")
    grad = None
    if mode == "image" and ms.n_particles:
        solid = scipy.ndimage.gaussian_filter((pid > 0).astype(np.float64), image_smoothing,
                                              mode="wrap")
        grad = [0.5 * (np.roll(solid, -1, axis=a) - np.roll(solid, 1, axis=a)) for a in range(3)]
    for d in range(3):
        pq = np.roll(pid, -1, axis=d)
        idx = np.flatnonzero((pid != pq).ravel())
        if table is not None:
            idx = np.union1d(idx, _self_image_faces(table, pid, pq, d, shape, h))
        p_lo = pid.ravel()[idx]
        p_hi = pq.ravel()[idx]
        index.append(idx)
        lo.append(mid.ravel()[idx])
        hi.append(np.roll(mid, -1, axis=d).ravel()[idx])
        is_contact = (p_lo > 0) & (p_hi > 0)
        is_contact_all.append(is_contact)
        s = np.ones(idx.size)
        # a sphere touching its own periodic image: the line of centres is e_d, s = 1
        self_image = is_contact & (p_lo == p_hi)
        if mode == "spheres" and idx.size:
            ijk = np.stack(np.unravel_index(idx, shape), axis=1).astype(np.float64)
            x_face = (ijk + 0.5) * h
            x_face[:, d] += 0.5 * h
            pm = ~is_contact
            part = np.maximum(p_lo, p_hi)[pm] - 1
            n_pm = _min_image(x_face[pm] - table.centers_m[part], box)
            s[pm] = _staircase_factor(n_pm)
            pp = is_contact & ~self_image
            if pp.any():
                a = p_lo[pp] - 1
                b = p_hi[pp] - 1
                n_pp = _min_image(table.centers_m[b] - table.centers_m[a], box)
                s[pp] = _staircase_factor(n_pp)
        if table is not None:
            film = np.full(idx.size, np.nan)
            key = np.full(idx.size, -1, dtype=np.int64)
            gap0 = np.zeros(0)
            if is_contact.any():
                ijk = np.stack(np.unravel_index(idx[is_contact], shape), axis=1)
                x_c = (ijk + 0.5) * h
                x_c[:, d] += 0.5 * h
                pa = np.minimum(p_lo, p_hi)[is_contact].astype(np.int64)
                pb = np.maximum(p_lo, p_hi)[is_contact].astype(np.int64)
                film[is_contact], gap0, shift = _contact_films(table, pa, pb, x_c, d, box)
                own = pa == pb  # a self-image contact seen from either side is one contact
                flip = own & (shift[:, d] < 0)
                shift[flip] *= -1
                keys_seen.extend(map(tuple, np.column_stack([pa, pb, shift])))
                key[is_contact] = np.arange(len(keys_seen) - pa.size, len(keys_seen))
            films.append(film)
            pair_keys.append(key)
            gaps.append(gap0)
        if mode == "image" and idx.size:
            pm = np.flatnonzero(~is_contact)
            p_flat = idx[pm]
            q_flat = np.ravel_multi_index(
                tuple(np.mod(c + (1 if a == d else 0), shape[a])
                      for a, c in enumerate(np.unravel_index(p_flat, shape))), shape)
            n_est = np.stack([0.5 * (grad[a].ravel()[p_flat] + grad[a].ravel()[q_flat])
                              for a in range(3)], axis=1)
            s[pm] = _staircase_factor(n_est)
        s_all.append(s)
    extra = {}
    if table is not None:
        # one contact = (particle p, particle q, image shift of q); faces -> contact index
        rows = np.array(keys_seen, dtype=np.int64).reshape(-1, 5)
        uniq, first, inverse, counts = np.unique(rows, axis=0, return_index=True,
                                                 return_inverse=True, return_counts=True)
        inverse = inverse.reshape(-1)
        gap_of_row = np.concatenate(gaps) if gaps else np.zeros(0)
        pairs = uniq[:, :2]
        face_pair = [np.where(k >= 0, inverse[np.maximum(k, 0)], -1) if inverse.size
                     else np.full_like(k, -1) for k in pair_keys]
        mat_of_particle = _particle_material_ids(ms)
        extra = dict(
            film=tuple(films),
            pair=tuple(face_pair), pair_particles=pairs, pair_gap_m=gap_of_row[first],
            pair_faces=counts,
            pair_material_ids=mat_of_particle[pairs].astype(np.int32),
            touch_gap_m=float(touch_gap_m), filled_voxels=filled,
            segments=_segment_faces(ms, staircase) if contact == "gap" else None,
            particle_mat=mat_of_particle)
    return FaceGeometry(tuple(shape), float(h), tuple(ms.names), mid, tuple(index), tuple(lo),
                        tuple(hi), tuple(is_contact_all), tuple(s_all), mode,
                        contact_model=contact, **extra)


def face_conductances(ms: Microstructure, mat: Materials, staircase: bool = True) -> np.ndarray:
    """Face conductances per unit area g, W/(m^2 K), shape (3, n1, n2, n3).

    Shorthand for ``face_geometry(ms, staircase, contact=mat.contact).conductances(mat)``.
    """
    return face_geometry(ms, staircase, contact=mat.contact).conductances(mat)


def load_vector(g: np.ndarray, voxel_m: float, E: np.ndarray) -> np.ndarray:
    """Right-hand side b(E) of ``A theta = b`` for the macroscopic gradient load E.

    With T = -E.x + theta and the outgoing face flux g (T_p - T_q), conservation in voxel p
    gives ``(A theta)_p = h * sum_d E_d (g_d[p - e_d] - g_d[p])``: a net flux density,
    W/m^2 for E in K/m (every term of the balance is divided by the face area h^2).

    Parameters
    ----------
    g : ndarray, shape (3, n1, n2, n3)
        Face conductances, W/(m^2 K).
    voxel_m : float
        Voxel edge h, m.
    E : array of 3 floats
        Load, K/m (E = e_j gives column j of the effective tensor).

    Returns
    -------
    b : ndarray, shape (n1, n2, n3)
    """
    b = np.zeros(g.shape[1:])
    for d in range(3):
        if E[d] != 0.0:
            b += (voxel_m * E[d]) * (np.roll(g[d], 1, axis=d) - g[d])
    return b


def apply_operator(g: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """``A theta``: net outgoing flux of every voxel for the periodic field theta (W/m^2)."""
    out = np.zeros_like(theta)
    for d in range(3):
        up = g[d] * (theta - np.roll(theta, -1, axis=d))
        out += up
        out -= np.roll(up, 1, axis=d)
    return out


def face_fluxes(g: np.ndarray, theta: np.ndarray, voxel_m: float, E: np.ndarray) -> np.ndarray:
    """Flux density through every face, W/m^2, shape (3, n1, n2, n3).

    ``q[d][p] = g_d[p] (T_p - T_{p+e_d})`` with ``T = -E.x + theta``, positive along +e_d.
    """
    q = np.empty_like(g)
    for d in range(3):
        np.multiply(g[d], theta - np.roll(theta, -1, axis=d) + voxel_m * E[d], out=q[d])
    return q


def mean_flux(g: np.ndarray, theta: np.ndarray, voxel_m: float, E: np.ndarray) -> np.ndarray:
    """Volume-averaged heat flux <q>, W/m^2 (each voxel owns its upper face on every axis)."""
    return np.array([np.mean(g[d] * (theta - np.roll(theta, -1, axis=d) + voxel_m * E[d]))
                     for d in range(3)])


def energy_tensor(g: np.ndarray, thetas: list[np.ndarray], voxel_m: float,
                  directions: tuple[int, ...]) -> np.ndarray:
    """Variational (energy) estimate of the effective tensor block, W/(m K).

    ``K_ij = 1 / (N h) * sum over faces g dT_i dT_j`` with ``dT = T_p - T_q`` of load case
    i and j. It equals the flux average at the exact solution (Hill-Mandel) but its error
    is quadratic in the solver error (the diagonal is an upper bound), so it stays accurate
    where the flux average loses digits, e.g. behind nearly insulating layers.

    Returns
    -------
    ndarray, shape (3, 3)
        NaN outside the solved block.
    """
    K = np.full((3, 3), np.nan)
    N = g[0].size
    for a, i in enumerate(directions):
        for b, j in enumerate(directions[a:], start=a):
            total = 0.0
            for d in range(3):
                dTi = thetas[a] - np.roll(thetas[a], -1, axis=d) + (voxel_m if d == i else 0.0)
                dTj = thetas[b] - np.roll(thetas[b], -1, axis=d) + (voxel_m if d == j else 0.0)
                total += float(np.sum(g[d] * dTi * dTj))
            K[i, j] = K[j, i] = total / (N * voxel_m)
    return K


def connected_components(g: np.ndarray) -> tuple[int, np.ndarray]:
    """Connected components of the voxel graph whose edges are faces with g > 0.

    Returns
    -------
    n : int
        Number of components (1 unless insulating interfaces cut off clusters).
    labels : ndarray of int32, shape (n1, n2, n3)
        Component of every voxel; component 0 is the largest.
    """
    shape = g.shape[1:]
    N = int(np.prod(shape))
    ids = np.arange(N).reshape(shape)
    rows, cols = [], []
    for d in range(3):
        mask = g[d] > 0
        rows.append(ids[mask])
        cols.append(np.roll(ids, -1, axis=d)[mask])
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    adj = scipy.sparse.coo_array((np.ones(r.size, dtype=np.int8), (r, c)), shape=(N, N)).tocsr()
    n, labels = scipy.sparse.csgraph.connected_components(adj, directed=False)
    if n > 1:
        sizes = np.bincount(labels, minlength=n)
        order = np.argsort(-sizes, kind="stable")
        remap = np.empty(n, dtype=np.int64)
        remap[order] = np.arange(n)
        labels = remap[labels]
    return int(n), labels.reshape(shape).astype(np.int32)
