"""The one place a solver is chosen: a :class:`Solver`, resolved once, carried as an object.

A solver is a registered method with its backend options and the device it runs on:

- ``"fft"``: the numba FFT-preconditioned CG (backend ``itr_fft``), on the CPU;
- ``"mg"``: the same with the particle-deflated multigrid preconditioner (high contrast,
  resistive interfaces), on the CPU;
- ``"fv"``: sparse assembly + pyamg (backend ``itr_fv``, the reference), on the CPU;
- ``"gpu"``: the array-API FFT-preconditioned CG (backend ``array_api``) on a CUDA device;
  its solves go only to Dask workers that declare the resource ``GPU``;
- ``"auto"`` (a name that is resolved, never carried): ``"gpu"`` where a CUDA device is
  seen, else ``"fft"``.

Measured (validation/results/crossval.md, bench_solvers.md; shared 2-core machine): the
numba FFT backend was faster than pyamg at every size tried (24^3 to 128^3: pyamg's set-up
alone costs more than the whole FFT solve), so on the CPU ``"auto"`` is always ``"fft"``.
Any registered backend name (``available_backends()``, e.g. ``"scipy_fft"``) is also a
method, on the CPU. The backends register themselves by entry point, so this module names
them without importing ``itr_fft``.

:func:`resolve_solver` turns what a user wrote (``solver``, ``device``) into a frozen
:class:`Solver` once, before any work, with the errors naming the user's arguments; settings
take a name or a Solver (:func:`as_solver`) and keep the Solver; everything below them
(requests, workloads, the reduced basis, the driver) carries the object and asks it for its
backend (:meth:`Solver.backend`), its Dask resources and its key (:attr:`Solver.key`: the
text that travels in campaign files, solve requests and the solve store's keys).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from .backends import Backend, available_backends, backend_for
from .devices import cuda_device_count, require_cuda

__all__ = ["Solver", "SolverChoice", "SOLVERS", "DEFAULT_SOLVER", "DEFAULT_DEVICE", "DEVICES",
           "default_solver", "as_solver", "resolve_solver", "solvers_for",
           "load_case_seconds", "CPU_REFERENCE_THREADS", "CPU_THREAD_EXPONENT"]

#: Where a solve may run.
DEVICES = ("cpu", "cuda", "auto")
#: The method every command and file uses when none is named.
DEFAULT_SOLVER = "fft"
#: The device every command uses when none is named: the CPU, whose results every
#: figure of the package was measured with (``auto`` takes a GPU where one is seen).
DEFAULT_DEVICE = "cpu"


@dataclass(frozen=True)
class SolverChoice:
    """A registered method: its backend, options, device and cost.

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
        Whether a grid this method solves slower than the CPU's default method, by the cost
        model (:func:`load_case_seconds`), goes to the CPU (:meth:`Solver.for_grid`).
    """

    name: str
    backend: str
    options: Mapping[str, Any] = field(default_factory=dict)
    device: str = "cpu"
    summary: str = ""
    seconds_per_voxel: float = 6e-6
    seconds_per_solve: float = 0.0
    small_to_cpu: bool = False


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


def _option_text(value: Any) -> Any:
    """An option's value as it is written into a key: a dtype by its name."""
    if isinstance(value, (type, np.dtype)):
        return np.dtype(value).name
    return value


