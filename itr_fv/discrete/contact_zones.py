"""Contact zones between nearly touching spheres: the pairs, their matrix films, and the
voxels and faces of the thin part of each film.

Two jobs of the gap contact model walk the same zones (:func:`zone_table`, written once):
:func:`fill_thin_films` gives the matrix voxels of a wedge thinner than a voxel to the
spheres, and :func:`zone_segments` finds the faces of a zone whose conductance the staircase
law takes from the analytic spheres along their centre-to-centre segments. Both walk the
cells of every zone in numba kernels (:mod:`itr_fv.discrete._geometry_kernels`);
:func:`contact_zones` lists the same zones with their cells, one at a time.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from ..rve.microstructure import Microstructure
from ..rve.sphere_geometry import min_image, particle_material_ids, segment_in_sphere
from . import _geometry_kernels as K
from .cut_cells import SHARES

__all__ = ["DEFAULT_TOUCH_GAP_M", "SEGMENT_ZONE_VOXELS", "ContactZone", "ZoneTable",
           "near_contacts", "wedge_radius", "zone_table", "contact_zones", "contact_films",
           "fill_thin_films", "zone_segments"]

#: Particle pairs whose closest surface gap is at most this touch (m): they carry contact
#: spots. Touching particles meet at their stated film (:mod:`itr_fv.rve.contact_film`; 0
#: by default); nearly touching pairs in a dense packing sit at 10-200 nm.
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


def _wedge_radii(dist: np.ndarray, ra: np.ndarray, rb: np.ndarray, h: float) -> np.ndarray:
    """:func:`wedge_radius` of many contacts at once (the same bisection, elementwise), m."""
    def film(rho: np.ndarray) -> np.ndarray:
        return (dist - np.sqrt(np.maximum(ra * ra - rho * rho, 0.0))
                - np.sqrt(np.maximum(rb * rb - rho * rho, 0.0)))
    top = np.minimum(ra, rb)
    lo, hi = np.zeros_like(top), top.copy()
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        thin = film(mid) <= h
        lo, hi = np.where(thin, mid, lo), np.where(thin, hi, mid)
    return np.where(film(top) <= h, top, lo)


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


@dataclass(frozen=True)
class ZoneTable:
    """The contact zones of one film thickness, as arrays with one row per zone.

    Attributes
    ----------
    a, b : ndarray of int64, shape (Z,)
        0-based particle indices (b may equal a: a sphere and its periodic image).
    offset : ndarray, shape (Z, 3)
        From the centre of a to the image of b that makes the contact, m.
    centre_a, centre_b : ndarray, shape (Z, 3)
        Centre of a in the box and of that image of b (``centre_a + offset``), m.
    radius_a, radius_b : ndarray, shape (Z,)
        Radii, m.
    distance, gap : ndarray, shape (Z,)
        Distance of the centres and closest-approach gap ``distance - r_a - r_b``, m.
    direction : ndarray, shape (Z, 3)
        Unit vector from a to b.
    rho_max : ndarray, shape (Z,)
        Distance from the line of centres within which the film is at most the zone's
        thickness, m.
    lo, hi : ndarray of int64, shape (Z, 3)
        First and last unwrapped voxel index of the box around each zone, per axis.
    """

    a: np.ndarray
    b: np.ndarray
    offset: np.ndarray
    centre_a: np.ndarray
    centre_b: np.ndarray
    radius_a: np.ndarray
    radius_b: np.ndarray
    distance: np.ndarray
    gap: np.ndarray
    direction: np.ndarray
    rho_max: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    def __len__(self) -> int:
        return int(self.a.size)


def zone_table(ms: Microstructure, thickness_m: float, margin_voxels: float) -> ZoneTable:
    """Every contact whose film is thinner than ``thickness_m`` (m) somewhere, with the box
    of voxels that holds its film thinner than that plus ``margin_voxels`` voxels.

    Parameters
    ----------
    ms : Microstructure
        With its particle table.
    thickness_m : float
        Film thickness that bounds a zone, m (> 0).
    margin_voxels : float
        Voxels added around the thin film on every side (>= 0).

    Returns
    -------
    ZoneTable
    """
    if ms.particles is None:
        raise ValueError("ms: contact zones need the particle table (a Microstructure from "
                         "from_spheres or generate_rve)")
    if not thickness_m > 0:
        raise ValueError(f"thickness_m: expected a film thickness > 0 (m), got {thickness_m!r}")
    if not margin_voxels >= 0:
        raise ValueError(f"margin_voxels: expected a number >= 0, got {margin_voxels!r}")
    table = ms.particles
    shape, h = ms.shape, ms.voxel_m
    c = np.mod(table.centers_m, np.array(shape, dtype=np.float64) * h)
    r = table.radii_m
    rule = table.contact
    kept = []
    for a, b, D in near_contacts(ms, thickness_m + rule.reach_m(float(r.max()))):
        dist = float(np.sqrt(D @ D))  # as contact_zones computes it (BLAS), per contact
        if dist <= 0.0:
            continue
        moved = dist - float(rule.clearance(dist - r[a] - r[b], r[a], r[b]))
        if moved - r[a] - r[b] >= thickness_m:
            continue
        # a touching pair meets at the stated film: the image of b moves along the line
        D = D * (moved / dist)
        kept.append((a, b, D, moved))
    a = np.array([k[0] for k in kept], dtype=np.int64)
    b = np.array([k[1] for k in kept], dtype=np.int64)
    D = np.array([k[2] for k in kept], dtype=np.float64).reshape(-1, 3)
    dist = np.array([k[3] for k in kept], dtype=np.float64)
    gap0 = dist - r[a] - r[b]
    u = D / dist[:, None]
    rho_max = _wedge_radii(dist, r[a], r[b], thickness_m)
    x_mid = c[a] + u * (r[a] + 0.5 * gap0)[:, None]  # closest approach, unwrapped near c[a]
    half = (rho_max + margin_voxels * h)[:, None]
    lo_i = np.floor((x_mid - half) / h - 0.5).astype(np.int64)
    hi_i = np.ceil((x_mid + half) / h - 0.5).astype(np.int64)
    return ZoneTable(a, b, D, c[a], c[a] + D, r[a], r[b], dist, gap0, u, rho_max, lo_i, hi_i)


def contact_zones(ms: Microstructure, thickness_m: float, margin_voxels: float
                  ) -> Iterator[ContactZone]:
    """Every contact whose film is thinner than ``thickness_m`` (m) somewhere, with the voxels
    of the box that holds its film thinner than that plus ``margin_voxels`` voxels (the
    zones of :func:`zone_table`, one at a time)."""
    zt = zone_table(ms, thickness_m, margin_voxels)
    for z in range(len(zt)):
        ii = [np.arange(zt.lo[z, k], zt.hi[z, k] + 1) for k in range(3)]
        cells = np.stack(np.meshgrid(*ii, indexing="ij"), axis=-1).reshape(-1, 3)
        yield ContactZone(int(zt.a[z]), int(zt.b[z]), zt.offset[z],
                          float(zt.distance[z]), float(zt.gap[z]), zt.direction[z],
                          float(zt.rho_max[z]), cells)


def contact_films(table, p_lo: np.ndarray, p_hi: np.ndarray, x_face: np.ndarray, d: int,
                   box: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Film thickness d(x_f) at contact faces, the contacts' closest gaps and image shifts.

    The two spheres are taken in their periodic images nearest to the face (in a small
    periodic cell one pair can touch through several images: each is its own contact).
    ``d = |c_q - c_p| - sqrt(a_p^2 - rho^2) - sqrt(a_q^2 - rho^2)`` with rho the distance of
    the face centre from the line of centres, clipped below at the closest gap
    ``|c_q - c_p| - a_p - a_q`` (and at 0). A sphere meeting its own periodic image (p == q)
    faces that image one box length along e_d.

    :func:`itr_fv.discrete.face_geometry.face_geometry` computes the same numbers in a numba
    kernel (:func:`itr_fv.discrete._geometry_kernels.sphere_faces`).

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
    ra = table.radii_m[a]
    rb = table.radii_m[b]
    dist = dist - table.contact.clearance(dist - ra - rb, ra, rb)
    w = x_face - ca
    along = (w * u).sum(axis=1)
    rho2 = np.maximum((w * w).sum(axis=1) - along * along, 0.0)
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
    threads = K.current_threads(math.prod(ms.shape))
    pid = K.parallel_copy(ms.particle_ids, threads)
    mid = K.parallel_copy(ms.material_ids, threads)
    if table is None or len(table) < 1:
        return pid, mid, 0
    zt = zone_table(ms, ms.voxel_m, 1.0)
    if len(zt) == 0:
        return pid, mid, 0
    mat_of = particle_material_ids(ms).astype(mid.dtype)
    filled = K.zone_fill(pid, mid, mat_of, zt.a, zt.b, zt.centre_a, zt.centre_b, zt.radius_a,
                         zt.radius_b, zt.direction, zt.distance, zt.rho_max, zt.lo, zt.hi,
                         float(ms.voxel_m))
    return pid, mid, int(filled)


def _share_rule(share: Callable[[np.ndarray, int], np.ndarray] | None) -> int | None:
    """The kernels' code of a share rule: 0 for None (1 per crossing), 1 for the staircase
    share; None for any other rule (walked in NumPy)."""
    if share is None:
        return 0
    if share is SHARES["staircase"]:
        return 1
    return None


def _squares(values: np.ndarray) -> np.ndarray:
    """``v ** 2`` of every value as a scalar power (``pow``): the zones square their scalars
    so (``rho_max ** 2``, ``r ** 2``); an array's ``** 2`` is a product, which differs from
    ``pow`` in the last bit for about 0.1 % of values."""
    return np.array([float(v) ** 2 for v in values], dtype=np.float64)


def _empty_segments() -> tuple[np.ndarray, ...]:
    """The seven columns of an axis without zone faces (empty float64, as ever)."""
    return tuple(np.asarray([]) for _ in range(7))


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
        :func:`itr_fv.rve.sphere_geometry.segment_in_sphere`). None and the staircase share
        (``SHARES["staircase"]``) run in a parallel numba kernel, any other rule in NumPy.

    Returns
    -------
    per axis: flat face index, length in sphere a, length in sphere b (m), summed interface
    shares of the crossings of a and of b, particle ids (1-based) of a and b. A face in
    two zones keeps the first zone's.
    """
    h = ms.voxel_m
    zt = zone_table(ms, SEGMENT_ZONE_VOXELS * h, 2.0)
    rule = _share_rule(share)
    if rule is None:
        return _zone_segments_numpy(ms, zt, share)
    if len(zt) == 0:
        return tuple(_empty_segments() for _ in range(3))
    sq = np.stack([_squares(zt.rho_max), _squares(zt.radius_a), _squares(zt.radius_b)],
                  axis=1)
    zones = dict(ca=zt.centre_a, cb=zt.centre_b, ra=zt.radius_a, rb=zt.radius_b, sq=sq,
                 u=zt.direction, dist=zt.distance, lo=zt.lo, hi=zt.hi)
    counts, flat, vals = K.zone_segment_faces(ms.shape, zones, h, rule,
                                              K.current_threads(math.prod(ms.shape)))
    n_faces = math.prod(ms.shape)
    out, at = [], 0
    for d in range(3):
        m = int(counts[:, d].sum())
        if m == 0:
            out.append(_empty_segments())
            continue
        out.append(K.first_segments(flat[at:at + m], vals[at:at + m],
                                    np.ascontiguousarray(counts[:, d]), zt.a, zt.b, n_faces))
        at += m
    return tuple(out)


