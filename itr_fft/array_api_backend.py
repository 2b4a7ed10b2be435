"""The backend ``"array_api"``: the FFT-preconditioned CG written once against the array API.

The operator (the 7-point face-conductance stencil of :mod:`itr_fv.discrete.model`), the
preconditioner (the exact inverse of the constant-coefficient periodic Laplacian with face
conductance ``g_ref``, applied with real FFTs) and the cluster projection use only functions
of the Python array API standard (``roll``, ``fft.rfftn``/``irfftn``, ``take``,
``cumulative_sum``, arithmetic, in-place updates), and CG is
:func:`itr_fv.solvers.krylov.conjugate_gradients` with :class:`ArrayAPIOps`. So NumPy, CuPy and
PyTorch arrays run the same lines, on the CPU or a GPU; ``array-api-strict`` (the
standard's reference implementation) runs them in the tests, which proves nothing outside
the standard is used.

Everything that happens once per system (the reference conductance, the Laplacian symbol,
the cluster ordering) is computed on the host with NumPy and moved to the device; the
face conductances move once; every load case moves b in and theta out.

Memory on the device: the conductances (3 N), the CG vectors x, r, p, q and b (5 N), the
half spectrum (~N complex) and the operator's temporaries (~3 N), in ``dtype``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from itr_fv.discrete.problem import DiscreteSystem
from itr_fv.solvers.backends import Backend, LoadCaseSolution, PreparedSystem, register_backend
from itr_fv.solvers.krylov import ArrayOps, conjugate_gradients

from .numba_backend import check_float32_tol, float_dtype, reference_conductance
from .spectral import inverse_laplacian

__all__ = ["ArrayAPIBackend", "ArrayAPIOps", "NAMESPACES", "DEVICES", "resolve_device"]

#: The float32 floor of this backend in units of ``float32_min_tol``: its operator sums in
#: float32 (the numba kernels in float64), and CG stalled at 1.09e-6 on the 64^3 dense
#: Al2O3 RVE where the numba floor is 1e-6.
FLOAT32_FLOOR_FACTOR = 4.0

#: Array libraries the backend can run on, and the devices it knows.
NAMESPACES = ("numpy", "array_api_strict", "cupy", "torch")
DEVICES = ("cpu", "cuda", "auto")


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


def _device_of(xp: Any, name: str, device: str) -> Any:
    if name == "torch":
        return "cuda" if device == "cuda" else "cpu"
    if name == "cupy":
        import cupy
        return cupy.cuda.Device()
    return None  # the library's default device


def to_numpy(x: Any) -> np.ndarray:
    """A host NumPy copy (or view) of an array of any supported library."""
    if isinstance(x, np.ndarray):
        return x
    mod = type(x).__module__.split(".")[0]
    if mod == "cupy":
        return x.get()
    if mod == "torch":
        return x.detach().cpu().numpy()
    return np.from_dlpack(x)


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

    def empty_like(self, x: Any) -> Any:
        return self.xp.zeros_like(x)


class _Operator:
    """A x = sum_d g_d (x - x_{+d}) - shift_{+1}(g_d (x - x_{+d})) (the model's stencil)."""

    def __init__(self, xp: Any, g: Any) -> None:
        self.xp = xp
        self.g = g

    def apply(self, x: Any, out: Any) -> None:
        xp = self.xp
        acc = None
        for d in range(3):
            up = self.g[d, ...] * (x - xp.roll(x, -1, axis=d))
            term = up - xp.roll(up, 1, axis=d)
            acc = term if acc is None else acc + term
        out[...] = acc


class _Clusters:
    """Removes the mean of every connected cluster (segment sums over a sorted order)."""

    def __init__(self, xp: Any, device: Any, labels: np.ndarray, dtype: Any) -> None:
        flat = labels.ravel()
        order = np.argsort(flat, kind="stable")
        counts = np.bincount(flat)
        ends = np.cumsum(counts) - 1
        self.xp = xp
        self.shape = labels.shape
        self.order = xp.asarray(order.astype(np.int64), device=device)
        self.ends = xp.asarray(ends.astype(np.int64), device=device)
        self.labels = xp.asarray(flat.astype(np.int64), device=device)
        self.counts = xp.asarray(counts.astype(np.float64), device=device)
        self.dtype = dtype

    def project(self, v: Any) -> None:
        xp = self.xp
        flat = xp.astype(xp.reshape(v, (-1,)), xp.float64)
        running = xp.cumulative_sum(xp.take(flat, self.order))
        at_end = xp.take(running, self.ends)
        sums = xp.concat([at_end[:1], at_end[1:] - at_end[:-1]])
        means = xp.astype(sums / self.counts, self.dtype)
        v -= xp.reshape(xp.take(means, self.labels), self.shape)


class _FFTPreconditioner:
    """z = (g_ref L)^+ r by real FFTs; cluster means removed when there are several."""

    def __init__(self, xp: Any, device: Any, shape: tuple[int, int, int], g_ref: float,
                 dtype: Any, clusters: _Clusters | None) -> None:
        inverse = inverse_laplacian(shape, g_ref)
        self.xp = xp
        self.shape = shape
        self.inverse = xp.asarray(inverse, dtype=dtype, device=device)
        self.clusters = clusters

    def apply(self, r: Any) -> Any:
        xp = self.xp
        axes = (0, 1, 2)
        z = xp.fft.irfftn(xp.fft.rfftn(r, axes=axes) * self.inverse, s=self.shape, axes=axes)
        if self.clusters is not None:
            self.clusters.project(z)
        return z


class _Prepared(PreparedSystem):
    def __init__(self, system: DiscreteSystem, voxel_m: float,
                 backend: ArrayAPIBackend) -> None:
        device, ns = resolve_device(backend.device, backend.namespace)
        xp = _namespace(ns)
        dev = _device_of(xp, ns, device)
        dtype = xp.float64 if backend.dtype == np.float64 else xp.float32
        g = system.g
        g_ref = reference_conductance(g)
        self.xp, self.dev, self.dtype = xp, dev, dtype
        self.g = xp.asarray(g, dtype=dtype, device=dev)
        self.clusters = (None if system.labels is None
                         else _Clusters(xp, dev, system.labels, dtype))
        self.operator = _Operator(xp, self.g)
        self.preconditioner = _FFTPreconditioner(xp, dev, tuple(g.shape[1:]), g_ref, dtype,
                                                 self.clusters)
        self.ops = ArrayAPIOps(xp)
        self.info = {"g_ref": g_ref, "k_ref": g_ref * voxel_m, "device": device,
                     "namespace": ns, "dtype": backend.dtype.name}

    def solve(self, b, x0, tol, maxiter, callback=None) -> LoadCaseSolution:
        xp = self.xp
        bx = xp.asarray(np.asarray(b), dtype=self.dtype, device=self.dev)
        x = (xp.zeros(bx.shape, dtype=self.dtype, device=self.dev) if x0 is None else
             xp.asarray(np.array(x0, dtype=np.float64), dtype=self.dtype, device=self.dev))
        project = None if self.clusters is None else self.clusters.project
        out = conjugate_gradients(self.operator, bx, x, tol=tol, maxiter=maxiter,
                                  preconditioner=self.preconditioner, callback=callback,
                                  ops=self.ops, project=project)
        theta = np.asarray(to_numpy(x), dtype=np.float64)
        return LoadCaseSolution(theta, out.iterations, out.history, out.residual, out.restarts)


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
        Precision of the vectors, conductances and FFTs (reductions in float64).
        float32 needs ``tol >= 4 float32_min_tol(shape)`` (:data:`FLOAT32_FLOOR_FACTOR`).
    """

    name = "array_api"
    default_maxiter = 3000

    def __init__(self, device: str = "auto", namespace: str | None = None,
                 dtype: Any = np.float64) -> None:
        resolve_device(device, namespace)  # checks the pair before any solve
        self.device = device
        self.namespace = namespace
        self.dtype = float_dtype(dtype, "dtype")

    def bytes_per_voxel(self) -> int:
        # 3 conductances, 5 CG vectors, half spectrum (complex) and 3 temporaries, plus
        # the geometry's set-up peak shared with the other backends
        return int(math.ceil(self.dtype.itemsize * (3 + 5 + 2 + 3) + 40))

    def options(self) -> dict[str, Any]:
        return {"device": self.device, "namespace": self.namespace,
                "dtype": self.dtype.name}

    def check(self, shape: tuple[int, int, int], tol: float) -> None:
        check_float32_tol(self.dtype, shape, tol, factor=FLOAT32_FLOOR_FACTOR)

    def prepare(self, system: DiscreteSystem, voxel_m: float) -> PreparedSystem:
        return _Prepared(system, voxel_m, self)
