"""Fused CUDA kernels (``numba.cuda``) of the 7-point operator and of CG's vector updates.

The array-API backend (:mod:`itr_fft.array_api_backend`) writes the operator and CG's
updates as whole-array expressions, which on a GPU make temporaries (an iteration took
39 ms at 512^3 against 5.7 ms of minimal memory traffic). The kernels here touch every
array once per step:

- :class:`FusedOperator` ``apply(x, out)``: ``out = A x`` with the stencil of
  :func:`itr_fv.discrete.operator.apply_operator`, ``apply_dot`` (also returns ``x . out``,
  which :func:`itr_fv.solvers.krylov.conjugate_gradients` uses when present) and
  ``apply_block`` (three right-hand sides, each conductance read once for the three);
- :class:`FusedOps`, the :class:`itr_fv.solvers.krylov.ArrayOps` of CG with fused
  ``update`` (``x += alpha p; r -= alpha q`` and ``r . r``), ``direction``
  (``p = z + beta p``), ``dot`` and ``residual``.

Arrays are C-contiguous, shape (n1, n2, n3), float64 or float32, on the device (CuPy or any
array with ``__cuda_array_interface__``) on a GPU, or NumPy arrays under numba's CUDA
simulator (``NUMBA_ENABLE_CUDASIM=1`` set before ``numba.cuda`` is first imported), which
runs the same kernels on the CPU for the tests. Every kernel sees the grid flattened to 1-D
(voxel ``t = (i n2 + j) n3 + k``, periodic neighbours ``t +- n2 n3``, ``t +- n3``,
``t +- 1`` wrapped per axis) and loops grid-stride over it. The stencil accumulates in the
array's dtype in the order of :func:`itr_fv.discrete.operator.apply_operator`; reductions
accumulate float64 products per thread, add them by a tree in shared memory per block and
sum the block partials on the host (no atomics: for a given launch shape the result does not
depend on scheduling). On a GPU, NVVM may contract ``a * b + c`` into a fused multiply-add,
so values differ from NumPy's in the last bit at most.

Memory traffic, in arrays of N values read + written (:data:`TRAFFIC`; the stencil's
neighbours and the conductances ``g_d[p - e_d]`` come from the L2 cache when it holds about
five planes of n2 n3 values, i.e. 10 MiB at 512^2 in float64): ``apply`` 5 (g 3, x 1, out 1),
``apply_dot`` 5, ``apply_block`` 9 (g 3, x 3, out 3), ``update`` 6 (read x, r, p, q; write
x, r), ``direction`` 3, ``dot`` 2, ``residual`` 3 after its ``apply``. One CG iteration is
``apply_dot`` + ``update`` + ``dot(r, z)`` + ``direction`` = 16 N besides the
preconditioner (:data:`CG_ITERATION_TRAFFIC`).

Importing this module never needs CUDA; :func:`fused_available` says whether the kernels
can run, and the classes raise ``RuntimeError`` where they cannot.
"""

from __future__ import annotations

import functools
import math
from types import SimpleNamespace
from typing import Any

import numpy as np

from itr_fv.solvers.krylov import ArrayOps

try:  # imports without a GPU; the kernels name it as a global (the simulator swaps it)
    from numba import cuda
except Exception:  # noqa: BLE001 - no numba or a broken install: fused_available() is False
    cuda = None

__all__ = ["FusedOperator", "FusedOps", "fused_available", "THREADS_PER_BLOCK",
           "MAX_THREADS_PER_BLOCK", "MAX_BLOCKS", "TRAFFIC", "CG_ITERATION_TRAFFIC"]

#: Threads per block of every kernel by default (a power of two: the block reduction halves
#: it) and the most a launch may ask for (the size of the reduction's shared array, kept
#: small so that the L1 cache keeps most of the shared/L1 memory of an SM).
THREADS_PER_BLOCK = 128
MAX_THREADS_PER_BLOCK = 256
#: Blocks at most per launch by default (grid-stride loops cover larger grids; 4096 x 128
#: threads fill an H100 twice over).
MAX_BLOCKS = 4096
#: Arrays of N values read + written by each operation (see the module docstring).
TRAFFIC = {"apply": 5, "apply_dot": 5, "apply_block": 9, "update": 6, "direction": 3,
           "dot": 2, "residual": 3}
#: One CG iteration without the preconditioner: apply_dot + update + dot(r, z) + direction.
CG_ITERATION_TRAFFIC = TRAFFIC["apply_dot"] + TRAFFIC["update"] + TRAFFIC["dot"] \
    + TRAFFIC["direction"]

