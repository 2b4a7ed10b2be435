"""The solve engine: full solves in-process or on a Dask cluster, each kept in a store.

Every full solve of identification (reduced-basis snapshots, anchors, replica scatter,
validation, discrepancy tables) is a :class:`~surrogate.requests.SolveRequest`.
:meth:`SolveEngine.solve` looks each request up in the
:class:`~surrogate.store.SolveStore` (keyed by RVE, parameters, contact, solver and
tolerance), runs the missing ones -- serially in this process, on a LocalCluster
(``workers``) or on a running scheduler (``scheduler``, set up by :mod:`surrogate.cluster`)
-- and writes each finished solve at once as its own Parquet part (atomically; a kill loses
at most the solves in flight, a re-run redoes none that finished).

Where files are written: only here, on the client. A worker gets plain data (the RVE's
spheres, the parameters) and returns plain data (:mod:`surrogate.worker`); no path is ever
sent to a worker, and the store's folder is made absolute when the engine is made, so a
worker started in another directory or on another machine (no shared filesystem) loses
nothing. The campaign runner (:mod:`surrogate.runner`) works the same way.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from itr_fv.io import counted
from itr_fv.solvers.choice import Solver

from .cluster import open_client, ready_workers, worker_memory_limit
from .requests import SolveRequest, SolveResult, request_payload, result_of_payload
from .store import SolveStore
from .worker import geometry_builds, run_payload, run_request

__all__ = ["SolveEngine"]


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

    def ready(self, solver: Solver, memory_per_worker: int) -> int:
        """Workers of this engine's cluster once it can run ``solver``'s tasks of
        ``memory_per_worker`` bytes (a worker's limit, :func:`worker_memory_limit`): a
        LocalCluster is made on first use (with GPU workers where ``solver`` needs them) and
        checked by :func:`ready_workers` before anything is submitted (ValueError, one
        line)."""
        with self._lock:
            if self._client is None:
                self._client, self._cluster = open_client(
                    self.workers, self.scheduler, memory_per_worker=memory_per_worker,
                    echo=self.echo, solver=solver)
            return ready_workers(self._client, self.scheduler, solver,
                                 memory_per_worker=memory_per_worker)

    def run_tasks(self, fn: Callable[..., Any], args: Mapping[str, tuple], *,
                  solver: Solver, memory_per_worker: int,
                  resources: Mapping[str, dict[str, int] | None] | None = None
                  ) -> Iterator[tuple[str, Any]]:
        """Run ``fn(*args[key])`` for every key on this engine's cluster (:meth:`ready`
        first); yields ``(key, future)`` as each finishes, for the caller to take its result
        or its error and release it. ``resources``: each task's Dask worker resources
        (default: ``solver``'s). The one Dask path of the package: the engine's solves and
        the campaign runner's tasks go through it."""
        from dask.distributed import as_completed

        self.ready(solver, memory_per_worker)
        futures = {self._client.submit(fn, *task, key=key, pure=False,
                                       resources=(solver.resources if resources is None
                                                  else resources[key])): key
                   for key, task in args.items()}
        for fut in as_completed(futures):
            yield futures[fut], fut

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
        from itr_fv.solvers.resources import estimate_peak_memory

        first = next(iter(requests.values()))
        # a GPU solver among them decides the cluster (and is refused before any submit);
        # sized by the backend's name: the client may have no GPU (its workers do)
        solver = next((r.solver for r in requests.values() if r.solver.needs_gpu),
                      first.solver)
        need = worker_memory_limit(estimate_peak_memory(first.rve.shape, solver.entry.backend,
                                                        store_fields=True))
        tasks = {f"itr-solve-{key}": (request_payload(req),) for key, req in requests.items()}
        resources = {f"itr-solve-{key}": req.solver.resources for key, req in requests.items()}
        for name, fut in self.run_tasks(run_payload, tasks, solver=solver,
                                        memory_per_worker=need, resources=resources):
            yield name[len("itr-solve-"):], result_of_payload(fut.result())

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
        sides = counted(self._side_processes, "side process", "side processes")
        where = (f"on scheduler {self.scheduler}" if self.scheduler else
                 f"on {self.workers} local workers" if self.workers else
                 f"in this process and {sides}" if self._side_processes else "in this process")
        repeated = (f" ({counted(self.repeated, 'request')} repeated a solve of this run)"
                    if self.repeated else "")
        earlier = (f"{counted(self.earlier, 'request')} from the store of an earlier run"
                   if self.earlier else "none from an earlier run")
        return (f"{counted(self.solved, 'full solve')} {where}{repeated}, {earlier}, "
                f"{counted(self.geometry_builds, 'geometry build')}")

