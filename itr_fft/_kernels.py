"""Fused numba kernels of the FFT-preconditioned CG solver.

Every kernel loops once over the grid (``parallel=True`` over the first axis), reads each
array once and accumulates its reduction in float64 (no fastmath: the CG scalars must not
be reassociated differently between runs). Reductions go through one partial sum per
row of the first axis, so results do not depend on the thread count. Arrays are
C-contiguous, shape (n1, n2, n3), float64 or float32 (one compiled specialisation per dtype,
cached on disk, see :mod:`itr_fv.numba_cache`).

Structure: each parallel kernel's ``prange`` body only stores what a serial row helper
(``_row_*``, one first-axis index i) returns; no scalar is accumulated across the
``prange`` loop. Numba's parfor reduction analysis recursed without end on a kernel that
accumulated two reductions in the loop body (``RecursionError`` on Python 3.12 with numba
0.68, Python 3.11 compiled it); with no reduction variable in any ``prange`` body there is
nothing for that analysis to do.

Layout convention (as in :mod:`itr_fv.discrete.model`): ``g[d][i, j, k]`` is the conductance per
unit
area (W/(m^2 K)) of the face between voxel (i, j, k) and its periodic neighbour + e_d, so

    (A theta)_p = sum_d g_d[p] (theta_p - theta_{p+e_d}) + g_d[p-e_d] (theta_p - theta_{p-e_d})
"""

from __future__ import annotations

import numba as nb
import numpy as np

from itr_fv.numba_cache import njit

_PAR = dict(parallel=True, fastmath=False, nogil=True)
_SER = dict(fastmath=False, nogil=True)


@njit(inline="always", **_SER)
def _stencil(g0, g1, g2, p, i, j, k, im, ip, jm, jp, km, kp):  # pragma: no cover - compiled
    """(A p) at voxel (i, j, k), W/m^2 per K of p, in float64: the one stencil definition."""
    pc = float(p[i, j, k])
    return (g0[i, j, k] * (pc - float(p[ip, j, k])) + g0[im, j, k] * (pc - float(p[im, j, k]))
            + g1[i, j, k] * (pc - float(p[i, jp, k])) + g1[i, jm, k] * (pc - float(p[i, jm, k]))
            + g2[i, j, k] * (pc - float(p[i, j, kp])) + g2[i, j, km] * (pc - float(p[i, j, km])))


@njit(inline="always", **_SER)
def _load(gd, d, hE, i, j, k, im, jm, km):  # pragma: no cover - compiled
    """b(E = hE/h e_d) at voxel (i, j, k): ``hE (g_d[p - e_d] - g_d[p])``."""
    if d == 0:
        return hE * (gd[im, j, k] - gd[i, j, k])
    if d == 1:
        return hE * (gd[i, jm, k] - gd[i, j, k])
    return hE * (gd[i, j, km] - gd[i, j, k])


@njit(**_SER)
def _line_matvec(g0, g1, g2, p, q, i, im, ip, j, loc):  # pragma: no cover - compiled
    """q = A p on the line (i, j, :); returns ``loc`` plus its p . q, added in k order."""
    n2, n3 = p.shape[1], p.shape[2]
    jm = j - 1 if j > 0 else n2 - 1
    jp = j + 1 if j < n2 - 1 else 0
    # k = 0 and k = n3 - 1 wrap; the interior loop has no branches
    for kk in range(2 if n3 > 1 else 1):
        k = 0 if kk == 0 else n3 - 1
        km = k - 1 if k > 0 else n3 - 1
        kp = k + 1 if k < n3 - 1 else 0
        s = _stencil(g0, g1, g2, p, i, j, k, im, ip, jm, jp, km, kp)
        q[i, j, k] = s
        loc += float(p[i, j, k]) * s
    for k in range(1, n3 - 1):
        s = _stencil(g0, g1, g2, p, i, j, k, im, ip, jm, jp, k - 1, k + 1)
        q[i, j, k] = s
        loc += float(p[i, j, k]) * s
    return loc


@njit(**_SER)
def _row_matvec(g0, g1, g2, p, q, i, im, ip):  # pragma: no cover - compiled
    loc = 0.0
    for j in range(p.shape[1]):
        loc = _line_matvec(g0, g1, g2, p, q, i, im, ip, j, loc)
    return loc


@njit(**_PAR)
def matvec_dot(g, p, q):  # pragma: no cover - compiled
    """q = A p (W/m^2 per K of p); returns p . q in float64."""
    n1 = p.shape[0]
    g0 = g[0]
    g1 = g[1]
    g2 = g[2]
    part = np.zeros(n1)
    for i in nb.prange(n1):
        part[i] = _row_matvec(g0, g1, g2, p, q, i, i - 1 if i > 0 else n1 - 1,
                              i + 1 if i < n1 - 1 else 0)
    return part.sum()


