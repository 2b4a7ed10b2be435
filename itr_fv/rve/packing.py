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

The work runs in slices: :func:`pack_spheres` calls the resumable sweep kernel
(:func:`_pack_sweeps`, its whole state passed in and out) for at most :data:`SLICE_WORK`
pair visits at a time, and the neighbour search for ranges of particles of about
:data:`SEARCH_WORK` candidate pairs (:func:`_neighbour_list`, also behind
:func:`pairs_within_gap`): tens of milliseconds a call, with returns to Python in between,
so that signal handlers (Ctrl-C, a SIGTERM handler that raises) run and a progress
callback can report. The result does not depend on the slicing, bit for bit.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..numba_cache import njit

__all__ = [
    "SEARCH_WORK",
    "SLICE_WORK",
    "PackingResult",
    "check_overlaps",
    "pack_spheres",
    "pairs_within_gap",
    "progress_fraction",
]

#: Work of one call of the sweep kernel between two returns to Python, in pair visits (a
#: sweep costs its listed pairs plus :data:`PARTICLE_WORK` per particle; at least one sweep
#: per call). Measured on a loaded 2-core machine: 10-20 ms a call with 7 000 particles;
#: with 250 000 one sweep (1.3 million visits, cache-bound) takes 60-110 ms.
SLICE_WORK = 1_000_000

#: Candidate pairs one call of the neighbour search looks at between two returns to Python
#: (at least one particle's). Measured: 8-15 ms a call with 7 000 particles, 30-90 ms with
#: 250 000 (whose random order in memory defeats the caches).
SEARCH_WORK = 500_000

#: Cost of the per-particle part of a sweep (clear, move, wrap), in pair visits.
PARTICLE_WORK = 2

#: Share of the progress fraction given to the growth of the scale (the rest: the final
#: overlap tolerance at full scale; measured: 89-95 % of the time goes to the growth).
GROWTH_SHARE = 0.9

# slots of the sweep kernel's state arrays ``real`` and ``count``
_S, _GROWTH, _S_BUILD, _MAXREL = 0, 1, 2, 3
_IT, _BUILDS, _NPAIR, _DONE, _STALE = 0, 1, 2, 3, 4


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
def _search_grid(pos, R, L, extra):
    """Cell list of a pair search with cutoff R_i + R_j + extra.

    Returns (head, nxt, nc, cell, rmax): the cell list, cells per edge, cell edge and the
    largest radius. The cell edge is about the typical contact distance, at least L/64.
    """
    n = pos.shape[0]
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, R[i])
    rmean = 0.0
    for i in range(n):
        rmean += R[i]
    rmean /= n
    cell = max(2.0 * rmean + extra, L / 64.0)
    nc = max(1, int(L / cell))
    cell = L / nc
    head, nxt = _cell_list(pos, L, nc)
    return head, nxt, nc, cell, rmax


@njit()
def _pairs_of(pos, R, L, extra, head, nxt, nc, cell, rmax, i0, i1, cap_i, cap_j, cnt):
    """Pairs (i, j > i), i in [i0, i1), with minimum-image distance < R_i + R_j + extra.

    Each particle searches the cells within its reach ``R_i + rmax + extra``. The pairs are
    written into cap_i / cap_j from position ``cnt`` on while room lasts; returns ``cnt``
    plus their number (the caller grows the arrays and calls again when that exceeds the
    capacity).
    """
    half = 0.5 * L
    cap = cap_i.shape[0]
    for i in range(i0, i1):
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
def _pack_start(pos, R, L, s_start):
    """Wrap ``pos`` into the box (in place); returns the volume weights R^3 and the radii
    at scale ``s_start``."""
    n = pos.shape[0]
    _wrap(pos, L)
    vol = np.empty(n)
    for i in range(n):
        vol[i] = R[i] ** 3
    Rs = np.empty(n)
    for i in range(n):
        Rs[i] = R[i] * s_start
    return vol, Rs


