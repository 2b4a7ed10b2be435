"""Contact zones between nearly touching spheres: the pairs, their matrix films, and the
voxels and faces of the thin part of each film.

Two jobs of the gap contact model walk the same zones (:func:`contact_zones`, written once):
:func:`fill_thin_films` gives the matrix voxels of a wedge thinner than a voxel to the
spheres, and :func:`zone_segments` finds the faces of a zone whose conductance the staircase
law takes from the analytic spheres along their centre-to-centre segments.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from ..rve.microstructure import Microstructure
from ..rve.sphere_geometry import min_image, particle_material_ids, segment_in_sphere

__all__ = ["DEFAULT_TOUCH_GAP_M", "SEGMENT_ZONE_VOXELS", "ContactZone", "near_contacts",
           "wedge_radius", "contact_zones", "contact_films", "fill_thin_films",
           "zone_segments"]

#: Particle pairs whose closest surface gap is at most this touch (m): they carry contact
#: spots. The packer leaves ~1 nm between touching particles; nearly touching pairs in a
#: dense packing sit at 10-200 nm.
DEFAULT_TOUCH_GAP_M = 5e-9

#: Contact zones whose film is at most this many voxels get segment conductances.
SEGMENT_ZONE_VOXELS = 3.0


def near_contacts(ms: Microstructure, max_gap: float) -> list[tuple[int, int, np.ndarray]]:
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
            D = min_image(c[pairs[:, 1]] - c[pairs[:, 0]], box)
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



def wedge_radius(dist: float, ra: float, rb: float, h: float) -> float:
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


@dataclass(frozen=True)
class ContactZone:
    """The thin part of the matrix film between two spheres and the voxels around it.

    Attributes
    ----------
    a, b : int
        0-based particle indices (b may equal a: a sphere and its periodic image).
    offset : ndarray, shape (3,)
        From the centre of a to the image of b that makes the contact, m.
    distance : float
        |offset|, m.
    gap : float
        Closest-approach gap ``distance - r_a - r_b``, m.
    direction : ndarray, shape (3,)
        Unit vector along the line of centres.
    rho_max : float
        Distance from the line of centres within which the film is at most the zone's
        thickness, m.
    cells : ndarray of int64, shape (m, 3)
        Unwrapped voxel indices of the box around the zone (take them modulo the grid).
    """

    a: int
    b: int
    offset: np.ndarray
    distance: float
    gap: float
    direction: np.ndarray
    rho_max: float
    cells: np.ndarray


def contact_zones(ms: Microstructure, thickness_m: float, margin_voxels: float
                  ) -> Iterator[ContactZone]:
    """Every contact whose film is thinner than ``thickness_m`` (m) somewhere, with the voxels
    of the box that holds its film thinner than that plus ``margin_voxels`` voxels."""
    table = ms.particles
    shape, h = ms.shape, ms.voxel_m
    c = np.mod(table.centers_m, np.array(shape, dtype=np.float64) * h)
    r = table.radii_m
    for a, b, D in near_contacts(ms, thickness_m):
        dist = float(np.sqrt(D @ D))
        gap0 = dist - r[a] - r[b]
        if gap0 >= thickness_m or dist <= 0.0:
            continue
        u = D / dist
        rho_max = wedge_radius(dist, r[a], r[b], thickness_m)
        x_mid = c[a] + u * (r[a] + 0.5 * gap0)  # closest approach, unwrapped near c[a]
        half = rho_max + margin_voxels * h
        lo_i = np.floor((x_mid - half) / h - 0.5).astype(int)
        hi_i = np.ceil((x_mid + half) / h - 0.5).astype(int)
        ii = [np.arange(lo_i[k], hi_i[k] + 1) for k in range(3)]
        cells = np.stack(np.meshgrid(*ii, indexing="ij"), axis=-1).reshape(-1, 3)
        yield ContactZone(int(a), int(b), D, dist, gap0, u, rho_max, cells)


def contact_films(table, p_lo: np.ndarray, p_hi: np.ndarray, x_face: np.ndarray, d: int,
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
    ca = x_face + min_image(table.centers_m[a] - x_face, box)
    cb = x_face + min_image(table.centers_m[b] - x_face, box)
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
    c = np.mod(table.centers_m, np.array(shape, dtype=np.float64) * h)
    r = table.radii_m
    mat_of = particle_material_ids(ms).astype(mid.dtype)
    filled = 0
    for z in contact_zones(ms, h, 1.0):
        a, b = z.a, z.b
        x = (z.cells + 0.5) * h
        w = x - c[a]
        t = w @ z.direction
        rho2 = (w * w).sum(axis=1) - t * t
        wrapped = tuple(np.mod(z.cells[:, k], shape[k]) for k in range(3))
        free = pid[wrapped] == 0
        da = np.sqrt((w * w).sum(axis=1)) - r[a]
        wb = x - (c[a] + z.offset)
        db = np.sqrt((wb * wb).sum(axis=1)) - r[b]
        sel = (free & (rho2 <= z.rho_max * z.rho_max) & (t > 0.0) & (t < z.distance)
               & (da > 0) & (db > 0))
        if not sel.any():
            continue
        owner = np.where(da[sel] <= db[sel], a, b) + 1
        target = tuple(w_[sel] for w_ in wrapped)
        pid[target] = owner
        mid[target] = mat_of[owner]
        filled += int(sel.sum())
    return pid, mid, filled


def zone_segments(ms: Microstructure, share: Callable[[np.ndarray, int], np.ndarray] | None
                  ) -> tuple[tuple[np.ndarray, ...], ...]:
    """Faces in the contact zones, with the geometry along their centre-to-centre segments.

    Around every pair of spheres whose matrix film is thinner than SEGMENT_ZONE_VOXELS
    voxels somewhere, the faces whose centre lies in that thin part of the film (and within
    a voxel of its two surfaces) get their conductance from the analytic spheres along the
    segment joining the two voxel centres, not from the voxel labels: a film resolved by
    voxels conducts as its voxelized thickness, which along a diagonal normal comes in
    layers of h max|n_i| (``validation/results/thin_film.md``).

    Parameters
    ----------
    ms : Microstructure
        With its particle table.
    share : callable or None
        Interface share of a surface crossing (see
        :func:`itr_fv.rve.sphere_geometry.segment_in_sphere`).

    Returns
    -------
    per axis: flat face index, length in sphere a, length in sphere b (m), summed interface
    shares of the crossings of a and of b, particle ids (1-based) of a and b.
    """
    table = ms.particles
    shape, h = ms.shape, ms.voxel_m
    c = np.mod(table.centers_m, np.array(shape, dtype=np.float64) * h)
    r = table.radii_m
    out = [[[] for _ in range(7)] for _ in range(3)]
    seen = [set() for _ in range(3)]
    for z in contact_zones(ms, SEGMENT_ZONE_VOXELS * h, 2.0):
        a, b, u = z.a, z.b, z.direction
        x = (z.cells + 0.5) * h
        cb = c[a] + z.offset
        for d in range(3):
            xf = x.copy()
            xf[:, d] += 0.5 * h
            w = xf - c[a]
            t = w @ u
            rho2 = np.maximum((w * w).sum(axis=1) - t * t, 0.0)
            surf_a = np.sqrt(np.maximum(r[a] ** 2 - rho2, 0.0))
            surf_b = z.distance - np.sqrt(np.maximum(r[b] ** 2 - rho2, 0.0))
            sel = (rho2 <= z.rho_max ** 2) & (t > surf_a - h) & (t < surf_b + h)
            if not sel.any():
                continue
            la, sa = segment_in_sphere(x[sel], d, h, c[a], r[a], share)
            lb, sb = segment_in_sphere(x[sel], d, h, cb, r[b], share)
            flat = np.ravel_multi_index(
                tuple(np.mod(z.cells[sel, k], shape[k]) for k in range(3)), shape)
            for f, la_, lb_, sa_, sb_ in zip(flat, la, lb, sa, sb):
                if f in seen[d]:
                    continue  # a face in two contact zones keeps the first
                seen[d].add(f)
                for k, v in enumerate((f, la_, lb_, sa_, sb_, a + 1, b + 1)):
                    out[d][k].append(v)
    return tuple(tuple(np.asarray(col) for col in axis) for axis in out)