@njit(**_SER)
def _row_matvec_block(g0, g1, g2, ps, qs, i, im, ip, part):  # pragma: no cover - compiled
    """Every field of the block on row i, line by line (a line of g stays in the L1 cache
    for all of them); ``part[c, i]`` gets field c's p . q of the row, in the order of
    :func:`_row_matvec`."""
    m = len(ps)
    for c in range(m):
        part[c, i] = 0.0
    for j in range(ps[0].shape[1]):
        for c in range(m):
            part[c, i] = _line_matvec(g0, g1, g2, ps[c], qs[c], i, im, ip, j, part[c, i])


@njit(**_PAR)
def matvec_dot_block(g, ps, qs):  # pragma: no cover - compiled
    """qs[c] = A ps[c] for every field c of the tuples ``ps``, ``qs`` (one pass over g);
    returns the ps[c] . qs[c], each as :func:`matvec_dot` computes it."""
    n1 = ps[0].shape[0]
    m = len(ps)
    g0 = g[0]
    g1 = g[1]
    g2 = g[2]
    part = np.zeros((m, n1))
    for i in nb.prange(n1):
        _row_matvec_block(g0, g1, g2, ps, qs, i, i - 1 if i > 0 else n1 - 1,
                          i + 1 if i < n1 - 1 else 0, part)
    out = np.zeros(m)
    for c in range(m):
        out[c] = part[c].sum()
    return out


@njit(**_SER)
def _row_residual_into(g0, g1, g2, x, b, out, i, im, ip):  # pragma: no cover - compiled
    n2, n3 = x.shape[1], x.shape[2]
    loc = 0.0
    for j in range(n2):
        jm = j - 1 if j > 0 else n2 - 1
        jp = j + 1 if j < n2 - 1 else 0
        for k in range(n3):
            km = k - 1 if k > 0 else n3 - 1
            kp = k + 1 if k < n3 - 1 else 0
            v = float(b[i, j, k]) - _stencil(g0, g1, g2, x, i, j, k, im, ip, jm, jp, km, kp)
            out[i, j, k] = v
            loc += v * v
    return loc


@njit(**_PAR)
def residual_into(g, x, b, out):  # pragma: no cover - compiled
    """out = b - A x, formed in float64 and then stored in out's precision; returns the
    float64 ||b - A x||^2 (before that rounding)."""
    n1 = x.shape[0]
    g0 = g[0]
    g1 = g[1]
    g2 = g[2]
    part = np.zeros(n1)
    for i in nb.prange(n1):
        part[i] = _row_residual_into(g0, g1, g2, x, b, out, i, i - 1 if i > 0 else n1 - 1,
                                     i + 1 if i < n1 - 1 else 0)
    return part.sum()


@njit(**_SER)
def _row_load(gd, d, hE, out, i, im):  # pragma: no cover - compiled
    n2, n3 = out.shape[1], out.shape[2]
    loc = 0.0
    for j in range(n2):
        jm = j - 1 if j > 0 else n2 - 1
        for k in range(n3):
            v = _load(gd, d, hE, i, j, k, im, jm, k - 1 if k > 0 else n3 - 1)
            out[i, j, k] = v
            loc += v * v
    return loc


@njit(**_PAR)
def load_into(g, d, hE, out):  # pragma: no cover - compiled
    """out = b(E = hE/h e_d): ``out_p = hE (g_d[p - e_d] - g_d[p])``; returns out . out."""
    n1 = out.shape[0]
    gd = g[d]
    part = np.zeros(n1)
    for i in nb.prange(n1):
        part[i] = _row_load(gd, d, hE, out, i, i - 1 if i > 0 else n1 - 1)
    return part.sum()


@njit(**_SER)
def _row_sub(a, b, i):  # pragma: no cover - compiled
    loc = 0.0
    for j in range(a.shape[1]):
        for k in range(a.shape[2]):
            v = a[i, j, k] - b[i, j, k]
            a[i, j, k] = v
            loc += v * v
    return loc


@njit(**_PAR)
def sub_into(a, b):  # pragma: no cover - compiled
    """a -= b; returns a . a (float64)."""
    n1 = a.shape[0]
    part = np.zeros(n1)
    for i in nb.prange(n1):
        part[i] = _row_sub(a, b, i)
    return part.sum()


@njit(**_SER)
def _row_cg(x, r, p, q, alpha, i):  # pragma: no cover - compiled
    loc = 0.0
    for j in range(x.shape[1]):
        for k in range(x.shape[2]):
            x[i, j, k] += alpha * p[i, j, k]
            v = r[i, j, k] - alpha * q[i, j, k]
            r[i, j, k] = v
            loc += v * v
    return loc


@njit(**_PAR)
def cg_update(x, r, p, q, alpha):  # pragma: no cover - compiled
    """x += alpha p; r -= alpha q; returns r . r (float64)."""
    n1 = x.shape[0]
    part = np.zeros(n1)
    for i in nb.prange(n1):
        part[i] = _row_cg(x, r, p, q, alpha, i)
    return part.sum()


