"""The backend ``"array_api"``: the FFT-preconditioned CG written once against the array API.

The operator is :func:`itr_fv.discrete.operator.apply_operator` (the one 7-point
face-conductance stencil in array code) and the cluster projection
:class:`itr_fv.discrete.connectivity.ClusterProjection`; the preconditioner (the exact inverse
of the constant-coefficient periodic Laplacian with face conductance ``g_ref``, symbol from
:mod:`itr_fft.spectral`, applied with real FFTs) uses only ``fft.rfftn``/``irfftn``, ``astype``
and arithmetic; CG is :func:`itr_fv.solvers.krylov.conjugate_gradients` with
:class:`ArrayAPIOps`. So NumPy, CuPy and PyTorch arrays run the same lines, on the CPU or a
GPU; ``array-api-strict`` (the standard's reference implementation) runs them in the tests,
which proves nothing outside the standard is used.

Everything that happens once per system (the reference conductance, the Laplacian symbol,
the cluster ordering) is computed on the host with NumPy and moved to the device; the face
conductances move once. The prepared system keeps its arrays on the device
(:class:`~itr_fv.solvers.backends.PreparedSystem`: ``xp``, ``g``, ``clusters``,
``to_host``): the driver builds every load vector there, the solution stays there, and the
gauge, the mean flux and the energy tensor are computed there; only the 3x3 tensors and the
fields asked for come back.

Memory on the device: the conductances (3 N) and the CG vectors x, r, p, q (4 N) in
``dtype``, the float64 load vector (N, plus its ``dtype`` copy for float32), the half
spectrum (~N complex) in ``fft_dtype``, the operator's temporaries (~3 N) and the float64
solutions of the earlier load cases (kept for the energy tensor).
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from itr_fv.discrete.connectivity import ClusterProjection
from itr_fv.discrete.face_classes import to_host
from itr_fv.discrete.operator import apply_operator
from itr_fv.discrete.problem import DiscreteSystem
from itr_fv.solvers.backends import Backend, LoadCaseSolution, PreparedSystem, register_backend
from itr_fv.solvers.krylov import ArrayOps, block_conjugate_gradients

from .numba_backend import check_float32_tol, float_dtype
from .spectral import inverse_laplacian, reference_conductance

__all__ = ["ArrayAPIBackend", "ArrayAPIOps", "NAMESPACES", "DEVICES", "PRECONDITIONERS",
           "KERNELS", "resolve_device"]

#: The float32 floor of this backend in units of ``float32_min_tol``: its operator sums in
#: float32 (the numba kernels in float64), and CG stalled at 1.09e-6 on the 64^3 dense
#: Al2O3 RVE where the numba floor is 1e-6.
FLOAT32_FLOOR_FACTOR = 4.0

#: Array libraries the backend can run on, and the devices it knows.
NAMESPACES = ("numpy", "array_api_strict", "cupy", "torch")
DEVICES = ("cpu", "cuda", "auto")
#: Preconditioners: the FFT Laplacian inverse, or the particle-deflated aggregation
#: multigrid of :mod:`itr_fft.array_api_multigrid` (high contrast, resistive interfaces).
PRECONDITIONERS = ("fft", "multigrid")
#: The operator and CG updates: whole-array expressions (any namespace), the fused kernels
#: of :mod:`itr_fft.fused_kernels` (numba's CUDA target), or ``"auto"``: fused on a CUDA
#: device with CuPy where numba's CUDA target is usable, else portable.
KERNELS = ("auto", "portable", "fused")


def _cuda_available() -> str | None:
    """The array library that has a usable CUDA device, or None."""
    try:
        import cupy
        if cupy.cuda.runtime.getDeviceCount() > 0:
            return "cupy"
    except Exception:  # noqa: BLE001 - no CuPy, no driver or no device: all mean "none"
        pass
    try:
        import torch
        if torch.cuda.is_available():
            return "torch"
    except Exception:  # noqa: BLE001
        pass
    return None


def resolve_device(device: str = "auto", namespace: str | None = None) -> tuple[str, str]:
    """(device, namespace) that a solve will use.

    Parameters
    ----------
    device : {"cpu", "cuda", "auto"}
        Where to run; ``"auto"`` takes a CUDA device when CuPy (or PyTorch) sees one,
        else the CPU.
    namespace : str, optional
        Array library (:data:`NAMESPACES`); default NumPy on the CPU, CuPy (else PyTorch)
        on CUDA.

    Raises
    ------
    ValueError
        An unknown device or library, or ``device="cuda"`` where no library sees a GPU.
    """
    if device not in DEVICES:
        raise ValueError(f"device: expected one of {DEVICES}, got {device!r}")
    if namespace is not None and namespace not in NAMESPACES:
        raise ValueError(f"namespace: expected one of {NAMESPACES}, got {namespace!r}")
    if device == "auto":
        device = "cuda" if namespace not in ("numpy", "array_api_strict") \
            and _cuda_available() else "cpu"
    if device == "cpu":
        ns = namespace or "numpy"
        if ns == "cupy":
            raise ValueError("namespace: CuPy arrays live on a GPU; use device='cuda'")
        return device, ns
    found = _cuda_available()
    if found is None:
        raise ValueError("device: 'cuda' asked for, but neither CuPy nor PyTorch sees a GPU "
                         "here (install the [gpu] extra on a machine with one)")
    ns = namespace or found
    if ns in ("numpy", "array_api_strict"):
        raise ValueError(f"namespace: {ns} runs on the CPU only; use device='cpu'")
    return device, ns


def _namespace(name: str) -> Any:
    if name == "array_api_strict":
        import array_api_strict
        return array_api_strict
    import array_api_compat
    if name == "numpy":
        import array_api_compat.numpy as xp
    elif name == "cupy":
        import array_api_compat.cupy as xp
    else:
        import array_api_compat.torch as xp
    del array_api_compat
    return xp


def _xp_float(xp: Any, dtype: np.dtype) -> Any:
    """The namespace's float dtype of the same precision as the NumPy ``dtype``."""
    return xp.float64 if dtype == np.float64 else xp.float32


