"""The solve engine: full solves in-process or on a Dask cluster, each kept in a store.

Every full solve of identification (reduced-basis snapshots, anchors, replica scatter,
validation, discrepancy tables) is a :class:`SolveRequest`: an RVE (its particle table and
grid, :class:`RVEData`), a parameter set under the package's flat names, the contact model,
the solver choice and the tolerance. :meth:`SolveEngine.solve` looks each request up in the
:class:`SolveStore` (keyed by all of these), runs the missing ones -- serially in this
process, on a LocalCluster (``workers``) or on a running scheduler (``scheduler``) -- and
writes each finished solve at once as its own Parquet part (atomically; a kill loses at most
the solves in flight, a re-run redoes none that finished). A worker rebuilds an RVE's voxels
from its particle table and keeps one :class:`~itr_fv.discrete.problem.DiscreteProblem` per RVE and
contact model (the geometry is built once per RVE per worker, never once per solve).

Rows have the campaign's columns (:mod:`surrogate.runner`): the RVE id, contact, solver and
tolerance, the parameters under their flat names, ``k_xx`` ... ``k_zz``, ``k_iso``,
iterations, residual and wall time, plus the request's labels (purpose, formulation,
replica). Temperature fields, where asked for (reduced-basis snapshots), sit beside the row
as ``.npz`` (no pickle).

Where files are written: only here, on the client. A worker gets plain data (the RVE's
spheres, the parameters) and returns plain data (the tensor, iterations, theta); no path
is ever sent to a worker, and the store's folder is made absolute when the engine is made,
so a worker started in another directory or on another machine (no shared filesystem)
loses nothing. The campaign runner (:mod:`surrogate.runner`) works the same way.

Which cluster can run a solver is decided in one place, :func:`open_client` and
:func:`ready_workers`, for the engine and the campaign runner alike: a solver that needs a
GPU (:func:`itr_fv.solvers.choice.worker_resources`) gets a LocalCluster of one worker per
CUDA device, each declaring the resource ``GPU=1`` (none found: a one-line refusal), and on
an external scheduler at least one worker must declare ``GPU`` (else a one-line refusal
before anything is submitted; such tasks would otherwise wait forever).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import threading
import time
import warnings
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from itr_fv.discrete.problem import DiscreteProblem
from itr_fv.io import atomic_path, counted
from itr_fv.materials import Materials
from itr_fv.rve.contact_film import ContactFilm
from itr_fv.rve.microstructure import Microstructure
from itr_fv.solvers.choice import (
    check_solver,
    default_solver,
    needs_gpu,
    solver_backend,
    solver_choice,
    solvers_for,
    worker_resources,
)
from itr_fv.solvers.devices import cuda_device_count

from .store import rve_id, tensor_columns, tensor_of

__all__ = ["RVEData", "SolveRequest", "SolveResult", "SolveStore", "SolveEngine",
           "open_client", "ready_workers",
           "worker_memory_limit", "geometry_builds", "clear_problem_cache", "solve_row",
           "default_workers", "MAX_DEFAULT_WORKERS"]


@dataclass(frozen=True, eq=False)
class RVEData:
    """What a worker needs to rebuild an RVE's voxels: spheres and grid.

    Attributes
    ----------
    centers_m : ndarray, shape (P, 3)
        Sphere centres, m.
    radii_m : ndarray, shape (P,)
        Radii, m.
    materials : tuple of str
        Phase of every sphere.
    box_m : float
        Box edge, m.
    shape : (int, int, int)
        Voxels per axis.
    matrix : str
        Matrix phase.
    contact : ContactFilm
        Which pairs touch and the film they meet at.
    """

    centers_m: np.ndarray
    radii_m: np.ndarray
    materials: tuple[str, ...]
    box_m: float
    shape: tuple[int, int, int]
    matrix: str
    contact: ContactFilm = ContactFilm()

    @classmethod
    def of(cls, ms: Microstructure) -> RVEData:
        """The sphere data of a packed microstructure (needs its particle table)."""
        table = ms.particles
        if table is None:
            raise ValueError("ms: the engine needs the particle table of the microstructure "
                             "(a packed RVE, e.g. from itr_fv.rve.generate_rve)")
        box = float(np.asarray(ms.box_m, dtype=np.float64).ravel()[0])
        return cls(np.asarray(table.centers_m, dtype=np.float64),
                   np.asarray(table.radii_m, dtype=np.float64),
                   tuple(str(m) for m in table.material), box, tuple(ms.shape), ms.names[0],
                   table.contact)

    @property
    def rve_id(self) -> str:
        """Hash of the particle table and the grid (the campaign store's RVE identity)."""
        cached = self.__dict__.get("_id")
        if cached is None:
            cached = rve_id(self.centers_m, self.radii_m, list(self.materials), self.shape,
                            self.box_m / self.shape[0], self.contact)
            object.__setattr__(self, "_id", cached)
        return cached

    def microstructure(self) -> Microstructure:
        """The voxel image (the same voxels as the packing that produced the data)."""
        return Microstructure.from_spheres(self.centers_m, self.radii_m, list(self.materials),
                                           box_m=self.box_m, shape=self.shape,
                                           matrix=self.matrix, contact=self.contact)

    def to_payload(self) -> dict:
        return {"centers_m": self.centers_m.tolist(), "radii_m": self.radii_m.tolist(),
                "materials": list(self.materials), "box_m": self.box_m,
                "shape": list(self.shape), "matrix": self.matrix,
                "contact": self.contact.to_dict()}

    @classmethod
    def from_payload(cls, d: Mapping[str, Any]) -> RVEData:
        return cls(np.asarray(d["centers_m"], dtype=np.float64).reshape(-1, 3),
                   np.asarray(d["radii_m"], dtype=np.float64), tuple(d["materials"]),
                   float(d["box_m"]), tuple(int(n) for n in d["shape"]), str(d["matrix"]),
                   ContactFilm.from_dict(d.get("contact")))


@dataclass(frozen=True)
class SolveRequest:
    """One full solve: an RVE, a parameter set, a contact model, a solver and a tolerance.

    Attributes
    ----------
    rve : RVEData
    parameters : mapping of str to float
        Every conductivity and resistance under the flat names (``Materials.to_parameters``).
    contact : {"gap", "area"}
    tol : float
        Relative residual of the solve.
    solver : str
        A resolved solver choice of :mod:`itr_fv.solvers.choice` (its default by default).
    fields : bool
        Keep theta (the reduced basis's snapshots need it).
    labels : mapping
        Purpose, formulation, replica...: written with the row, not part of the key.
    """

    rve: RVEData
    parameters: Mapping[str, float]
    contact: str
    tol: float
    solver: str = field(default_factory=default_solver)
    fields: bool = False
    labels: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def for_materials(cls, rve: RVEData, mat: Materials, tol: float, *,
                      solver: str | None = None, fields: bool = False,
                      **labels: Any) -> SolveRequest:
        if mat.matrix != rve.matrix:
            raise ValueError(f"mat: matrix {mat.matrix!r} differs from the RVE's {rve.matrix!r}")
        return cls(rve, dict(mat.to_parameters()), mat.contact, float(tol), check_solver(solver),
                   bool(fields), dict(labels))

    def materials(self) -> Materials:
        return Materials.from_parameters(self.parameters, self.rve.matrix, contact=self.contact)

    @property
    def key(self) -> str:
        """The store key: RVE, parameters (to 12 significant digits), contact, solver, tol."""
        params = {k: float(f"{float(v):.12g}") for k, v in sorted(self.parameters.items())}
        text = json.dumps({"rve": self.rve.rve_id, "parameters": params,
                           "contact": self.contact, "solver": self.solver,
                           "tol": float(f"{self.tol:.6g}")}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:20]


@dataclass
class SolveResult:
    """A finished solve: the tensor (W/(m K)), its energy estimate, iterations, residual,
    seconds, theta (when asked for), whether it came from the store, and whether the worker
    built the RVE's geometry for it."""

    k_eff: np.ndarray
    k_eff_energy: np.ndarray
    iterations: list[int]
    residual: float
    wall_s: float
    theta: np.ndarray | None = None
    cached: bool = False
    geometry_built: bool = False

    @property
    def k_diagonal(self) -> np.ndarray:
        return np.diag(self.k_eff).copy()


# ---------------------------------------------------------------- worker side
#: Discrete problems kept per process, keyed by (rve id, contact); the least recently used
#: goes when they would hold more than PROBLEM_CACHE_BYTES.
_PROBLEMS: OrderedDict[tuple[str, str], DiscreteProblem] = OrderedDict()
#: Budget of the per-process problem cache, bytes (a problem is counted as
#: PROBLEM_BYTES_PER_VOXEL per voxel: measured 2.1-2.2 MB at 48^3 for the geometry and
#: 0.9 MB for the voxel labels, i.e. ~55 bytes per voxel).
PROBLEM_CACHE_BYTES = 2 * 10**9
PROBLEM_BYTES_PER_VOXEL = 64
_BUILDS = {"count": 0}


def geometry_builds() -> int:
    """Discrete problems (face geometries) this process has built for the engine."""
    return _BUILDS["count"]


def clear_problem_cache() -> None:
    """Forget this process's discrete problems (the next solve of an RVE builds it again)."""
    _PROBLEMS.clear()


def cached_problem(rve: RVEData, contact: str) -> tuple[DiscreteProblem, bool]:
    """The RVE's discrete problem under ``contact`` from this process's cache (built on a
    miss); returns (problem, built_now)."""
    key = (rve.rve_id, contact)
    problem = _PROBLEMS.get(key)
    if problem is not None:
        _PROBLEMS.move_to_end(key)
        return problem, False
    problem = DiscreteProblem(rve.microstructure(), contact=contact)
    _BUILDS["count"] += 1
    _PROBLEMS[key] = problem
    size = PROBLEM_BYTES_PER_VOXEL * math.prod(rve.shape)
    while len(_PROBLEMS) > 1 and len(_PROBLEMS) * size > PROBLEM_CACHE_BYTES:
        _PROBLEMS.popitem(last=False)
    return problem, True


def run_request(request: SolveRequest, threads: int | None = None) -> SolveResult:
    """Solve one request in this process (the problem from the cache); ``threads`` of the
    FFT backend (None: its default for the grid; a Dask worker uses 1)."""
    from itr_fv.checks import VoxelContactWarning
    from itr_fv.solvers.driver import homogenize

    problem, built = cached_problem(request.rve, request.contact)
    backend = solver_backend(request.solver, threads=threads,
                             voxels=math.prod(problem.shape))
    t = time.perf_counter()
    with warnings.catch_warnings():
        # the per-area model is tied to its voxel on purpose; its reports say so
        warnings.simplefilter("ignore", VoxelContactWarning)
        res = homogenize(problem, request.materials(), backend=backend, tol=request.tol,
                         store_fields=request.fields)
    return SolveResult(res.k_eff, res.k_eff_energy, list(res.iterations),
                       float(max(res.residuals)), time.perf_counter() - t,
                       np.stack(res.theta) if request.fields else None, False, built)


def _run_payload(payload: dict) -> dict:
    """Dask task: a request in plain data in, a result in plain data out."""
    req = SolveRequest(RVEData.from_payload(payload["rve"]), payload["parameters"],
                       payload["contact"], payload["tol"], payload["solver"],
                       payload["fields"], payload["labels"])
    res = run_request(req, threads=1)
    return {"k_eff": res.k_eff.tolist(), "k_eff_energy": res.k_eff_energy.tolist(),
            "iterations": res.iterations, "residual": res.residual, "wall_s": res.wall_s,
            "theta": res.theta, "geometry_built":
            res.geometry_built, "worker_pid": os.getpid()}


def _payload(req: SolveRequest) -> dict:
    return {"rve": req.rve.to_payload(), "parameters": dict(req.parameters),
            "contact": req.contact, "tol": req.tol, "solver": req.solver,
            "fields": req.fields, "labels": dict(req.labels)}


def solve_row(request: SolveRequest, result: SolveResult) -> dict[str, Any]:
    """One finished solve as the store's row: the request's key, RVE, contact, solver and
    tolerance, its labels, the flat parameters, the tensor (:func:`tensor_columns`),
    iterations, residual and wall time (the campaign row's columns where they are shared).
    The one record format of a full solve: the store writes it and a run's
    ``full_solves.parquet`` lists it."""
    from itr_fv import __version__

    row: dict[str, Any] = {"key": request.key, "rve_id": request.rve.rve_id,
                           "n": request.rve.shape[0],
                           "voxel_um": request.rve.box_m / request.rve.shape[0] * 1e6,
                           "box_um": request.rve.box_m * 1e6, "contact": request.contact,
                           "solver": request.solver, "tol": request.tol,
                           "package_version": __version__}
    row.update({str(k): (json.dumps(v) if isinstance(v, (list, dict)) else v)
                for k, v in request.labels.items()})
    row.update({k: float(v) for k, v in sorted(request.parameters.items())})
    row.update(tensor_columns(result.k_eff))
    row.update({"k_energy_json": json.dumps(np.asarray(result.k_eff_energy).tolist()),
                "iterations": int(max(result.iterations, default=0)),
                "iterations_json": json.dumps([int(i) for i in result.iterations]),
                "residual": float(result.residual), "wall_s": float(result.wall_s)})
    return row


# ---------------------------------------------------------------- the store
class SolveStore:
    """Finished solves in a folder: ``solves/<key>.parquet`` (one row each) and
    ``fields/<key>.npz`` (theta, where asked for), each written atomically, by the client
    (``folder`` is made absolute at once)."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder).absolute()

    def _row_path(self, key: str) -> Path:
        return self.folder / "solves" / f"{key}.parquet"

    def _field_path(self, key: str) -> Path:
        return self.folder / "fields" / f"{key}.npz"

    def get(self, request: SolveRequest) -> SolveResult | None:
        """The stored result of ``request`` (None if not finished, or fields missing)."""
        key = request.key
        path = self._row_path(key)
        if not path.is_file():
            return None
        theta = None
        if request.fields:
            fpath = self._field_path(key)
            if not fpath.is_file():
                return None
            with np.load(fpath, allow_pickle=False) as data:
                theta = data["theta"]
        row = pq.read_table(path).to_pylist()[0]
        k = tensor_of(row)
        ke = np.array(json.loads(row["k_energy_json"]))
        return SolveResult(k, ke, json.loads(row["iterations_json"]), row["residual"],
                           row["wall_s"], theta, True, False)

    def put(self, request: SolveRequest, result: SolveResult) -> None:
        """Write one finished solve (fields first, so a row always has its fields)."""
        key = request.key
        if request.fields and result.theta is not None:
            self._field_path(key).parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(self._field_path(key)) as tmp, open(tmp, "wb") as fh:
                np.savez(fh, theta=result.theta)
        row = solve_row(request, result)
        path = self._row_path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            pq.write_table(pa.Table.from_pylist([row]), tmp)

    def _rows(self) -> list[Path]:
        folder = self.folder / "solves"
        if not folder.is_dir():
            return []
        # partial files of a killed write start with a dot (itr_fv.io.atomic_path)
        return sorted(p for p in folder.glob("*.parquet") if not p.name.startswith("."))

    def count(self) -> int:
        """Finished solves in the store."""
        return len(self._rows())

    def _fields(self) -> list[Path]:
        folder = self.folder / "fields"
        return sorted(folder.glob("*.npz")) if folder.is_dir() else []

    def field_count(self) -> tuple[int, int]:
        """(number, bytes) of the stored fields."""
        files = self._fields()
        return len(files), sum(f.stat().st_size for f in files)

    def drop_fields(self) -> tuple[int, int]:
        """Remove every stored field (the rows stay: a request that keeps fields is then
        solved again, one that does not is still answered); returns (number, bytes)."""
        n, size = self.field_count()
        for f in self._fields():
            f.unlink(missing_ok=True)
        return n, size

    def table(self) -> pa.Table:
        """Every stored solve as one table (columns of all rows)."""
        files = self._rows()
        if not files:
            return pa.table({})
        return pa.concat_tables([pq.read_table(f) for f in files], promote_options="default")


# ---------------------------------------------------------------- the engine
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


def _gpu_refusal(solver: str, why: str, scheduler: str | None = None) -> str:
    start = f"'dask worker {scheduler or 'ADDRESS'} --resources GPU=1' (one per GPU)"
    others = " or ".join(map(repr, solvers_for("cpu")[:2]))
    if scheduler:
        return (f"solver {solver!r} solves on a GPU, but {why}; start GPU workers with "
                f"{start}, or choose another solver (e.g. {others})")
    return (f"solver {solver!r} solves on a GPU, but {why}; choose another solver (e.g. "
            f"{others}), or use --scheduler with GPU workers started as {start}")


#: Local Dask workers at most where none are asked for.
MAX_DEFAULT_WORKERS = 4


def default_workers() -> int:
    """Local Dask workers where none are asked for: the cores, at most
    :data:`MAX_DEFAULT_WORKERS` (fewer where memory is short: :func:`open_client`)."""
    return max(1, min(os.cpu_count() or 1, MAX_DEFAULT_WORKERS))


def open_client(workers: int | None, scheduler: str | None, *, memory_per_worker: int,
                echo: Callable[[str], None] = print, solver: str | None = None):
    """A dask client on ``scheduler``, or on a new LocalCluster of ``workers`` processes
    (fewer if ``memory_per_worker`` bytes each do not fit); returns (client, cluster or None).

    With a ``solver`` that needs a GPU (:func:`needs_gpu`), the LocalCluster has one worker
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

    gpu = needs_gpu(solver)
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


def ready_workers(client, scheduler: str | None, solver: str | None = None, *,
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
    if needs_gpu(solver) and not any((w.get("resources") or {}).get("GPU", 0) >= 1
                                     for w in workers.values()):
        why = (f"no worker of --scheduler {scheduler!r} ({counted(len(workers), 'worker')} "
               "connected) declares the resource GPU" if scheduler
               else "the local cluster has no GPU worker")
        raise ValueError(_gpu_refusal(solver, why, scheduler))
    return len(workers)


class SolveEngine:
    """Runs full solves where they are asked to run, and remembers every finished one.

    Parameters
    ----------
    store : path or SolveStore, optional
        Where finished solves are kept (none: nothing is kept across runs).
    workers : int, optional
        Solve on a LocalCluster of this many processes (None and no ``scheduler``: serially
        in this process, the fastest on 2 cores for the default sizes).
    scheduler : str, optional
        Address of a running dask scheduler (``tcp://host:port``); connected at once
        (ValueError ``--scheduler: cannot reach ...`` if it does not answer).
    echo : callable
        Where one-line messages go.

    Attributes
    ----------
    solved : int
        Full solves this engine ran.
    repeated : int
        Requests answered by a solve of this engine (its stored row, or a duplicate in one
        call): no new solve, but no work of an earlier run either.
    earlier : int
        Requests answered from the store by a row this engine did not write (an earlier
        run's, or another process's).
    """

    def __init__(self, store: str | Path | SolveStore | None = None, *,
                 workers: int | None = None, scheduler: str | None = None,
                 echo: Callable[[str], None] = print) -> None:
        if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                    or workers < 1):
            raise ValueError(f"workers: expected a whole number >= 1, got {workers!r}")
        self.store = store if isinstance(store, SolveStore) or store is None \
            else SolveStore(store)
        self.workers = workers
        self.scheduler = scheduler
        self.echo = echo
        self._client = self._cluster = None
        self._lock = threading.Lock()  # models may be built from several threads
        self.solved = self.repeated = self.earlier = 0
        self._written: set[str] = set()   # keys of the rows this engine solved
        self._worker_builds = 0
        self._side_processes = 0
        self._local_builds0 = geometry_builds()
        if scheduler:  # refuse an unreachable scheduler before any work
            self._client, self._cluster = open_client(None, scheduler, memory_per_worker=1,
                                                      echo=echo)

    @property
    def reused(self) -> int:
        """Requests answered without a new solve: :attr:`repeated` plus :attr:`earlier`."""
        return self.repeated + self.earlier

    @property
    def distributed(self) -> bool:
        return bool(self.workers or self.scheduler)

    def _ensure_client(self, shape: Sequence[int], solver: str | None = None):
        """The client (a LocalCluster made on first use, with GPU workers where ``solver``
        needs them), checked by :func:`ready_workers` for ``solver`` before any submit."""
        from itr_fv.solvers.resources import estimate_peak_memory

        # sized by the backend's name: the client may have no GPU (its workers do)
        backend = solver_choice(solver).backend
        need = worker_memory_limit(estimate_peak_memory(shape, backend, store_fields=True))
        with self._lock:
            if self._client is None:
                self._client, self._cluster = open_client(
                    self.workers, self.scheduler, memory_per_worker=need, echo=self.echo,
                    solver=solver)
            ready_workers(self._client, self.scheduler, solver, memory_per_worker=need)
            return self._client

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
        if self._cluster is not None:
            self._cluster.close()
        self._client = self._cluster = None

    def __enter__(self) -> SolveEngine:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def solve(self, requests: Sequence[SolveRequest],
              tick: Callable[[], None] | None = None) -> list[SolveResult]:
        """Results of ``requests`` in order: from the store where finished, else solved
        (in parallel on the cluster) and stored one by one as they finish."""
        out: list[SolveResult | None] = [None] * len(requests)
        todo: dict[str, list[int]] = {}
        for i, req in enumerate(requests):
            hit = self.store.get(req) if self.store is not None else None
            if hit is not None:
                out[i] = hit
                self._count_hit(req.key)
                if tick is not None:
                    tick()
            else:
                todo.setdefault(req.key, []).append(i)
        if todo:
            first = {key: requests[idx[0]] for key, idx in todo.items()}
            for key, res in self._run(first):
                if self.store is not None:
                    self.store.put(first[key], res)
                with self._lock:
                    self.solved += 1
                    self.repeated += len(todo[key]) - 1   # the same request twice in one call
                    self._written.add(key)
                    if self.distributed:
                        self._worker_builds += int(res.geometry_built)
                for i in todo[key]:
                    out[i] = res
                    if tick is not None:
                        tick()
        return out  # type: ignore[return-value]

    def _count_hit(self, key: str) -> None:
        """Count a request the store answered: a repeat of this engine's own solve, or a
        row of an earlier run."""
        with self._lock:
            if key in self._written:
                self.repeated += 1
            else:
                self.earlier += 1

    def solve_one(self, request: SolveRequest) -> SolveResult:
        return self.solve([request])[0]

    def _run(self, requests: Mapping[str, SolveRequest]):
        if not self.distributed:
            for key, req in requests.items():
                yield key, run_request(req)
            return
        from dask.distributed import as_completed

        shape = next(iter(requests.values())).rve.shape
        # a GPU solver among them decides the cluster (and is refused before any submit)
        solver = next((r.solver for r in requests.values() if needs_gpu(r.solver)),
                      next(iter(requests.values())).solver)
        client = self._ensure_client(shape, solver)
        futures = {client.submit(_run_payload, _payload(req), key=f"itr-solve-{key}",
                                 pure=False, resources=worker_resources(req.solver)): key
                   for key, req in requests.items()}
        for fut in as_completed(futures):
            d = fut.result()
            yield futures[fut], SolveResult(
                np.asarray(d["k_eff"]), np.asarray(d["k_eff_energy"]), d["iterations"],
                d["residual"], d["wall_s"],
                None if d["theta"] is None else np.asarray(d["theta"]), False,
                d["geometry_built"])

    def counts(self) -> dict[str, Any]:
        """What this engine did, for another engine on the same store to add
        (:meth:`absorb`): its full solves, repeats, answers from an earlier run's store, the
        keys it wrote and its geometry builds."""
        return {"solved": self.solved, "repeated": self.repeated, "earlier": self.earlier,
                "written": sorted(self._written), "geometry_builds": self.geometry_builds}

    def absorb(self, counts: Mapping[str, Any]) -> None:
        """Add the :meth:`counts` of an engine that ran in a side process of this run on the
        same store (its solves are this run's: a later request for one repeats it)."""
        with self._lock:
            self.solved += int(counts["solved"])
            self.repeated += int(counts["repeated"])
            self.earlier += int(counts["earlier"])
            self._written.update(counts["written"])
            self._worker_builds += int(counts["geometry_builds"])
            self._side_processes += 1

    @property
    def geometry_builds(self) -> int:
        """Discrete problems built since this engine started: in this process (its solves
        and the reduced bases' problems) plus those the workers and side processes
        report."""
        return geometry_builds() - self._local_builds0 + self._worker_builds

    def summary(self) -> str:
        """One line: the full solves of this run and where they ran, the requests that
        repeated one of them, those an earlier run's store answered, the geometry builds;
        e.g. ``330 full solves in this process (32 requests repeated a solve of this run),
        none from an earlier run, 24 geometry builds``."""
        where = (f"on scheduler {self.scheduler}" if self.scheduler else
                 f"on {self.workers} local workers" if self.workers else
                 f"in this process and {counted(self._side_processes, 'side process', 'side processes')}"
                 if self._side_processes else "in this process")
        repeated = (f" ({counted(self.repeated, 'request')} repeated a solve of this run)"
                    if self.repeated else "")
        earlier = (f"{counted(self.earlier, 'request')} from the store of an earlier run"
                   if self.earlier else "none from an earlier run")
        return (f"{counted(self.solved, 'full solve')} {where}{repeated}, {earlier}, "
                f"{counted(self.geometry_builds, 'geometry build')}")

