"""Numba kernels of the aggregation multigrid preconditioner (:mod:`itr_fft.multigrid`).

Layout as in :mod:`itr_fft._kernels`: ``g[d][i, j, k]`` is the conductance of the face
between voxel (i, j, k) and its periodic neighbour + e_d. A coarse cell is the box of fine
cells ``2 I, 2 I + 1`` along every axis (one cell when the axis is odd and I is the last);
its aggregate is the box's cells of the box's majority group (particle), so the Galerkin
operator ``P^T A P`` of the piecewise-constant prolongation P is again a 7-point face
operator, with a diagonal excess ``s`` (``A x = L_g x + s x``). Membership: see
:func:`memberships`. Parallel over the first axis; no reduction crosses a ``prange``.
Coarse indices are ``ci, J, K``.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from itr_fv.numba_cache import njit

_PAR = dict(parallel=True, fastmath=False, nogil=True)
_SER = dict(fastmath=False, nogil=True)


@njit(**_PAR)
def coarse_groups(groups):  # pragma: no cover - compiled
    """Group of every coarse cell: the most frequent group among its fine cells (the
    smallest id on a tie), so that aggregates follow particles."""
    n1, n2, n3 = groups.shape
    c1, c2, c3 = (n1 + 1) // 2, (n2 + 1) // 2, (n3 + 1) // 2
    out = np.empty((c1, c2, c3), dtype=groups.dtype)
    for ci in nb.prange(c1):
        cand = np.empty(8, dtype=groups.dtype)
        for J in range(c2):
            for K in range(c3):
                m = 0
                for i in range(2 * ci, min(2 * ci + 2, n1)):
                    for j in range(2 * J, min(2 * J + 2, n2)):
                        for k in range(2 * K, min(2 * K + 2, n3)):
                            cand[m] = groups[i, j, k]
                            m += 1
                best = cand[0]
                best_n = 0
                for a in range(m):
                    c = 0
                    for b in range(m):
                        if cand[b] == cand[a]:
                            c += 1
                    if c > best_n or (c == best_n and cand[a] < best):
                        best = cand[a]
                        best_n = c
                out[ci, J, K] = best
    return out


@njit(inline="always", **_SER)
def _bulk(g, groups, i, j, k, im, ip, jm, jp, km, kp):  # pragma: no cover - compiled
    """Largest conductance from a cell to a neighbour of its own group (its bulk scale)."""
    gp = groups[i, j, k]
    b = 0.0
    if groups[ip, j, k] == gp:
        b = max(b, g[0, i, j, k])
    if groups[im, j, k] == gp:
        b = max(b, g[0, im, j, k])
    if groups[i, jp, k] == gp:
        b = max(b, g[1, i, j, k])
    if groups[i, jm, k] == gp:
        b = max(b, g[1, i, jm, k])
    if groups[i, j, kp] == gp:
        b = max(b, g[2, i, j, k])
    if groups[i, j, km] == gp:
        b = max(b, g[2, i, j, km])
    return b


@njit(**_PAR)
def bulk_scale(g, groups):  # pragma: no cover - compiled
    """:func:`_bulk` of every cell, W/(m^2 K)."""
    n1, n2, n3 = groups.shape
    out = np.empty((n1, n2, n3))
    for i in nb.prange(n1):
        im = i - 1 if i > 0 else n1 - 1
        ip = i + 1 if i < n1 - 1 else 0
        for j in range(n2):
            jm = j - 1 if j > 0 else n2 - 1
            jp = j + 1 if j < n2 - 1 else 0
            for k in range(n3):
                out[i, j, k] = _bulk(g, groups, i, j, k, im, ip, jm, jp,
                                     k - 1 if k > 0 else n3 - 1, k + 1 if k < n3 - 1 else 0)
    return out


@njit(inline="always", **_SER)
def _tie(g_face, groups, groups_c, bulk, theta, i, j, k, qi, qj, qk):  # pragma: no cover
    """(strong face to a member of this cell's box, face to its own group's box across)."""
    same_box = (qi >> 1) == (i >> 1) and (qj >> 1) == (j >> 1) and (qk >> 1) == (k >> 1)
    gq = groups[qi, qj, qk]
    if same_box:
        member = gq == groups_c[i >> 1, j >> 1, k >> 1]
        strong = g_face >= theta * min(bulk[i, j, k], bulk[qi, qj, qk])
        return member and strong, False
    return False, gq == groups[i, j, k] and groups_c[qi >> 1, qj >> 1, qk >> 1] == gq


@njit(**_PAR)
def memberships(g, groups, groups_c, bulk, theta):  # pragma: no cover - compiled
    """1 where a cell is a member of its box's aggregate, else 0.

    A cell of the box's group is a member. A cell of another group is left out (to the
    smoother) only when its group continues, through a face, into a neighbouring box of
    that group, and none of its faces to the box's members is strong: a face is strong
    when its conductance is at least ``theta`` times the smaller bulk scale of its two
    cells (:func:`bulk_scale`), i.e. the interface is not resistive against the bulk on
    either side. So aggregates cross perfect and mildly resistive interfaces (where a
    box-constant correction is cheap) and stop at resistive ones.
    """
    n1, n2, n3 = groups.shape
    out = np.empty((n1, n2, n3), dtype=np.uint8)
    for i in nb.prange(n1):
        im = i - 1 if i > 0 else n1 - 1
        ip = i + 1 if i < n1 - 1 else 0
        for j in range(n2):
            jm = j - 1 if j > 0 else n2 - 1
            jp = j + 1 if j < n2 - 1 else 0
            for k in range(n3):
                if groups[i, j, k] == groups_c[i >> 1, j >> 1, k >> 1]:
                    out[i, j, k] = 1
                    continue
                km = k - 1 if k > 0 else n3 - 1
                kp = k + 1 if k < n3 - 1 else 0
                s0, o0 = _tie(g[0, i, j, k], groups, groups_c, bulk, theta, i, j, k, ip, j, k)
                s1, o1 = _tie(g[0, im, j, k], groups, groups_c, bulk, theta, i, j, k, im, j, k)
                s2, o2 = _tie(g[1, i, j, k], groups, groups_c, bulk, theta, i, j, k, i, jp, k)
                s3, o3 = _tie(g[1, i, jm, k], groups, groups_c, bulk, theta, i, j, k, i, jm, k)
                s4, o4 = _tie(g[2, i, j, k], groups, groups_c, bulk, theta, i, j, k, i, j, kp)
                s5, o5 = _tie(g[2, i, j, km], groups, groups_c, bulk, theta, i, j, k, i, j, km)
                strong = s0 or s1 or s2 or s3 or s4 or s5
                owned = o0 or o1 or o2 or o3 or o4 or o5
                out[i, j, k] = 0 if owned and not strong else 1
    return out


@njit(inline="always", **_SER)
def _member(member, i, j, k):  # pragma: no cover - compiled
    return member[i, j, k] != 0


@njit(**_PAR)
def coarse_operator(g, s, member, c_shape):  # pragma: no cover - compiled
    """Galerkin operator ``P^T A P`` of the group-following aggregation.

    A fine cell is a member of its aggregate (the 2 x 2 x 2 box around it) when its group
    is the box's; P puts the coarse value on members and 0 elsewhere. The product is again
    a 7-point operator, now with a diagonal excess: returns the coarse face conductances
    (the sums of the fine faces between members of neighbouring boxes) and the excess (the
    faces from members to non-members, and the fine excesses of the members).
    """
    n1, n2, n3 = member.shape
    c1, c2, c3 = c_shape
    gc = np.zeros((3, c1, c2, c3))
    diag = np.zeros((c1, c2, c3))
    for ci in nb.prange(c1):
        for i in range(2 * ci, min(2 * ci + 2, n1)):
            im = i - 1 if i > 0 else n1 - 1
            ip = i + 1 if i < n1 - 1 else 0
            for j in range(n2):
                jm = j - 1 if j > 0 else n2 - 1
                jp = j + 1 if j < n2 - 1 else 0
                J = j >> 1
                for k in range(n3):
                    if not _member(member, i, j, k):
                        continue
                    km = k - 1 if k > 0 else n3 - 1
                    kp = k + 1 if k < n3 - 1 else 0
                    K = k >> 1
                    dsum = float(s[i, j, k])
                    # a face to a member of another box is part of a coarse face (counted
                    # in gc by the lower box, t even) and of the diagonal; a face to a
                    # non-member is the excess
                    for t in range(6):
                        d = t >> 1
                        if t == 0:
                            qi, qj, qk, w = ip, j, k, g[0, i, j, k]
                        elif t == 1:
                            qi, qj, qk, w = im, j, k, g[0, im, j, k]
                        elif t == 2:
                            qi, qj, qk, w = i, jp, k, g[1, i, j, k]
                        elif t == 3:
                            qi, qj, qk, w = i, jm, k, g[1, i, jm, k]
                        elif t == 4:
                            qi, qj, qk, w = i, j, kp, g[2, i, j, k]
                        else:
                            qi, qj, qk, w = i, j, km, g[2, i, j, km]
                        if not _member(member, qi, qj, qk):
                            dsum += w
                        elif (qi >> 1) != ci or (qj >> 1) != J or (qk >> 1) != K:
                            dsum += w
                            if t % 2 == 0:
                                gc[d, ci, J, K] += w
                    diag[ci, J, K] += dsum
    sc = np.empty((c1, c2, c3))
    for ci in nb.prange(c1):
        Im = ci - 1 if ci > 0 else c1 - 1
        for J in range(c2):
            Jm = J - 1 if J > 0 else c2 - 1
            for K in range(c3):
                Km = K - 1 if K > 0 else c3 - 1
                off = (gc[0, ci, J, K] + gc[0, Im, J, K] + gc[1, ci, J, K] + gc[1, ci, Jm, K]
                       + gc[2, ci, J, K] + gc[2, ci, J, Km])
                sc[ci, J, K] = max(diag[ci, J, K] - off, 0.0)
    return gc, sc


@njit(inline="always", **_SER)
def _diag(g, s, i, j, k, im, jm, km):  # pragma: no cover - compiled
    """Six face conductances of a cell (+ its excess; ``s`` None on the finest level)."""
    d = (g[0, i, j, k] + g[0, im, j, k] + g[1, i, j, k] + g[1, i, jm, k]
         + g[2, i, j, k] + g[2, i, j, km])
    if s is not None:
        d += s[i, j, k]
    return d


@njit(inline="always", **_SER)
def _ax(g, s, x, i, j, k, im, ip, jm, jp, km, kp):  # pragma: no cover - compiled
    """(A x) at a cell: the 7-point face stencil (+ the excess when ``s`` is given)."""
    xc = x[i, j, k]
    a = (g[0, i, j, k] * (xc - x[ip, j, k]) + g[0, im, j, k] * (xc - x[im, j, k])
         + g[1, i, j, k] * (xc - x[i, jp, k]) + g[1, i, jm, k] * (xc - x[i, jm, k])
         + g[2, i, j, k] * (xc - x[i, j, kp]) + g[2, i, j, km] * (xc - x[i, j, km]))
    if s is not None:
        a += s[i, j, k] * xc
    return a


@njit(inline="always", **_SER)
def _jacobi_cell(g, s, omega, b, x, out, i, j, k, im, ip, jm, jp, km, kp):  # pragma: no cover
    d = _diag(g, s, i, j, k, im, jm, km)
    res = b[i, j, k] - _ax(g, s, x, i, j, k, im, ip, jm, jp, km, kp)
    out[i, j, k] = x[i, j, k] + (omega * res / d if d > 0.0 else 0.0)


@njit(**_SER)
def _row_jacobi(g, s, omega, b, x, out, i, im, ip):  # pragma: no cover - compiled
    n2, n3 = x.shape[1], x.shape[2]
    for j in range(n2):
        jm = j - 1 if j > 0 else n2 - 1
        jp = j + 1 if j < n2 - 1 else 0
        # the two wrapping cells apart, so that the interior loop has no branches
        for kk in range(2 if n3 > 1 else 1):
            k = 0 if kk == 0 else n3 - 1
            _jacobi_cell(g, s, omega, b, x, out, i, j, k, im, ip, jm, jp,
                         k - 1 if k > 0 else n3 - 1, k + 1 if k < n3 - 1 else 0)
        for k in range(1, n3 - 1):
            _jacobi_cell(g, s, omega, b, x, out, i, j, k, im, ip, jm, jp, k - 1, k + 1)


@njit(**_PAR)
def jacobi_sweep(g, s, omega, b, x, out):  # pragma: no cover - compiled
    """out = x + omega D^-1 (b - A x) (weighted Jacobi, D from g on the fly; out must not
    alias x; a cell with no conductance keeps its value)."""
    n1 = x.shape[0]
    for i in nb.prange(n1):
        _row_jacobi(g, s, omega, b, x, out, i, i - 1 if i > 0 else n1 - 1,
                    i + 1 if i < n1 - 1 else 0)


@njit(**_PAR)
def scaled_copy(g, s, omega, b, out):  # pragma: no cover - compiled
    """out = omega D^-1 b (the first Jacobi sweep from x = 0)."""
    n1, n2, n3 = b.shape
    for i in nb.prange(n1):
        im = i - 1 if i > 0 else n1 - 1
        for j in range(n2):
            jm = j - 1 if j > 0 else n2 - 1
            for k in range(n3):
                d = _diag(g, s, i, j, k, im, jm, k - 1 if k > 0 else n3 - 1)
                out[i, j, k] = omega * b[i, j, k] / d if d > 0.0 else 0.0


@njit(**_PAR)
def restrict_residual(g, s, member, b, x, out):  # pragma: no cover - compiled
    """out[I, J, K] = sum over the members of the aggregate of (b - A x) (P^T).

    One coarse row I per thread, the fine rows 2I, 2I+1 streamed in memory order."""
    n1, n2, n3 = x.shape
    c1 = out.shape[0]
    for ci in nb.prange(c1):
        out[ci] = 0.0
        for i in range(2 * ci, min(2 * ci + 2, n1)):
            im = i - 1 if i > 0 else n1 - 1
            ip = i + 1 if i < n1 - 1 else 0
            for j in range(n2):
                jm = j - 1 if j > 0 else n2 - 1
                jp = j + 1 if j < n2 - 1 else 0
                for k in range(n3):
                    if member[i, j, k] == 0:
                        continue
                    km = k - 1 if k > 0 else n3 - 1
                    kp = k + 1 if k < n3 - 1 else 0
                    out[ci, j >> 1, k >> 1] += (b[i, j, k]
                                               - _ax(g, s, x, i, j, k, im, ip, jm, jp, km, kp))


@njit(**_PAR)
def prolong_add(x, e, member, scale):  # pragma: no cover - compiled
    """x += scale P e: the coarse value on the members of every aggregate."""
    n1, n2, n3 = x.shape
    for i in nb.prange(n1):
        for j in range(n2):
            for k in range(n3):
                if member[i, j, k] != 0:
                    x[i, j, k] += scale * e[i >> 1, j >> 1, k >> 1]


@njit(**_SER)
def _row_minus(g, s, x, r, out, i, im, ip):  # pragma: no cover - compiled
    n2, n3 = x.shape[1], x.shape[2]
    for j in range(n2):
        jm = j - 1 if j > 0 else n2 - 1
        jp = j + 1 if j < n2 - 1 else 0
        for kk in range(2 if n3 > 1 else 1):
            k = 0 if kk == 0 else n3 - 1
            km = k - 1 if k > 0 else n3 - 1
            kp = k + 1 if k < n3 - 1 else 0
            out[i, j, k] = r[i, j, k] - _ax(g, s, x, i, j, k, im, ip, jm, jp, km, kp)
        for k in range(1, n3 - 1):
            out[i, j, k] = r[i, j, k] - _ax(g, s, x, i, j, k, im, ip, jm, jp, k - 1, k + 1)


@njit(**_PAR)
def minus_operator(g, s, x, r, out):  # pragma: no cover - compiled
    """out = r - A x (out may alias r)."""
    n1 = r.shape[0]
    for i in nb.prange(n1):
        _row_minus(g, s, x, r, out, i, i - 1 if i > 0 else n1 - 1, i + 1 if i < n1 - 1 else 0)


# ------------------------------------------------------------------ particle deflation
@njit(**_SER)
def _chunk_group_sums(v, groups, n_groups, lo, hi):  # pragma: no cover - compiled
    s = np.zeros(n_groups)
    for i in range(lo, hi):
        for j in range(v.shape[1]):
            for k in range(v.shape[2]):
                s[groups[i, j, k]] += v[i, j, k]
    return s


@njit(**_PAR)
def group_sums(v, groups, n_groups):  # pragma: no cover - compiled
    """Sum of v over every group (Z^T v), float64; independent of the thread count."""
    n1 = v.shape[0]
    n_chunks = min(n1, 16)
    part = np.zeros((n_chunks, n_groups))
    for c in nb.prange(n_chunks):
        part[c] = _chunk_group_sums(v, groups, n_groups, c * n1 // n_chunks,
                                    (c + 1) * n1 // n_chunks)
    return part.sum(axis=0)


@njit(**_PAR)
def minus_operator_of_groups(g, groups, c, r, out):  # pragma: no cover - compiled
    """out = r - A Z c: Z c is c[group] on every cell, so only faces between groups act."""
    n1, n2, n3 = r.shape
    for i in nb.prange(n1):
        im = i - 1 if i > 0 else n1 - 1
        ip = i + 1 if i < n1 - 1 else 0
        for j in range(n2):
            jm = j - 1 if j > 0 else n2 - 1
            jp = j + 1 if j < n2 - 1 else 0
            for k in range(n3):
                km = k - 1 if k > 0 else n3 - 1
                kp = k + 1 if k < n3 - 1 else 0
                cc = c[groups[i, j, k]]
                a = (g[0, i, j, k] * (cc - c[groups[ip, j, k]])
                     + g[0, im, j, k] * (cc - c[groups[im, j, k]])
                     + g[1, i, j, k] * (cc - c[groups[i, jp, k]])
                     + g[1, i, jm, k] * (cc - c[groups[i, jm, k]])
                     + g[2, i, j, k] * (cc - c[groups[i, j, kp]])
                     + g[2, i, j, km] * (cc - c[groups[i, j, km]]))
                out[i, j, k] = r[i, j, k] - a


@njit(**_SER)
def _row_add_groups_dot(y, groups, c, r, z, i):  # pragma: no cover - compiled
    loc = 0.0
    for j in range(y.shape[1]):
        for k in range(y.shape[2]):
            v = float(y[i, j, k]) + c[groups[i, j, k]]
            z[i, j, k] = v
            loc += float(r[i, j, k]) * v
    return loc


@njit(**_PAR)
def add_groups_dot(y, groups, c, r, z):  # pragma: no cover - compiled
    """z = y + Z c (z may alias y); returns r . z in float64."""
    n1 = y.shape[0]
    part = np.zeros(n1)
    for i in nb.prange(n1):
        part[i] = _row_add_groups_dot(y, groups, c, r, z, i)
    return part.sum()


@njit(**_SER)
def group_operator_entries(g, groups):  # pragma: no cover - compiled
    """(rows, cols, values) of the faces between different groups: E = Z^T A Z's couplings."""
    n1, n2, n3 = groups.shape
    m = 0
    for d in range(3):
        for i in range(n1):
            for j in range(n2):
                for k in range(n3):
                    q = (groups[(i + 1) % n1, j, k] if d == 0 else
                         groups[i, (j + 1) % n2, k] if d == 1 else groups[i, j, (k + 1) % n3])
                    if q != groups[i, j, k] and g[d, i, j, k] != 0.0:
                        m += 1
    rows = np.empty(m, dtype=np.int64)
    cols = np.empty(m, dtype=np.int64)
    vals = np.empty(m)
    t = 0
    for d in range(3):
        for i in range(n1):
            for j in range(n2):
                for k in range(n3):
                    q = (groups[(i + 1) % n1, j, k] if d == 0 else
                         groups[i, (j + 1) % n2, k] if d == 1 else groups[i, j, (k + 1) % n3])
                    if q != groups[i, j, k] and g[d, i, j, k] != 0.0:
                        rows[t] = groups[i, j, k]
                        cols[t] = q
                        vals[t] = g[d, i, j, k]
                        t += 1
    return rows, cols, vals