def _device_of(xp: Any, name: str, device: str) -> Any:
    if name == "torch":
        return "cuda" if device == "cuda" else "cpu"
    if name == "cupy":
        import cupy
        return cupy.cuda.Device()
    return None  # the library's default device


#: A host NumPy copy (or view) of an array of any supported library (the package's one
#: conversion, :func:`itr_fv.discrete.face_classes.to_host`).
to_numpy = to_host


class ArrayAPIOps(ArrayOps):
    """CG's vector operations in one array API namespace (reductions in float64)."""

    def __init__(self, xp: Any) -> None:
        self.xp = xp

    def dot(self, a: Any, b: Any) -> float:
        xp = self.xp
        if a.dtype != xp.float64:
            a = xp.astype(a, xp.float64)
            b = xp.astype(b, xp.float64)
        return float(xp.sum(xp.reshape(a * b, (-1,))))

    def update(self, x: Any, r: Any, p: Any, q: Any, alpha: float) -> float:
        x += alpha * p
        r -= alpha * q
        return self.dot(r, r)

    def direction(self, p: Any, z: Any, beta: float) -> None:
        p *= beta
        p += z

    def residual(self, operator: Any, b: Any, x: Any, out: Any) -> float:
        operator.apply(x, out)
        out[...] = b - out
        return self.dot(out, out)

    def scale(self, x: Any, c: float) -> None:
        x *= c

    def is_zero(self, x: Any) -> bool:
        return not bool(self.xp.any(x))

    def like(self, z: Any, x: Any) -> Any:
        return z if z.dtype == x.dtype else self.xp.astype(z, x.dtype)

    def copy_into(self, dst: Any, src: Any) -> None:
        dst[...] = self.like(src, dst)

    def empty_like(self, x: Any) -> Any:
        return self.xp.zeros_like(x)


class _Operator:
    """``out = A x`` by :func:`itr_fv.discrete.operator.apply_operator` (the one stencil)
    on the device conductances ``g`` of namespace ``xp``."""

    def __init__(self, xp: Any, g: Any) -> None:
        self.xp = xp
        self.g = g

    def apply(self, x: Any, out: Any) -> None:
        apply_operator(self.g, x, out)