_UNAVAILABLE = ("fused kernels need numba.cuda with a CUDA device, or numba's CUDA simulator "
                "(set NUMBA_ENABLE_CUDASIM=1 before numba.cuda is first imported)")


def fused_available() -> bool:
    """True where ``numba.cuda`` imports and sees a CUDA device or runs the simulator."""
    if cuda is None:
        return False
    try:
        return bool(cuda.is_available())
    except Exception:  # noqa: BLE001 - no driver or a broken toolkit: both mean "no"
        return False


_PROBED: dict[str, str | None] = {}


def fused_failure(xp: Any) -> str | None:
    """None where the fused kernels compile and run here (one operator apply, a dot, an
    update and a direction on a 4^3 grid of ``xp``'s arrays, float64; once per namespace);
    else why not, in one line. A numba whose CUDA target does not build with this NumPy
    (seen: ``numpy.row_stack`` gone) is caught here, before a solve."""
    key = getattr(xp, "__name__", str(xp))
    if key not in _PROBED:
        try:
            if not fused_available():
                raise RuntimeError(_UNAVAILABLE)
            g = xp.ones((3, 4, 4, 4), dtype=xp.float64)
            x = xp.ones((4, 4, 4), dtype=xp.float64)
            out, r, p, q = (xp.zeros((4, 4, 4), dtype=xp.float64) for _ in range(4))
            FusedOperator(g).apply(x, out)
            ops = FusedOps()
            ops.dot(x, x)
            ops.update(out, r, p, q, 0.5)
            ops.direction(p, x, 0.5)
            _PROBED[key] = None
        except Exception as exc:  # noqa: BLE001 - any failure means: do not use them
            _PROBED[key] = " ".join(f"{type(exc).__name__}: {exc}".split())[:300]
    return _PROBED[key]


# --------------------------------------------------------------------------- device code

def _index_functions() -> SimpleNamespace:
    """Device functions: voxel coordinates and periodic neighbours of a flat index."""

    @cuda.jit(device=True)
    def coords(t, n2, n3):
        """(i, j, k) of the flat index t = (i n2 + j) n3 + k."""
        return t // (n2 * n3), (t // n3) % n2, t % n3

    @cuda.jit(device=True)
    def neighbours(t, c, n, s):
        """Flat indices of the periodic neighbours + e and - e of t (coordinate c of n
        along an axis of flat stride s)."""
        up = t + s if c + 1 < n else t - (n - 1) * s
        down = t - s if c > 0 else t + (n - 1) * s
        return up, down

    return SimpleNamespace(coords=coords, neighbours=neighbours)


def _stencil_functions(idx: SimpleNamespace) -> SimpleNamespace:
    """Device functions: ``(A x)_t`` for one field and for three fields at once."""
    coords, neighbours = idx.coords, idx.neighbours

    @cuda.jit(device=True)
    def flows(g, d, x, t, up, down):
        """Axis d's two face flows at t: g_d[t] (x_t - x_up) and g_d[down] (x_down - x_t)."""
        return g[d, t] * (x[t] - x[up]), g[d, down] * (x[down] - x[t])

    @cuda.jit(device=True)
    def stencil_at(g, x, t, n1, n2, n3):
        """(A x)_t in x's dtype, summed term by term in the order of
        :func:`itr_fv.discrete.operator.apply_operator` (+up_0 -down_0 +up_1 ...), so the
        results agree to the last bit where no multiply-add is contracted."""
        i, j, k = coords(t, n2, n3)
        up, down = neighbours(t, i, n1, n2 * n3)
        u, w = flows(g, 0, x, t, up, down)
        acc = u - w
        up, down = neighbours(t, j, n2, n3)
        u, w = flows(g, 1, x, t, up, down)
        acc = (acc + u) - w
        up, down = neighbours(t, k, n3, 1)
        u, w = flows(g, 2, x, t, up, down)
        return (acc + u) - w

    @cuda.jit(device=True)
    def flows3(g, d, x, t, up, down):
        """Axis d's face flows at t for the fields f = 0, 1, 2 of x (shape (3, N)), each
        conductance read once: (up_0, down_0, up_1, down_1, up_2, down_2)."""
        gu = g[d, t]
        gd = g[d, down]
        return (gu * (x[0, t] - x[0, up]), gd * (x[0, down] - x[0, t]),
                gu * (x[1, t] - x[1, up]), gd * (x[1, down] - x[1, t]),
                gu * (x[2, t] - x[2, up]), gd * (x[2, down] - x[2, t]))

    @cuda.jit(device=True)
    def stencil3_at(g, x, t, n1, n2, n3):
        """(A x_f)_t for the three fields, each summed as in :func:`stencil_at`."""
        i, j, k = coords(t, n2, n3)
        up, down = neighbours(t, i, n1, n2 * n3)
        u0, w0, u1, w1, u2, w2 = flows3(g, 0, x, t, up, down)
        a0, a1, a2 = u0 - w0, u1 - w1, u2 - w2
        up, down = neighbours(t, j, n2, n3)
        u0, w0, u1, w1, u2, w2 = flows3(g, 1, x, t, up, down)
        a0, a1, a2 = (a0 + u0) - w0, (a1 + u1) - w1, (a2 + u2) - w2
        up, down = neighbours(t, k, n3, 1)
        u0, w0, u1, w1, u2, w2 = flows3(g, 2, x, t, up, down)
        return (a0 + u0) - w0, (a1 + u1) - w1, (a2 + u2) - w2

    return SimpleNamespace(stencil_at=stencil_at, stencil3_at=stencil3_at)


