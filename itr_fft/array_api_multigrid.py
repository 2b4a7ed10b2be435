"""The particle-aware aggregation multigrid and the particle deflation, in array-API code.

The device twins of :class:`itr_fft.multigrid.AggregationMultigrid` and
:class:`itr_fft.deflation.ParticleDeflation`: the same preconditioner ``z = M r``, applied
by functions of the Python array API standard only (``roll``, ``reshape``, ``sum``,
``repeat``, ``where``, ``take``, ``cumulative_sum``, ``matmul``, arithmetic), so NumPy,
CuPy and ``array-api-strict`` run the same lines on arrays that stay on their device.

What happens once per system is done on the host by the numba code and moved to the
device once: the hierarchy (the aggregates' members, the coarse face conductances ``g``
and diagonal excesses ``s`` of every level, the coarsest level's dense pseudo-inverse)
comes from an :class:`~itr_fft.multigrid.AggregationMultigrid` built on the host, the
group operator ``E = Z^T A Z`` of the deflation from
:func:`itr_fft.deflation.group_operator`, factorised by SuperLU on the host. Per
application the deflation moves ``n_groups`` float64 values to the host and back twice
(the two coarse group solves); everything else stays on the device.

One V-cycle per level: ``sweeps`` weighted-Jacobi sweeps (the first from x = 0), the
residual restricted by a masked 2 x 2 x 2 block sum (``reshape`` + ``sum``; an odd axis's
last box is one cell wide, as on the host), the coarse correction, prolonged by
``repeat`` and the member mask and scaled by ``over_correction``, and ``sweeps`` sweeps
again. The 7-point operator with its diagonal excess is :func:`face_stencil` (``roll``),
the one place to swap for a shared array-API stencil.

Device memory per voxel (measured with NumPy and tracemalloc on the 64^3 AlN RVE, four
levels, 199 groups): kept 28 bytes with the float32 hierarchy (finest g 12, its Jacobi
scale 4, member mask 1, coarser levels 2.9, the groups' sort order and ids 8 as int32) when
the CG operator's float64 conductances are shared (``g_device``), 24 more when they are not;
31 bytes with a float64 hierarchy that shares them. One application peaks 56 (float32
hierarchy) or 66 (float64) bytes above that in temporaries (the deflation's float64 work
vectors and the stencil's rolls; a CuPy memory pool keeps that peak). The coarsest level's
pseudo-inverse is at most ``coarsest^2`` float64 values (2.9 MB), whatever the grid.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from itr_fv.discrete.face_classes import to_host
from itr_fv.discrete.operator import apply_operator

from .deflation import group_operator
from .multigrid import AggregationMultigrid, coupled_groups

__all__ = ["ArrayAPIMultigrid", "ArrayAPIDeflation", "ParticleMultigridPreconditioner",
           "face_stencil"]


# ------------------------------------------------------------------ array-API primitives
def face_stencil(xp: Any, g: Any, x: Any, s: Any | None = None) -> Any:
    """``A x`` of the 7-point face operator with a diagonal excess.

    ``A x = sum_d [g_d (x - x_{+d}) - shift_{+d}(g_d (x - x_{+d}))] + s x`` on the periodic
    grid: the package's one array-API stencil
    (:func:`itr_fv.discrete.operator.apply_operator`) plus the excess.

    Parameters
    ----------
    xp : array namespace
    g : array, shape (3, n1, n2, n3)
        Face conductances, W/(m^2 K) (``g[d]`` couples a cell to its neighbour + e_d).
    x : array, shape (n1, n2, n3)
        Field, K.
    s : array, shape (n1, n2, n3), optional
        Diagonal excess, W/(m^2 K) (None: zero).

    Returns
    -------
    array, shape (n1, n2, n3)
        Net outflow per face area, W/m^2, in the precision of ``g`` and ``x``.
    """
    acc = apply_operator(g, x)
    return acc if s is None else acc + s * x


def _to_host(x: Any) -> np.ndarray:
    """A float64 NumPy copy of a small device array (n_groups values)."""
    return np.asarray(to_host(x), dtype=np.float64)


def _float_dtype(xp: Any, dtype: Any, name: str) -> Any:
    """The namespace's float32 or float64 for a NumPy float dtype; ValueError naming ``name``."""
    try:
        dt = np.dtype(dtype)
    except TypeError:
        dt = None
    if dt == np.float64:
        return xp.float64
    if dt == np.float32:
        return xp.float32
    raise ValueError(f"{name}: expected numpy.float64 or numpy.float32, got {dtype!r}")