class _SweepSettings(NamedTuple):
    """The constants of one packing, passed whole to the sweep kernel (lengths in the unit
    of the box; numba takes the named tuple as it is).

    Attributes
    ----------
    box : float
        Edge of the periodic cube.
    s_start, s_end : float
        Scale of the radii at the start and at the end of the growth (``1 + inflate``).
    alpha : float
        Fraction of a pair's overlap removed per sweep.
    tol_final : float
        Largest relative overlap at ``s_end`` that ends the packing (``inflate / 2``).
    grow_tol : float
        The scale grows only while the largest relative overlap is below this.
    max_iter : int
        Sweep limit.
    skin : float
        Verlet-list margin beyond the contact distance.
    rmax : float
        Largest radius (with half the minimum gap).
    """

    box: float
    s_start: float
    s_end: float
    alpha: float
    tol_final: float
    grow_tol: float
    max_iter: int
    skin: float
    rmax: float


@njit()
def _jacobi_sweep(pos, R, vol, disp, pi, pj, npair, s, L, alpha):
    """One Jacobi sweep at scale ``s``: the pushes of all overlapping listed pairs, summed
    into ``disp`` (cleared first); returns the largest relative overlap."""
    n = pos.shape[0]
    half = 0.5 * L
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
        maxrel = max(maxrel, rel)
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
    return maxrel


@njit()
def _move(pos, disp, acc, L):
    """Move every particle by its ``disp`` (wrapped into the box), add the distance to
    ``acc``; returns the largest accumulated distance."""
    n = pos.shape[0]
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
        dmax = max(dmax, acc[i])
    _wrap(pos, L)
    return dmax


@njit()
def _grown(s, growth, maxrel, sweep):
    """``(s, growth)`` after a sweep below full scale: the scale grows while the largest
    relative overlap ``maxrel`` is below ``grow_tol``; the rate adapts (faster while the
    overlaps stay small, slower when they build up)."""
    if maxrel < sweep.grow_tol:
        s = min(sweep.s_end, s * (1.0 + growth))
        if maxrel < 0.25 * sweep.grow_tol:
            growth = min(growth * 1.2, 0.02)
    else:
        growth = max(growth * 0.7, 1e-5)
    return s, growth


@njit()
def _pack_sweeps(pos, R, vol, Rs, disp, acc, pi, pj, real, count, sweep, budget):
    """Growth + collective rearrangement, resumable: Jacobi sweeps from the state in the
    arguments, which are updated in place (``sweep``: the packing's :class:`_SweepSettings`).

    Sweeps until the final tolerance is met (``count[_DONE] = 1``), ``sweep.max_iter``
    sweeps are done in all, this call has done ``budget`` pair visits (a sweep costs its
    listed pairs plus :data:`PARTICLE_WORK` per particle), or the neighbour list must be
    rebuilt: then ``Rs`` holds the radii at the current scale, ``acc`` is cleared and
    ``count[_STALE] = 1``; the caller builds the list (:func:`_neighbour_list`) and resumes.
    """
    n = pos.shape[0]
    s = real[_S]
    growth = real[_GROWTH]
    s_build = real[_S_BUILD]
    maxrel = real[_MAXREL]
    it = count[_IT]
    npair = count[_NPAIR]
    work = 0
    done = 0
    stale = 0
    while it < sweep.max_iter and work < budget:
        it += 1
        work += npair + PARTICLE_WORK * n
        maxrel = _jacobi_sweep(pos, R, vol, disp, pi, pj, npair, s, sweep.box, sweep.alpha)
        at_end = s >= sweep.s_end
        if at_end and maxrel < sweep.tol_final:
            done = 1
            break
        dmax = _move(pos, disp, acc, sweep.box)
        if not at_end:
            s, growth = _grown(s, growth, maxrel, sweep)
        # the list stays valid while no unlisted pair can have come into contact
        if 2.0 * dmax + 2.0 * sweep.rmax * (s - s_build) > sweep.skin:
            for i in range(n):
                Rs[i] = R[i] * s
                acc[i] = 0.0
            stale = 1
            break
    real[_S] = s
    real[_GROWTH] = growth
    real[_MAXREL] = maxrel
    count[_IT] = it
    count[_DONE] = done
    count[_STALE] = stale