def _reduction_function() -> Any:
    """Device function: the block's sum of one float64 per thread into ``partial``."""

    @cuda.jit(device=True)
    def block_sum(cache, value, partial):
        """Tree sum in shared memory; thread 0 writes partial[blockIdx.x]."""
        tid = cuda.threadIdx.x
        cache[tid] = value
        cuda.syncthreads()
        half = cuda.blockDim.x // 2
        while half > 0:
            if tid < half:
                cache[tid] += cache[tid + half]
            cuda.syncthreads()
            half //= 2
        if tid == 0:
            partial[cuda.blockIdx.x] = cache[0]

    return block_sum


def _operator_kernels(stencil: SimpleNamespace, block_sum: Any) -> SimpleNamespace:
    """Kernels of the operator (flat arrays: g (3, N), x and out (N,) or (3, N))."""
    from numba import float64
    stencil_at, stencil3_at = stencil.stencil_at, stencil.stencil3_at

    @cuda.jit
    def apply(g, x, out, n1, n2, n3):
        """out = A x. Traffic 5 N: g 3, x 1, out 1 (neighbours from cache)."""
        for t in range(cuda.grid(1), x.size, cuda.gridsize(1)):
            out[t] = stencil_at(g, x, t, n1, n2, n3)

    @cuda.jit
    def apply_dot(g, x, out, n1, n2, n3, partial):
        """out = A x and the block partials of x . out (float64). Traffic 5 N."""
        cache = cuda.shared.array(MAX_THREADS_PER_BLOCK, float64)
        acc = 0.0
        for t in range(cuda.grid(1), x.size, cuda.gridsize(1)):
            v = stencil_at(g, x, t, n1, n2, n3)
            out[t] = v
            acc += float(x[t]) * float(v)
        block_sum(cache, acc, partial)

    @cuda.jit
    def apply_dot3(g, x0, x1, x2, o0, o1, o2, m, n1, n2, n3, part0, part1, part2):
        """o_f = A x_f and the block partials of x_f . o_f for the first m (1 to 3) fields,
        each as :func:`apply_dot` computes it; g comes from the cache for the second and
        third field. Traffic (2 m + 3) N."""
        c0 = cuda.shared.array(MAX_THREADS_PER_BLOCK, float64)
        c1 = cuda.shared.array(MAX_THREADS_PER_BLOCK, float64)
        c2 = cuda.shared.array(MAX_THREADS_PER_BLOCK, float64)
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        for t in range(cuda.grid(1), x0.size, cuda.gridsize(1)):
            v = stencil_at(g, x0, t, n1, n2, n3)
            o0[t] = v
            a0 += float(x0[t]) * float(v)
            if m > 1:
                v = stencil_at(g, x1, t, n1, n2, n3)
                o1[t] = v
                a1 += float(x1[t]) * float(v)
            if m > 2:
                v = stencil_at(g, x2, t, n1, n2, n3)
                o2[t] = v
                a2 += float(x2[t]) * float(v)
        block_sum(c0, a0, part0)
        block_sum(c1, a1, part1)
        block_sum(c2, a2, part2)

    @cuda.jit
    def apply_block(g, x, out, n1, n2, n3):
        """out_f = A x_f, f = 0, 1, 2, g read once for the three. Traffic 9 N."""
        for t in range(cuda.grid(1), x.shape[1], cuda.gridsize(1)):
            out[0, t], out[1, t], out[2, t] = stencil3_at(g, x, t, n1, n2, n3)

    return SimpleNamespace(apply=apply, apply_dot=apply_dot, apply_dot3=apply_dot3,
                           apply_block=apply_block)