def _dot64(xp: Any, a: Any, b: Any) -> float:
    """``a . b`` summed in float64."""
    a = xp.astype(a, xp.float64, copy=False)
    b = xp.astype(b, xp.float64, copy=False)
    return float(xp.sum(xp.reshape(a * b, (-1,))))


# ------------------------------------------------------------------ multigrid
class _DeviceLevel:
    """One level on the device: g, s (None on the finest), omega / diagonal, members."""

    __slots__ = ("g", "s", "scale", "member", "shape", "coarse_shape")

    def __init__(self, xp: Any, device: Any, dtype: Any, level: Any, omega: float,
                 g_device: Any | None) -> None:
        g = np.asarray(level.g, dtype=np.float64)
        s = None if level.s is None else np.asarray(level.s, dtype=np.float64)
        diag = sum(g[d] + np.roll(g[d], 1, axis=d) for d in range(3))
        if s is not None:
            diag = diag + s
        scale = np.divide(omega, diag, out=np.zeros_like(diag), where=diag > 0.0)
        self.g = xp.asarray(level.g, dtype=dtype, device=device) if g_device is None \
            else g_device
        self.s = None if s is None else xp.asarray(s, dtype=dtype, device=device)
        self.scale = xp.asarray(scale, dtype=dtype, device=device)
        self.member = xp.asarray(np.asarray(level.member) != 0, device=device)
        self.shape = tuple(g.shape[1:])
        self.coarse_shape = tuple(level.coarse_shape)


