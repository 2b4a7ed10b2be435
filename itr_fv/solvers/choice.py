"""The one place a solver is chosen: every command, campaign file, engine request and the
reduced basis name a solver here, and get a backend of :mod:`itr_fv.solvers.backends`.

A choice is a registered name with its backend options, its device and the Dask worker
resources one of its solves needs:

- ``"fft"``: the numba FFT-preconditioned CG (backend ``itr_fft``), on the CPU;
- ``"mg"``: the same with the particle-deflated multigrid preconditioner (high contrast,
  resistive interfaces), on the CPU;
- ``"fv"``: sparse assembly + pyamg (backend ``itr_fv``, the reference), on the CPU;
- ``"gpu"``: the array-API FFT-preconditioned CG (backend ``array_api``) on a CUDA device;
  its solves go only to Dask workers that declare the resource ``GPU``;
- ``"auto"``: ``"gpu"`` on a CUDA device, else ``"fft"``.

Measured (validation/results/crossval.md, bench_solvers.md; shared 2-core machine): the
numba FFT backend was faster than pyamg at every size tried (24^3 to 128^3: pyamg's set-up
alone costs more than the whole FFT solve), so on the CPU ``"auto"`` is always ``"fft"``.
Any registered backend name (``available_backends()``, e.g. ``"scipy_fft"``) is also a
choice, on the CPU. The backends register themselves by entry point, so this module names
them without importing ``itr_fft``.

``device`` (``"cpu"``, ``"cuda"`` or ``"auto"``: a CUDA device where one is seen) picks
where a choice runs: :func:`resolve_solver` turns ``(solver, device)`` into one registered
name, which is what travels in campaign files, solve requests and the solve store's keys.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from .backends import Backend, available_backends, backend_for
from .devices import cuda_device_count, require_cuda

__all__ = ["SolverChoice", "SOLVERS", "DEFAULT_SOLVER", "DEFAULT_DEVICE", "DEVICES",
           "default_solver", "other_device_solver", "check_solver", "resolve_solver",
           "solver_choice", "solver_backend", "solvers_for", "worker_resources", "needs_gpu",
           "load_case_seconds", "grid_solver", "CPU_REFERENCE_THREADS", "CPU_THREAD_EXPONENT"]

#: Where a solve may run.
DEVICES = ("cpu", "cuda", "auto")
#: The solver every command and file uses when none is named.
DEFAULT_SOLVER = "fft"
#: The device every command uses when none is named: the CPU, whose results every
#: figure of the package was measured with (``auto`` takes a GPU where one is seen).
DEFAULT_DEVICE = "cpu"


@dataclass(frozen=True)
class SolverChoice:
    """A registered solver name.

    Attributes
    ----------
    name : str
        The name commands and files use (``"fft"``).
    backend : str
        The registered backend (:func:`~itr_fv.solvers.backends.available_backends`).
    options : mapping
        The backend's constructor options.
    device : {"cpu", "cuda"}
        Where its arrays live.
    summary : str
        One line for help texts.
    seconds_per_voxel : float
        Measured wall time of one load case per voxel at tol 1e-8, s (dense 60 % Al2O3,
        about 80 CG iterations; the time estimate of :mod:`itr_surrogate.workload`); a CPU
        choice's on :data:`CPU_REFERENCE_THREADS` threads.
    seconds_per_solve : float
        Fixed wall time of one load case whatever its grid, s: on a GPU the kernel launches
        and a host sync per CG iteration and the transfers, which small grids cannot hide.
    small_to_cpu : bool
        Whether a grid this choice solves slower than the CPU's default solver, by the cost
        model (:func:`load_case_seconds`), goes to the CPU (:func:`grid_solver`).
    """

    name: str
    backend: str
    options: Mapping[str, Any] = field(default_factory=dict)
    device: str = "cpu"
    summary: str = ""
    seconds_per_voxel: float = 6e-6
    seconds_per_solve: float = 0.0
    small_to_cpu: bool = False

    @property
    def resources(self) -> dict[str, int] | None:
        """Dask worker resources one solve needs: ``{"GPU": 1}`` on a CUDA device, else
        None (any worker)."""
        return {"GPU": 1} if self.device == "cuda" else None


def _registry(*choices: SolverChoice) -> Mapping[str, SolverChoice]:
    return MappingProxyType({c.name: c for c in choices})


#: Threads the CPU choices' seconds per voxel were measured on, and the exponent of their
#: scaling with threads, ``(CPU_REFERENCE_THREADS / threads) ** CPU_THREAD_EXPONENT``: one
#: FFT-preconditioned load case at 128^3 took 1.5e-6 s per voxel on 2 cores and 3.3e-7 s on
#: the 16 cores of an H200's host (../shared/gpu/README.md: 0.58 s at 68 iterations, taken
#: to 80), 4.5x for 8x the threads.
CPU_REFERENCE_THREADS = 2
CPU_THREAD_EXPONENT = 0.72

#: The registered short names. Seconds per voxel and load case: fft and fv from
#: validation/results/bench_solvers.md (2-core CPU: 256^3 in 65.9 s, 128^3 in 36.8 s, three
#: load cases), mg from the AlN-60 solves of validation/results/bench_gpu.md; gpu on an H200
#: with the portable kernels (../shared/gpu/README.md, 2026-11-28: al2o3_60 512^3 in 12.7 s
#: for three load cases, 3.2e-8 s per voxel and load case; ``itr reproduce --device cuda``
#: 1.6-2.6 s per full solve of three load cases at 48^3, 0.5 s per load case whatever the
#: grid); an unnamed backend is taken at fv's.
SOLVERS = _registry(
    SolverChoice("fft", "itr_fft", {}, "cpu", "numba FFT-preconditioned CG (the default)",
                 1.5e-6),
    SolverChoice("mg", "itr_fft", {"preconditioner": "multigrid"}, "cpu",
                 "numba CG with the particle-deflated multigrid (high contrast)", 3e-6),
    SolverChoice("fv", "itr_fv", {}, "cpu", "sparse assembly + pyamg (the reference)", 6e-6),
    SolverChoice("gpu", "array_api", {"device": "cuda"}, "cuda",
                 "array-API FFT-preconditioned CG on a CUDA device (CuPy)", 3.2e-8,
                 seconds_per_solve=0.5, small_to_cpu=True),
)


def load_case_seconds(entry: SolverChoice, voxels: int, threads: int | None = None) -> float:
    """The cost model: wall time of one load case of ``entry`` on ``voxels`` voxels, s.

    ``seconds_per_solve + voxels * seconds_per_voxel``, a CPU choice's per-voxel time scaled
    to ``threads`` (None: :data:`CPU_REFERENCE_THREADS`, the figure as measured) by
    :data:`CPU_THREAD_EXPONENT`. An order of magnitude: the plans' estimates and
    :func:`grid_solver`'s choice read it.
    """
    per_voxel = entry.seconds_per_voxel
    if entry.device == "cpu" and threads is not None:
        per_voxel *= (CPU_REFERENCE_THREADS / max(int(threads), 1)) ** CPU_THREAD_EXPONENT
    return entry.seconds_per_solve + voxels * per_voxel


def grid_solver(choice: str | None, voxels: int, *, threads: int | None = None) -> str:
    """The solver a grid of ``voxels`` voxels goes to: for a choice that sends small grids
    to the CPU (``small_to_cpu``: the GPU's), the CPU's default solver where the cost model
    (:func:`load_case_seconds`, the CPU on ``threads``, None: this machine's cores) has it
    sooner, else the choice itself. Measured on an H200 and its 16 host cores, the crossover
    lies near 120^3 voxels (about 70^3 against 2 cores): ``itr reproduce``'s 48^3 solves
    took 0.5 s per load case on the GPU against 0.15 s on one CPU thread."""
    choice = check_solver(choice)
    entry = solver_choice(choice)
    if not entry.small_to_cpu:
        return choice
    cpu = SOLVERS[DEFAULT_SOLVER]
    threads = (os.cpu_count() or 1) if threads is None else threads
    sooner = load_case_seconds(cpu, voxels, threads) < load_case_seconds(entry, voxels)
    return DEFAULT_SOLVER if sooner else choice


def default_solver() -> str:
    """The solver of every setting, request and command that names none
    (:data:`DEFAULT_SOLVER`): the one place the default is read; settings take it as their
    field's default (``field(default_factory=default_solver)``)."""
    return DEFAULT_SOLVER


def other_device_solver(choice: str | None) -> str:
    """The solver of the same method on the other device: ``"gpu"`` for a CPU choice, the
    default CPU solver for a CUDA one (what a plan says the other device would take)."""
    return DEFAULT_SOLVER if solver_choice(choice).device == "cuda" else "gpu"


def check_solver(choice: object, name: str = "solver") -> str:
    """``choice`` if it names a solver (a short name, ``"auto"`` or a registered backend;
    None: :func:`default_solver`), else a ValueError naming the argument ``name`` and the
    choices."""
    if choice is None:
        return DEFAULT_SOLVER
    if isinstance(choice, str) and (choice in SOLVERS or choice == "auto"
                                    or choice in available_backends()):
        return choice  # (the short names first: no scan of the installed backends)
    names = ", ".join(repr(c) for c in (*SOLVERS, "auto", *available_backends()))
    raise ValueError(f"{name}: expected one of {names}, got {choice!r}")


def _check_device(device: object, name: str) -> str:
    if device not in DEVICES:
        raise ValueError(f"{name}: expected one of {', '.join(map(repr, DEVICES))}, "
                         f"got {device!r}")
    return str(device)


def resolve_solver(solver: str = DEFAULT_SOLVER, device: str | None = None, *,
                   solver_argument: str = "solver", device_argument: str = "device",
                   local: bool = True) -> str:
    """The registered name that solves ``solver`` on ``device``; checked before any work.

    ``"fft"`` or ``"auto"`` on ``"cuda"`` is ``"gpu"`` (the FFT-preconditioned CG on the
    device); a CPU-only solver on ``"cuda"`` is refused, as is ``"gpu"`` on ``"cpu"``. A
    solve on a CUDA device where this machine has none is refused in one line.

    Parameters
    ----------
    solver : str
        A short name, ``"auto"`` or a registered backend name.
    device : {"cpu", "cuda", "auto"}, optional
        Where to solve (``"auto"``: a CUDA device where one is seen, else the CPU); None:
        where ``solver`` runs (``"gpu"`` on CUDA, the others on :data:`DEFAULT_DEVICE`).
    solver_argument, device_argument : str
        The names the errors give the two arguments (e.g. ``--solver``, ``--device``).
    local : bool
        Whether the solves run on this machine, whose CUDA devices are then checked; False
        for solves on a remote Dask cluster (its workers declare their GPUs; ``"auto"``
        still looks at this machine).

    Raises
    ------
    ValueError
        One line naming the argument at fault.
    """
    solver = check_solver(solver, solver_argument)
    at_fault = device_argument if device is not None else solver_argument
    if device is None:
        device = "cuda" if solver == "gpu" else DEFAULT_DEVICE
    device = _check_device(device, device_argument)
    if device == "auto":
        on_device = solver == "gpu" or (solver in ("auto", "fft") and cuda_device_count() > 0)
        device = "cuda" if on_device else "cpu"
    if solver == "auto" or (solver == "fft" and device == "cuda"):
        solver = "gpu" if device == "cuda" else DEFAULT_SOLVER
    runs_on = SOLVERS[solver].device if solver in SOLVERS else "cpu"
    if runs_on != device:
        other = "--device cuda" if runs_on == "cuda" else "--device cpu"
        raise ValueError(f"{device_argument}: the solver {solver!r} runs on the "
                         f"{runs_on.upper()}, not on {device!r}; use {other}, or a solver "
                         f"for {device!r} ({', '.join(map(repr, solvers_for(device)))})")
    if device == "cuda" and local:
        require_cuda(f"solver {solver!r}", at_fault)
    return solver


def solvers_for(device: str) -> tuple[str, ...]:
    """The short names that run on ``device`` (``"cpu"`` or ``"cuda"``)."""
    return tuple(n for n, c in SOLVERS.items() if c.device == device)


def solver_choice(choice: str | None, argument: str = "solver") -> SolverChoice:
    """The :class:`SolverChoice` of a resolved name (a registered backend name stands for
    itself, on the CPU; None: :func:`default_solver`); a ValueError naming ``argument`` for
    an unknown one."""
    choice = check_solver(choice, argument)
    if choice == "auto":
        choice = resolve_solver("auto", "cpu")
    return SOLVERS.get(choice) or SolverChoice(choice, choice)


def solver_backend(choice: str, *, threads: int | None = None, voxels: int | None = None,
                   argument: str = "solver") -> Backend:
    """The backend object of a solver choice.

    Parameters
    ----------
    choice : str
        A short name, ``"auto"`` or a registered backend name.
    threads : int, optional
        Threads of the numba FFT backend (None: its default for the grid).
    voxels : int, optional
        The grid's voxels, where the caller knows them: a choice that sends small grids to
        the CPU then gets the CPU's backend for a grid the CPU solves sooner
        (:func:`grid_solver`).
    argument : str
        The name an error gives the argument.
    """
    if voxels is not None:
        choice = grid_solver(check_solver(choice, argument), voxels, threads=threads)
    entry = solver_choice(choice, argument)
    options = dict(entry.options)
    if entry.backend == "itr_fft" and threads is not None:
        options["workers"] = threads
    return backend_for(entry.backend, **options)


def worker_resources(choice: str) -> dict[str, int] | None:
    """Dask worker resources one solve of ``choice`` needs (``{"GPU": 1}`` or None)."""
    return solver_choice(choice).resources


def needs_gpu(choice: str | None) -> bool:
    """Whether a choice's solves ask the Dask workers for the resource ``GPU``."""
    return bool(choice) and bool((worker_resources(choice) or {}).get("GPU"))
