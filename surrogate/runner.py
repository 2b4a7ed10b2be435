"""Run a campaign on dask.distributed: a LocalCluster by default, or an existing scheduler.

A task (:class:`~itr_surrogate.campaign.Task`) is one RVE and a block of parameter sets. On a
worker, :func:`run_task` packs and voxelizes the RVE (seeded: the same table every time),
builds its :class:`~itr_fv.discrete.problem.DiscreteProblem` once, and solves the block's parameter
sets in order, each warm-started from the nearest set already solved in the task. It writes
nothing: it returns the rows and the RVE's particle table to the client. The driver
(:func:`run_campaign`) submits the tasks whose part file is missing through the solve
engine's cluster (:meth:`~itr_surrogate.engine.SolveEngine.run_tasks`, the package's one
Dask path), shows a progress bar,
and, as each task finishes, writes its RVE table and its rows as one Parquet part file,
atomically (:class:`~itr_surrogate.store.CampaignStore`, whose folder is absolute in the
client's working directory); a failure is recorded without stopping the others. No path
goes to a worker, so workers started in any directory, on machines without a shared
filesystem, lose nothing. At the end every task reported done must have its part file
(else a :class:`~itr_surrogate.campaign.CampaignError` names the missing ones).

Results do not depend on the number of workers or threads: the solvers' reductions are
ordered (``itr_fft._kernels``), every RVE comes from its seed, and a task always solves its
block from the same cold start.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Collection
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from itr_fv.io import counted
from itr_fv.materials.parameters import parse_parameter
from itr_fv.rve import PackedRVE, build_rve

from .campaign import Campaign, CampaignError, Task, nearest_solved
from .engine import SolveEngine
from .rows import rve_id, tensor_columns
from .store import CampaignStore

__all__ = ["run_campaign", "run_task", "run_tasks_here", "write_task_result", "campaign_rve",
           "RunSummary", "worker_memory"]


@dataclass(frozen=True)
class RunSummary:
    """What one ``run_campaign`` call did."""

    tasks_run: int
    tasks_skipped: int
    tasks_failed: int
    solves: int
    wall_s: float
    workers: int


def _backend(camp: Campaign):
    """The campaign's solver backend (its :class:`~itr_fv.solvers.choice.Solver`'s)."""
    return camp.solver.backend(camp.threads_per_worker)


def campaign_rve(camp: Campaign, formulation: str, replica: int) -> PackedRVE:
    """The RVE that a campaign's tasks solve for one formulation and replica
    (:func:`itr_fv.rve.build_rve` of the campaign's RVE specification: the same particles
    as in the campaign's results) and the packing seed that made it."""
    if formulation not in {f.name for f in camp.formulations} or not (
            isinstance(replica, int) and 0 <= replica < camp.replicas):
        raise ValueError(f"formulation/replica: the campaign {camp.name!r} has no RVE "
                         f"({formulation!r}, replica {replica})")
    # the box cut of the coarse tail: reported by the report, not a warning per task
    return build_rve(camp.rve, camp.formulation(formulation).specs(), replica,
                     matrix=camp.matrix, warn_box_cut=False)


def run_task(camp: Campaign, task: Task, packed: PackedRVE | None = None) -> dict:
    """Solve one task; returns ``{"task_id", "solves", "wall_s", "rows", "rve"}``: the
    part's rows and the RVE's particle table (``"rve"``: ``rid``, ``centers_m``,
    ``radii_m``, ``materials``, ``meta``), for the client to write.

    Runs on a dask worker, with the campaign as the client holds it (its formulations,
    size distributions and base values already those of its material system: a worker
    reads no system of its own); it writes no file. ``packed``: the task's RVE where it was
    packed elsewhere
    (:func:`campaign_rve` of the same campaign, formulation and replica, e.g. in a pool of
    processes ahead of a GPU); default: packed here.
    """
    from itr_fv import __version__, homogenize
    from itr_fv.discrete.problem import DiscreteProblem

    t0 = time.perf_counter()
    ms, seed = packed if packed is not None else campaign_rve(camp, task.formulation,
                                                              task.replica)
    table = ms.particles
    rid = rve_id(table.centers_m, table.radii_m, list(table.material), ms.shape, ms.voxel_m,
                 table.contact)
    rve = {"rid": rid, "centers_m": np.asarray(table.centers_m, dtype=np.float64),
           "radii_m": np.asarray(table.radii_m, dtype=np.float64),
           "materials": [str(m) for m in table.material],
           "meta": {"formulation": task.formulation, "replica": task.replica,
                    "seed": seed, "box_um": camp.box_um, "voxel_um": camp.voxel_um,
                    "shape": list(ms.shape), "matrix": camp.matrix,
                    "contact": table.contact.to_dict()}}
    problem = DiscreteProblem(ms, contact=camp.contact)
    backend = _backend(camp)
    sets = camp.parameter_sets(camp.formulation(task.formulation))
    solved, thetas, rows = [], [], []
    for i in task.set_indices:
        pset = sets[i]
        mat = camp.materials(pset)
        near = nearest_solved(pset, solved)
        t = time.perf_counter()
        res = homogenize(problem, mat, solver=backend, tol=camp.tol,
                         x0=None if near is None else thetas[near])
        wall = time.perf_counter() - t
        solved.append(pset)
        thetas.append(np.stack(res.theta))
        rows.append(_row(camp, task, i, rid, mat, res, wall, near is not None, __version__)
                    | {"seed": seed})
    return {"task_id": task.task_id, "solves": len(rows), "wall_s": time.perf_counter() - t0,
            "rows": rows, "rve": rve}


def write_task_result(store: CampaignStore, result: dict) -> Path:
    """Write what :func:`run_task` returned into ``store`` (on the client): the RVE's
    particle table first, then the part file (each atomically); returns the part's path."""
    rve = result["rve"]
    store.write_rve(rve["rid"], np.asarray(rve["centers_m"], dtype=np.float64).reshape(-1, 3),
                    np.asarray(rve["radii_m"], dtype=np.float64), list(rve["materials"]),
                    rve["meta"])
    return store.write_part(result["task_id"], result["rows"])


def _row(camp: Campaign, task: Task, index: int, rid: str, mat, res, wall: float,
         warm: bool, version: str) -> dict:
    k = res.k_eff
    row = {"formulation": task.formulation, "replica": task.replica, "set_index": index,
           "seed": task.seed, "task_id": task.task_id, "rve_id": rid, "box_um": camp.box_um,
           "voxel_um": camp.voxel_um, "n": camp.shape[0], "contact": camp.contact,
           "solver": res.solver, "tol": camp.tol, "package_version": version}
    phases = {camp.matrix, *camp.formulation(task.formulation).fractions}
    row.update({name: float(v) for name, v in sorted(mat.to_parameters().items())
                if set(parse_parameter(name)[1]) <= phases})
    row.update(tensor_columns(k))
    row.update({"iterations": int(max(res.iterations)),
                "iterations_total": int(sum(res.iterations)),
                "residual": float(max(res.residuals)), "warm_start": warm, "wall_s": wall})
    return row


def local_workers(workers: int | None) -> int | None:
    """The local Dask workers of a run given ``workers`` (the ``--workers`` option): None
    for 0 (every task in this process), else ``workers`` or, where it is None, the default
    of :func:`itr_surrogate.cluster.open_client` (the cores, at most
    :data:`~itr_surrogate.cluster.MAX_DEFAULT_WORKERS`)."""
    from .cluster import default_workers

    if workers == 0:
        return None
    return workers or default_workers()


def worker_memory(camp: Campaign) -> int:
    """Memory limit of a worker, bytes: the solver's peak estimate with the fields kept plus
    the warm-start fields of a block, sized by :func:`surrogate.cluster.worker_memory_limit`
    (interpreter and allocator slack added, peak kept at dask's pause mark)."""
    from itr_fv.solvers.resources import estimate_peak_memory

    from .cluster import worker_memory_limit

    # a GPU solver's backend is sized by name: the client that sizes the workers may have no
    # GPU (its workers do), and a GPU worker's host memory is at most the CPU run's
    backend = camp.solver.entry.backend if camp.solver.needs_gpu else _backend(camp)
    peak = estimate_peak_memory(camp.shape, backend, store_fields=True)
    fields = 3 * 8 * int(np.prod(camp.shape)) * camp.block_size
    return worker_memory_limit(peak + fields)


def run_campaign(campaign: Campaign, folder: str | Path, *, workers: int | None = None,
                 scheduler: str | None = None, progress: bool = True,
                 echo: Callable[[str], None] = print,
                 skip: Collection[str] = ()) -> RunSummary:
    """Run every task of ``campaign`` whose results are not yet in ``folder`` (nor among
    ``skip``).

    Parameters
    ----------
    campaign : Campaign
    folder : path
        Campaign folder (created; must be new or hold this same campaign).
    workers : int, optional
        Workers of the LocalCluster (default: the cores, at most 4; fewer if memory is
        short); 0: every task in this process, one after the other, without Dask (a
        machine with one GPU and no Dask). Ignored with ``scheduler``.
    scheduler : str, optional
        Address of a running dask scheduler (``tcp://host:port``) to use instead.
    progress : bool
        Show a progress bar with ETA on standard error.
    echo : callable
        Where the one-line messages go.
    skip : collection of str
        Task ids solved elsewhere (another machine's store of the same campaign, e.g. a
        GPU's): left out here and counted as done.

    Returns
    -------
    RunSummary
    """
    t0 = time.perf_counter()
    store = CampaignStore(folder)  # absolute in this (the client's) working directory
    store.check_for(campaign)
    tasks = campaign.tasks()
    done = store.done_tasks() | set(skip)
    todo = [t for t in tasks if t.task_id not in done]
    if not todo:
        echo(f"campaign {campaign.name}: all {len(tasks)} tasks are done; nothing to solve")
        return RunSummary(0, len(tasks), 0, 0, time.perf_counter() - t0, 0)
    if workers == 0 and scheduler is None:
        return _run_here(campaign, store, todo, len(tasks), progress, echo, t0)
    try:
        engine = SolveEngine(workers=None if scheduler else local_workers(workers),
                             scheduler=scheduler, echo=echo)
        with engine:
            n_workers = engine.ready(campaign.solver, worker_memory(campaign))
            store.open_for(campaign)
            store.remove_partial_files()
            echo(f"campaign {campaign.name}: {len(todo)} of {len(tasks)} tasks to run "
                 f"({sum(len(t.set_indices) for t in todo)} solves on {campaign.shape[0]}^3 "
                 f"voxels, {counted(n_workers, 'worker')})")
            solves, failed, written = _execute(engine, campaign, todo, store, progress)
    except ValueError as err:   # the cluster's one-line refusals, before any submit
        raise CampaignError(str(err)) from None
    missing = sorted(t for t in written if not store.part_path(t).is_file())
    if missing:
        raise CampaignError(f"{counted(len(missing), 'task')} reported done without a part file in "
                            f"{str(store.folder / 'parts')!r}: {', '.join(missing)}")
    summary = RunSummary(len(todo) - failed, len(tasks) - len(todo), failed, solves,
                         time.perf_counter() - t0, n_workers)
    echo(f"campaign {campaign.name}: {summary.tasks_run} tasks ({solves} solves) in "
         f"{summary.wall_s:.1f} s on {counted(n_workers, 'worker')}; {failed} failed")
    return summary


def run_tasks_here(campaign: Campaign, store: CampaignStore, todo: list[Task], *,
                   progress: bool = False) -> tuple[int, int, list[str]]:
    """Run ``todo`` in this process, one task after the other, each task's part written as
    it finishes (a killed run keeps every finished task); a task's failure is recorded as
    on a cluster. Returns (solves, failures, the tasks written)."""
    from tqdm import tqdm

    failed = solves = 0
    written: list[str] = []
    for task in tqdm(todo, unit="task", disable=not progress, desc=campaign.name):
        try:
            result = run_task(campaign, task)
        except Exception as exc:  # noqa: BLE001 - a task's failure is recorded, not fatal
            failed += 1
            store.record_failure(task.task_id, f"{type(exc).__name__}: {exc}")
            continue
        write_task_result(store, result)
        written.append(result["task_id"])
        solves += result["solves"]
    return solves, failed, written


def _run_here(campaign: Campaign, store: CampaignStore, todo: list[Task], n_tasks: int,
              progress: bool, echo: Callable, t0: float) -> RunSummary:
    store.open_for(campaign)
    store.remove_partial_files()
    echo(f"campaign {campaign.name}: {len(todo)} of {n_tasks} tasks to run in this process "
         f"({sum(len(t.set_indices) for t in todo)} solves on {campaign.shape[0]}^3 voxels)")
    solves, failed, _ = run_tasks_here(campaign, store, todo, progress=progress)
    summary = RunSummary(len(todo) - failed, n_tasks - len(todo), failed, solves,
                         time.perf_counter() - t0, 1)
    echo(f"campaign {campaign.name}: {summary.tasks_run} tasks ({solves} solves) in "
         f"{summary.wall_s:.1f} s in this process; {failed} failed")
    return summary


def _execute(engine: SolveEngine, campaign: Campaign, todo: list[Task], store: CampaignStore,
             progress: bool) -> tuple[int, int, list[str]]:
    """Submit the tasks through the engine's cluster, write each finished task's part here
    on the client, record each failure, show progress; returns (solves, failures, the
    tasks written)."""
    from tqdm import tqdm

    prefix = f"itr-{campaign.fingerprint()[:8]}-"
    failed = solves = 0
    written: list[str] = []
    tasks = {prefix + t.task_id: (campaign, t) for t in todo}
    with tqdm(total=len(todo), unit="task", disable=not progress, desc=campaign.name) as bar:
        for key, fut in engine.run_tasks(run_task, tasks, solver=campaign.solver,
                                         memory_per_worker=worker_memory(campaign)):
            task_id = key[len(prefix):]
            try:
                result = fut.result()
            except Exception as exc:  # noqa: BLE001 - a task's failure is recorded, not fatal
                failed += 1
                store.record_failure(task_id, f"{type(exc).__name__}: {exc}")
            else:
                write_task_result(store, result)  # a write error here is fatal: loud
                written.append(result["task_id"])
                solves += result["solves"]
            fut.release()  # its rows are on disk: free them on the worker and here
            bar.update(1)
            bar.set_postfix(solves=solves, failed=failed)
    return solves, failed, written
