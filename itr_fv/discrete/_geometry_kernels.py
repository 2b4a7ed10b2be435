"""Numba kernels of the face geometry build (:mod:`itr_fv.discrete.face_geometry`,
:mod:`itr_fv.discrete.contact_zones`), and the threads that run them.

Every kernel does the arithmetic of the NumPy expressions it replaces in the same order, so
its results are the same bits, with one exception: a dot product with a direction (``w @ u``
in NumPy goes to BLAS, whose kernel may fuse multiply-adds depending on the CPU) is a
plain sum of three products here. Such dot products only decide which cells a contact zone
takes, at a threshold they would have to meet to the last bit.

Layout: ``pid[i, j, k]`` (C order); a face of axis d is named by the flat index
``(i n2 + j) n3 + k`` of its lower voxel p, the other voxel is q = p + e_d (periodic).

Threads: the kernels are serial and release the GIL (``nogil``); :func:`parallel_map` runs
one on disjoint ranges of rows, faces or zones in a pool of ``workers`` threads, each range
writing its own part of the output, so results do not depend on the thread count. Lists
whose length is only known after the scan are built in two calls of the same kernel: one
counts per range, one writes at the counted offsets. (numba's ``parallel=True`` would do the
same, but compiles each ``prange`` loop into its own function: 14 s of compilation for these
kernels on two cores, against 5 s serial.) Compiled once per argument type and cached on
disk (:mod:`itr_fv.numba_cache`).

Bounded calls: no kernel call does more than about 0.1 s of work (:data:`SCAN_VOXELS`,
:data:`FACE_WORK`, :data:`ZONE_CELLS`, :data:`SEGMENT_ROWS`): the ranges are cut that fine
on any thread count, and the sequential kernels (:func:`zone_fill`,
:func:`first_segments`) run zone range after zone range, resuming where the last call
stopped. Between calls the main thread is back in Python, or waiting on the pool where
signals reach it too, so Ctrl-C or a SIGTERM handler that raises stops a build within a
call (a thread pool lets its running calls end first). The results do not depend on the
cuts.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any

import numba as nb
import numpy as np

from ..numba_cache import njit
from ..rve.contact_film import clearance

__all__ = ["SERIAL_BELOW", "threads_for", "using_threads", "current_threads", "chunk_ranges",
           "cost_ranges", "zone_cells", "parallel_map", "interface_faces", "sphere_faces",
           "zone_fill", "zone_segment_faces", "first_segments", "parallel_copy"]

_SER = dict(fastmath=False, nogil=True)

#: :func:`itr_fv.rve.contact_film.clearance`, compiled: the stated film of touching pairs.
_clearance = njit(**_SER)(clearance)

#: Grids with fewer voxels than this are built single-threaded by default.
SERIAL_BELOW = 40 ** 3

_THREADS: ContextVar[int | None] = ContextVar("itr_fv_geometry_threads", default=None)

#: Ranges per thread in :func:`chunk_ranges` (zones differ in size: several per thread even
#: out the load).
CHUNKS_PER_THREAD = 4

# The most work of one kernel call (measured on two loaded cores, 320^3 and 640^3 grids of
# 60 % Al2O3: 70 ms at most).
#: Voxels of the rows one call of the face scan reads (about 15 ns a voxel).
SCAN_VOXELS = 1 << 22
#: Faces one call of :func:`sphere_faces` visits (about 70 ns a face).
FACE_WORK = 1 << 19
#: Cells of the zone boxes one call of :func:`zone_fill` or :func:`zone_segment_faces`
#: visits (the latter: three times, once per axis).
ZONE_CELLS = 1 << 20
#: Rows of zone faces one call of :func:`first_segments` reads.
SEGMENT_ROWS = 1 << 20


def threads_for(n_voxels: int, workers: int | None = None) -> int:
    """Threads for a build on ``n_voxels`` voxels: ``workers`` if given, else 1 below
    :data:`SERIAL_BELOW` voxels and numba's thread count (``NUMBA_NUM_THREADS``) above;
    never more than the machine's cores."""
    if workers is None:
        workers = 1 if n_voxels < SERIAL_BELOW else nb.config.NUMBA_NUM_THREADS
    elif isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) \
            or workers < 1:
        raise ValueError(f"workers: expected a positive integer, got {workers!r}")
    return int(max(1, min(workers, os.cpu_count() or 1)))