@njit(**_SER)
def _row_bulk_range(g, groups, i, ip):  # pragma: no cover - compiled
    lo = np.inf
    hi = 0.0
    n2, n3 = groups.shape[1], groups.shape[2]
    for j in range(n2):
        jp = j + 1 if j < n2 - 1 else 0
        for k in range(n3):
            kp = k + 1 if k < n3 - 1 else 0
            gp = groups[i, j, k]
            for d in range(3):
                if d == 0:
                    same = groups[ip, j, k] == gp
                elif d == 1:
                    same = groups[i, jp, k] == gp
                else:
                    same = groups[i, j, kp] == gp
                v = g[d, i, j, k]
                if same and v > 0.0:
                    lo = min(lo, v)
                    hi = max(hi, v)
    return lo, hi


@njit(**_PAR)
def bulk_range(g, groups):  # pragma: no cover - compiled
    """(smallest, largest) positive conductance of the faces inside a group (the bulk of
    the matrix and of the particles; interfaces and contacts excluded), W/(m^2 K)."""
    n1 = groups.shape[0]
    lo = np.empty(n1)
    hi = np.empty(n1)
    for i in nb.prange(n1):
        lo[i], hi[i] = _row_bulk_range(g, groups, i, i + 1 if i < n1 - 1 else 0)
    return lo.min(), hi.max()


