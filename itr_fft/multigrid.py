"""Aggregation multigrid preconditioner of the face-conductance operator (numba).

One V-cycle (or W-cycle) ``z = M r`` of a hierarchy built from the face conductances and
the particle ids:

- aggregates follow particles: a coarse cell is a 2 x 2 x 2 box of cells (one cell wide on
  an odd axis's last box), and its aggregate is the box's cells of the box's majority group
  (particle id, 0 = matrix). The prolongation P puts the coarse value on those members and
  nothing on the box's other cells, which belong to a neighbouring particle or the matrix
  across a (resistive) interface: a box-constant correction across such an interface is
  exactly what fails when interfaces are resistive or the contrast is high (measured on
  AlN-60: the plain box aggregation's iterations doubled with every grid refinement);
- the coarse operator is the Galerkin product ``P^T A P``, again a 7-point face operator
  with a diagonal excess ``s`` (``A x = L_g x + s x``): coarse face conductances are the
  sums of the fine faces between members of neighbouring boxes, the excess collects the
  faces from members to non-members (:func:`itr_fft._mg_kernels.coarse_operator`);
- smoothing: ``sweeps`` weighted-Jacobi sweeps (weight ``omega``) before and as many after
  the coarse correction, which keeps M symmetric; the correction is scaled by
  ``over_correction`` (a piecewise-constant P underestimates smooth errors; the classic
  remedy of aggregation multigrid, still symmetric);
- the coarsest level (``coarsest`` cells or fewer) is solved with the pseudo-inverse of its
  dense matrix.

Cost per application: ``2 sweeps`` stencil passes and one restriction pass on the fine
grid, an eighth of that per coarser level. Memory: see :data:`MG_BYTES_PER_VOXEL`.
"""

from __future__ import annotations

import math

import numpy as np

from . import _mg_kernels as MG

__all__ = ["AggregationMultigrid", "MG_BYTES_PER_VOXEL", "coupled_groups"]

#: Extra peak bytes per voxel of a multigrid solve over an FFT-preconditioned one (the
#: hierarchy, the deflation's vectors; no FFT buffers). Measured: peak RSS 180 vs 148 bytes
#: per voxel, AlN-60 at 192^3, one load case, fields not kept.
MG_BYTES_PER_VOXEL = 32

#: Passes of :func:`coupled_groups` at most (a bridge of matrix cells is joined one cell
#: deeper per pass; the contact necks seen are one or two cells long).
JOIN_PASSES = 8


def coupled_groups(g: np.ndarray, particle_ids: np.ndarray | None, *,
                   theta: float = 0.5) -> np.ndarray | None:
    """The groups the multigrid and the particle deflation follow: the particle ids, with
    every matrix cell that conducts like a particle's bulk joined to that particle.

    Where touching particles meet at a thin film (the stated film, 0 nm by default), the
    faces of a few matrix cells in the contact neck carry the filler's conductance (their
    segments run through filler). Grouped with the matrix, such a cell ties a particle to
    the matrix's aggregates and deflation constant as if by filler, and CG slows: AlN-60 at
    0.125 um took 82 iterations per load case instead of 46
    (``validation/results/contact_iterations.md``). A matrix cell takes the group of its
    neighbour across its strongest face whose conductance is at least ``theta`` times that
    neighbour's particle's bulk scale (its largest face between two of its cells, W/(m^2
    K): the filler's own), repeated so that
    a bridge of several cells is joined (at most :data:`JOIN_PASSES` passes). Only the
    preconditioner sees these groups: the operator, and so the solution, is unchanged.

    Parameters
    ----------
    g : ndarray, shape (3, n1, n2, n3)
        Face conductances, ``g[d][p]`` between cell ``p`` and ``p + e_d``, W/(m^2 K) (any
        common scale).
    particle_ids : int ndarray, shape (n1, n2, n3), or None
        Particle of every cell, 0 = matrix (``DiscreteSystem.particle_ids``).
    theta : float
        Fraction of the particle's bulk scale a face must reach, in (0, 1].

    Returns
    -------
    int32 ndarray or None
        The groups (None where ``particle_ids`` is None).
    """
    if particle_ids is None:
        return None
    if not 0.0 < theta <= 1.0:
        raise ValueError(f"theta: expected a fraction in (0, 1], got {theta!r}")
    g = np.ascontiguousarray(g, dtype=np.float64)
    cur = np.array(particle_ids, dtype=np.int32, order="C")  # a copy: the passes swap
    scale = MG.group_scales(MG.bulk_scale(g, cur), cur, int(cur.max()) + 1)
    nxt = np.empty_like(cur)
    for _ in range(JOIN_PASSES):
        if not MG.join_pass(g, cur, scale, float(theta), nxt):
            break
        cur, nxt = nxt, cur
    return cur