@contextmanager
def using_threads(n: int) -> Iterator[int]:
    """Inside the block, the builds of this context run on ``n`` threads
    (:func:`current_threads`); :func:`itr_fv.discrete.face_geometry.face_geometry` sets it
    for the zone walks its interface law asks for."""
    token = _THREADS.set(int(n))
    try:
        yield int(n)
    finally:
        _THREADS.reset(token)


def current_threads(n_voxels: int) -> int:
    """Threads of a build on ``n_voxels`` voxels: those of :func:`using_threads` inside
    one, else :func:`threads_for`'s default."""
    n = _THREADS.get()
    return threads_for(n_voxels) if n is None else n


def chunk_ranges(n: int, threads: int, most: int | None = None) -> list[tuple[int, int]]:
    """Consecutive ranges ``(lo, hi)`` covering ``range(n)``: one on one thread, else
    :data:`CHUNKS_PER_THREAD` per thread (at most n); more, of equal length, where a range
    would hold more than ``most`` items."""
    parts = 1 if threads <= 1 else max(1, min(n, threads * CHUNKS_PER_THREAD))
    if most is not None and n > 0:
        parts = max(parts, -(-n // max(1, int(most))))
    ends = [n * k // parts for k in range(parts + 1)]
    return [(ends[k], ends[k + 1]) for k in range(parts)]


def cost_ranges(cost: np.ndarray, threads: int, budget: float) -> list[tuple[int, int]]:
    """The ranges of :func:`chunk_ranges` over ``range(cost.size)``, each cut further into
    consecutive ranges whose summed ``cost`` stays within ``budget`` (a range holds at
    least one item)."""
    cum = np.concatenate([[0.0], np.cumsum(np.asarray(cost, dtype=np.float64))])
    out = []
    for lo, hi in chunk_ranges(cost.size, threads):
        if lo == hi:
            out.append((lo, hi))
        while lo < hi:
            end = int(np.searchsorted(cum, cum[lo] + budget, side="right")) - 1
            end = min(hi, max(lo + 1, end))
            out.append((lo, end))
            lo = end
    return out


def zone_cells(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Cells in the box ``lo..hi`` (inclusive, int64 (Z, 3)) of every zone."""
    return np.prod(np.maximum(hi - lo + 1, 0), axis=1)


def parallel_map(task: Callable[[Any], Any], items: Sequence[Any], threads: int) -> list:
    """``[task(x) for x in items]`` on ``threads`` threads (the tasks call nogil kernels)."""
    if threads <= 1 or len(items) < 2:
        return [task(x) for x in items]
    with ThreadPoolExecutor(max_workers=threads) as pool:
        return list(pool.map(task, items))


def parallel_copy(a: np.ndarray, threads: int) -> np.ndarray:
    """A C-contiguous copy of ``a``, copied by ranges of its first axis (of at most
    :data:`SCAN_VOXELS` elements) on ``threads`` threads (a large fresh array is mostly page
    faults: they run in parallel too)."""
    if a.ndim == 0:
        return np.array(a, order="C", copy=True)
    out = np.empty(a.shape, dtype=a.dtype)
    rows = SCAN_VOXELS // max(1, math.prod(a.shape[1:]))
    parallel_map(lambda r: np.copyto(out[r[0]:r[1]], a[r[0]:r[1]]),
                 chunk_ranges(a.shape[0], threads, rows), threads)
    return out


def offsets(counts: np.ndarray) -> tuple[np.ndarray, int]:
    """Exclusive prefix sum of ``counts`` (int64) and the total."""
    start = np.zeros(counts.size, dtype=np.int64)
    np.cumsum(counts[:-1], out=start[1:])
    return start, int(counts.sum())


# ------------------------------------------------------------------ interface faces
@njit(**_SER)
def _scan_rows(pid, mid, d, i0, i1, at, idx, plo, phi, mlo, mhi,
               write):  # pragma: no cover - compiled
    """Faces of rows i0..i1-1 (first axis) where the particle id changes along axis d, in
    flat order; written from position ``at`` when ``write``; returns their number."""
    n1, n2, n3 = pid.shape
    m = 0
    for i in range(i0, i1):
        for j in range(n2):
            for k in range(n3):
                qi, qj, qk = i, j, k
                if d == 0:
                    qi = i + 1 if i + 1 < n1 else 0
                elif d == 1:
                    qj = j + 1 if j + 1 < n2 else 0
                else:
                    qk = k + 1 if k + 1 < n3 else 0
                a = pid[i, j, k]
                b = pid[qi, qj, qk]
                if a != b:
                    if write:
                        w = at + m
                        idx[w] = (i * n2 + j) * n3 + k
                        plo[w] = a
                        phi[w] = b
                        mlo[w] = mid[i, j, k]
                        mhi[w] = mid[qi, qj, qk]
                    m += 1
    return m


def interface_faces(pid: np.ndarray, mid: np.ndarray, d: int, threads: int = 1
                    ) -> tuple[np.ndarray, ...]:
    """Faces of axis d between voxels of different particle ids, in flat order.

    Parameters
    ----------
    pid, mid : ndarray, shape (n1, n2, n3), C-contiguous
        Particle and material ids.
    d : int
        Axis.
    threads : int
        Threads (ranges of rows of the first axis).

    Returns
    -------
    idx : int64 array, flat index of p; p_lo, p_hi : particle ids of p and q;
    m_lo, m_hi : material ids of p and q.
    """
    e_i = np.zeros(0, dtype=np.int64)
    e_p, e_m = np.zeros(0, dtype=pid.dtype), np.zeros(0, dtype=mid.dtype)
    ranges = chunk_ranges(pid.shape[0], threads,
                          SCAN_VOXELS // max(1, pid.shape[1] * pid.shape[2]))
    counts = np.array(parallel_map(
        lambda r: _scan_rows(pid, mid, d, r[0], r[1], 0, e_i, e_p, e_p, e_m, e_m, False),
        ranges, threads), dtype=np.int64)
    start, m = offsets(counts)
    idx = np.empty(m, dtype=np.int64)
    plo, phi = np.empty(m, dtype=pid.dtype), np.empty(m, dtype=pid.dtype)
    mlo, mhi = np.empty(m, dtype=mid.dtype), np.empty(m, dtype=mid.dtype)
    parallel_map(lambda r: _scan_rows(pid, mid, d, r[0][0], r[0][1], r[1], idx, plo, phi, mlo,
                                      mhi, True), list(zip(ranges, start)), threads)
    return idx, plo, phi, mlo, mhi


# ------------------------------------------------------------------ analytic spheres
@njit(**_SER)
def _min_image(dx, box):  # pragma: no cover - compiled
    """``dx - box * round(dx / box)`` (round half to even, as NumPy)."""
    return dx - box * np.rint(dx / box)


@njit(**_SER)
def _staircase(n0, n1, n2):  # pragma: no cover - compiled
    """|n_0| + |n_1| + |n_2| over |n|; 1 where n = 0."""
    norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if norm > 0:
        return (abs(n0) + abs(n1) + abs(n2)) / norm
    return 1.0


@njit(**_SER)
def _face_centre(p, d, n2, n3, h, x):  # pragma: no cover - compiled
    """x = (ijk + 1/2) h + h/2 e_d of the face of axis d of voxel p (flat index)."""
    x[0] = (p // (n2 * n3) + 0.5) * h
    x[1] = ((p // n3) % n2 + 0.5) * h
    x[2] = (p % n3 + 0.5) * h
    x[d] += 0.5 * h


@njit(**_SER)
def _sphere_faces(f0, f1, c0, c1, idx, p_lo, p_hi, cont, d, n2, n3, h, centers, radii, box,
                  rule, s, film, gap, shift):  # pragma: no cover - compiled
    """Staircase factors of faces f0..f1-1 and films of contact faces ``cont[c0:c1]`` of
    :func:`sphere_faces`, written into its output arrays."""
    x = np.empty(3)
    ca = np.empty(3)
    cb = np.empty(3)
    D = np.empty(3)
    for f in range(f0, f1):
        _face_centre(idx[f], d, n2, n3, h, x)
        lo = np.int64(p_lo[f])
        hi = np.int64(p_hi[f])
        if lo > 0 and hi > 0:  # contact: along the line of centres; s = 1 for an own image
            if lo != hi:
                a, b = lo - 1, hi - 1
                s[f] = _staircase(_min_image(centers[b, 0] - centers[a, 0], box[0]),
                                  _min_image(centers[b, 1] - centers[a, 1], box[1]),
                                  _min_image(centers[b, 2] - centers[a, 2], box[2]))
        else:
            c = max(lo, hi) - 1
            s[f] = _staircase(_min_image(x[0] - centers[c, 0], box[0]),
                              _min_image(x[1] - centers[c, 1], box[1]),
                              _min_image(x[2] - centers[c, 2], box[2]))
    for r in range(c0, c1):
        f = cont[r]
        _face_centre(idx[f], d, n2, n3, h, x)
        lo = np.int64(p_lo[f])
        hi = np.int64(p_hi[f])
        a = min(lo, hi) - 1
        b = max(lo, hi) - 1
        for k in range(3):
            ca[k] = x[k] + _min_image(centers[a, k] - x[k], box[k])
            cb[k] = x[k] + _min_image(centers[b, k] - x[k], box[k])
        if a == b:  # the other image lies on the other side of the face along e_d
            cb[d] = ca[d] + (1.0 if x[d] >= ca[d] else -1.0) * box[d]
        for k in range(3):
            D[k] = cb[k] - ca[k]
            shift[r, k] = np.int64(np.rint((D[k] - (centers[b, k] - centers[a, k])) / box[k]))
        dist = math.sqrt(D[0] * D[0] + D[1] * D[1] + D[2] * D[2])
        w0, w1, w2 = x[0] - ca[0], x[1] - ca[1], x[2] - ca[2]
        along = w0 * (D[0] / dist) + w1 * (D[1] / dist) + w2 * (D[2] / dist)
        rho2 = max((w0 * w0 + w1 * w1 + w2 * w2) - along * along, 0.0)
        ra = radii[a]
        rb = radii[b]
        dist -= _clearance(dist - ra - rb, ra, rb, rule[0], rule[1], rule[2])
        g0 = dist - ra - rb
        fi = (dist - math.sqrt(max(ra * ra - rho2, 0.0))
              - math.sqrt(max(rb * rb - rho2, 0.0)))
        film[f] = max(fi, max(g0, 0.0))
        gap[r] = g0
        if a == b and shift[r, d] < 0:
            for k in range(3):
                shift[r, k] = -shift[r, k]


def sphere_faces(idx: np.ndarray, p_lo: np.ndarray, p_hi: np.ndarray, d: int,
                 shape: tuple[int, int, int], h: float, centers: np.ndarray,
                 radii: np.ndarray, staircase: bool, threads: int = 1,
                 rule: tuple[float, float, float] = (0.0, 0.0, 0.0)
                 ) -> tuple[np.ndarray, ...]:
    """Contact faces, staircase factors, films, closest gaps and image shifts.

    The face centre is ``x_f = (ijk + 1/2) h + h/2 e_d``. A particle-matrix face takes its
    normal from the particle centre to x_f, a contact face between two particles along their
    line of centres (s = 1 where a sphere meets its own image), all as minimum images in the
    box (s = 1 everywhere when not ``staircase``). At a contact face (both ids > 0): the
    film and gap of :func:`itr_fv.discrete.contact_zones.contact_films` between particles
    min and max of the two ids, and the image shift of the contact (made positive along
    e_d for a sphere and its own image).

    Parameters
    ----------
    idx, p_lo, p_hi : ndarray, shape (m,)
        Faces (flat index of p) and the particle ids of p and q.
    d : int
        Axis.
    shape : tuple of int
        Grid shape.
    h : float
        Voxel edge, m.
    centers, radii : ndarray, shape (P, 3) and (P,)
        Particle table, m.
    staircase : bool
        Compute the staircase factors.
    threads : int
        Threads (ranges of faces and of contact faces).
    rule : tuple of float
        ``ContactFilm.args`` of the table: touching pairs meet at the stated film.

    Returns
    -------
    contact : bool array (m,); s, film (NaN off contacts, m) : float64 arrays (m,);
    at : int64 array (c,), the contact faces; gap (m) : float64 array (c,); shift : int64
    array (c, 3).
    """
    m = idx.size
    contact = (p_lo > 0) & (p_hi > 0)
    at = np.flatnonzero(contact)
    s = np.ones(m)
    film = np.full(m, np.nan)
    gap = np.zeros(at.size)
    shift = np.zeros((at.size, 3), dtype=np.int64)
    box = np.array(shape, dtype=np.float64) * h
    tasks = [(f0, f1, 0, 0) for f0, f1 in chunk_ranges(m, threads, FACE_WORK)] \
        if staircase else []
    tasks += [(0, 0, c0, c1) for c0, c1 in chunk_ranges(at.size, threads, FACE_WORK)]
    parallel_map(lambda t: _sphere_faces(t[0], t[1], t[2], t[3], idx, p_lo, p_hi, at, d,
                                         shape[1], shape[2], h, centers, radii, box,
                                         np.asarray(rule, dtype=np.float64), s, film,
                                         gap, shift), tasks, threads)
    return contact, s, film, at, gap, shift


# ------------------------------------------------------------------ contact zones
def zone_fill(pid: np.ndarray, mid: np.ndarray, mat_of: np.ndarray, za: np.ndarray,
              zb: np.ndarray, ca: np.ndarray, cb: np.ndarray, ra: np.ndarray, rb: np.ndarray,
              u: np.ndarray, dist: np.ndarray, rho_max: np.ndarray, lo: np.ndarray,
              hi: np.ndarray, h: float) -> int:
    """Give the matrix voxels of every zone's thin wedge to the nearer sphere, zone after
    zone (:func:`itr_fv.discrete.contact_zones.fill_thin_films`), in place; returns the
    number of voxels written.

    A voxel is free for a zone when it was matrix before the zone (a voxel an earlier zone
    took is not free); within one zone every selected cell is written, in cell order. Runs
    in calls of at most :data:`ZONE_CELLS` cells, in zone order.
    """
    filled = 0
    for z0, z1 in cost_ranges(zone_cells(lo, hi), 1, ZONE_CELLS):
        filled += _zone_fill(pid, mid, mat_of, za, zb, ca, cb, ra, rb, u, dist, rho_max, lo,
                             hi, h, z0, z1)
    return int(filled)


@njit(**_SER)
def _zone_fill(pid, mid, mat_of, za, zb, ca, cb, ra, rb, u, dist, rho_max, lo, hi, h, z0,
               z1):  # pragma: no cover - compiled
    """Zones z0..z1-1 of :func:`zone_fill`; returns the number of voxels written."""
    n1, n2, n3 = pid.shape
    filled = 0
    for z in range(z0, z1):
        e0, e1, e2 = hi[z, 0] - lo[z, 0] + 1, hi[z, 1] - lo[z, 1] + 1, hi[z, 2] - lo[z, 2] + 1
        if e0 <= 0 or e1 <= 0 or e2 <= 0:
            continue
        flat = np.empty(e0 * e1 * e2, dtype=np.int64)
        owner = np.empty(e0 * e1 * e2, dtype=np.int64)
        m = 0
        r2 = rho_max[z] * rho_max[z]
        for ci in range(lo[z, 0], hi[z, 0] + 1):
            x0 = (ci + 0.5) * h
            wi = ci % n1
            for cj in range(lo[z, 1], hi[z, 1] + 1):
                x1 = (cj + 0.5) * h
                wj = cj % n2
                for ck in range(lo[z, 2], hi[z, 2] + 1):
                    wk = ck % n3
                    if pid[wi, wj, wk] != 0:
                        continue
                    x2 = (ck + 0.5) * h
                    w0, w1, w2 = x0 - ca[z, 0], x1 - ca[z, 1], x2 - ca[z, 2]
                    t = w0 * u[z, 0] + w1 * u[z, 1] + w2 * u[z, 2]
                    ww = w0 * w0 + w1 * w1 + w2 * w2
                    if not (ww - t * t <= r2 and t > 0.0 and t < dist[z]):
                        continue
                    da = math.sqrt(ww) - ra[z]
                    v0, v1, v2 = x0 - cb[z, 0], x1 - cb[z, 1], x2 - cb[z, 2]
                    db = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2) - rb[z]
                    if da > 0 and db > 0:
                        flat[m] = (wi * n2 + wj) * n3 + wk
                        owner[m] = (za[z] if da <= db else zb[z]) + 1
                        m += 1
        for r in range(m):
            p = flat[r]
            i, j, k = p // (n2 * n3), (p // n3) % n2, p % n3
            pid[i, j, k] = owner[r]
            mid[i, j, k] = mat_of[owner[r]]
        filled += m
    return filled


@njit(**_SER)
def _segment(x0, x1, x2, d, h, c, radius, share):  # pragma: no cover - compiled
    """Length of the segment x -> x + h e_d inside the sphere (c, radius), m, and the
    summed shares of its surface crossings inside the segment (1 each when ``share`` is 0,
    the staircase factor of the normal there when 1), as
    :func:`itr_fv.rve.sphere_geometry.segment_in_sphere`."""
    w0, w1, w2 = x0 - c[0], x1 - c[1], x2 - c[2]
    wd = w0 if d == 0 else (w1 if d == 1 else w2)
    disc = radius * radius - ((w0 * w0 + w1 * w1 + w2 * w2) - wd * wd)
    if not disc > 0:
        return 0.0, 0.0
    root = math.sqrt(disc)
    t1 = (-wd - root) / h
    t2 = (-wd + root) / h
    inside = max(min(t2, 1.0) - max(t1, 0.0), 0.0) * h
    total = 0.0
    for t in (t1, t2):
        if t > 0.0 and t < 1.0:
            if share == 0:
                total += 1.0
            else:
                n0, n1, n2 = w0, w1, w2
                if d == 0:
                    n0 += t * h
                elif d == 1:
                    n1 += t * h
                else:
                    n2 += t * h
                total += _staircase(n0, n1, n2)
    return inside, total


@njit(**_SER)
def _zone_axis(z, d, n, ca, cb, ra, rb, sq, u, dist, lo, hi, h, share, at,
               flat, vals, write):  # pragma: no cover - compiled
    """Faces of axis d of zone z whose centre lies in the thin film (see
    :func:`itr_fv.discrete.contact_zones.zone_segments`); writes them from ``at`` when
    ``write``; returns their number. ``sq[z]`` holds rho_max^2, r_a^2 and r_b^2 (squared
    by the caller as the NumPy code squares them: ``x ** 2`` of a scalar is ``pow``)."""
    m = 0
    r2, raa, rbb = sq[z, 0], sq[z, 1], sq[z, 2]
    for ci in range(lo[z, 0], hi[z, 0] + 1):
        for cj in range(lo[z, 1], hi[z, 1] + 1):
            for ck in range(lo[z, 2], hi[z, 2] + 1):
                x0, x1, x2 = (ci + 0.5) * h, (cj + 0.5) * h, (ck + 0.5) * h
                f0, f1, f2 = x0, x1, x2
                if d == 0:
                    f0 += 0.5 * h
                elif d == 1:
                    f1 += 0.5 * h
                else:
                    f2 += 0.5 * h
                w0, w1, w2 = f0 - ca[z, 0], f1 - ca[z, 1], f2 - ca[z, 2]
                t = w0 * u[z, 0] + w1 * u[z, 1] + w2 * u[z, 2]
                rho2 = max((w0 * w0 + w1 * w1 + w2 * w2) - t * t, 0.0)
                if not rho2 <= r2:
                    continue
                surf_a = math.sqrt(max(raa - rho2, 0.0))
                surf_b = dist[z] - math.sqrt(max(rbb - rho2, 0.0))
                if not (t > surf_a - h and t < surf_b + h):
                    continue
                if write:
                    w = at + m
                    flat[w] = ((ci % n[0]) * n[1] + cj % n[1]) * n[2] + ck % n[2]
                    vals[w, 0], vals[w, 2] = _segment(x0, x1, x2, d, h, ca[z], ra[z], share)
                    vals[w, 1], vals[w, 3] = _segment(x0, x1, x2, d, h, cb[z], rb[z], share)
                m += 1
    return m


@njit(**_SER)
def _zone_faces(z0, z1, n, ca, cb, ra, rb, sq, u, dist, lo, hi, h, share, counts, start, flat,
                vals, write):  # pragma: no cover - compiled
    """Zones z0..z1-1 of :func:`zone_segment_faces`: count their faces per axis into
    ``counts``, or (``write``) write them from ``start``."""
    for z in range(z0, z1):
        for d in range(3):
            m = _zone_axis(z, d, n, ca, cb, ra, rb, sq, u, dist, lo, hi, h, share,
                           start[z, d], flat, vals, write)
            if not write:
                counts[z, d] = m


def zone_segment_faces(shape: tuple[int, int, int], zones: dict, h: float, share: int,
                       threads: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The faces of every contact zone and axis whose centre lies in the zone's thin film,
    with the geometry along their segments (:func:`itr_fv.discrete.contact_zones.zone_segments`).

    Parameters
    ----------
    shape : tuple of int
        Grid shape.
    zones : dict of ndarray
        Per zone (Z rows): ``ca``, ``cb`` (centres of a and of the image of b, m, (Z, 3)),
        ``ra``, ``rb`` (radii, m), ``sq`` (rho_max^2, r_a^2, r_b^2, (Z, 3)), ``u`` (unit
        vector a -> b, (Z, 3)), ``dist`` (m), ``lo``, ``hi`` (box of unwrapped voxel indices,
        int64 (Z, 3)).
    h : float
        Voxel edge, m.
    share : int
        0: each surface crossing counts 1; 1: it counts its staircase factor.
    threads : int
        Threads (ranges of zones).

    Returns
    -------
    counts : int64 array (Z, 3), faces per zone and axis;
    flat : int64 array, flat face indices, ordered by axis, then zone, then cell (i, j, k);
    vals : float64 array (F, 4), length in sphere a, in b (m), shares of a, of b.
    """
    n = np.array(shape, dtype=np.int64)
    args = (n, zones["ca"], zones["cb"], zones["ra"], zones["rb"], zones["sq"], zones["u"],
            zones["dist"], zones["lo"], zones["hi"], float(h), int(share))
    nz = zones["ra"].size
    counts = np.zeros((nz, 3), dtype=np.int64)
    start = np.zeros((nz, 3), dtype=np.int64)
    e_f, e_v = np.zeros(0, dtype=np.int64), np.zeros((0, 4))
    ranges = cost_ranges(3 * zone_cells(zones["lo"], zones["hi"]), threads, ZONE_CELLS)
    parallel_map(lambda r: _zone_faces(r[0], r[1], *args, counts, start, e_f, e_v, False),
                 ranges, threads)
    by_axis, total = offsets(counts.T.reshape(-1))  # axis, then zone
    start[...] = by_axis.reshape(3, nz).T
    flat = np.empty(total, dtype=np.int64)
    vals = np.empty((total, 4))
    parallel_map(lambda r: _zone_faces(r[0], r[1], *args, counts, start, flat, vals, True),
                 ranges, threads)
    return counts, flat, vals


def first_segments(flat: np.ndarray, vals: np.ndarray, counts: np.ndarray, za: np.ndarray,
                   zb: np.ndarray, n_faces: int) -> tuple[np.ndarray, ...]:
    """The rows of ``flat`` (faces of zone after zone: ``counts[z]`` rows of zone z) whose
    face comes first, with their segment values and particle ids.

    Runs in calls of at most :data:`SEGMENT_ROWS` rows, in zone order.

    Parameters
    ----------
    flat : int64 array (F,), faces in [0, n_faces); vals : float64 array (F, 4);
    counts : int64 array (Z,); za, zb : int64 arrays (Z,), 0-based particles of each zone.

    Returns
    -------
    flat, la, lb, sa, sb, pa, pb : the kept rows (pa, pb 1-based particle ids).
    """
    seen = np.zeros((n_faces + 7) // 8, dtype=np.uint8)
    f = np.empty(flat.size, dtype=np.int64)
    out = np.empty((4, flat.size))
    pa = np.empty(flat.size, dtype=np.int64)
    pb = np.empty(flat.size, dtype=np.int64)
    m = r = 0
    for z0, z1 in cost_ranges(counts, 1, SEGMENT_ROWS):
        r, m = _first_segments(flat, vals, counts, za, zb, seen, f, out, pa, pb, z0, z1, r, m)
    return (f[:m].copy(), out[0, :m].copy(), out[1, :m].copy(), out[2, :m].copy(),
            out[3, :m].copy(), pa[:m].copy(), pb[:m].copy())


@njit(**_SER)
def _first_segments(flat, vals, counts, za, zb, seen, f, out, pa, pb, z0, z1, r,
                    m):  # pragma: no cover - compiled
    """Zones z0..z1-1 of :func:`first_segments`, from row ``r`` of ``flat`` with ``m`` rows
    kept so far (``seen``: bit map of the faces kept); returns the next (r, m)."""
    for z in range(z0, z1):
        for _ in range(counts[z]):
            v = flat[r]
            bit = np.uint8(1 << (v & 7))
            if seen[v >> 3] & bit == 0:
                seen[v >> 3] |= bit
                f[m] = v
                for k in range(4):
                    out[k, m] = vals[r, k]
                pa[m] = za[z] + 1
                pb[m] = zb[z] + 1
                m += 1
            r += 1
    return r, m
