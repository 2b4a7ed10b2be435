"""The backend ``"itr_fft"``: FFT-preconditioned CG on the discrete model of
:mod:`itr_fv.discrete.model`
with fused numba kernels (the CG itself is :func:`itr_fv.solvers.krylov.conjugate_gradients`).

The operator is exactly the one ``itr_fv`` assembles (same face conductances, imported from
``itr_fv.discrete.model``), applied matrix-free by a fused numba stencil kernel. The preconditioner
is the exact inverse of the constant-coefficient periodic 7-point operator with face
conductance ``g_ref`` (W/(m^2 K)), i.e. of ``k_ref / h^2 * sum_d 4 sin^2(pi xi_d / n_d)``
times the voxel volume per face area h with ``k_ref = g_ref h``, zero mode removed, applied
with real FFTs (``scipy.fft.rfftn`` / ``irfftn``).

Choice of ``g_ref``: preconditioned CG is invariant under a constant rescaling of the
preconditioner (z -> z / c rescales alpha by c and leaves beta, the iterates and the
residuals unchanged), so ``g_ref`` does not change the iteration count; it only sets the
units/magnitude of the preconditioned residual. The default is the geometric mean of the
positive face conductances (measured: min / geometric / arithmetic / max give the same
iteration counts, see ``validation/results/bench_solvers.md``). The iteration count is
governed by the spread of the face conductances, roughly ``sqrt(max g / min g)`` for the
worst case, and by the interface resistance relative to the voxel: a resistive interface
of ``R >> h / k_m`` adds small eigenvalues ~ ``h / (R k)`` that grow the count under grid
refinement.

Memory: the float64 conductances (3 N), the load vector (N), the CG vectors x, r, p, q
(4 N), and per iteration the rfftn half spectrum (~N) and the irfftn output z (N), where
N = n1 n2 n3. Measured peak 89-106 bytes per voxel (64^3 to 192^3, float64 and float32
vectors: the float64 set-up sets the peak; ``validation/results/memory.md``).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Sequence
from typing import Any

import numba
import numpy as np

from itr_fv.discrete.problem import DiscreteSystem
from itr_fv.solvers.backends import Backend, LoadCaseSolution, PreparedSystem, register_backend
from itr_fv.solvers.krylov import ArrayOps, block_conjugate_gradients, conjugate_gradients

from . import _kernels as K
from . import _mg_kernels as MG
from .deflation import ParticleDeflation
from .fft_pair import FFTS, fft_pair, fftw_available
from .multigrid import MG_BYTES_PER_VOXEL, AggregationMultigrid, coupled_groups
from .spectral import laplacian_symbol, reference_conductance

__all__ = ["NumbaFFTBackend", "reference_conductance", "FLOAT32_MIN_TOL", "float32_min_tol",
           "PRECISIONS", "MIXED_MIN_TOL", "REPLACE_BELOW",
           "choose_preconditioner", "AUTO_CONTRAST", "PRECONDITIONERS",
           "FFT_BYTES_PER_VOXEL"]

#: Measured peak bytes per voxel, float64 or float32 vectors (module docstring), rounded up.
FFT_BYTES_PER_VOXEL = 120

#: Smallest relative residual accepted with ``dtype=np.float32``: the rounding of a float32
#: theta alone leaves a relative residual of a few 1e-7 (it grows with the grid size).
FLOAT32_MIN_TOL = 1e-6


def float32_min_tol(shape: Sequence[int]) -> float:
    """Smallest tol accepted with float32 vectors on a grid of this shape.

    The rounding of a float32 theta leaves a residual floor that grows like n^2 (the
    operator amplifies the rounding noise of neighbouring voxels): measured on the dense
    60 % Al2O3 RVE, CG stalls at 9e-6 on 256^3. The floor used, ``max(1e-6, 2.5e-10 n^2)``
    (n the largest grid dimension), keeps a margin of ~2x above the stall.
    """
    return max(FLOAT32_MIN_TOL, 2.5e-10 * float(max(shape)) ** 2)


def check_float32_tol(dtype: np.dtype, shape: Sequence[int], tol: float,
                      factor: float = 1.0) -> None:
    """Raise ValueError when float32 vectors cannot reach ``tol`` on this grid (below
    ``factor * float32_min_tol(shape)``; a backend without float64 accumulation in its
    operator states a factor > 1)."""
    floor = factor * float32_min_tol(shape)
    if dtype == np.float32 and tol < floor:
        raise ValueError(f"tol: {tol:.1e} is below what float32 vectors can reach on "
                         f"this grid ({floor:.1e}); use dtype=numpy.float64")


#: CG precisions of :class:`NumbaFFTBackend` (its ``precision``).
PRECISIONS = ("double", "mixed")

#: Mixed precision: the recursive float32 residual is replaced by the float64 true one
#: whenever it has fallen below this factor times the last true one.
REPLACE_BELOW = 0.1

#: Smallest tol accepted with ``precision="mixed"``: measured at 64^3 on al2o3_60,
#: aln_60, random30_Rinf and fcc_R1e-6 of the common set, mixed precision reached 1e-12 on
#: the float64 residual in the iterations of double precision (at most 2 more) with k
#: within 2e-12 of it (validation/results/bench_limit.md).
MIXED_MIN_TOL = 1e-12

#: Extra bytes per voxel of mixed precision (the float32 copy of the conductances, less
#: the float32 work vectors' saving) and of each load case solved beside the first in a
#: block (its load vector, x, r, p, q), rounded up.
MIXED_BYTES_PER_VOXEL = 12
BLOCK_BYTES_PER_CASE = 48

#: Preconditioners of :class:`NumbaFFTBackend`: the FFT Laplacian inverse, particle
#: deflation around an aggregation-multigrid V-cycle (:mod:`itr_fft.multigrid`,
#: :mod:`itr_fft.deflation`) for high contrast and resistive interfaces, and the choice
#: between them by :func:`choose_preconditioner`.
PRECONDITIONERS = ("auto", "fft", "multigrid")

#: Bulk conductivity contrast from which ``"auto"`` takes the multigrid. Measured at 128^3
#: (validation/results/bench_preconditioners.md): at contrast 167 (Al2O3/silicone) the two
#: cost the same (dense 60 %) or the FFT wins (30 % spheres); at ~1100 (AlN/silicone, the
#: hybrids) the multigrid needs 5x fewer iterations and 2.6x less time.
AUTO_CONTRAST = 500.0


def choose_preconditioner(system: DiscreteSystem) -> str:
    """``"multigrid"`` where the bulk conductivity contrast (largest over smallest
    conductance of a face inside a particle or inside the matrix) reaches
    :data:`AUTO_CONTRAST` and the particles are known, else ``"fft"``."""
    ids = system.particle_ids
    if ids is None or not ids.any():
        return "fft"
    lo, hi = MG.bulk_range(system.g, np.ascontiguousarray(ids, dtype=np.int32))
    return "multigrid" if np.isfinite(lo) and hi >= AUTO_CONTRAST * lo else "fft"


#: Grids with fewer voxels than this run single-threaded by default: on 2 cores a 48^3
#: gap-model solve (3 load cases) took 0.44 s on one thread and 0.51 s on two, a 64^3 one
#: 1.05 s and 0.86 s (2026-11-29): the threads' start and join per kernel outweigh the
#: split below about 56^3.
SERIAL_BELOW = 56 ** 3


class _Preconditioner:
    """z = P (g_ref L)^+ P r with real FFTs; P removes cluster means when there are several."""

    def __init__(self, shape: tuple[int, int, int], g_ref: float, workers: int,
                 labels_flat: np.ndarray | None, counts: np.ndarray | None,
                 fft_dtype: np.dtype, fft: str = "scipy") -> None:
        self.shape = shape
        self.fft_dtype = fft_dtype
        self.pair = fft_pair(fft, shape, fft_dtype, workers)
        self.s = [laplacian_symbol(n) for n in shape]
        self.inv_gref = 1.0 / g_ref
        self.workers = workers
        self.labels_flat = labels_flat
        self.counts = counts

    def apply_dot(self, r: np.ndarray) -> tuple[np.ndarray, float]:
        """z and r . z (the latter from the spectrum, fused with the division)."""
        r_in = r if r.dtype == self.fft_dtype else r.astype(self.fft_dtype)
        rhat = self.pair.forward(r_in)
        del r_in
        rz = K.spectral_solve(rhat, self.s[0], self.s[1], self.s[2], self.shape[2],
                              self.inv_gref)
        z = self.pair.inverse(rhat)
        del rhat
        if self.labels_flat is not None:
            K.project_clusters(z, self.labels_flat, self.counts)
        return z, rz

    def apply(self, r: np.ndarray) -> np.ndarray:
        return self.apply_dot(r)[0]


class _MultigridPreconditioner:
    """Particle deflation around an aggregation-multigrid V-cycle, then cluster means out."""

    def __init__(self, system: DiscreteSystem, labels_flat: np.ndarray | None,
                 counts: np.ndarray | None) -> None:
        ids = coupled_groups(system.g, system.particle_ids)
        self.multigrid = AggregationMultigrid(system.g, ids)
        self.deflation = (ParticleDeflation(system.g, ids, self.multigrid)
                          if ids is not None and ids.any() else None)
        self.labels_flat = labels_flat
        self.counts = counts

    def apply_dot(self, r: np.ndarray) -> tuple[np.ndarray, float]:
        if self.deflation is not None:
            z, rz = self.deflation.apply_dot(r)
        else:
            z = self.multigrid.apply(r).astype(np.float64)
            rz = K.dot(np.ascontiguousarray(r, dtype=np.float64), z)
        if self.labels_flat is not None:
            K.project_clusters(z, self.labels_flat, self.counts)
            # r . z again: r's cluster sums are round-off, not zero, and z's cluster
            # constants before the projection were large
            rz = K.dot(np.ascontiguousarray(r, dtype=np.float64), z)
        return z, rz

    def apply(self, r: np.ndarray) -> np.ndarray:
        return self.apply_dot(r)[0]


class _StencilOperator:
    """The 7-point operator of the face conductances g, matrix-free (fused numba stencil);
    several fields at once with g read once (``apply_dot_block``)."""

    def __init__(self, g: np.ndarray) -> None:
        self.g = g

    def apply(self, x: np.ndarray, out: np.ndarray) -> None:
        K.matvec_dot(self.g, x, out)

    def apply_dot(self, x: np.ndarray, out: np.ndarray) -> float:
        return K.matvec_dot(self.g, x, out)

    def apply_dot_block(self, xs: Sequence[np.ndarray], outs: Sequence[np.ndarray]
                        ) -> np.ndarray:
        """``outs[c] = A xs[c]`` for every c in one pass over g; returns the xs[c] . outs[c]."""
        return K.matvec_dot_block(self.g, tuple(xs), tuple(outs))


class _FusedOps(ArrayOps):
    """CG's vector operations as parallel numba kernels (reductions in float64)."""

    def dot(self, a: np.ndarray, b: np.ndarray) -> float:
        return K.dot(a, b)

    def update(self, x, r, p, q, alpha) -> float:
        return K.cg_update(x, r, p, q, alpha)

    def direction(self, p, z, beta) -> None:
        K.direction_update(p, z, beta)

    def residual(self, operator, b, x, out) -> float:
        """out = b - A x formed in float64 (then stored in out's precision); returns its
        float64 squared norm."""
        return K.residual_into(operator.g, x, b, out)

    def copy_into(self, dst, src) -> None:
        np.copyto(dst, src, casting="same_kind")