class ArrayAPIMultigrid:
    """Aggregation multigrid ``z ~ A^+ r`` of the face conductances, cycled on the device.

    The hierarchy is :class:`itr_fft.multigrid.AggregationMultigrid`'s (built on the host
    with the numba kernels, in ``dtype``, then moved once); :meth:`apply` equals its
    ``apply`` to round-off.

    Parameters
    ----------
    xp : array namespace
        Array API namespace of the device arrays (NumPy, CuPy, array_api_strict, ...).
    g : ndarray, shape (3, n1, n2, n3)
        Face conductances on the host, W/(m^2 K).
    groups : int ndarray, shape (n1, n2, n3), optional
        Particle id of every cell (0 = matrix); aggregates follow particles. Without,
        plain 2 x 2 x 2 boxes.
    device : optional
        Device of the arrays (the namespace's ``device=`` argument; None: its default).
    dtype : numpy.float32 or numpy.float64
        Precision of the hierarchy and the cycle (it is a preconditioner: float32 halves
        its memory and traffic; CG keeps its own precision).
    g_device : array, optional
        The conductances already on the device in ``dtype`` (e.g. the CG operator's),
        shared by the finest level instead of copied.
    sweeps, omega, over_correction, coarsest, cycle, theta
        As :class:`~itr_fft.multigrid.AggregationMultigrid` (Jacobi sweeps, Jacobi
        weight, coarse-correction factor, cells solved exactly, "V" or "W", strong-face
        threshold).
    """

    def __init__(self, xp: Any, g: np.ndarray, groups: np.ndarray | None = None, *,
                 device: Any = None, dtype: Any = np.float32, g_device: Any | None = None,
                 sweeps: int = 2, omega: float = 0.8, over_correction: float = 1.6,
                 coarsest: int = 600, cycle: str = "V", theta: float = 0.5) -> None:
        self.xp = xp
        self.dtype = _float_dtype(xp, dtype, "dtype")
        host = AggregationMultigrid(np.asarray(g), groups, sweeps=sweeps, omega=omega,
                                    over_correction=over_correction, coarsest=coarsest,
                                    cycle=cycle, dtype=np.dtype(dtype), theta=theta)
        if g_device is not None and (tuple(g_device.shape) != (3, *host.shape)
                                     or g_device.dtype != self.dtype):
            raise ValueError(f"g_device: expected shape {(3, *host.shape)} in {dtype!r}")
        self.shape = host.shape
        self.sweeps = host.sweeps
        self.over_correction = host.over_correction
        self.gamma = host.gamma
        self.levels = [_DeviceLevel(xp, device, self.dtype, lv, host.omega,
                                    g_device if i == 0 else None)
                       for i, lv in enumerate(host.levels)]
        self.coarse_shape = host.coarse_shape
        self.coarse_inverse = xp.asarray(np.asarray(host.coarse_inverse, dtype=np.float64),
                                         device=device)
        self._zero = xp.asarray(0.0, dtype=self.dtype, device=device)

    @property
    def n_levels(self) -> int:
        """Levels including the coarsest."""
        return len(self.levels) + 1

    def _smooth(self, lv: _DeviceLevel, b: Any, x: Any) -> Any:
        """``sweeps`` weighted-Jacobi sweeps from x: x + omega D^-1 (b - A x)."""
        for _ in range(self.sweeps):
            x = x + lv.scale * (b - face_stencil(self.xp, lv.g, x, lv.s))
        return x

    def _restrict(self, lv: _DeviceLevel, v: Any) -> Any:
        """P^T v: the sum of v over every aggregate's members (masked 2x2x2 block sums; an
        odd axis gets a zero slab so that its last box is one cell wide)."""
        xp = self.xp
        v = xp.where(lv.member, v, self._zero)
        for axis, n in enumerate(lv.shape):
            if n % 2:
                pad = list(v.shape)
                pad[axis] = 1
                v = xp.concat([v, xp.zeros(tuple(pad), dtype=v.dtype, device=v.device)],
                              axis=axis)
        c1, c2, c3 = lv.coarse_shape
        blocks = xp.reshape(v, (c1, 2, c2, 2, c3, 2))
        return xp.astype(xp.sum(blocks, axis=(1, 3, 5), dtype=xp.float64), self.dtype)

    def _prolong(self, lv: _DeviceLevel, e: Any) -> Any:
        """P e: every coarse value on its aggregate's members, 0 on the other cells."""
        xp = self.xp
        for axis in range(3):
            e = xp.repeat(e, 2, axis=axis)
        n1, n2, n3 = lv.shape
        return xp.where(lv.member, e[:n1, :n2, :n3], self._zero)

    def _coarsest(self, b: Any) -> Any:
        """The coarsest level exactly: its dense pseudo-inverse times b (float64)."""
        xp = self.xp
        flat = xp.astype(xp.reshape(b, (-1,)), xp.float64, copy=False)
        return xp.astype(xp.reshape(self.coarse_inverse @ flat, b.shape), self.dtype)

    def _cycle(self, level: int, b: Any) -> Any:
        """M_level b (a V- or W-cycle from this level down)."""
        if level == len(self.levels):
            return self._coarsest(b)
        xp = self.xp
        lv = self.levels[level]
        x = lv.scale * b  # the first sweep, from x = 0
        for _ in range(self.sweeps - 1):
            x = x + lv.scale * (b - face_stencil(xp, lv.g, x, lv.s))
        bc = self._restrict(lv, b - face_stencil(xp, lv.g, x, lv.s))
        ec = self._cycle(level + 1, bc)
        if self.gamma == 2 and level + 1 < len(self.levels):
            nxt = self.levels[level + 1]
            ec = ec + self._cycle(level + 1, bc - face_stencil(xp, nxt.g, ec, nxt.s))
        x = x + self.over_correction * self._prolong(lv, ec)
        return self._smooth(lv, b, x)

    def apply(self, r: Any) -> Any:
        """z = M r, in the hierarchy's precision (a new array).

        Parameters
        ----------
        r : array, shape (n1, n2, n3)
            Residual on the device, W/m^2.
        """
        if tuple(r.shape) != tuple(self.shape):
            raise ValueError(f"r: expected shape {self.shape}, got {tuple(r.shape)}")
        if r.dtype != self.dtype:
            r = self.xp.astype(r, self.dtype)
        return self._cycle(0, r)


# ------------------------------------------------------------------ particle deflation
class _GroupSolve:
    """E^+ of the group operator on the host: SuperLU of E + shift I, constant removed
    (the shift and the weights of :class:`itr_fft.deflation.ParticleDeflation`)."""

    def __init__(self, g: np.ndarray, groups: np.ndarray, n_groups: int) -> None:
        e = group_operator(g, groups, n_groups)
        diag = e.diagonal()
        shift = 1e-9 * float(diag.mean()) if diag.any() else 1.0
        self._lu = spla.splu((e + shift * sp.identity(n_groups, format="csc")).tocsc())
        self._weights = np.bincount(groups.ravel(), minlength=n_groups) / groups.size

    def __call__(self, sums: np.ndarray) -> np.ndarray:
        c = self._lu.solve(sums)
        c -= float(self._weights @ c)
        return c


