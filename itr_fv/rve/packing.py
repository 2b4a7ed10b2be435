"""Dense packing of polydisperse, non-overlapping spheres in a periodic cube (numba kernels).

The algorithm is a collective-rearrangement scheme with Lubachevsky-Stillinger-like growth
(close to the "force-biased" algorithm of Mościński, Bargieł et al., 1989):

1. Centres start uniformly random; all radii are multiplied by a common scale ``s`` chosen
   so that the scaled packing fraction is low (``phi_start``).
2. Every iteration, each overlapping pair (minimum-image distance ``d < s (R_i + R_j)``)
   is pushed apart along its line of centres by a fraction of the overlap; the push is
   shared in inverse proportion to the particle volumes (big particles move less), and
   the pushes of all pairs are summed before they are applied (Jacobi sweep). This is a
   preconditioned gradient descent on the harmonic overlap energy ``sum overlap^2``.
3. While the largest relative overlap is small the scale grows geometrically (the growth
   rate adapts: faster while overlaps stay small, slower when they build up), up to
   ``s_end = 1 + inflate``.
4. At ``s_end`` the sweep continues until the largest relative overlap of the inflated
   spheres is below ``inflate / 2``: the real spheres (scale 1) are then separated by at
   least ``inflate/2 * (R_i + R_j)`` -- strictly non-overlapping.

Pairs come from a Verlet neighbour list (cutoff ``s (R_i + R_j) + skin``) built on a cell
list; each particle searches the cells within its own reach ``s (R_i + R_max) + skin``,
so large particles in a polydisperse packing do not force a coarse grid on everyone.
The list is rebuilt when the accumulated displacements plus the growth could bring an
unlisted pair into contact.

Lengths here are in any consistent unit (the RVE generator uses micrometres). All numba
functions are compiled with ``cache=True``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..numba_cache import njit

__all__ = ["PackingResult", "pack_spheres", "pairs_within_gap", "check_overlaps"]


# --------------------------------------------------------------------------- kernels
@njit(inline="always")
def _min_image(dx, L, half):
    """Minimum-image component of a difference dx in a periodic box of edge L."""
    if dx > half:
        return dx - L
    if dx < -half:
        return dx + L
    return dx


@njit()
def _wrap(pos, L):
    n = pos.shape[0]
    for i in range(n):
        for d in range(3):
            x = pos[i, d]
            if x < 0.0 or x >= L:
                x = x - L * math.floor(x / L)
                if x >= L:  # rounding of tiny negative numbers
                    x = 0.0
                pos[i, d] = x


@njit()
def _cell_list(pos, L, nc):
    n = pos.shape[0]
    head = -np.ones(nc * nc * nc, dtype=np.int64)
    nxt = -np.ones(n, dtype=np.int64)
    for i in range(n):
        cx = int(pos[i, 0] / L * nc) % nc
        cy = int(pos[i, 1] / L * nc) % nc
        cz = int(pos[i, 2] / L * nc) % nc
        c = (cx * nc + cy) * nc + cz
        nxt[i] = head[c]
        head[c] = i
    return head, nxt


@njit()
def _pairs(pos, R, L, extra, cap_i, cap_j):
    """Pairs i < j with minimum-image distance < R_i + R_j + extra.

    Writes into cap_i / cap_j while room lasts; returns the total count (the caller
    reallocates and calls again when the count exceeds the capacity).
    """
    n = pos.shape[0]
    if n < 2:
        return 0
    rmax = 0.0
    for i in range(n):
        if R[i] > rmax:
            rmax = R[i]
    # cell edge: about the typical contact distance, at least L/64
    rmean = 0.0
    for i in range(n):
        rmean += R[i]
    rmean /= n
    cell = max(2.0 * rmean + extra, L / 64.0)
    nc = max(1, int(L / cell))
    cell = L / nc
    head, nxt = _cell_list(pos, L, nc)
    half = 0.5 * L
    cnt = 0
    cap = cap_i.shape[0]
    for i in range(n):
        reach = R[i] + rmax + extra
        k = int(math.ceil(reach / cell))
        cx = int(pos[i, 0] / L * nc) % nc
        cy = int(pos[i, 1] / L * nc) % nc
        cz = int(pos[i, 2] / L * nc) % nc
        full = 2 * k + 1 >= nc
        if full:
            lo = 0
            hi = nc
        else:
            lo = -k
            hi = k + 1
        for a in range(lo, hi):
            ax = a % nc if full else (cx + a) % nc
            for b in range(lo, hi):
                by = b % nc if full else (cy + b) % nc
                for c in range(lo, hi):
                    cz2 = c % nc if full else (cz + c) % nc
                    j = head[(ax * nc + by) * nc + cz2]
                    while j >= 0:
                        if j > i:
                            dx = _min_image(pos[j, 0] - pos[i, 0], L, half)
                            dy = _min_image(pos[j, 1] - pos[i, 1], L, half)
                            dz = _min_image(pos[j, 2] - pos[i, 2], L, half)
                            cut = R[i] + R[j] + extra
                            if dx * dx + dy * dy + dz * dz < cut * cut:
                                if cnt < cap:
                                    cap_i[cnt] = i
                                    cap_j[cnt] = j
                                cnt += 1
                        j = nxt[j]
    return cnt


@njit()
def _build_list(pos, R, L, extra, pi, pj):
    cnt = _pairs(pos, R, L, extra, pi, pj)
    if cnt > pi.shape[0]:
        cap = int(cnt * 1.3) + 16
        pi = np.empty(cap, dtype=np.int64)
        pj = np.empty(cap, dtype=np.int64)
        cnt = _pairs(pos, R, L, extra, pi, pj)
    return pi, pj, cnt


@njit()
def _pack_kernel(pos, R, L, s_start, s_end, growth0, alpha, tol_final, grow_tol,
                 max_iter, skin):
    """Growth + collective rearrangement. ``pos`` is moved in place.

    Returns (iterations, final scale, max relative overlap at the final scale,
    number of neighbour-list builds).
    """
    n = pos.shape[0]
    _wrap(pos, L)
    rmax = 0.0
    for i in range(n):
        if R[i] > rmax:
            rmax = R[i]
    vol = np.empty(n)
    for i in range(n):
        vol[i] = R[i] ** 3
    s = s_start
    growth = growth0
    disp = np.zeros((n, 3))
    acc = np.zeros(n)  # displacement accumulated since the last list build
    cap = 16 * n + 64
    pi = np.empty(cap, dtype=np.int64)
    pj = np.empty(cap, dtype=np.int64)
    Rs = np.empty(n)
    for i in range(n):
        Rs[i] = R[i] * s
    pi, pj, npair = _build_list(pos, Rs, L, skin, pi, pj)
    s_build = s
    builds = 1
    half = 0.5 * L
    maxrel = 0.0
    it = 0
    while it < max_iter:
        it += 1
        # ------------------------------------------------ one Jacobi sweep at scale s
        for i in range(n):
            disp[i, 0] = 0.0
            disp[i, 1] = 0.0
            disp[i, 2] = 0.0
        maxrel = 0.0
        for p in range(npair):
            i = pi[p]
            j = pj[p]
            dx = _min_image(pos[j, 0] - pos[i, 0], L, half)
            dy = _min_image(pos[j, 1] - pos[i, 1], L, half)
            dz = _min_image(pos[j, 2] - pos[i, 2], L, half)
            sig = s * (R[i] + R[j])
            d2 = dx * dx + dy * dy + dz * dz
            if d2 >= sig * sig:
                continue
            d = math.sqrt(d2)
            ov = sig - d
            rel = ov / sig
            if rel > maxrel:
                maxrel = rel
            if d > 1e-12 * sig:
                ux = dx / d
                uy = dy / d
                uz = dz / d
            else:  # coincident centres: any direction, deterministic
                ux = 1.0
                uy = 0.0
                uz = 0.0
            wsum = vol[i] + vol[j]
            wi = vol[j] / wsum  # i moves by the share of the other's volume
            wj = vol[i] / wsum
            m = alpha * ov
            disp[i, 0] -= m * wi * ux
            disp[i, 1] -= m * wi * uy
            disp[i, 2] -= m * wi * uz
            disp[j, 0] += m * wj * ux
            disp[j, 1] += m * wj * uy
            disp[j, 2] += m * wj * uz
        at_end = s >= s_end
        if at_end and maxrel < tol_final:
            break
        # ------------------------------------------------ move
        dmax = 0.0
        for i in range(n):
            ddx = disp[i, 0]
            ddy = disp[i, 1]
            ddz = disp[i, 2]
            if ddx != 0.0 or ddy != 0.0 or ddz != 0.0:
                pos[i, 0] += ddx
                pos[i, 1] += ddy
                pos[i, 2] += ddz
                acc[i] += math.sqrt(ddx * ddx + ddy * ddy + ddz * ddz)
                if acc[i] > dmax:
                    dmax = acc[i]
            elif acc[i] > dmax:
                dmax = acc[i]
        _wrap(pos, L)
        # ------------------------------------------------ grow
        if not at_end:
            if maxrel < grow_tol:
                s = min(s_end, s * (1.0 + growth))
                if maxrel < 0.25 * grow_tol:
                    growth = min(growth * 1.2, 0.02)
            else:
                growth = max(growth * 0.7, 1e-5)
        # ------------------------------------------------ list still valid?
        if 2.0 * dmax + 2.0 * rmax * (s - s_build) > skin:
            for i in range(n):
                Rs[i] = R[i] * s
                acc[i] = 0.0
            pi, pj, npair = _build_list(pos, Rs, L, skin, pi, pj)
            s_build = s
            builds += 1
    return it, s, maxrel, builds


@njit()
def _gap_pairs(pos, r, L, gap):
    """Pairs i < j whose surface gap (min image) is below ``gap``: (i, j, gap_ij)."""
    n = pos.shape[0]
    cap = 8 * n + 16
    pi = np.empty(cap, dtype=np.int64)
    pj = np.empty(cap, dtype=np.int64)
    pi, pj, cnt = _build_list(pos, r, L, gap, pi, pj)
    g = np.empty(cnt)
    half = 0.5 * L
    for p in range(cnt):
        i = pi[p]
        j = pj[p]
        dx = _min_image(pos[j, 0] - pos[i, 0], L, half)
        dy = _min_image(pos[j, 1] - pos[i, 1], L, half)
        dz = _min_image(pos[j, 2] - pos[i, 2], L, half)
        g[p] = math.sqrt(dx * dx + dy * dy + dz * dz) - r[i] - r[j]
    return pi[:cnt].copy(), pj[:cnt].copy(), g


# --------------------------------------------------------------------------- public
@dataclass(frozen=True)
class PackingResult:
    """Outcome of :func:`pack_spheres`.

    Attributes
    ----------
    centers : ndarray, shape (P, 3)
        Sphere centres in ``[0, L)`` (same length unit as the input).
    iterations : int
        Jacobi sweeps done.
    neighbour_builds : int
        Verlet-list rebuilds.
    max_rel_overlap : float
        Largest overlap of the *inflated* spheres relative to the contact distance at the
        end (below ``inflate / 2`` on success).
    converged : bool
        True when the final tolerance was met within ``max_iter``.
    seconds : float
        Wall time of the packing, s.
    """

    centers: np.ndarray
    iterations: int
    neighbour_builds: int
    max_rel_overlap: float
    converged: bool
    seconds: float


def pack_spheres(radii: np.ndarray, box: float, rng: np.random.Generator,
                 min_gap: float = 0.0, inflate: float = 1e-3, phi_start: float = 0.25,
                 alpha: float = 0.6, grow_tol: float = 0.02, max_iter: int = 200_000,
                 centers: np.ndarray | None = None) -> PackingResult:
    """Pack spheres of given radii without overlap in a periodic cube.

    Parameters
    ----------
    radii : ndarray, shape (P,)
        Sphere radii (any length unit, the same as ``box``), > 0.
    box : float
        Edge of the periodic cube.
    rng : numpy.random.Generator
        Source of the random initial centres (ignored when ``centers`` is given).
    min_gap : float
        Smallest surface-to-surface distance wanted between any two spheres (same unit).
    inflate : float
        Relative inflation of the contact distance used while packing (> 0): the real
        spheres end up separated by at least ``inflate/2 * (r_i + r_j) + min_gap``.
    phi_start : float
        Packing fraction of the shrunken spheres at the start.
    alpha : float
        Fraction of a pair's overlap removed per sweep (0 < alpha <= 1).
    grow_tol : float
        The radii grow only while the largest relative overlap is below this.
    max_iter : int
        Sweep limit; :attr:`PackingResult.converged` is False when it is hit.
    centers : ndarray, shape (P, 3), optional
        Initial centres (default: uniform random in the box).

    Returns
    -------
    PackingResult
    """
    t0 = time.perf_counter()
    r = np.ascontiguousarray(radii, dtype=np.float64)
    L = float(box)
    if r.ndim != 1 or r.size == 0:
        raise ValueError("radii: expected a non-empty 1-D array")
    if not np.all(np.isfinite(r)) or np.any(r <= 0):
        raise ValueError("radii: every radius must be finite and > 0")
    if not (math.isfinite(L) and L > 0):
        raise ValueError(f"box: must be finite and > 0, got {box!r}")
    if not (inflate > 0):
        raise ValueError(f"inflate: must be > 0, got {inflate!r}")
    if min_gap < 0:
        raise ValueError(f"min_gap: must be >= 0, got {min_gap!r}")
    R = r + 0.5 * float(min_gap)
    if 2.0 * R.max() * (1.0 + inflate) >= 0.5 * L:
        raise ValueError("radii: the largest diameter (plus gap) must stay below half the box "
                         "for the minimum-image pair search")
    phi_full = 4.0 / 3.0 * math.pi * float(np.sum(R ** 3)) / L ** 3
    s_end = 1.0 + float(inflate)
    s_start = min(s_end, (phi_start / phi_full) ** (1.0 / 3.0)) if phi_full > 0 else s_end
    if centers is None:
        pos = rng.uniform(0.0, L, size=(r.size, 3))
    else:
        pos = np.array(centers, dtype=np.float64, copy=True)
        if pos.shape != (r.size, 3):
            raise ValueError(f"centers: expected shape ({r.size}, 3), got {pos.shape}")
    pos = np.ascontiguousarray(pos)
    skin = 0.3 * float(np.mean(R))
    it, s, maxrel, builds = _pack_kernel(pos, R, L, s_start, s_end, 1e-3, float(alpha),
                                         0.5 * float(inflate), float(grow_tol),
                                         int(max_iter), skin)
    converged = bool(s >= s_end and maxrel < 0.5 * inflate)
    return PackingResult(pos, int(it), int(builds), float(maxrel), converged,
                         time.perf_counter() - t0)


def pairs_within_gap(centers: np.ndarray, radii: np.ndarray, box: float,
                     gap: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All sphere pairs whose surface gap (periodic minimum image) is below ``gap``.

    Complete (every pair is considered through a cell list), exact in float64.

    Parameters
    ----------
    centers : ndarray, shape (P, 3)
    radii : ndarray, shape (P,)
    box : float
        Edge of the periodic cube (same unit); the largest diameter must be below box/2.
    gap : float
        Gap threshold (>= 0 finds overlaps and contacts closer than ``gap``).

    Returns
    -------
    i, j : ndarray of int64
        Pair indices, ``i < j``.
    g : ndarray of float
        Surface gaps ``|c_i - c_j| - r_i - r_j`` (negative = overlap).
    """
    c = np.ascontiguousarray(np.mod(np.asarray(centers, dtype=np.float64), box))
    r = np.ascontiguousarray(radii, dtype=np.float64)
    if r.size and 2 * (2 * r.max() + gap) >= box:
        # minimum image still exact while r_i + r_j + gap < box/2
        raise ValueError("radii: too large for the minimum-image pair search in this box")
    return _gap_pairs(c, r, float(box), float(max(gap, 0.0)))


def check_overlaps(centers: np.ndarray, radii: np.ndarray, box: float,
                   min_gap: float = 0.0) -> tuple[int, float]:
    """Exact overlap check with periodic images.

    Returns
    -------
    n_bad : int
        Number of pairs closer than ``min_gap`` (surface to surface; with ``min_gap = 0``:
        overlapping pairs).
    smallest_gap : float
        Smallest surface gap among near pairs (``inf`` when no pair is within the search
        distance ``max(min_gap, 0) + 1e-9 box``).
    """
    i, j, g = pairs_within_gap(centers, radii, box, max(min_gap, 0.0) + 1e-9 * box)
    n_bad = int(np.count_nonzero(g < min_gap))
    return n_bad, (float(g.min()) if g.size else math.inf)