class _MixedOps(_FusedOps):
    """The same operations with float32 work vectors r, p, q (x stays float64)."""

    def empty_like(self, x: np.ndarray) -> np.ndarray:
        return np.empty(x.shape, dtype=np.float32)


_OPS = _FusedOps()
_MIXED_OPS = _MixedOps()


class _PreparedFFT(PreparedSystem):
    def __init__(self, system: DiscreteSystem, voxel_m: float,
                 backend: NumbaFFTBackend) -> None:
        g = system.g
        shape = g.shape[1:]
        self.g = g
        self.dtype = backend.dtype
        self.block = backend.block
        self.workers = backend.threads_for(shape)
        self.labels_flat = self.counts = None
        if system.labels is not None:
            self.labels_flat = np.ascontiguousarray(system.labels.ravel(), dtype=np.int32)
            self.counts = np.bincount(self.labels_flat).astype(np.float64)
        g_ref = reference_conductance(g, backend.reference)
        fdt = backend.dtype if backend.dtype == np.float32 else backend.fft_dtype
        self.mixed = backend.precision == "mixed"
        if self.mixed:  # CG iterates on float32 copies; x and the true residual in float64
            self.operator = _StencilOperator(np.ascontiguousarray(g, dtype=np.float32))
            self.true_operator, self.ops = _StencilOperator(g), _MIXED_OPS
        else:
            self.operator = _StencilOperator(g)
            self.true_operator, self.ops = None, _OPS
        self._old_threads = numba.get_num_threads()
        numba.set_num_threads(self.workers)
        kind = backend.preconditioner
        if kind == "auto":
            kind = choose_preconditioner(system)
        if kind == "multigrid":
            self.preconditioner = _MultigridPreconditioner(system, self.labels_flat,
                                                           self.counts)
        else:
            self.preconditioner = _Preconditioner(shape, g_ref, self.workers,
                                                  self.labels_flat, self.counts, fdt,
                                                  backend.fft)
        self.info = {"g_ref": g_ref, "k_ref": g_ref * voxel_m, "dtype": self.dtype.name,
                     "fft_dtype": fdt.name, "fft": backend.fft, "workers": self.workers,
                     "preconditioner": kind, "precision": backend.precision,
                     "block": self.block}
        if kind == "multigrid":
            pre = self.preconditioner
            self.info["levels"] = pre.multigrid.n_levels
            self.info["deflated_groups"] = (0 if pre.deflation is None
                                            else pre.deflation.n_groups)

    def _project(self, v: np.ndarray) -> None:
        K.project_clusters(v, self.labels_flat, self.counts)

    def _start(self, b: np.ndarray, x0: np.ndarray | None) -> np.ndarray:
        return np.zeros(b.shape, dtype=self.dtype) if x0 is None else \
            np.array(x0, dtype=self.dtype, copy=True)

    def solve_block(self, loads, starts, tol, maxiter, callback=None
                    ) -> list[LoadCaseSolution]:
        xs = [self._start(b, x0) for b, x0 in zip(loads, starts)]
        options = dict(tol=tol, maxiter=maxiter, preconditioner=self.preconditioner,
                       ops=self.ops,
                       project=None if self.labels_flat is None else self._project,
                       true_operator=self.true_operator,
                       replace_below=REPLACE_BELOW if self.mixed else None)
        if self.block:
            outs = block_conjugate_gradients(self.operator, loads, xs, callback=callback,
                                             **options)
            seconds = [None] * len(xs)
        else:
            outs, seconds = [], []
            for c, (b, x) in enumerate(zip(loads, xs)):
                step = None if callback is None else \
                    (lambda it, res, _c=c: callback(_c, it, res))
                t = time.perf_counter()
                outs.append(conjugate_gradients(self.operator, b, x, callback=step, **options))
                seconds.append(time.perf_counter() - t)
        return [LoadCaseSolution(x if self.dtype == np.float64 else x.astype(np.float64),
                                 out.iterations, out.history, out.residual, out.restarts,
                                 out.replacements, s)
                for x, out, s in zip(xs, outs, seconds)]

    def solve(self, b, x0, tol, maxiter, callback=None) -> LoadCaseSolution:
        step = None if callback is None else (lambda _c, it, res: callback(it, res))
        return self.solve_block([b], [x0], tol, maxiter, step)[0]

    def close(self) -> None:
        numba.set_num_threads(self._old_threads)


