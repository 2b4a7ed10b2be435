"""Memory guard: estimate a solve's peak memory before it starts, refuse what cannot fit.

Without it a 400^3 RVE given to the FV solver ran for 31 s and died in the operator assembly
with a MemoryError at 7.6 GB. The estimates are linear in the number of voxels N: each
backend states its measured peak bytes per voxel
(:meth:`itr_fv.solvers.backends.Backend.bytes_per_voxel`, measured as peak resident memory over a
fresh interpreter, dense 60 % Al2O3 RVE, three load cases, store_fields=False;
``validation/results/memory.md``, written by ``validation/bench_memory.py``), plus
``FIELD_BYTES_PER_VOXEL_CASE`` per load case when the fields are kept
(``store_fields=True``: theta, temperature and three face fluxes in float64). A backend
whose arrays live on an accelerator also states its bytes per voxel there
(:meth:`~itr_fv.solvers.backends.Backend.device_bytes_per_voxel`), checked against the
device's free memory (:func:`check_device_memory`), not the host's. This module knows no
backend by name: it asks the registry.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover
    from .backends import Backend

__all__ = ["InsufficientMemoryError", "available_memory", "estimate_peak_memory",
           "check_memory", "check_device_memory", "FIELD_BYTES_PER_VOXEL_CASE"]

#: theta + temperature (8 B each) and three face fluxes (24 B) per load case, plus the
#: temporaries of the flux computation.
FIELD_BYTES_PER_VOXEL_CASE = 64
#: Fraction of the available memory a solve may plan to use.
HEADROOM = 0.9


class InsufficientMemoryError(MemoryError):
    """A solve's estimated peak memory exceeds what the machine has available.

    Attributes
    ----------
    estimate : int
        Estimated peak, bytes.
    available : int
        Available memory, bytes.
    """

    def __init__(self, message: str, estimate: int, available: int) -> None:
        super().__init__(message)
        self.estimate = estimate
        self.available = available


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _cgroup_available() -> int | None:
    """Limit minus usage of this process's cgroup (v2, then v1), if it is limited."""
    pairs = [("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
             ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
              "/sys/fs/cgroup/memory/memory.usage_in_bytes")]
    for limit_file, usage_file in pairs:
        try:
            with open(limit_file, encoding="ascii") as fh:
                raw = fh.read().strip()
            if raw == "max":
                return None
            limit = int(raw)
            with open(usage_file, encoding="ascii") as fh:
                usage = int(fh.read().strip())
        except (OSError, ValueError):
            continue
        if limit >= 1 << 60:  # cgroup v1 "unlimited"
            return None
        return max(limit - usage, 0)
    return None


def available_memory() -> int | None:
    """Memory a new allocation can get now, bytes (None where it cannot be read).

    Linux: the smaller of MemAvailable (/proc/meminfo) and the cgroup's limit minus usage;
    elsewhere the physical memory (``os.sysconf``), or None.
    """
    values = [v for v in (_meminfo_available(), _cgroup_available()) if v is not None]
    if values:
        return min(values)
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def _backend(solver: "str | Backend", dtype: str | None) -> "Backend":
    from .backends import backend_for  # the registry, not any backend
    if dtype is None or not isinstance(solver, str):
        return backend_for(solver)
    return backend_for(solver, dtype=str(dtype))


def estimate_peak_memory(shape: Sequence[int], solver: "str | Backend", *,
                         dtype: str | None = None, store_fields: bool = True,
                         load_cases: int = 3) -> int:
    """Estimated peak memory of one homogenization, bytes.

    Parameters
    ----------
    shape : (n1, n2, n3)
        Voxel grid.
    solver : str or Backend
        A backend name (:func:`itr_fv.solvers.backends.available_backends`) or a configured backend;
        its :meth:`~itr_fv.solvers.backends.Backend.bytes_per_voxel` is the measured cost.
    dtype : {"float64", "float32"}, optional
        CG vector precision, for a named backend that has this option.
    store_fields : bool
        Whether the result keeps the fields.
    load_cases : int
        Number of load cases solved.

    Returns
    -------
    int
    """
    n = math.prod(int(s) for s in shape)
    try:
        per = _backend(solver, dtype).bytes_per_voxel()
    except ValueError as err:
        raise ValueError(f"solver: {err}") from None
    if store_fields:
        per += FIELD_BYTES_PER_VOXEL_CASE * int(load_cases)
    return int(n * per)