class _FFTPreconditioner:
    """z = (g_ref L)^+ r by real FFTs in ``fft_dtype``; cluster means removed when there
    are several. With float32 FFTs and float64 vectors, r is rounded to float32 on the
    way in and z comes back in float32 (CG promotes it where it keeps it), as the numba
    backend's ``fft_dtype``."""

    def __init__(self, xp: Any, device: Any, shape: tuple[int, int, int], g_ref: float,
                 fft_dtype: Any, clusters: ClusterProjection | None) -> None:
        inverse = inverse_laplacian(shape, g_ref)
        self.xp = xp
        self.shape = shape
        self.fft_dtype = fft_dtype
        self.inverse = xp.asarray(inverse, dtype=fft_dtype, device=device)
        self.clusters = clusters

    def apply(self, r: Any) -> Any:
        xp = self.xp
        axes = (0, 1, 2)
        r_in = xp.astype(r, self.fft_dtype, copy=False)
        z = xp.fft.irfftn(xp.fft.rfftn(r_in, axes=axes) * self.inverse, s=self.shape,
                          axes=axes)
        if self.clusters is not None:
            self.clusters.project(z)
        return z


#: What the portable kernels cost against the fused ones, measured on one H200 (NumPy 2.5,
#: CuPy 14.2; ../shared/gpu/README.md, 2026-11-28): what the fallback's warning says.
PORTABLE_COST = ("about 2.3x slower per CG iteration (al2o3_60 512^3 on an H200: 27.7 ms "
                 "against 12.1 ms; AlN-60 512^3 wall 20.6 s against 12.9 s)")
#: The fallback reasons already told in this process (the warning is given once per reason).
_TOLD: set[str] = set()


def _use_fused(kernels: str, device: str, namespace: str, xp: Any = None) -> bool:
    """Whether the fused kernels of :mod:`itr_fft.fused_kernels` run this solve: where they
    are asked for, or for ``"auto"`` on a CUDA device with CuPy arrays, and only where they
    compile and run there (:func:`~itr_fft.fused_kernels.fused_failure`); ``"auto"`` then
    takes the portable kernels with a warning, ``"fused"`` is a ValueError saying why."""
    if kernels == "portable":
        return False
    from .fused_kernels import fused_available, fused_failure

    usable = fused_available() and namespace in ("cupy", "numpy")
    if kernels == "fused" and not usable:
        raise ValueError("kernels: 'fused' needs numba's CUDA target with a CUDA device "
                         "and CuPy arrays (or NUMBA_ENABLE_CUDASIM=1 with NumPy arrays); "
                         "use kernels='portable' or 'auto'")
    wanted = usable and (kernels == "fused" or (device == "cuda" and namespace == "cupy"))
    if not wanted or xp is None:
        return wanted
    why = fused_failure(xp)
    if why is None:
        return True
    if kernels == "fused":
        raise ValueError(f"kernels: the fused kernels do not run here ({why}); use "
                         "kernels='portable' or 'auto'")
    if why not in _TOLD:
        _TOLD.add(why)
        warnings.warn(f"the fused kernels do not run here ({why}); kernels='auto' uses the "
                      f"portable kernels, {PORTABLE_COST}", RuntimeWarning, stacklevel=3)
    return False