def float_dtype(value: Any, name: str) -> np.dtype:
    """``value`` as numpy.float64 or numpy.float32; ValueError naming ``name`` otherwise."""
    try:
        dt = np.dtype(value)
    except TypeError:
        dt = None
    if dt not in (np.dtype(np.float64), np.dtype(np.float32)):
        raise ValueError(f"{name}: expected numpy.float64 or numpy.float32, got {value!r}")
    return dt


@register_backend
class NumbaFFTBackend(Backend):
    """FFT-preconditioned CG with fused numba kernels (the fast CPU backend).

    Parameters
    ----------
    dtype : np.float64 or np.float32
        Storage precision of the CG vectors and FFTs (reductions, conductances and the
        final residual stay float64). float32 halves vector memory and FFT time and needs
        ``tol >= float32_min_tol(shape)`` (1e-6 up to 63^3, growing like n^2); at
        tol = 3e-6 k_eff agrees with float64 to ~3e-7 of max |K| (diagonal ~3e-8;
        off-diagonals are first order in the residual).
    workers : int, optional
        Threads for the FFTs and the numba kernels (default: 1 below 40^3 voxels, else
        all threads numba may use).
    reference : str or float
        Reference face conductance of the preconditioner (see
        :func:`reference_conductance`); does not change the iteration count.
    fft_dtype : np.float32 or np.float64
        Precision of the preconditioner's FFTs only. The preconditioner is an approximation
        of A^-1 anyway: applying the exact Laplacian inverse in float32 leaves the CG
        vectors, the operator, the residual check and hence the converged answer in
        ``dtype``, gives the same iteration counts (measured to tol = 1e-10) and costs
        2.6x less FFT time at 128^3. Use float64 to apply it to double precision.
    preconditioner : {"auto", "fft", "multigrid"}
        ``"auto"`` (default): :func:`choose_preconditioner` picks one per system, by the
        bulk conductivity contrast. ``"fft"``: the exact inverse of the constant-coefficient
        Laplacian (one FFT pair per iteration; its iterations grow with the conductivity
        contrast and with resistive interfaces under refinement). ``"multigrid"``: particle
        deflation (:mod:`itr_fft.deflation`) around an aggregation-multigrid V-cycle whose
        aggregates stop at resistive interfaces (:mod:`itr_fft.multigrid`), in float32;
        measured in
        ``validation/results/bench_preconditioners.md``.
    precision : {"double", "mixed"}
        ``"double"`` (default): CG in ``dtype``. ``"mixed"``: CG iterates on a float32 copy
        of the conductances with float32 work vectors r, p, q (reductions in float64), x
        stays float64, and the float64 true residual replaces the recursive one whenever
        that has fallen tenfold (reliable updates), so ``tol`` holds on the float64
        residual as in ``"double"``; needs ``dtype=np.float64`` and ``tol >=``
        :data:`MIXED_MIN_TOL`. Measured against ``"double"`` in
        ``validation/results/bench_limit.md``.
    fft : {"scipy", "fftw"}
        The FFT preconditioner's FFT pair (:mod:`itr_fft.fft_pair`): SciPy's (default) or
        FFTW's through pyFFTW, the optional extra ``pip install 'itr-composites[fft]'``
        (FFTW is GPL-2.0-or-later; measured against SciPy's in
        ``validation/results/bench_default_solve.md``). The same iterations; the tensor
        within round-off of SciPy's.
    block : bool
        Solve the load cases of one call together: one CG per load case in lockstep, each
        conductance read once per iteration for all of them (the same iterates as one at a
        time), at 96 more bytes per voxel for three load cases. Default False (one after
        the other): on 2 cores the block measured 0.94-1.05x the time of single solves
        (validation/results/bench_limit.md), the stencil kernel being bound by its
        arithmetic there, not by memory traffic.
    """

    name = "itr_fft"
    default_maxiter = 3000

    def __init__(self, dtype: Any = np.float64, workers: int | None = None,
                 reference: str | float = "geometric", fft_dtype: Any = np.float32,
                 preconditioner: str = "auto", precision: str = "double",
                 block: bool = False, fft: str = "scipy") -> None:
        if preconditioner not in PRECONDITIONERS:
            raise ValueError(f"preconditioner: expected one of {PRECONDITIONERS}, got "
                             f"{preconditioner!r}")
        self.preconditioner = preconditioner
        self.dtype = float_dtype(dtype, "dtype")
        if precision not in PRECISIONS:
            raise ValueError(f"precision: expected one of {PRECISIONS}, got {precision!r}")
        if precision == "mixed" and self.dtype != np.float64:
            raise ValueError("precision: 'mixed' keeps theta in float64 and iterates in "
                             "float32; use dtype=numpy.float64 with it")
        self.precision = precision
        if not isinstance(block, (bool, np.bool_)):
            raise ValueError(f"block: expected True or False, got {block!r}")
        self.block = bool(block)
        self.fft_dtype = float_dtype(fft_dtype, "fft_dtype")
        if fft not in FFTS:
            raise ValueError(f"fft: expected one of {FFTS}, got {fft!r}")
        if fft == "fftw" and not fftw_available():
            raise ValueError("fft: 'fftw' needs pyFFTW (pip install 'itr-composites[fft]'); "
                             "use fft='scipy'")
        self.fft = fft
        if workers is not None and (isinstance(workers, bool) or
                                    not isinstance(workers, (int, np.integer)) or workers < 1):
            raise ValueError(f"workers: expected a positive integer, got {workers!r}")
        self.workers = None if workers is None else int(workers)
        if isinstance(reference, str):
            if reference not in ("geometric", "arithmetic", "harmonic", "min", "max"):
                raise ValueError(f"reference: unknown choice {reference!r} (geometric, "
                                 "arithmetic, harmonic, min, max or a number)")
        else:
            reference_conductance(np.ones((3, 1, 1, 1)), reference)  # checks the number
        self.reference = reference

    def bytes_per_voxel(self) -> int:
        per = FFT_BYTES_PER_VOXEL
        if self.precision == "mixed":
            per += MIXED_BYTES_PER_VOXEL
        if self.block:
            per += 2 * BLOCK_BYTES_PER_CASE
        if self.preconditioner != "fft":  # "auto" may take the multigrid
            per += MG_BYTES_PER_VOXEL
        return per

    def options(self) -> dict[str, Any]:
        opts = {"dtype": self.dtype.name, "workers": self.workers,
                "reference": self.reference, "fft_dtype": self.fft_dtype.name}
        opts["preconditioner"] = self.preconditioner
        opts["precision"] = self.precision
        opts["block"] = self.block
        if self.fft != "scipy":  # the store's keys of every SciPy run stay as they were
            opts["fft"] = self.fft
        return opts

    def check(self, shape: tuple[int, int, int], tol: float) -> None:
        check_float32_tol(self.dtype, shape, tol)
        if self.precision == "mixed" and tol < MIXED_MIN_TOL:
            raise ValueError(f"tol: {tol:.1e} is below what precision='mixed' is measured "
                             f"to reach ({MIXED_MIN_TOL:.0e}); use precision='double'")

    def threads_for(self, shape: Sequence[int]) -> int:
        """Threads used on this grid (threads do not pay below ~40^3 voxels)."""
        workers = self.workers
        if workers is None:
            workers = 1 if math.prod(shape) < SERIAL_BELOW else numba.config.NUMBA_NUM_THREADS
        return int(min(workers, numba.config.NUMBA_NUM_THREADS, os.cpu_count() or 1))

    def prepare(self, system: DiscreteSystem, voxel_m: float) -> PreparedSystem:
        return _PreparedFFT(system, voxel_m, self)