@dataclass(frozen=True, eq=False)
class Solver:
    """A resolved solver: a method, the backend options it adds, and where it runs.

    Made by :func:`resolve_solver` (what a user wrote, checked once) or :func:`as_solver`
    (a settings field); immutable, compared and hashed by :attr:`key`.

    Attributes
    ----------
    method : str
        A registered short name (:data:`SOLVERS`) or a registered backend name; never
        ``"auto"``.
    options : mapping
        Backend options over the method's own (e.g. ``{"dtype": "float32"}``).
    """

    method: str
    options: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.method, str) or not (
                self.method in SOLVERS or self.method in available_backends()):
            raise ValueError(f"solver: expected one of {_names()}, got {self.method!r}")
        # a plain dict of its own (a mapping proxy would not pickle to a Dask worker)
        opts = {str(k): _option_text(v) for k, v in dict(self.options or {}).items()}
        object.__setattr__(self, "options", opts)

    @property
    def entry(self) -> SolverChoice:
        """The registry entry (cost model, device); an unnamed backend as fv's cost."""
        return SOLVERS.get(self.method) or SolverChoice(self.method, self.method)

    @property
    def device(self) -> str:
        """``"cpu"`` or ``"cuda"``."""
        return self.entry.device

    @property
    def key(self) -> str:
        """The text that stands for this solver in files and store keys: the method, and
        its options as sorted JSON where it has any (``'mg'``, ``'fft{"dtype": "float32"}'``)."""
        if not self.options:
            return self.method
        return self.method + json.dumps(dict(self.options), sort_keys=True, default=str)

    @property
    def summary(self) -> str:
        """One line for reports: what the method is."""
        return self.entry.summary or self.key

    @property
    def resources(self) -> dict[str, int] | None:
        """Dask worker resources one solve needs: ``{"GPU": 1}`` on a CUDA device, else
        None (any worker)."""
        return {"GPU": 1} if self.device == "cuda" else None

    @property
    def needs_gpu(self) -> bool:
        """Whether its solves ask the Dask workers for the resource ``GPU``."""
        return self.resources is not None

    def for_grid(self, voxels: int, *, threads: int | None = None) -> Solver:
        """The solver a grid of ``voxels`` voxels goes to: for a method that sends small
        grids to the CPU (``small_to_cpu``: the GPU's), the CPU's default where the cost
        model (:func:`load_case_seconds`, the CPU on ``threads``, None: this machine's
        cores) has it sooner, else this one. Measured on an H200 and its 16 host cores, the
        crossover lies near 120^3 voxels (about 70^3 against 2 cores): ``itr reproduce``'s
        48^3 solves took 0.5 s per load case on the GPU against 0.15 s on one CPU thread."""
        if not self.entry.small_to_cpu:
            return self
        cpu = SOLVERS[DEFAULT_SOLVER]
        threads = (os.cpu_count() or 1) if threads is None else threads
        sooner = load_case_seconds(cpu, voxels, threads) < load_case_seconds(self.entry,
                                                                            voxels)
        return Solver(DEFAULT_SOLVER) if sooner else self

    def on_other_device(self) -> Solver:
        """The default method of the other device (what a plan says the other would take)."""
        return Solver(DEFAULT_SOLVER if self.device == "cuda" else "gpu")

    def backend(self, threads: int | None = None, *, voxels: int | None = None) -> Backend:
        """A new backend object of this solver.

        Parameters
        ----------
        threads : int, optional
            Threads of the numba FFT backend (None: its default for the grid).
        voxels : int, optional
            The grid's voxels, where the caller knows them: a method that sends small grids
            to the CPU then gets the CPU's backend for a grid the CPU solves sooner
            (:meth:`for_grid`).
        """
        solver = self if voxels is None else self.for_grid(voxels, threads=threads)
        entry = solver.entry
        options = {**entry.options, **solver.options}
        if entry.backend == "itr_fft" and threads is not None:
            options["workers"] = threads
        return backend_for(entry.backend, **options)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Solver) and other.key == self.key

    def __hash__(self) -> int:
        return hash(self.key)

    def __str__(self) -> str:
        return self.key


def _names() -> str:
    return ", ".join(repr(c) for c in (*SOLVERS, "auto", *available_backends()))


def default_solver() -> Solver:
    """The solver of every setting, request and command that names none
    (:data:`DEFAULT_SOLVER` on the CPU): settings take it as their field's default
    (``field(default_factory=default_solver)``)."""
    return Solver(DEFAULT_SOLVER)


def load_case_seconds(entry: SolverChoice | Solver, voxels: int,
                      threads: int | None = None) -> float:
    """The cost model: wall time of one load case of ``entry`` on ``voxels`` voxels, s.

    ``seconds_per_solve + voxels * seconds_per_voxel``, a CPU method's per-voxel time scaled
    to ``threads`` (None: :data:`CPU_REFERENCE_THREADS`, the figure as measured) by
    :data:`CPU_THREAD_EXPONENT`. An order of magnitude: the plans' estimates and
    :meth:`Solver.for_grid` read it.
    """
    if isinstance(entry, Solver):
        entry = entry.entry
    per_voxel = entry.seconds_per_voxel
    if entry.device == "cpu" and threads is not None:
        per_voxel *= (CPU_REFERENCE_THREADS / max(int(threads), 1)) ** CPU_THREAD_EXPONENT
    return entry.seconds_per_solve + voxels * per_voxel


def _parse_key(text: str, argument: str) -> Solver:
    """A Solver from its :attr:`Solver.key` (a method, optionally with JSON options)."""
    method, brace, rest = text.partition("{")
    options: dict[str, Any] = {}
    if brace:
        try:
            options = json.loads(brace + rest)
        except ValueError:
            raise ValueError(f"{argument}: options of {method!r} are not JSON: "
                             f"{brace + rest!r}") from None
    try:
        return Solver(method, options)
    except ValueError:
        raise ValueError(f"{argument}: expected one of {_names()}, got {text!r}") from None