def _vector_kernels(block_sum: Any) -> SimpleNamespace:
    """Kernels of CG's vector operations (flat arrays of one dtype, scalars in it)."""
    from numba import float64

    @cuda.jit
    def update(x, r, p, q, alpha, partial):
        """x += alpha p; r -= alpha q; block partials of r . r. Traffic 6 N."""
        cache = cuda.shared.array(MAX_THREADS_PER_BLOCK, float64)
        acc = 0.0
        for t in range(cuda.grid(1), x.size, cuda.gridsize(1)):
            x[t] += alpha * p[t]
            rt = r[t] - alpha * q[t]
            r[t] = rt
            acc += float(rt) * float(rt)
        block_sum(cache, acc, partial)

    @cuda.jit
    def direction(p, z, beta):
        """p = z + beta p. Traffic 3 N."""
        for t in range(cuda.grid(1), p.size, cuda.gridsize(1)):
            p[t] = z[t] + beta * p[t]

    @cuda.jit
    def dot(a, b, partial):
        """Block partials of a . b (float64 products). Traffic 2 N."""
        cache = cuda.shared.array(MAX_THREADS_PER_BLOCK, float64)
        acc = 0.0
        for t in range(cuda.grid(1), a.size, cuda.gridsize(1)):
            acc += float(a[t]) * float(b[t])
        block_sum(cache, acc, partial)

    @cuda.jit
    def subtract_from(b, out, partial):
        """out = b - out; block partials of out . out. Traffic 3 N."""
        cache = cuda.shared.array(MAX_THREADS_PER_BLOCK, float64)
        acc = 0.0
        for t in range(cuda.grid(1), out.size, cuda.gridsize(1)):
            v = b[t] - out[t]
            out[t] = v
            acc += float(v) * float(v)
        block_sum(cache, acc, partial)

    return SimpleNamespace(update=update, direction=direction, dot=dot,
                           subtract_from=subtract_from)


@functools.cache
def _kernels() -> SimpleNamespace:
    """Every kernel, compiled lazily per dtype on first launch (``RuntimeError`` without
    CUDA or the simulator)."""
    if not fused_available():
        raise RuntimeError(_UNAVAILABLE)
    stencil = _stencil_functions(_index_functions())
    block_sum = _reduction_function()
    ops = _operator_kernels(stencil, block_sum)
    vec = _vector_kernels(block_sum)
    return SimpleNamespace(**vars(ops), **vars(vec))


# --------------------------------------------------------------------------- host side

class _Launcher:
    """Grid-stride launches of ``threads_per_block`` threads in at most ``max_blocks``
    blocks, and the float64 sum of a reduction's block partials (one buffer, reused)."""

    def __init__(self, *, threads_per_block: int, max_blocks: int) -> None:
        t = int(threads_per_block)
        if t < 1 or t > MAX_THREADS_PER_BLOCK or t & (t - 1):
            raise ValueError("threads_per_block: a power of two up to "
                             f"{MAX_THREADS_PER_BLOCK} expected, got {threads_per_block}")
        if int(max_blocks) < 1:
            raise ValueError(f"max_blocks: a positive count expected, got {max_blocks}")
        self.threads = t
        self.max_blocks = int(max_blocks)
        self.kernels = _kernels()
        self.partial = cuda.device_array(self.max_blocks, dtype=np.float64)
        self.partials = cuda.device_array((3, self.max_blocks), dtype=np.float64)

    def blocks(self, n: int) -> int:
        """Blocks of a launch over n items."""
        return max(1, min(math.ceil(n / self.threads), self.max_blocks))

    def launch(self, name: str, n: int, *args: Any) -> None:
        """Kernel ``name`` over n items."""
        getattr(self.kernels, name)[self.blocks(n), self.threads](*args)

    def reduce(self, name: str, n: int, *args: Any) -> float:
        """Kernel ``name`` over n items with the partials buffer last; their float64 sum."""
        blocks = self.blocks(n)
        getattr(self.kernels, name)[blocks, self.threads](*args, self.partial)
        return float(np.sum(self.partial[:blocks].copy_to_host()))

    def reduce3(self, name: str, n: int, *args: Any) -> np.ndarray:
        """Kernel ``name`` over n items with three partials buffers last; their three
        float64 sums (each summed as :meth:`reduce` sums one)."""
        blocks = self.blocks(n)
        p = self.partials
        getattr(self.kernels, name)[blocks, self.threads](*args, p[0], p[1], p[2])
        host = p[:, :blocks].copy_to_host()
        return np.array([float(np.sum(host[f])) for f in range(3)])