class _SegmentSums:
    """Z^T v on the device: float64 sums of v over every group, as differences of one
    running sum over the cells sorted by group (``take`` + ``cumulative_sum``)."""

    def __init__(self, xp: Any, device: Any, groups: np.ndarray, n_groups: int) -> None:
        flat = groups.ravel()
        index = np.int32 if flat.size < 2**31 else np.int64
        counts = np.bincount(flat, minlength=n_groups)
        bounds = np.concatenate([[0], np.cumsum(counts)])
        self.xp = xp
        self.order = xp.asarray(np.argsort(flat, kind="stable").astype(index), device=device)
        self.bounds = xp.asarray(bounds.astype(np.int64), device=device)
        self.ids = xp.asarray(flat.astype(index), device=device)

    def sums(self, v: Any) -> Any:
        """Group sums of v (float64, on the device)."""
        xp = self.xp
        flat = xp.astype(xp.reshape(v, (-1,)), xp.float64, copy=False)
        running = xp.cumulative_sum(xp.take(flat, self.order), include_initial=True)
        at = xp.take(running, self.bounds)
        return at[1:] - at[:-1]

    def expand(self, c: Any, shape: tuple[int, ...]) -> Any:
        """Z c: the group value on every cell."""
        return self.xp.reshape(self.xp.take(c, self.ids), shape)


class ArrayAPIDeflation:
    """Particle deflation around a preconditioner, on the device.

    The balancing combination of :class:`itr_fft.deflation.ParticleDeflation`:
    ``c1 = E^+ Z^T r``, ``r1 = r - A Z c1``, ``y = M r1``, ``c2 = E^+ Z^T (r1 - A y)``,
    ``z = y + Z (c1 + c2)``, with ``E = Z^T A Z`` solved on the host (``n_groups`` values
    each way, twice per application) and the stencils in float64.

    Parameters
    ----------
    xp : array namespace
    g : ndarray, shape (3, n1, n2, n3)
        Face conductances on the host, W/(m^2 K).
    groups : int ndarray, shape (n1, n2, n3)
        Group of every cell (particle ids, 0 = matrix).
    inner : object with ``apply(r)``
        Symmetric positive preconditioner of the same operator on the device (e.g.
        :class:`ArrayAPIMultigrid`).
    device : optional
        Device of the arrays.
    g64 : array, optional
        The float64 conductances already on the device, shared instead of copied.
    """

    def __init__(self, xp: Any, g: np.ndarray, groups: np.ndarray, inner: Any, *,
                 device: Any = None, g64: Any | None = None) -> None:
        g = np.asarray(g)
        if groups is None or tuple(groups.shape) != tuple(g.shape[1:]):
            raise ValueError(f"groups: expected an int array of shape {g.shape[1:]}")
        if g64 is not None and (tuple(g64.shape) != tuple(g.shape) or g64.dtype != xp.float64):
            raise ValueError(f"g64: expected float64 conductances of shape {g.shape}")
        groups = np.ascontiguousarray(groups, dtype=np.int32)
        self.xp = xp
        self.device = device
        self.shape = tuple(g.shape[1:])
        self.n_groups = int(groups.max()) + 1 if groups.size else 1
        self.inner = inner
        self._solve = _GroupSolve(np.ascontiguousarray(g, dtype=np.float64), groups,
                                  self.n_groups)
        self._segments = _SegmentSums(xp, device, groups, self.n_groups)
        self.g = xp.asarray(g, dtype=xp.float64, device=device) if g64 is None else g64

    def _coarse(self, v: Any) -> np.ndarray:
        """E^+ Z^T v on the host (float64, n_groups values)."""
        return self._solve(_to_host(self._segments.sums(v)))

    def _field(self, c: np.ndarray) -> Any:
        """Z c on the device."""
        xp = self.xp
        return self._segments.expand(xp.asarray(c, dtype=xp.float64, device=self.device),
                                     self.shape)

    def apply_dot(self, r: Any) -> tuple[Any, float]:
        """z = M_2 r (float64, a new array) and r . z (float64)."""
        xp = self.xp
        r = xp.astype(r, xp.float64, copy=False)
        c1 = self._coarse(r)
        r1 = r - face_stencil(xp, self.g, self._field(c1))
        y = xp.astype(self.inner.apply(r1), xp.float64, copy=False)
        r2 = r1 - face_stencil(xp, self.g, y)
        z = y + self._field(c1 + self._coarse(r2))
        return z, _dot64(xp, r, z)

    def apply(self, r: Any) -> Any:
        """z = M_2 r (float64, a new array)."""
        return self.apply_dot(r)[0]


