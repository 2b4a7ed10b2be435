"""Fused numba kernels of the FFT-preconditioned CG solver.

Every kernel loops once over the grid (``parallel=True`` over the first axis), reads each
array once and accumulates its reduction in float64 (no fastmath: the CG scalars must not
be reassociated differently between runs); reductions go through one partial sum per
row of the first axis, so results do not depend on the thread count). Arrays are
C-contiguous, shape (n1, n2, n3), float64 or float32 (one compiled specialisation per dtype,
cached on disk).

Layout convention (as in :mod:`itr_fv.model`): ``g[d][i, j, k]`` is the conductance per unit
area (W/(m^2 K)) of the face between voxel (i, j, k) and its periodic neighbour + e_d, so

    (A theta)_p = sum_d g_d[p] (theta_p - theta_{p+e_d}) + g_d[p-e_d] (theta_p - theta_{p-e_d})
"""

from __future__ import annotations

import numba as nb
import numpy as np

_OPTS = dict(parallel=True, cache=True, fastmath=False, nogil=True)


@nb.njit(**_OPTS)
def matvec_dot(g, p, q):  # pragma: no cover - compiled
    """q = A p (W/m^2 per K of p); returns p . q in float64."""
    n1, n2, n3 = p.shape
    g0 = g[0]
    g1 = g[1]
    g2 = g[2]
    part = np.zeros(n1)
    for i in nb.prange(n1):
        im = i - 1 if i > 0 else n1 - 1
        ip = i + 1 if i < n1 - 1 else 0
        loc = 0.0
        for j in range(n2):
            jm = j - 1 if j > 0 else n2 - 1
            jp = j + 1 if j < n2 - 1 else 0
            # k = 0 and k = n3 - 1 wrap; the interior loop has no branches
            for kk in range(2 if n3 > 1 else 1):
                k = 0 if kk == 0 else n3 - 1
                km = k - 1 if k > 0 else n3 - 1
                kp = k + 1 if k < n3 - 1 else 0
                pc = p[i, j, k]
                s = (g0[i, j, k] * (pc - p[ip, j, k]) + g0[im, j, k] * (pc - p[im, j, k])
                     + g1[i, j, k] * (pc - p[i, jp, k]) + g1[i, jm, k] * (pc - p[i, jm, k])
                     + g2[i, j, k] * (pc - p[i, j, kp]) + g2[i, j, km] * (pc - p[i, j, km]))
                q[i, j, k] = s
                loc += pc * s
            for k in range(1, n3 - 1):
                pc = p[i, j, k]
                s = (g0[i, j, k] * (pc - p[ip, j, k]) + g0[im, j, k] * (pc - p[im, j, k])
                     + g1[i, j, k] * (pc - p[i, jp, k]) + g1[i, jm, k] * (pc - p[i, jm, k])
                     + g2[i, j, k] * (pc - p[i, j, k + 1])
                     + g2[i, j, k - 1] * (pc - p[i, j, k - 1]))
                q[i, j, k] = s
                loc += pc * s
        part[i] = loc
    return part.sum()


@nb.njit(**_OPTS)
def load_into(g, d, hE, out):  # pragma: no cover - compiled
    """out = b(E = hE/h e_d): ``out_p = hE (g_d[p - e_d] - g_d[p])``; returns out . out."""
    n1, n2, n3 = out.shape
    gd = g[d]
    part = np.zeros(n1)
    for i in nb.prange(n1):
        im = i - 1 if i > 0 else n1 - 1
        loc = 0.0
        for j in range(n2):
            jm = j - 1 if j > 0 else n2 - 1
            for k in range(n3):
                km = k - 1 if k > 0 else n3 - 1
                if d == 0:
                    v = hE * (gd[im, j, k] - gd[i, j, k])
                elif d == 1:
                    v = hE * (gd[i, jm, k] - gd[i, j, k])
                else:
                    v = hE * (gd[i, j, km] - gd[i, j, k])
                out[i, j, k] = v
                loc += v * v
        part[i] = loc
    return part.sum()


@nb.njit(**_OPTS)
def sub_into(a, b):  # pragma: no cover - compiled
    """a -= b; returns a . a (float64)."""
    n1, n2, n3 = a.shape
    part = np.zeros(n1)
    for i in nb.prange(n1):
        loc = 0.0
        for j in range(n2):
            for k in range(n3):
                v = a[i, j, k] - b[i, j, k]
                a[i, j, k] = v
                loc += v * v
        part[i] = loc
    return part.sum()


@nb.njit(**_OPTS)
def cg_update(x, r, p, q, alpha):  # pragma: no cover - compiled
    """x += alpha p; r -= alpha q; returns r . r (float64)."""
    n1, n2, n3 = x.shape
    part = np.zeros(n1)
    for i in nb.prange(n1):
        loc = 0.0
        for j in range(n2):
            for k in range(n3):
                x[i, j, k] += alpha * p[i, j, k]
                v = r[i, j, k] - alpha * q[i, j, k]
                r[i, j, k] = v
                loc += v * v
        part[i] = loc
    return part.sum()


@nb.njit(**_OPTS)
def direction_update(p, z, beta):  # pragma: no cover - compiled
    """p = z + beta p."""
    n1, n2, n3 = p.shape
    for i in nb.prange(n1):
        for j in range(n2):
            for k in range(n3):
                p[i, j, k] = z[i, j, k] + beta * p[i, j, k]