def _zone_segments_numpy(ms: Microstructure, zt: ZoneTable,
                         share: Callable[[np.ndarray, int], np.ndarray]
                         ) -> tuple[tuple[np.ndarray, ...], ...]:
    """:func:`zone_segments` for any share rule, zone by zone in NumPy."""
    shape, h = ms.shape, ms.voxel_m
    flats: list[list[np.ndarray]] = [[] for _ in range(3)]
    vals: list[list[np.ndarray]] = [[] for _ in range(3)]
    counts = np.zeros((len(zt), 3), dtype=np.int64)
    for z in range(len(zt)):
        ii = [np.arange(zt.lo[z, k], zt.hi[z, k] + 1) for k in range(3)]
        cells = np.stack(np.meshgrid(*ii, indexing="ij"), axis=-1).reshape(-1, 3)
        x = (cells + 0.5) * h
        ca, u = zt.centre_a[z], zt.direction[z]
        ra, rb = zt.radius_a[z], zt.radius_b[z]
        for d in range(3):
            xf = x.copy()
            xf[:, d] += 0.5 * h
            w = xf - ca
            t = w @ u
            rho2 = np.maximum((w * w).sum(axis=1) - t * t, 0.0)
            surf_a = np.sqrt(np.maximum(ra ** 2 - rho2, 0.0))
            surf_b = zt.distance[z] - np.sqrt(np.maximum(rb ** 2 - rho2, 0.0))
            sel = (rho2 <= zt.rho_max[z] ** 2) & (t > surf_a - h) & (t < surf_b + h)
            if not sel.any():
                continue
            la, sa = segment_in_sphere(x[sel], d, h, ca, ra, share)
            lb, sb = segment_in_sphere(x[sel], d, h, zt.centre_b[z], rb, share)
            flats[d].append(np.ravel_multi_index(
                tuple(np.mod(cells[sel, k], shape[k]) for k in range(3)), shape))
            vals[d].append(np.stack([la, lb, sa, sb], axis=1))
            counts[z, d] = la.size
    out = []
    for d in range(3):
        if not flats[d]:
            out.append(_empty_segments())
            continue
        out.append(K.first_segments(np.concatenate(flats[d]), np.concatenate(vals[d]),
                                    np.ascontiguousarray(counts[:, d]), zt.a, zt.b,
                                    math.prod(shape)))
    return tuple(out)