@njit()
def _gaps(pos, r, L, pi, pj, cnt):
    """Surface gaps |c_i - c_j| - r_i - r_j (minimum image) of the first ``cnt`` pairs."""
    g = np.empty(cnt)
    half = 0.5 * L
    for p in range(cnt):
        i = pi[p]
        j = pj[p]
        dx = _min_image(pos[j, 0] - pos[i, 0], L, half)
        dy = _min_image(pos[j, 1] - pos[i, 1], L, half)
        dz = _min_image(pos[j, 2] - pos[i, 2], L, half)
        g[p] = math.sqrt(dx * dx + dy * dy + dz * dz) - r[i] - r[j]
    return g


# --------------------------------------------------------------------------- slices
def _search_ranges(R: np.ndarray, extra: float, nc: int, cell: float, rmax: float,
                   budget: int) -> list[tuple[int, int]]:
    """Consecutive particle ranges of a pair search, each looking at about ``budget``
    candidate pairs (at least one particle): particle i scans ``min(2 k_i + 1, nc)^3``
    cells of ``n / nc^3`` particles on average, ``k_i = ceil((R_i + rmax + extra) / cell)``.
    """
    n = R.size
    side = np.minimum(2.0 * np.ceil((R + rmax + extra) / cell) + 1.0, nc)
    cum = np.cumsum(side ** 3 * (n / float(nc) ** 3) + 1.0)
    ends = np.searchsorted(cum, np.arange(1, math.ceil(cum[-1] / budget)) * budget) + 1
    ends = np.unique(np.concatenate([ends[ends < n], [n]]))
    starts = np.concatenate([[0], ends[:-1]])
    return [(int(a), int(b)) for a, b in zip(starts, ends)]


