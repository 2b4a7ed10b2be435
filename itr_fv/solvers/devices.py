"""What accelerators this process sees: CUDA devices and their free memory.

Asked through CuPy (the package's GPU array library, the ``[gpu]`` extra), else PyTorch;
without either library, a driver or a device the answer is "none" and nothing raises, so
the CPU-only machines of CI take the same code path. Nothing here imports a backend.
"""

from __future__ import annotations

__all__ = ["cuda_device_count", "cuda_free_memory", "require_cuda"]


def cuda_device_count() -> int:
    """CUDA devices this process sees: CuPy's count (else PyTorch's); 0 without either
    library, without a driver or without a device (never raises)."""
    try:
        import cupy
        return int(cupy.cuda.runtime.getDeviceCount())
    except Exception:  # noqa: BLE001 - no CuPy, no driver or no device: all mean "none"
        pass
    try:
        import torch
        return int(torch.cuda.device_count()) if torch.cuda.is_available() else 0
    except Exception:  # noqa: BLE001
        return 0


def cuda_free_memory() -> int | None:
    """Free memory of the current CUDA device, bytes (None where no library can say)."""
    try:
        import cupy
        free, _total = cupy.cuda.runtime.memGetInfo()
        return int(free)
    except Exception:  # noqa: BLE001
        pass
    try:
        import torch
        if torch.cuda.is_available():
            free, _total = torch.cuda.mem_get_info()
            return int(free)
    except Exception:  # noqa: BLE001
        pass
    return None


def require_cuda(what: str, argument: str) -> None:
    """A one-line ValueError naming ``argument`` where no CUDA device is seen for ``what``
    (e.g. ``"solver 'gpu'"``)."""
    if cuda_device_count() < 1:
        raise ValueError(f"{argument}: {what} solves on a GPU, but this machine has no CUDA "
                         "device (neither CuPy nor PyTorch finds one); choose another solver "
                         "(e.g. 'fft' or 'mg') or --device cpu, or use --scheduler with GPU "
                         "workers started as 'dask worker ADDRESS --resources GPU=1' (one "
                         "per GPU)")