# ------------------------------------------------------------------ what a backend uses
class ParticleMultigridPreconditioner:
    """The ``"multigrid"`` preconditioner of the numba backend, on the device.

    Particle deflation around an :class:`ArrayAPIMultigrid` V-cycle where particles are
    known (the V-cycle alone where not), then the cluster projection; ``apply_dot``
    returns ``(z, r . z)`` for :func:`itr_fv.solvers.krylov.conjugate_gradients`.

    Parameters
    ----------
    xp : array namespace
    g : ndarray, shape (3, n1, n2, n3)
        Face conductances on the host, W/(m^2 K) (``DiscreteSystem.g``).
    particle_ids : int ndarray, shape (n1, n2, n3), optional
        Particle of every voxel, 0 = matrix (``DiscreteSystem.particle_ids``); the
        hierarchy and the deflation follow :func:`itr_fft.multigrid.coupled_groups` of
        them, as the numba backend's do.
    device : optional
        Device of the arrays.
    dtype : numpy.float32 or numpy.float64
        Precision of the multigrid hierarchy (the numba backend uses float32).
    g_device : array, optional
        The conductances already on the device (the CG operator's ``g``), float32 or
        float64: shared by the finest level when in ``dtype`` and by the deflation when
        float64, instead of copied.
    project : callable, optional
        Removes the null space from z in place (e.g. the cluster means of
        ``ClusterProjection.project`` when ``DiscreteSystem.labels`` is set).
    **options
        Further keyword arguments of :class:`ArrayAPIMultigrid` (sweeps, omega, ...).
    """

    def __init__(self, xp: Any, g: np.ndarray, particle_ids: np.ndarray | None = None, *,
                 device: Any = None, dtype: Any = np.float32, g_device: Any | None = None,
                 project: Callable[[Any], None] | None = None, **options: Any) -> None:
        mg_dtype = _float_dtype(xp, dtype, "dtype")
        shared = g_device if g_device is not None and g_device.dtype == mg_dtype else None
        g64 = g_device if g_device is not None and g_device.dtype == xp.float64 else None
        self.xp = xp
        particle_ids = coupled_groups(g, particle_ids)  # the numba backend's groups
        self.multigrid = ArrayAPIMultigrid(xp, g, particle_ids, device=device, dtype=dtype,
                                           g_device=shared, **options)
        self.deflation = (ArrayAPIDeflation(xp, g, particle_ids, self.multigrid,
                                            device=device, g64=g64)
                          if particle_ids is not None and np.any(particle_ids) else None)
        self.project = project

    @classmethod
    def from_system(cls, xp: Any, system: Any, *, device: Any = None,
                    dtype: Any = np.float32, g_device: Any | None = None,
                    project: Callable[[Any], None] | None = None
                    ) -> ParticleMultigridPreconditioner:
        """The preconditioner of a :class:`itr_fv.discrete.problem.DiscreteSystem`
        (``system.g`` and ``system.particle_ids``, as the numba backend passes them)."""
        return cls(xp, system.g, system.particle_ids, device=device, dtype=dtype,
                   g_device=g_device, project=project)

    @property
    def info(self) -> dict[str, int]:
        """Levels of the hierarchy and deflated groups (the numba backend's info keys)."""
        return {"levels": self.multigrid.n_levels,
                "deflated_groups": 0 if self.deflation is None else self.deflation.n_groups}

    def apply_dot(self, r: Any) -> tuple[Any, float]:
        """z (float64, a new array) and r . z (float64)."""
        xp = self.xp
        if self.deflation is not None:
            z, rz = self.deflation.apply_dot(r)
        else:
            z = xp.astype(self.multigrid.apply(r), xp.float64, copy=False)
            rz = _dot64(xp, r, z)
        if self.project is not None:
            self.project(z)
            rz = _dot64(xp, r, z)
        return z, rz

    def apply(self, r: Any) -> Any:
        """z (float64, a new array)."""
        return self.apply_dot(r)[0]