def _neighbour_list(pos: np.ndarray, R: np.ndarray, L: float, extra: float,
                    pi: np.ndarray, pj: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """All pairs i < j with minimum-image distance < R_i + R_j + extra, in the arrays
    ``pi``/``pj`` (grown when too small: the arrays returned may be new).

    The search runs over ranges of particles of about :data:`SEARCH_WORK` candidate pairs
    each, with returns to Python in between; the list is the same whatever the ranges.

    Returns
    -------
    pi, pj : ndarray of int64
        The pairs in their first ``count`` entries.
    count : int
    """
    n = pos.shape[0]
    if n < 2:
        return pi, pj, 0
    head, nxt, nc, cell, rmax = _search_grid(pos, R, L, extra)
    cnt = 0
    for i0, i1 in _search_ranges(R, extra, int(nc), float(cell), float(rmax), SEARCH_WORK):
        new = _pairs_of(pos, R, L, extra, head, nxt, nc, cell, rmax, i0, i1, pi, pj, cnt)
        if new > pi.shape[0]:
            cap = int(new * 1.3) + 16 + int(new / i1 * (n - i1) * 1.3)
            pi = np.concatenate([pi[:cnt], np.empty(cap - cnt, dtype=np.int64)])
            pj = np.concatenate([pj[:cnt], np.empty(cap - cnt, dtype=np.int64)])
            new = _pairs_of(pos, R, L, extra, head, nxt, nc, cell, rmax, i0, i1, pi, pj,
                            cnt)
        cnt = new
    return pi, pj, int(cnt)


@dataclass
class _PackState:
    """What the sweep kernel carries from one slice to the next.

    ``pos`` (centres, moved in place), ``vol`` (weights R^3), ``rs`` (radii of the last
    list build), ``disp`` (displacements of one sweep), ``acc`` (displacements accumulated
    since the last list build), the Verlet list ``pi``/``pj`` (its first ``count[_NPAIR]``
    entries), ``real`` = ``[s, growth, s_build, maxrel]`` and ``count`` = ``[iterations,
    builds, npair, done, stale]``.
    """

    pos: np.ndarray
    vol: np.ndarray
    rs: np.ndarray
    disp: np.ndarray
    acc: np.ndarray
    pi: np.ndarray
    pj: np.ndarray
    real: np.ndarray
    count: np.ndarray

    @property
    def finished(self) -> bool:
        """The final tolerance is met."""
        return bool(self.count[_DONE])


def _rebuild(state: _PackState, R: np.ndarray, sweep: _SweepSettings) -> None:
    """A new neighbour list at the radii ``state.rs`` (the current scale)."""
    state.pi, state.pj, npair = _neighbour_list(state.pos, state.rs, sweep.box, sweep.skin,
                                                state.pi, state.pj)
    state.count[_NPAIR] = npair
    state.count[_BUILDS] += 1
    state.count[_STALE] = 0
    state.real[_S_BUILD] = state.real[_S]


def _start(pos: np.ndarray, R: np.ndarray, sweep: _SweepSettings) -> _PackState:
    """The state before the first sweep, with its neighbour list (``pos`` is wrapped into
    the box in place)."""
    vol, rs = _pack_start(pos, R, sweep.box, sweep.s_start)
    n = pos.shape[0]
    cap = 16 * n + 64
    real = np.array([sweep.s_start, 1e-3, sweep.s_start, 0.0])
    state = _PackState(pos, vol, rs, np.zeros((n, 3)), np.zeros(n),
                       np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64), real,
                       np.zeros(5, dtype=np.int64))
    _rebuild(state, R, sweep)
    return state


def _slice(state: _PackState, R: np.ndarray, sweep: _SweepSettings, budget: int) -> None:
    """At most ``budget`` pair visits of sweeps from ``state`` (updated in place), and the
    neighbour list when the sweeps made it stale."""
    _pack_sweeps(state.pos, R, state.vol, state.rs, state.disp, state.acc, state.pi,
                 state.pj, state.real, state.count, sweep, budget)
    if state.count[_STALE]:
        _rebuild(state, R, sweep)


def progress_fraction(s: float, max_rel_overlap: float, s_start: float, s_end: float,
                      grow_tol: float, tol_final: float) -> float:
    """Fraction of a packing done, in [0, 1], from its scale and largest overlap.

    The growth of the scale ``s`` from ``s_start`` to ``s_end`` counts
    :data:`GROWTH_SHARE` of the way, in the volume of the spheres (``s^3``); the final
    phase at ``s_end`` the rest, in ``log`` of the largest relative overlap from
    ``grow_tol`` (about where it stands when the growth ends) down to ``tol_final``. (Not
    linear in time: a dense packing slows down as it grows, 60 % Al2O3 takes about half
    its time beyond 90 % of the volume.)
    """
    if s < s_end:
        grown = (s ** 3 - s_start ** 3) / (s_end ** 3 - s_start ** 3)
        return GROWTH_SHARE * min(max(grown, 0.0), 1.0)
    if max_rel_overlap <= tol_final or grow_tol <= tol_final:
        settled = 1.0
    elif max_rel_overlap >= grow_tol:
        settled = 0.0
    else:
        settled = math.log(grow_tol / max_rel_overlap) / math.log(grow_tol / tol_final)
    return GROWTH_SHARE + (1.0 - GROWTH_SHARE) * settled