def as_solver(value: object, argument: str = "solver") -> Solver:
    """A settings field's solver: a :class:`Solver` as it is, None the default, a name or
    key resolved by :func:`resolve_solver` (``"auto"``: a GPU where this machine sees one;
    a GPU method is not checked against this machine: its solves may run on Dask workers).

    Raises
    ------
    ValueError
        Naming ``argument``, for anything else.
    """
    if value is None:
        return default_solver()
    if isinstance(value, Solver):
        return value
    if isinstance(value, str) and "{" in value:
        return _parse_key(value, argument)
    if isinstance(value, str):
        device = "auto" if value == "auto" else None
        return resolve_solver(value, device, solver_argument=argument, local=False)
    raise ValueError(f"{argument}: expected one of {_names()} or a Solver, got {value!r}")


def _check_device(device: object, name: str) -> str:
    if device not in DEVICES:
        raise ValueError(f"{name}: expected one of {', '.join(map(repr, DEVICES))}, "
                         f"got {device!r}")
    return str(device)


def _method_on(solver: str, device: str) -> str:
    """The method that solves ``solver`` on a concrete ``device``."""
    if solver == "auto" or (solver == "fft" and device == "cuda"):
        return "gpu" if device == "cuda" else DEFAULT_SOLVER
    return solver


def resolve_solver(solver: str | Solver | None = DEFAULT_SOLVER, device: str | None = None,
                   *, solver_argument: str = "solver", device_argument: str = "device",
                   local: bool = True, **options: Any) -> Solver:
    """The :class:`Solver` that solves ``solver`` on ``device``; checked before any work.

    ``"fft"`` or ``"auto"`` on ``"cuda"`` is ``"gpu"`` (the FFT-preconditioned CG on the
    device); a CPU-only method on ``"cuda"`` is refused, as is ``"gpu"`` on ``"cpu"``. A
    solve on a CUDA device where this machine has none is refused in one line.

    Parameters
    ----------
    solver : str or Solver, optional
        A short name, ``"auto"``, a registered backend name or a Solver (None: the default).
    device : {"cpu", "cuda", "auto"}, optional
        Where to solve (``"auto"``: a CUDA device where one is seen, else the CPU); None:
        where ``solver`` runs (``"gpu"`` on CUDA, the others on :data:`DEFAULT_DEVICE`).
    solver_argument, device_argument : str
        The names the errors give the two arguments (e.g. ``--solver``, ``--device``).
    local : bool
        Whether the solves run on this machine, whose CUDA devices are then checked; False
        for solves on a remote Dask cluster (its workers declare their GPUs; ``"auto"``
        still looks at this machine).
    **options
        Backend options over the method's (e.g. ``dtype=np.float32``).

    Raises
    ------
    ValueError
        One line naming the argument at fault.
    """
    if isinstance(solver, Solver):
        options = {**solver.options, **options}
        solver = solver.method
    if solver is None:
        solver = DEFAULT_SOLVER
    if not isinstance(solver, str) or not (solver in SOLVERS or solver == "auto"
                                           or solver in available_backends()):
        raise ValueError(f"{solver_argument}: expected one of {_names()}, got {solver!r}")
    at_fault = device_argument if device is not None else solver_argument
    if device is None:
        device = "cuda" if solver == "gpu" else DEFAULT_DEVICE
    device = _check_device(device, device_argument)
    if device == "auto":
        on_device = solver == "gpu" or (solver in ("auto", "fft") and cuda_device_count() > 0)
        device = "cuda" if on_device else "cpu"
    method = _method_on(solver, device)
    runs_on = SOLVERS[method].device if method in SOLVERS else "cpu"
    if runs_on != device:
        other = "--device cuda" if runs_on == "cuda" else "--device cpu"
        raise ValueError(f"{device_argument}: the solver {method!r} runs on the "
                         f"{runs_on.upper()}, not on {device!r}; use {other}, or a solver "
                         f"for {device!r} ({', '.join(map(repr, solvers_for(device)))})")
    if device == "cuda" and local:
        require_cuda(f"solver {method!r}", at_fault)
    return Solver(method, options)


def solvers_for(device: str) -> tuple[str, ...]:
    """The short names that run on ``device`` (``"cpu"`` or ``"cuda"``)."""
    return tuple(n for n, c in SOLVERS.items() if c.device == device)