@njit(**_SER)
def _chunk_minus_sums(g, x, r, out, groups, n_groups, lo, hi):  # pragma: no cover
    n1, n2, n3 = r.shape
    sums = np.zeros(n_groups)
    for i in range(lo, hi):
        im = i - 1 if i > 0 else n1 - 1
        ip = i + 1 if i < n1 - 1 else 0
        for j in range(n2):
            jm = j - 1 if j > 0 else n2 - 1
            jp = j + 1 if j < n2 - 1 else 0
            for k in range(n3):
                km = k - 1 if k > 0 else n3 - 1
                kp = k + 1 if k < n3 - 1 else 0
                v = r[i, j, k] - _ax(g, None, x, i, j, k, im, ip, jm, jp, km, kp)
                out[i, j, k] = v
                sums[groups[i, j, k]] += v
    return sums


@njit(**_PAR)
def minus_operator_group_sums(g, x, r, out, groups, n_groups):  # pragma: no cover
    """out = r - A x (out may alias r), and Z^T out (float64), in one pass."""
    n1 = r.shape[0]
    n_chunks = min(n1, 16)
    part = np.zeros((n_chunks, n_groups))
    for c in nb.prange(n_chunks):
        part[c] = _chunk_minus_sums(g, x, r, out, groups, n_groups, c * n1 // n_chunks,
                                    (c + 1) * n1 // n_chunks)
    return part.sum(axis=0)


@njit(inline="always", **_SER)
def _pull(g_face, cur, scale, theta, qi, qj, qk, best, who):  # pragma: no cover - compiled
    """(best, who) after looking at neighbour q across a face of conductance ``g_face``."""
    gq = cur[qi, qj, qk]
    if gq > 0 and g_face >= theta * scale[gq] and g_face > best:
        return g_face, gq
    return best, who


@njit(**_SER)
def group_scales(bulk, groups, n_groups):  # pragma: no cover - compiled
    """Largest bulk scale (:func:`bulk_scale`) over the cells of every group."""
    out = np.zeros(n_groups)
    flat_b = bulk.ravel()
    flat_g = groups.ravel()
    for t in range(flat_g.size):
        if flat_b[t] > out[flat_g[t]]:
            out[flat_g[t]] = flat_b[t]
    return out


@njit(**_PAR)
def join_pass(g, cur, scale, theta, nxt):  # pragma: no cover - compiled
    """One pass of :func:`itr_fft.multigrid.coupled_groups`: every matrix cell (group 0)
    of ``cur`` takes the group of its neighbour across its strongest face that is at least
    ``theta`` times that group's scale (``scale[group]``, :func:`group_scales`); returns
    how many cells changed."""
    n1, n2, n3 = cur.shape
    changed = np.zeros(n1, dtype=np.int64)
    for i in nb.prange(n1):
        im = i - 1 if i > 0 else n1 - 1
        ip = i + 1 if i < n1 - 1 else 0
        for j in range(n2):
            jm = j - 1 if j > 0 else n2 - 1
            jp = j + 1 if j < n2 - 1 else 0
            for k in range(n3):
                nxt[i, j, k] = cur[i, j, k]
                if cur[i, j, k] != 0:
                    continue
                km = k - 1 if k > 0 else n3 - 1
                kp = k + 1 if k < n3 - 1 else 0
                best, who = 0.0, 0
                best, who = _pull(g[0, i, j, k], cur, scale, theta, ip, j, k, best, who)
                best, who = _pull(g[0, im, j, k], cur, scale, theta, im, j, k, best, who)
                best, who = _pull(g[1, i, j, k], cur, scale, theta, i, jp, k, best, who)
                best, who = _pull(g[1, i, jm, k], cur, scale, theta, i, jm, k, best, who)
                best, who = _pull(g[2, i, j, k], cur, scale, theta, i, j, kp, best, who)
                best, who = _pull(g[2, i, j, km], cur, scale, theta, i, j, km, best, who)
                if who:
                    nxt[i, j, k] = who
                    changed[i] += 1
    return changed.sum()
