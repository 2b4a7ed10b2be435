"""The parametrisations of one run identified side by side, one process each.

``itr reproduce`` (and ``itr identify`` under both parametrisations) identifies the data
under parametrisations that share nothing but the measurements and the store of full
solves: each one's RVEs, reduced bases and posterior samplings (the identification's, the
floor's, leave-one-out's) are its own. Most of that work is single-threaded (the sampler's
steps, the reduced bases' greedy loop) or runs faster on one thread than on two (the 48^3
full solves of the default RVE: 0.44 s on one thread, 0.51 s on two, 2 cores), so on a
machine with two cores or more each parametrisation runs in a spawned process of its own,
solving on one thread (:data:`ONE_THREAD` set to 1 in its environment). Its one-line messages
come to this process's ``echo`` as they are written; its full solves go to the same store
(each keyed by its request, so the processes never write one file); its identification
comes back with the models tied to this process's engine, and its engine's counts are
added to this one's (:meth:`~itr_surrogate.engine.SolveEngine.absorb`).

Every seed is the one a serial run uses; the numbers are a serial run's up to the
rounding of the solver's reductions on one thread instead of two.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any

from ..forward.work_estimate import side_by_side_possible

__all__ = ["identify_side_by_side", "side_by_side_possible", "tie_to"]

#: Where a side process's lines go (set in the process by :func:`_start`).
_LINES = None


def _start(lines) -> None:
    global _LINES
    _LINES = lines


def _echo(line: str) -> None:
    _LINES.put(line)


#: The thread counts a side process starts with: numba's (the solver's kernels and the
#: chunked posterior evaluations) and the BLAS libraries' (NumPy's matrix products).
ONE_THREAD = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
              "MKL_NUM_THREADS")


@contextmanager
def _one_thread_children() -> Iterator[None]:
    """Processes started inside run on one thread (:data:`ONE_THREAD` in their
    environment); this process's environment is restored after."""
    old = {name: os.environ.get(name) for name in ONE_THREAD}
    os.environ.update(dict.fromkeys(ONE_THREAD, "1"))
    try:
        yield
    finally:
        for name, value in old.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _forward(lines, echo: Callable[[str], None]) -> None:
    """Hand each line of the side processes to ``echo`` until the closing None."""
    while (line := lines.get()) is not None:
        echo(line)


def identify_side_by_side(job: Callable[..., Any], parametrisations: list[str], *,
                          echo: Callable[[str], None], **kwargs) -> dict[str, dict]:
    """``job(parametrisation, echo=..., **kwargs)`` of each parametrisation in a spawned
    process of its own (module notes); ``job`` is a module-level function returning a dict.
    Returns each parametrisation's dict, in the order given, with ``process_wall_s`` (the
    job's wall in its process, s) added."""
    ctx = multiprocessing.get_context("spawn")
    lines = ctx.Queue()
    reader = threading.Thread(target=_forward, args=(lines, echo), daemon=True)
    reader.start()
    pool = ProcessPoolExecutor(len(parametrisations), mp_context=ctx, initializer=_start,
                               initargs=(lines,))
    try:
        with _one_thread_children():   # each submit starts its process, in this environment
            futures = {p: pool.submit(_timed, job, p, **kwargs) for p in parametrisations}
        return {p: futures[p].result() for p in parametrisations}
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        lines.put(None)
        reader.join()


def _timed(job: Callable[..., Any], parametrisation: str, **kwargs) -> dict:
    t = time.perf_counter()
    out = job(parametrisation, echo=_echo, **kwargs)
    out["process_wall_s"] = time.perf_counter() - t
    return out


def tie_to(models: Mapping[str, Any], engine) -> None:
    """Set each model's engine to ``engine`` (this process's), after the trip back."""
    for m in models.values():
        m.engine = engine