@nb.njit(cache=True, nogil=True)
def _spectral_row(row, sij, s3, n3, inv_gref):  # pragma: no cover - compiled
    m3 = row.shape[0]
    loc = 0.0
    for k in range(m3):
        lam = sij + s3[k]
        v = row[k]
        if lam > 0.0:
            c = inv_gref / lam
            w = 1.0 if (k == 0 or 2 * k == n3) else 2.0
            loc += w * c * (v.real * v.real + v.imag * v.imag)
            row[k] = v * c
        else:
            row[k] = 0.0
    return loc


@nb.njit(**_OPTS)
def spectral_solve(rhat, s1, s2, s3, n3, inv_gref):  # pragma: no cover - compiled
    """In place: rhat /= g_ref * lambda(xi), zero mode set to 0; returns r . z.

    ``lambda = s1[i] + s2[j] + s3[k]`` with ``s_d = 4 sin^2(pi xi_d / n_d)``, the symbol of
    the periodic 7-point Laplacian (unit face conductance). ``rhat`` is the unnormalised
    half spectrum of scipy's rfftn (last axis of length n3 // 2 + 1), so by Parseval
    ``r . z = (1/N) sum_xi w(xi) |rhat|^2 / (g_ref lambda)`` with w = 1 on the k = 0 and
    (n3 even) k = n3/2 planes, 2 elsewhere.
    """
    m1, m2, m3 = rhat.shape
    part = np.zeros(m1)
    for i in nb.prange(m1):
        loc = 0.0
        for j in range(m2):
            loc += _spectral_row(rhat[i, j], s1[i] + s2[j], s3, n3, inv_gref)
        part[i] = loc
    return part.sum() / (n3 * m1 * m2)


@nb.njit(**_OPTS)
def dot(a, b):  # pragma: no cover - compiled
    """a . b in float64."""
    n1, n2, n3 = a.shape
    part = np.zeros(n1)
    for i in nb.prange(n1):
        loc = 0.0
        for j in range(n2):
            for k in range(n3):
                loc += float(a[i, j, k]) * float(b[i, j, k])
        part[i] = loc
    return part.sum()


@nb.njit(cache=True, nogil=True)
def _cluster_sums(v, labels, n):  # pragma: no cover - compiled
    s = np.zeros(n)
    for t in range(v.size):
        s[labels[t]] += v[t]
    return s


@nb.njit(**_OPTS)
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


@nb.njit(**_OPTS)
def log_sum_positive(g):  # pragma: no cover - compiled
    """(sum of log g over faces with g > 0, their count); g of shape (3, n1, n2, n3)."""
    _, n1, n2, n3 = g.shape
    part = np.zeros(n1)
    cnts = np.zeros(n1, dtype=np.int64)
    for i in nb.prange(n1):
        loc = 0.0
        c = 0
        for d in range(3):
            for j in range(n2):
                for k in range(n3):
                    v = g[d, i, j, k]
                    if v > 0.0:
                        loc += np.log(v)
                        c += 1
        part[i] = loc
        cnts[i] = c
    return part.sum(), cnts.sum()


def laplacian_symbol(n: int) -> np.ndarray:
    """``4 sin^2(pi xi / n)`` for xi = 0..n-1 (float64)."""
    return 4.0 * np.sin(np.pi * np.arange(n) / n) ** 2


@nb.njit(**_OPTS)
def residual_norm2(g, x, d, hE):  # pragma: no cover - compiled
    """||b(E) - A x||^2 in float64 without temporaries (b as in :func:`load_into`).

    ``g`` should be the float64 conductances, so that the reported residual is the one of
    the exact operator whatever the storage precision of ``x``.
    """
    n1, n2, n3 = x.shape
    g0 = g[0]
    g1 = g[1]
    g2 = g[2]
    gd = g[d]
    part = np.zeros(n1)
    for i in nb.prange(n1):
        im = i - 1 if i > 0 else n1 - 1
        ip = i + 1 if i < n1 - 1 else 0
        loc = 0.0
        for j in range(n2):
            jm = j - 1 if j > 0 else n2 - 1
            jp = j + 1 if j < n2 - 1 else 0
            for k in range(n3):
                km = k - 1 if k > 0 else n3 - 1
                kp = k + 1 if k < n3 - 1 else 0
                pc = float(x[i, j, k])
                s = (g0[i, j, k] * (pc - float(x[ip, j, k]))
                     + g0[im, j, k] * (pc - float(x[im, j, k]))
                     + g1[i, j, k] * (pc - float(x[i, jp, k]))
                     + g1[i, jm, k] * (pc - float(x[i, jm, k]))
                     + g2[i, j, k] * (pc - float(x[i, j, kp]))
                     + g2[i, j, km] * (pc - float(x[i, j, km])))
                if d == 0:
                    b = hE * (gd[im, j, k] - gd[i, j, k])
                elif d == 1:
                    b = hE * (gd[i, jm, k] - gd[i, j, k])
                else:
                    b = hE * (gd[i, j, km] - gd[i, j, k])
                v = b - s
                loc += v * v
        part[i] = loc
    return part.sum()