def _run(state: _PackState, R: np.ndarray, sweep: _SweepSettings,
         progress: Callable[[float], object] | None) -> None:
    """Slices of sweeps until converged or ``max_iter`` sweeps; ``progress`` after each
    slice with the fraction done (never decreasing)."""
    done = 0.0
    while not state.finished and state.count[_IT] < sweep.max_iter:
        _slice(state, R, sweep, SLICE_WORK)
        if progress is not None and not state.finished:
            done = max(done, progress_fraction(float(state.real[_S]),
                                               float(state.real[_MAXREL]), sweep.s_start,
                                               sweep.s_end, sweep.grow_tol, sweep.tol_final))
            progress(done)


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


def _contact_radii(radii: np.ndarray, box: float, min_gap: float, inflate: float
                   ) -> tuple[np.ndarray, float]:
    """The packer's radii ``r + min_gap / 2`` and the box edge, checked (ValueError naming
    the argument): radii finite and > 0, a box > 0, ``inflate`` > 0, ``min_gap`` >= 0, the
    largest inflated diameter below half the box (the minimum-image pair search)."""
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
    return R, L


def pack_spheres(radii: np.ndarray, box: float, rng: np.random.Generator,
                 min_gap: float = 0.0, inflate: float = 1e-3, phi_start: float = 0.25,
                 alpha: float = 0.6, grow_tol: float = 0.02, max_iter: int = 200_000,
                 centers: np.ndarray | None = None, *,
                 progress: Callable[[float], object] | None = None) -> PackingResult:
    """Pack spheres of given radii without overlap in a periodic cube.

    The sweeps run in slices of :data:`SLICE_WORK` (tens of milliseconds) with returns to
    Python in between: a signal handler (``KeyboardInterrupt``, a SIGTERM handler that
    raises) stops the packing within one slice. The slicing does not change the result.

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
    progress : callable, optional
        Called after every slice with the fraction of the way done, in [0, 1] and never
        decreasing (see :func:`progress_fraction`), and with 1.0 once converged; for a
        progress bar.

    Returns
    -------
    PackingResult
    """
    t0 = time.perf_counter()
    R, L = _contact_radii(radii, box, min_gap, inflate)
    phi_full = 4.0 / 3.0 * math.pi * float(np.sum(R ** 3)) / L ** 3
    s_end = 1.0 + float(inflate)
    s_start = min(s_end, (phi_start / phi_full) ** (1.0 / 3.0)) if phi_full > 0 else s_end
    if centers is None:
        pos = rng.uniform(0.0, L, size=(R.size, 3))
    else:
        pos = np.array(centers, dtype=np.float64, copy=True)
        if pos.shape != (R.size, 3):
            raise ValueError(f"centers: expected shape ({R.size}, 3), got {pos.shape}")
    pos = np.ascontiguousarray(pos)
    sweep = _SweepSettings(L, s_start, s_end, float(alpha), 0.5 * float(inflate),
                           float(grow_tol), int(max_iter), 0.3 * float(np.mean(R)),
                           float(R.max()))
    state = _start(pos, R, sweep)
    _run(state, R, sweep, progress)
    s, maxrel = float(state.real[_S]), float(state.real[_MAXREL])
    converged = bool(s >= s_end and maxrel < 0.5 * inflate)
    if converged and progress is not None:
        progress(1.0)
    return PackingResult(state.pos, int(state.count[_IT]), int(state.count[_BUILDS]), maxrel,
                         converged, time.perf_counter() - t0)


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
    n = r.size
    pi, pj, cnt = _neighbour_list(c, r, float(box), float(max(gap, 0.0)),
                                  np.empty(8 * n + 16, dtype=np.int64),
                                  np.empty(8 * n + 16, dtype=np.int64))
    return pi[:cnt].copy(), pj[:cnt].copy(), _gaps(c, r, float(box), pi, pj, cnt)


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
    _, _, g = pairs_within_gap(centers, radii, box, max(min_gap, 0.0) + 1e-9 * box)
    n_bad = int(np.count_nonzero(g < min_gap))
    return n_bad, (float(g.min()) if g.size else math.inf)