class _Level:
    """One level: its operator (g, and s, None on the finest level where it is zero), the
    members of its aggregates, and persistent work arrays (no allocation per cycle)."""

    __slots__ = ("g", "s", "member", "coarse_shape", "x", "tmp", "b")

    def __init__(self, g: np.ndarray, s: np.ndarray | None, member: np.ndarray,
                 coarse_shape: tuple[int, int, int], dtype: np.dtype, finest: bool) -> None:
        self.g = np.ascontiguousarray(g, dtype=dtype)
        self.s = None if s is None else np.ascontiguousarray(s, dtype=dtype)
        self.member = member
        self.coarse_shape = coarse_shape
        shape = g.shape[1:]
        self.x = np.empty(shape, dtype=dtype)
        self.tmp = np.empty(shape, dtype=dtype)
        # the finest level's right-hand side is the caller's residual
        self.b = np.empty(0 if finest else shape, dtype=dtype)


def _dense_operator(g: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The dense matrix of ``L_g + diag(s)`` (small grids only)."""
    shape = g.shape[1:]
    n = math.prod(shape)
    idx = np.arange(n).reshape(shape)
    a = np.diag(s.ravel().astype(np.float64))
    for d in range(3):
        p = idx.ravel()
        q = np.roll(idx, -1, axis=d).ravel()
        w = g[d].ravel()
        np.add.at(a, (p, p), w)
        np.add.at(a, (q, q), w)
        np.add.at(a, (p, q), -w)
        np.add.at(a, (q, p), -w)
    return a


class AggregationMultigrid:
    """Multigrid preconditioner ``z ~ A^+ r`` of the face conductances ``g``.

    Parameters
    ----------
    g : ndarray, shape (3, n1, n2, n3)
        Face conductances, W/(m^2 K) (zero on insulating faces).
    groups : int ndarray, shape (n1, n2, n3), optional
        Particle id of every cell (0 = matrix); aggregates do not cross groups. Without,
        plain 2 x 2 x 2 boxes.
    sweeps : int
        Jacobi sweeps before and after each coarse correction.
    omega : float
        Jacobi weight, in (0, 1].
    over_correction : float
        Factor of the coarse correction, in [1, 2).
    coarsest : int
        Largest number of cells solved exactly (dense pseudo-inverse).
    cycle : {"V", "W"}
        One coarse correction per level (V), or two (W: the second on the residual of the
        first; 1.33x the V-cycle's work in 3-D).
    dtype : numpy float dtype
        Precision of the hierarchy and the cycle (float32 halves its memory traffic; it is
        a preconditioner, CG keeps its own precision).
    theta : float
        A face between groups is strong (its cells may share an aggregate) when its
        conductance is at least ``theta`` times the smaller bulk conductance of its two
        cells (:func:`itr_fft._mg_kernels.memberships`).
    """

    def __init__(self, g: np.ndarray, groups: np.ndarray | None = None, *, sweeps: int = 2,
                 omega: float = 0.8, over_correction: float = 1.6, coarsest: int = 600,
                 cycle: str = "V", dtype: type = np.float32, theta: float = 0.5) -> None:
        if sweeps < 1:
            raise ValueError(f"sweeps: expected a positive integer, got {sweeps!r}")
        if not 0.0 < omega <= 1.0:
            raise ValueError(f"omega: expected a Jacobi weight in (0, 1], got {omega!r}")
        if not 1.0 <= over_correction < 2.0:
            raise ValueError("over_correction: expected a factor in [1, 2), got "
                             f"{over_correction!r}")
        if cycle not in ("V", "W"):
            raise ValueError(f"cycle: expected 'V' or 'W', got {cycle!r}")
        shape = tuple(g.shape[1:])
        self.follow_groups = groups is not None
        self.theta = float(theta)
        if groups is None:
            groups = np.zeros(shape, dtype=np.int32)
        elif groups.shape != shape:
            raise ValueError(f"groups: expected shape {shape}, got {groups.shape}")
        self.sweeps = int(sweeps)
        self.omega = float(omega)
        self.over_correction = float(over_correction)
        self.gamma = 1 if cycle == "V" else 2
        self.dtype = np.dtype(dtype)
        self.shape = shape
        self.levels: list[_Level] = []
        gl = np.ascontiguousarray(g, dtype=np.float64)
        sl = np.zeros(shape)
        grp = np.ascontiguousarray(groups, dtype=np.int32)
        while math.prod(gl.shape[1:]) > coarsest and max(gl.shape[1:]) > 1:
            grp_c = MG.coarse_groups(grp)
            member = (MG.memberships(gl, grp, grp_c, MG.bulk_scale(gl, grp), self.theta)
                      if self.follow_groups else np.ones(grp.shape, dtype=np.uint8))
            finest = not self.levels
            self.levels.append(_Level(gl, None if finest else sl, member, grp_c.shape,
                                      self.dtype, finest))
            gl, sl = MG.coarse_operator(gl, sl, member, grp_c.shape)
            grp = grp_c
        self.coarse_shape = tuple(gl.shape[1:])
        self.coarse_inverse = np.linalg.pinv(_dense_operator(gl, sl), hermitian=True)
        self._input = np.empty(0, dtype=self.dtype)  # r in the hierarchy's precision

    @property
    def n_levels(self) -> int:
        """Levels including the coarsest."""
        return len(self.levels) + 1

    def _cycle(self, level: int, b: np.ndarray) -> np.ndarray:
        """M_level b, in one of the level's work arrays (valid until the next cycle)."""
        if level == len(self.levels):
            return (self.coarse_inverse @ b.ravel()).reshape(b.shape).astype(self.dtype)
        lv = self.levels[level]
        g, s, w = lv.g, lv.s, self.omega
        x, tmp = lv.x, lv.tmp
        MG.scaled_copy(g, s, w, b, x)
        for _ in range(self.sweeps - 1):
            MG.jacobi_sweep(g, s, w, b, x, tmp)
            x, tmp = tmp, x
        nxt = self.levels[level + 1] if level + 1 < len(self.levels) else None
        bc = nxt.b if nxt is not None else np.empty(lv.coarse_shape, dtype=self.dtype)
        MG.restrict_residual(g, s, lv.member, b, x, bc)
        ec = self._cycle(level + 1, bc)
        if self.gamma == 2 and nxt is not None:
            ec = ec.copy()  # the second cycle reuses the level's work arrays
            rc = np.empty_like(bc)
            MG.minus_operator(nxt.g, nxt.s, ec, bc, rc)
            ec += self._cycle(level + 1, rc)
        MG.prolong_add(x, ec, lv.member, self.over_correction)
        for _ in range(self.sweeps):
            MG.jacobi_sweep(g, s, w, b, x, tmp)
            x, tmp = tmp, x
        return x

    def apply(self, r: np.ndarray) -> np.ndarray:
        """z = M r, in a work array of the hierarchy's precision that the next call
        overwrites (copy it to keep it)."""
        if r.dtype == self.dtype and r.flags.c_contiguous:
            return self._cycle(0, r)
        if self._input.shape != r.shape:
            self._input = np.empty(r.shape, dtype=self.dtype)
        np.copyto(self._input, r, casting="same_kind")
        return self._cycle(0, self._input)