def _flat(a: Any, name: str, lead: tuple[int, ...] = ()) -> Any:
    """A flat view (shape lead + (N,)) of the C-contiguous array a."""
    if not a.flags["C_CONTIGUOUS"]:
        raise ValueError(f"{name}: a C-contiguous array is needed")
    return a.reshape(lead + (-1,))


def _check_like(a: Any, name: str, shape: tuple[int, ...], dtype: Any) -> None:
    """ValueError unless a has the given shape and dtype."""
    if tuple(a.shape) != shape:
        raise ValueError(f"{name}: shape {shape} expected, got {tuple(a.shape)}")
    if np.dtype(a.dtype) != np.dtype(dtype):
        raise ValueError(f"{name}: dtype {np.dtype(dtype)} expected, got {a.dtype}")


def _device_conductances(g: Any) -> Any:
    """g checked (shape (3, n1, n2, n3), float64 or float32) and on the device."""
    if len(g.shape) != 4 or g.shape[0] != 3:
        raise ValueError(f"g: shape (3, n1, n2, n3) expected, got {tuple(g.shape)}")
    if np.dtype(g.dtype) not in (np.float64, np.float32):
        raise ValueError(f"g: float64 or float32 expected, got {g.dtype}")
    if not fused_available():
        raise RuntimeError(_UNAVAILABLE)
    if hasattr(g, "__cuda_array_interface__"):
        return g
    return cuda.to_device(np.ascontiguousarray(g))


class FusedOperator:
    """``A x`` of the periodic 7-point face-conductance stencil by fused CUDA kernels.

    Parameters
    ----------
    g : array, shape (3, n1, n2, n3), float64 or float32
        Face conductances, W/(m^2 K) (``g[d][p]`` on the face between p and p + e_d). A
        NumPy array is moved to the device once.
    threads_per_block, max_blocks : int
        Launch shape (a power of two up to :data:`MAX_THREADS_PER_BLOCK`; blocks at most,
        grid-stride beyond). Small values speed up the simulator.

    Raises
    ------
    ValueError
        ``g`` of the wrong shape or dtype, or a bad launch shape.
    RuntimeError
        No CUDA device and no simulator (:func:`fused_available`).
    """

    def __init__(self, g: Any, *, threads_per_block: int = THREADS_PER_BLOCK,
                 max_blocks: int = MAX_BLOCKS) -> None:
        self.shape = tuple(int(n) for n in g.shape[1:])
        self.dtype = np.dtype(g.dtype)
        self.g = _flat(_device_conductances(g), "g", (3,))
        self.launcher = _Launcher(threads_per_block=threads_per_block, max_blocks=max_blocks)

    def _fields(self, x: Any, out: Any, lead: tuple[int, ...] = ()) -> tuple[Any, Any]:
        """Flat views of x and out, checked against the grid and g's dtype."""
        _check_like(x, "x", lead + self.shape, self.dtype)
        _check_like(out, "out", lead + self.shape, self.dtype)
        return _flat(x, "x", lead), _flat(out, "out", lead)

    def apply(self, x: Any, out: Any) -> None:
        """``out = A x`` (W/m^2 per K of x); x and out of shape (n1, n2, n3), g's dtype."""
        xf, of = self._fields(x, out)
        self.launcher.launch("apply", xf.size, self.g, xf, of, *self.shape)

    def apply_dot(self, x: Any, out: Any) -> float:
        """``out = A x``; returns ``x . out`` (float64), in one pass."""
        xf, of = self._fields(x, out)
        return self.launcher.reduce("apply_dot", xf.size, self.g, xf, of, *self.shape)

    def apply_dot_block(self, xs: Any, outs: Any) -> list[float]:
        """``outs[f] = A xs[f]`` for up to three fields in one launch (g read once); returns
        the ``xs[f] . outs[f]``, each as :meth:`apply_dot` gives it (more than three fields
        go three at a time)."""
        if len(xs) != len(outs):
            raise ValueError(f"outs: expected {len(xs)} fields, got {len(outs)}")
        dots: list[float] = []
        for start in range(0, len(xs), 3):
            fields = [self._fields(x, o) for x, o in zip(xs[start:start + 3],
                                                      outs[start:start + 3])]
            m = len(fields)
            fields += [fields[-1]] * (3 - m)  # unused slots: never touched (m < 3)
            xf = [f[0] for f in fields]
            of = [f[1] for f in fields]
            sums = self.launcher.reduce3("apply_dot3", xf[0].size, self.g, *xf, *of, m,
                                         *self.shape)
            dots += [float(v) for v in sums[:m]]
        return dots

    def apply_block(self, x: Any, out: Any) -> None:
        """``out[f] = A x[f]`` for f = 0, 1, 2 (shape (3, n1, n2, n3)), g read once."""
        xf, of = self._fields(x, out, (3,))
        self.launcher.launch("apply_block", xf.shape[1], self.g, xf, of, *self.shape)