class _Prepared(PreparedSystem):
    def __init__(self, system: DiscreteSystem, voxel_m: float,
                 backend: ArrayAPIBackend) -> None:
        device, ns = resolve_device(backend.device, backend.namespace)
        xp = _namespace(ns)
        dev = _device_of(xp, ns, device)
        dtype = _xp_float(xp, backend.dtype)
        self.xp, self.dev, self.dtype = xp, dev, dtype
        host = isinstance(system.g, np.ndarray)
        g_ref = reference_conductance(system.g)
        self.g = xp.asarray(system.g, dtype=dtype, device=dev)
        self.clusters = ClusterProjection(system.labels, like=self.g)
        several = self.clusters.n_clusters > 1
        self._project = self.clusters.project if several else None
        fused = _use_fused(backend.kernels, device, ns, xp)
        if fused:
            from .fused_kernels import FusedOperator, FusedOps

            self.operator, self.ops = FusedOperator(self.g), FusedOps()
        else:
            self.operator, self.ops = _Operator(xp, self.g), ArrayAPIOps(xp)
        self.info = {"g_ref": g_ref, "k_ref": g_ref * voxel_m, "device": device,
                     "namespace": ns, "dtype": backend.dtype.name,
                     "fft_dtype": backend.fft_dtype_for().name,
                     "kernels": "fused" if fused else "portable",
                     "preconditioner": backend.preconditioner}
        if backend.preconditioner == "multigrid":
            from .array_api_multigrid import ParticleMultigridPreconditioner

            g_host = system.g if host else to_numpy(system.g)
            self.preconditioner = ParticleMultigridPreconditioner(
                xp, g_host, system.particle_ids, device=dev, dtype=np.float32,
                g_device=self.g, project=self._project)
            self.info.update(self.preconditioner.info)
        else:
            fft_dtype = _xp_float(xp, backend.fft_dtype_for())
            self.preconditioner = _FFTPreconditioner(xp, dev, tuple(self.g.shape[1:]), g_ref,
                                                     fft_dtype,
                                                     self.clusters if several else None)

    def to_host(self, x: Any) -> np.ndarray:
        """A host NumPy copy of one of this system's device arrays."""
        return to_numpy(x)

    def solve_block(self, loads, starts, tol, maxiter, callback=None
                    ) -> list[LoadCaseSolution]:
        """The load cases in lockstep (:func:`~itr_fv.solvers.krylov.block_conjugate_gradients`):
        the same iterates as one at a time; with the fused kernels the operator products
        of one iteration are one launch that reads g once."""
        xp = self.xp
        bxs = [xp.astype(xp.asarray(b, device=self.dev), self.dtype, copy=False)
               for b in loads]
        xs = [xp.zeros(bx.shape, dtype=self.dtype, device=self.dev) if x0 is None else
              xp.asarray(np.array(x0, dtype=np.float64), dtype=self.dtype, device=self.dev)
              for bx, x0 in zip(bxs, starts)]
        outs = block_conjugate_gradients(self.operator, bxs, xs, tol=tol, maxiter=maxiter,
                                         preconditioner=self.preconditioner,
                                         callback=callback, ops=self.ops,
                                         project=self._project)
        del bxs
        return [LoadCaseSolution(xp.astype(x, xp.float64, copy=False), out.iterations,
                                 out.history, out.residual, out.restarts)
                for x, out in zip(xs, outs)]

    def solve(self, b, x0, tol, maxiter, callback=None) -> LoadCaseSolution:
        step = None if callback is None else (lambda _c, it, res: callback(it, res))
        return self.solve_block([b], [x0], tol, maxiter, step)[0]


