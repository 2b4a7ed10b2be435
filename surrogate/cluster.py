"""Where solves run: the Dask cluster set-up shared by the solve engine and the campaign
runner.

Which cluster can run a solver is decided here, once: :func:`open_client` makes a client on
a running scheduler or a LocalCluster sized by memory (a solver that needs a GPU,
:attr:`itr_fv.solvers.choice.Solver.resources`, gets one worker per CUDA device, each
declaring the resource ``GPU=1``; none found: a one-line refusal), and
:func:`ready_workers` checks, before anything is submitted, that a worker joined, that one
has the memory a task needs and, for a GPU solver, that one declares ``GPU`` (such tasks
would otherwise wait forever).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence

from itr_fv.io import counted
from itr_fv.solvers.choice import Solver, solvers_for
from itr_fv.solvers.devices import cuda_device_count

__all__ = ["open_client", "ready_workers", "worker_memory_limit", "default_workers",
           "MAX_DEFAULT_WORKERS", "WORKER_BASE_BYTES"]


#: Resident bytes of a worker before its first task: the interpreter, numba, scipy, pyarrow,
#: dask and the allocator's slack after a large solve (measured: ~1.5 GB above the solve's own
#: peak at 250^3).
WORKER_BASE_BYTES = 1.5e9


def worker_memory_limit(task_bytes: float) -> int:
    """The memory limit a dask worker needs to run a task whose own peak is ``task_bytes``.

    Dask pauses a worker at ``distributed.worker.memory.pause`` of its limit (0.8 by default)
    and its nanny restarts it at ``terminate`` (0.95): the limit is sized so the task's peak
    plus :data:`WORKER_BASE_BYTES` sits at the pause mark, never near the restart.

    Parameters
    ----------
    task_bytes : float
        Estimated peak of one task, bytes.

    Returns
    -------
    int
        Bytes.
    """
    import dask

    pause = dask.config.get("distributed.worker.memory.pause", 0.8) or 0.8
    return int((float(task_bytes) + WORKER_BASE_BYTES) / float(pause))


def _gpu_refusal(solver: Solver, why: str, scheduler: str | None = None) -> str:
    start = f"'dask worker {scheduler or 'ADDRESS'} --resources GPU=1' (one per GPU)"
    others = " or ".join(map(repr, solvers_for("cpu")[:2]))
    if scheduler:
        return (f"solver {solver.key!r} solves on a GPU, but {why}; start GPU workers with "
                f"{start}, or choose another solver (e.g. {others})")
    return (f"solver {solver.key!r} solves on a GPU, but {why}; choose another solver (e.g. "
            f"{others}), or use --scheduler with GPU workers started as {start}")


#: Local Dask workers at most where none are asked for.
MAX_DEFAULT_WORKERS = 4


def default_workers() -> int:
    """Local Dask workers where none are asked for: the cores, at most
    :data:`MAX_DEFAULT_WORKERS` (fewer where memory is short: :func:`open_client`)."""
    return max(1, min(os.cpu_count() or 1, MAX_DEFAULT_WORKERS))


def open_client(workers: int | None, scheduler: str | None, *, memory_per_worker: int,
                echo: Callable[[str], None] = print, solver: Solver | None = None):
    """A dask client on ``scheduler``, or on a new LocalCluster of ``workers`` processes
    (fewer if ``memory_per_worker`` bytes each do not fit); returns (client, cluster or None).

    With a ``solver`` that needs a GPU (:attr:`~itr_fv.solvers.choice.Solver.needs_gpu`),
    the LocalCluster has one worker
    per CUDA device (:func:`cuda_device_count`; at most ``workers``), each declaring the
    resource ``GPU=1``. An external scheduler's workers are checked by :func:`ready_workers`.

    Raises
    ------
    ValueError
        ``--scheduler: cannot reach ...`` when the scheduler does not answer in 5 s;
        ``solver 'gpu' solves on a GPU, but ...`` when a local cluster is asked for GPU
        solves on a machine without a CUDA device (nothing is started).
    """
    from dask.distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout="5s"), None
        except (OSError, TimeoutError) as exc:
            raise ValueError(f"--scheduler: cannot reach {scheduler!r} ({exc})") from None
    from itr_fv.solvers.resources import available_memory

    gpu = solver is not None and solver.needs_gpu
    if gpu:
        devices = cuda_device_count()
        if devices < 1:
            raise ValueError(_gpu_refusal(solver, "this machine has no CUDA device for a "
                                                  "local cluster (neither CuPy nor PyTorch "
                                                  "finds one)"))
        n = min(workers or devices, devices)
    else:
        n = workers or default_workers()
    avail = available_memory() or memory_per_worker
    fit = max(1, int(avail // memory_per_worker))
    if fit < n:
        echo(f"memory: {n} workers of {memory_per_worker / 1e9:.2f} GB do not fit in "
             f"{avail / 1e9:.1f} GB; using {fit}")
        n = fit
    if gpu:
        cluster = _gpu_cluster(n, memory_per_worker)
    else:
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               memory_limit=memory_per_worker, dashboard_address=None)
    try:
        return Client(cluster), cluster
    except BaseException:
        cluster.close()
        raise


def _gpu_cluster(n: int, memory_per_worker: int):
    """A local cluster of ``n`` worker processes, worker i seeing only the i-th CUDA device
    (``CUDA_VISIBLE_DEVICES``, within any the command itself was limited to) and declaring
    the resource ``GPU=1``: one solve per device at a time, every device used. Where
    dask-cuda is installed its ``LocalCUDACluster`` starts them (it also pins each worker
    to the CPU cores and network nearest its GPU); else a SpecCluster of plain workers."""
    visible = [d.strip() for d in os.environ.get("CUDA_VISIBLE_DEVICES", "").split(",")
               if d.strip()] or [str(i) for i in range(n)]
    try:
        from dask_cuda import LocalCUDACluster
    except ImportError:
        return _spec_gpu_cluster(visible[:n], memory_per_worker)
    return LocalCUDACluster(CUDA_VISIBLE_DEVICES=",".join(visible[:n]), n_workers=n,
                            threads_per_worker=1, memory_limit=memory_per_worker,
                            resources={"GPU": 1}, dashboard_address=None,
                            silence_logs=logging.ERROR)


def _spec_gpu_cluster(devices: Sequence[str], memory_per_worker: int):
    """One plain Dask worker per CUDA device in ``devices``, each seeing only its own."""
    from dask.distributed import Nanny, Scheduler, SpecCluster

    workers = {f"gpu-{i}": {"cls": Nanny, "options": {
        "nthreads": 1, "memory_limit": memory_per_worker, "resources": {"GPU": 1},
        "env": {"CUDA_VISIBLE_DEVICES": device}}} for i, device in enumerate(devices)}
    return SpecCluster(workers=workers, silence_logs=logging.ERROR,
                       scheduler={"cls": Scheduler, "options": {"dashboard_address": None}})


def ready_workers(client, scheduler: str | None, solver: Solver | None = None, *,
                  timeout: float = 60, memory_per_worker: int | None = None) -> int:
    """Number of workers on ``client``'s cluster once it can run ``solver``'s solves: waits
    up to ``timeout`` s for a first worker of an external ``scheduler``; there, where
    ``memory_per_worker`` (bytes, :func:`worker_memory_limit` of one task) is given, requires
    a worker whose memory limit holds it (a worker without a limit is taken to); for a
    solver that needs a GPU, a worker that declares the resource ``GPU``. Call it before
    submitting anything.

    Raises
    ------
    ValueError
        One line: no worker joined; no worker has the memory; or no worker declares a GPU.
    """
    workers = client.scheduler_info().get("workers", {})
    if not workers:
        try:
            client.wait_for_workers(1, timeout=timeout)
        except TimeoutError:
            raise ValueError(f"--scheduler: no worker joined {scheduler!r} within "
                             f"{timeout:.0f} s; start workers with 'dask worker ADDRESS'"
                             ) from None
        workers = client.scheduler_info().get("workers", {})
    limits = [int(w.get("memory_limit") or 0) for w in workers.values()]
    if scheduler and memory_per_worker and all(0 < m < memory_per_worker for m in limits):
        raise ValueError(f"--scheduler: no worker of {scheduler!r} has the memory one task "
                         f"needs (~{memory_per_worker / 1e9:.1f} GB as a worker's limit; the "
                         f"largest has {max(limits) / 1e9:.1f} GB); start workers with "
                         "'dask worker ADDRESS --memory-limit' of at least that, or use a "
                         "coarser voxel or a smaller box")
    gpus = [(w.get("resources") or {}).get("GPU", 0) for w in workers.values()]
    if solver is not None and solver.needs_gpu and not any(g >= 1 for g in gpus):
        why = (f"no worker of --scheduler {scheduler!r} ({counted(len(workers), 'worker')} "
               "connected) declares the resource GPU" if scheduler
               else "the local cluster has no GPU worker")
        raise ValueError(_gpu_refusal(solver, why, scheduler))
    return len(workers)