@njit(**_PAR)
def direction_update(p, z, beta):  # pragma: no cover - compiled
    """p = z + beta p."""
    n1, n2, n3 = p.shape
    for i in nb.prange(n1):
        for j in range(n2):
            for k in range(n3):
                p[i, j, k] = z[i, j, k] + beta * p[i, j, k]


@njit(**_SER)
def _row_spectral(rhat, i, s1i, s2, s3, n3, inv_gref):  # pragma: no cover - compiled
    loc = 0.0
    for j in range(rhat.shape[1]):
        sij = s1i + s2[j]
        for k in range(rhat.shape[2]):
            lam = sij + s3[k]
            v = rhat[i, j, k]
            if lam > 0.0:
                c = inv_gref / lam
                w = 1.0 if (k == 0 or 2 * k == n3) else 2.0
                loc += w * c * (v.real * v.real + v.imag * v.imag)
                rhat[i, j, k] = v * c
            else:
                rhat[i, j, k] = 0.0
    return loc


@njit(**_PAR)
def spectral_solve(rhat, s1, s2, s3, n3, inv_gref):  # pragma: no cover - compiled
    """In place: rhat /= g_ref * lambda(xi), zero mode set to 0; returns r . z.

    ``lambda = s1[i] + s2[j] + s3[k]`` with ``s_d = 4 sin^2(pi xi_d / n_d)``, the symbol of
    the periodic 7-point Laplacian (unit face conductance). ``rhat`` is the unnormalised
    half spectrum of scipy's rfftn (last axis of length n3 // 2 + 1), so by Parseval
    ``r . z = (1/N) sum_xi w(xi) |rhat|^2 / (g_ref lambda)`` with w = 1 on the k = 0 and
    (n3 even) k = n3/2 planes, 2 elsewhere.
    """
    m1, m2 = rhat.shape[0], rhat.shape[1]
    part = np.zeros(m1)
    for i in nb.prange(m1):
        part[i] = _row_spectral(rhat, i, s1[i], s2, s3, n3, inv_gref)
    return part.sum() / (n3 * m1 * m2)


@njit(**_SER)
def _row_dot(a, b, i):  # pragma: no cover - compiled
    loc = 0.0
    for j in range(a.shape[1]):
        for k in range(a.shape[2]):
            loc += float(a[i, j, k]) * float(b[i, j, k])
    return loc


@njit(**_PAR)
def dot(a, b):  # pragma: no cover - compiled
    """a . b in float64."""
    n1 = a.shape[0]
    part = np.zeros(n1)
    for i in nb.prange(n1):
        part[i] = _row_dot(a, b, i)
    return part.sum()


@njit(**_SER)
def _cluster_sums(v, labels, n):  # pragma: no cover - compiled
    s = np.zeros(n)
    for t in range(v.size):
        s[labels[t]] += v[t]
    return s


@njit(**_PAR)
def _subtract_by_label(v, labels, means):  # pragma: no cover - compiled
    for t in nb.prange(v.size):
        v[t] -= means[labels[t]]


def project_clusters(v: np.ndarray, labels_flat: np.ndarray, counts: np.ndarray) -> None:
    """Remove the mean of ``v`` on every connected cluster (in place).

    This is the orthogonal projection onto range(A) (null(A) is spanned by the cluster
    indicators), used only when insulating interfaces cut the grid into several clusters.
    """
    flat = v.reshape(-1)
    sums = _cluster_sums(flat, labels_flat, counts.size)
    _subtract_by_label(flat, labels_flat, (sums / counts).astype(v.dtype))


@njit(**_SER)
def _row_residual(g0, g1, g2, gd, x, d, hE, i, im, ip):  # pragma: no cover - compiled
    n2, n3 = x.shape[1], x.shape[2]
    loc = 0.0
    for j in range(n2):
        jm = j - 1 if j > 0 else n2 - 1
        jp = j + 1 if j < n2 - 1 else 0
        for k in range(n3):
            km = k - 1 if k > 0 else n3 - 1
            kp = k + 1 if k < n3 - 1 else 0
            v = (_load(gd, d, hE, i, j, k, im, jm, km)
                 - _stencil(g0, g1, g2, x, i, j, k, im, ip, jm, jp, km, kp))
            loc += v * v
    return loc


@njit(**_PAR)
def residual_norm2(g, x, d, hE):  # pragma: no cover - compiled
    """||b(E) - A x||^2 in float64 without temporaries (b as in :func:`load_into`).

    ``g`` should be the float64 conductances, so that the reported residual is the one of
    the exact operator whatever the storage precision of ``x``.
    """
    n1 = x.shape[0]
    g0 = g[0]
    g1 = g[1]
    g2 = g[2]
    gd = g[d]
    part = np.zeros(n1)
    for i in nb.prange(n1):
        part[i] = _row_residual(g0, g1, g2, gd, x, d, hE, i, i - 1 if i > 0 else n1 - 1,
                                i + 1 if i < n1 - 1 else 0)
    return part.sum()