def _zeros_like(x: Any) -> Any:
    """Zeros of the shape, dtype and library (NumPy or CuPy) of x."""
    if isinstance(x, np.ndarray):
        return np.zeros_like(x)
    if type(x).__module__.split(".")[0] == "cupy":
        import cupy
        return cupy.zeros_like(x)
    raise ValueError(f"x: NumPy or CuPy array expected, got {type(x).__name__}")


def _same_size(a: Any, b: Any, name: str) -> None:
    if a.size != b.size:
        raise ValueError(f"{name}: {a.size} values expected, got {b.size}")


class FusedOps(ArrayOps):
    """CG's vector operations by fused CUDA kernels (reductions in float64).

    The contract of :class:`itr_fv.solvers.krylov.ArrayOps` and
    :class:`itr_fft.array_api_backend.ArrayAPIOps`, for C-contiguous CuPy arrays on a GPU
    or NumPy arrays under the simulator; ``alpha``/``beta`` are rounded to the vectors'
    dtype first, as the array expressions do.

    Parameters
    ----------
    threads_per_block, max_blocks : int
        Launch shape, as for :class:`FusedOperator`.

    Raises
    ------
    RuntimeError
        No CUDA device and no simulator (:func:`fused_available`).
    """

    def __init__(self, *, threads_per_block: int = THREADS_PER_BLOCK,
                 max_blocks: int = MAX_BLOCKS) -> None:
        self.launcher = _Launcher(threads_per_block=threads_per_block, max_blocks=max_blocks)

    def dot(self, a: Any, b: Any) -> float:
        """``a . b`` in float64, in one pass."""
        af, bf = _flat(a, "a"), _flat(b, "b")
        _same_size(af, bf, "b")
        return self.launcher.reduce("dot", af.size, af, bf)

    def update(self, x: Any, r: Any, p: Any, q: Any, alpha: float) -> float:
        """``x += alpha p``, ``r -= alpha q`` in one pass; returns ``r . r``."""
        xf, rf, pf, qf = _flat(x, "x"), _flat(r, "r"), _flat(p, "p"), _flat(q, "q")
        for v, name in ((rf, "r"), (pf, "p"), (qf, "q")):
            _same_size(xf, v, name)
        a = np.dtype(x.dtype).type(alpha)
        return self.launcher.reduce("update", xf.size, xf, rf, pf, qf, a)

    def direction(self, p: Any, z: Any, beta: float) -> None:
        """``p = z + beta p`` in place, in one pass."""
        pf, zf = _flat(p, "p"), _flat(z, "z")
        _same_size(pf, zf, "z")
        self.launcher.launch("direction", pf.size, pf, zf, np.dtype(p.dtype).type(beta))

    def residual(self, operator: Any, b: Any, x: Any, out: Any) -> float:
        """``out = b - A x``; returns ``||out||^2`` (the subtraction and norm in one pass)."""
        operator.apply(x, out)
        bf, of = _flat(b, "b"), _flat(out, "out")
        _same_size(of, bf, "b")
        return self.launcher.reduce("subtract_from", of.size, bf, of)

    def scale(self, x: Any, c: float) -> None:
        """``x *= c`` in place."""
        x *= np.dtype(x.dtype).type(c)

    def is_zero(self, x: Any) -> bool:
        return not bool(x.any())

    def like(self, z: Any, x: Any) -> Any:
        """``z`` in the precision of ``x`` (itself when it already is)."""
        return z if z.dtype == x.dtype else z.astype(x.dtype)

    def empty_like(self, x: Any) -> Any:
        """A zeroed work vector of the shape, precision and library of ``x``."""
        return _zeros_like(x)
