"""Memory guard: estimate a solve's peak memory before it starts, refuse what cannot fit.

Without it a 400^3 RVE given to the FV solver ran for 31 s and died in the operator assembly
with a MemoryError at 7.6 GB. The estimates are linear in the number of voxels N, with
per-voxel costs measured as peak resident memory over a fresh interpreter (ru_maxrss minus
the memory held before the solve, dense 60 % Al2O3 RVE, three load cases, store_fields=False;
``validation/results/memory.md``, written by ``validation/bench_memory.py``):

========================  ====================
solver, vectors            bytes per voxel
========================  ====================
itr_fv (pyamg, classical)  ``FV_BYTES_PER_VOXEL``
itr_fft, float64           ``FFT64_BYTES_PER_VOXEL``
itr_fft, float32           ``FFT32_BYTES_PER_VOXEL``
========================  ====================

plus ``FIELD_BYTES_PER_VOXEL_CASE`` per load case when the fields are kept
(``store_fields=True``: theta, temperature and three face fluxes in float64). Measured: FV
1109-1236, FFT float64 89-101, FFT float32 93-106 bytes per voxel (64^3 to 192^3). float32
vectors do not lower the FFT solver's peak: it is reached while the float64 face
conductances and the geometry are built.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

__all__ = ["InsufficientMemoryError", "available_memory", "estimate_peak_memory",
           "check_memory", "FV_BYTES_PER_VOXEL", "FFT64_BYTES_PER_VOXEL",
           "FFT32_BYTES_PER_VOXEL", "FIELD_BYTES_PER_VOXEL_CASE"]

#: Measured peak bytes per voxel of each solver (see the module docstring), rounded up.
FV_BYTES_PER_VOXEL = 1250
FFT64_BYTES_PER_VOXEL = 110
FFT32_BYTES_PER_VOXEL = 110  # measured 93-106: the set-up (float64 conductances) sets the peak
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


def estimate_peak_memory(shape: Sequence[int], solver: str, *, dtype: str = "float64",
                         store_fields: bool = True, load_cases: int = 3) -> int:
    """Estimated peak memory of one homogenization, bytes.

    Parameters
    ----------
    shape : (n1, n2, n3)
        Voxel grid.
    solver : {"itr_fv", "itr_fft"}
    dtype : {"float64", "float32"}
        CG vector precision (itr_fft only).
    store_fields : bool
        Whether the result keeps the fields.
    load_cases : int
        Number of load cases solved.

    Returns
    -------
    int
    """
    n = math.prod(int(s) for s in shape)
    if solver == "itr_fv":
        per = FV_BYTES_PER_VOXEL
    elif solver == "itr_fft":
        per = FFT32_BYTES_PER_VOXEL if str(dtype) == "float32" else FFT64_BYTES_PER_VOXEL
    else:
        raise ValueError(f"solver: expected 'itr_fv' or 'itr_fft', got {solver!r}")
    if store_fields:
        per += FIELD_BYTES_PER_VOXEL_CASE * int(load_cases)
    return int(n * per)


def _gb(b: float) -> str:
    return f"{b / 1e9:.1f} GB"


def check_memory(shape: Sequence[int], solver: str, *, dtype: str = "float64",
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
        With the estimate, the available memory and the options that would fit; pass
        ``check_memory=False`` to the solver to go ahead anyway.
    """
    est = estimate_peak_memory(shape, solver, dtype=dtype, store_fields=store_fields,
                               load_cases=load_cases)
    avail = available_memory() if available is None else int(available)
    if avail is None or est <= HEADROOM * avail:
        return est
    candidates = [("itr_fft", "float64", store_fields), ("itr_fft", "float64", False)]
    options = []
    for cand in dict.fromkeys(candidates):  # keeps order, drops repeats
        if cand == (solver, str(dtype), store_fields):
            continue
        e = estimate_peak_memory(shape, cand[0], dtype=cand[1], store_fields=cand[2],
                                 load_cases=load_cases)
        if e <= HEADROOM * avail:
            extra = "" if cand[2] else ", store_fields=False"
            options.append(f"{cand[0]} with dtype={cand[1]}{extra} (~{_gb(e)})")
            break
    hint = ("; would fit: " + "; ".join(options)) if options else \
        "; no solver fits: use a coarser voxel or a smaller box"
    grid = "x".join(str(int(s)) for s in shape)
    raise InsufficientMemoryError(
        f"memory: {solver} ({dtype}) on a {grid} grid needs ~{_gb(est)} but {_gb(avail)} is "
        f"available{hint}; pass check_memory=False to try anyway",
        est, avail)