@register_backend
class ArrayAPIBackend(Backend):
    """FFT-preconditioned CG in any array API library, on the CPU or a GPU.

    Parameters
    ----------
    device : {"cpu", "cuda", "auto"}
        Where to run (``"auto"``: a CUDA device when CuPy or PyTorch sees one).
    namespace : {"numpy", "array_api_strict", "cupy", "torch"}, optional
        Array library (default: NumPy on the CPU, CuPy, else PyTorch, on CUDA).
    dtype : np.float64 or np.float32
        Precision of the vectors and conductances (reductions in float64).
        float32 needs ``tol >= 4 float32_min_tol(shape)`` (:data:`FLOAT32_FLOOR_FACTOR`).
    fft_dtype : np.float64 or np.float32, optional
        Precision of the preconditioner's FFTs only, the option of the same name of the
        numba backend (:class:`~itr_fft.numba_backend.NumbaFFTBackend`): the CG vectors,
        the operator, the residual check and the converged answer stay in ``dtype``.
        Default: ``dtype`` (float32 vectors always take float32 FFTs). float32 FFTs with
        float64 vectors halve the spectrum's memory and traffic.
    preconditioner : {"fft", "multigrid"}
        The FFT Laplacian inverse, or the particle-deflated aggregation multigrid
        (:class:`~itr_fft.array_api_multigrid.ParticleMultigridPreconditioner`: its hierarchy
        built once on the host with the numba code, applied on the device; 5x fewer
        iterations on AlN-like contrast on the CPU).
    kernels : {"auto", "portable", "fused"}
        The operator and CG's vector updates as whole-array expressions (``"portable"``, any
        namespace) or as the fused kernels of :mod:`itr_fft.fused_kernels`; ``"auto"``
        takes the fused ones on a CUDA device with CuPy where numba's CUDA target works.
    """

    name = "array_api"
    default_maxiter = 3000

    def __init__(self, device: str = "auto", namespace: str | None = None,
                 dtype: Any = np.float64, fft_dtype: Any = None, *,
                 preconditioner: str = "fft", kernels: str = "auto") -> None:
        resolve_device(device, namespace)  # checks the pair before any solve
        if preconditioner not in PRECONDITIONERS:
            raise ValueError(f"preconditioner: expected one of {PRECONDITIONERS}, got "
                             f"{preconditioner!r}")
        if kernels not in KERNELS:
            raise ValueError(f"kernels: expected one of {KERNELS}, got {kernels!r}")
        self.device = device
        self.namespace = namespace
        self.dtype = float_dtype(dtype, "dtype")
        self.fft_dtype = None if fft_dtype is None else float_dtype(fft_dtype, "fft_dtype")
        self.preconditioner = preconditioner
        self.kernels = kernels

    def array_namespace(self) -> tuple[Any, Any]:
        """The namespace and device of the solve: the driver builds the face conductances
        there (they move to the device once per geometry, then one pass per parameter
        set)."""
        device, ns = resolve_device(self.device, self.namespace)
        xp = _namespace(ns)
        return xp, _device_of(xp, ns, device)

    def fft_dtype_for(self) -> np.dtype:
        """Precision the preconditioner's FFTs run in (float32 with float32 vectors)."""
        if self.dtype == np.float32 or self.fft_dtype is None:
            return self.dtype
        return self.fft_dtype

    def _array_bytes_per_voxel(self) -> int:
        # 3 conductances and, for each of the three load cases solved together, 4 CG
        # vectors in dtype and its float64 load vector and solution; the half spectrum
        # (complex) in fft_dtype and 3 temporaries; the face classes the conductances are
        # built from (int32 slots per axis and the material ids: 16 B); the multigrid's
        # hierarchy and its peak during an application (28 + 56 B, measured with
        # tracemalloc at 64^3, AlN-60)
        item, fft = self.dtype.itemsize, self.fft_dtype_for().itemsize
        mg = 84 if self.preconditioner == "multigrid" else 0
        return int(math.ceil(item * (3 + 3 * 4 + 3) + 8 * 6 + 2 * fft + 16 + mg))

    def bytes_per_voxel(self) -> int:
        # the arrays (on the host on a CPU; counted here on a GPU too, to stay on the safe
        # side) plus the geometry's set-up peak shared with the other backends
        return self._array_bytes_per_voxel() + 40

    def device_bytes_per_voxel(self) -> int:
        device, _ = resolve_device(self.device, self.namespace)
        return 0 if device == "cpu" else self._array_bytes_per_voxel()

    def options(self) -> dict[str, Any]:
        opts = {"device": self.device, "namespace": self.namespace, "dtype": self.dtype.name}
        if self.fft_dtype is not None:
            opts["fft_dtype"] = self.fft_dtype.name
        if self.preconditioner != "fft":
            opts["preconditioner"] = self.preconditioner
        if self.kernels != "auto":
            opts["kernels"] = self.kernels
        return opts

    def check(self, shape: tuple[int, int, int], tol: float) -> None:
        check_float32_tol(self.dtype, shape, tol, factor=FLOAT32_FLOOR_FACTOR)

    def prepare(self, system: DiscreteSystem, voxel_m: float) -> PreparedSystem:
        return _Prepared(system, voxel_m, self)