def check_device_memory(shape: Sequence[int], backend: "Backend", *,
                        free: int | None = None) -> int:
    """Refuse a solve whose arrays on the accelerator exceed its free memory.

    Parameters
    ----------
    shape : (n1, n2, n3)
        Voxel grid.
    backend : Backend
        A configured backend; its :meth:`~itr_fv.solvers.backends.Backend.
        device_bytes_per_voxel` is the cost (0: nothing on a device, nothing checked).
    free : int, optional
        Free device bytes (default: :func:`itr_fv.solvers.devices.cuda_free_memory`).

    Returns
    -------
    int
        The estimate on the device, bytes (0 for a host backend).

    Raises
    ------
    InsufficientMemoryError
        One line with the estimate, the free device memory and what would fit.
    """
    per = int(backend.device_bytes_per_voxel())
    if per <= 0:
        return 0
    from .devices import cuda_free_memory

    n = math.prod(int(s) for s in shape)
    est = n * per
    free = cuda_free_memory() if free is None else int(free)
    if free is None or est <= HEADROOM * free:
        return est
    grid = "x".join(str(int(s)) for s in shape)
    fits = int((HEADROOM * free / per) ** (1.0 / 3.0))
    raise InsufficientMemoryError(
        f"memory: {backend.name} on a {grid} grid needs ~{_gb(est)} of GPU memory but "
        f"{_gb(free)} is free on the device; a grid of at most ~{fits}^3 fits (or "
        "dtype=float32 where the tolerance allows); pass check_memory=False to try anyway",
        est, free)


def _gb(b: float) -> str:
    return f"{b / 1e9:.1f} GB"


def check_memory(shape: Sequence[int], solver: "str | Backend", *, dtype: str | None = None,
                 store_fields: bool = True, load_cases: int = 3,
                 available: int | None = None) -> int:
    """Refuse a solve whose estimated peak exceeds the available memory.

    Parameters
    ----------
    shape, solver, dtype, store_fields, load_cases
        As in :func:`estimate_peak_memory`.
    available : int, optional
        Available bytes (default: :func:`available_memory`).

    Returns
    -------
    int
        The estimate, bytes.

    Raises
    ------
    InsufficientMemoryError
        With the estimate, the available memory and the cheapest registered backend that
        would fit; pass ``check_memory=False`` to the solver to go ahead anyway.
    """
    from .backends import available_backends, backend_for

    chosen = _backend(solver, dtype)
    check_device_memory(shape, chosen)
    est = estimate_peak_memory(shape, chosen, store_fields=store_fields, load_cases=load_cases)
    avail = available_memory() if available is None else int(available)
    if avail is None or est <= HEADROOM * avail:
        return est
    label = f"{chosen.name}" + "".join(f", {k}={v}" for k, v in chosen.options().items()
                                       if k == "dtype")
    options = []
    others = sorted((backend_for(name) for name in available_backends()),
                    key=lambda b: b.bytes_per_voxel())
    for other in others[:1]:
        for keep in dict.fromkeys((store_fields, False)):
            if other.name == chosen.name and keep == store_fields:
                continue
            e = estimate_peak_memory(shape, other, store_fields=keep, load_cases=load_cases)
            if e <= HEADROOM * avail:
                extra = "" if keep else ", store_fields=False"
                opts = "".join(f" with {k}={v}" for k, v in other.options().items()
                               if k == "dtype")
                options.append(f"{other.name}{opts}{extra} (~{_gb(e)})")
                break
    hint = ("; would fit: " + "; ".join(options)) if options else \
        "; no solver fits: use a coarser voxel or a smaller box"
    grid = "x".join(str(int(s)) for s in shape)
    raise InsufficientMemoryError(
        f"memory: {label} on a {grid} grid needs ~{_gb(est)} but {_gb(avail)} is "
        f"available{hint}; pass check_memory=False to try anyway",
        est, avail)
