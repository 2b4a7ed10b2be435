"""The parametrisations of a run side by side in spawned processes (:mod:`itr_identify.
workflows.side_processes`), and the engine counting their solves as this run's."""

from __future__ import annotations

import os

import numpy as np
import pytest

from itr_identify.workflows.side_processes import identify_side_by_side, side_by_side_possible


def _job(par: str, *, echo, value: int, together=None) -> dict:
    """A side process's job: a line, its environment's numba threads, its process id;
    ``together``: a barrier both jobs must reach (they run at the same time)."""
    echo(f"{par}: working on {value}")
    if value < 0:
        raise ValueError(f"value: expected >= 0, got {value}")
    if together is not None:
        together.wait(timeout=120)
    return {"threads": os.environ.get("NUMBA_NUM_THREADS"), "pid": os.getpid(),
            "value": 2 * value}


def test_each_parametrisation_runs_in_a_process_of_its_own_on_one_thread():
    before = os.environ.get("NUMBA_NUM_THREADS")
    lines: list[str] = []
    import multiprocessing

    with multiprocessing.get_context("spawn").Manager() as manager:
        out = identify_side_by_side(_job, ["area", "gap"], echo=lines.append, value=3,
                                    together=manager.Barrier(2))
    assert list(out) == ["area", "gap"]
    assert [o["value"] for o in out.values()] == [6, 6]
    assert {o["threads"] for o in out.values()} == {"1"}
    assert len({o["pid"] for o in out.values()} | {os.getpid()}) == 3
    assert sorted(lines) == ["area: working on 3", "gap: working on 3"]
    assert all(o["process_wall_s"] >= 0 for o in out.values())
    assert os.environ.get("NUMBA_NUM_THREADS") == before       # this process's is kept


def test_a_side_process_error_reaches_the_caller_as_itself():
    with pytest.raises(ValueError, match="value: expected >= 0"):
        identify_side_by_side(_job, ["area", "gap"], echo=lambda line: None, value=-1)


def test_side_by_side_only_with_two_jobs_cores_and_a_local_engine():
    assert not side_by_side_possible(1, distributed=False)
    assert not side_by_side_possible(2, distributed=True)
    assert side_by_side_possible(2, distributed=False) == ((os.cpu_count() or 1) > 1)


def test_the_engine_counts_a_side_processes_solves_as_this_runs(tmp_path):
    """A side engine's solves on the same store are this run's: the run's summary counts
    them, and a later request for one repeats a solve of this run, not an earlier run's."""
    from itr_fv.materials import Materials
    from itr_fv.rve.generate import FillerSpec, generate_rve
    from itr_fv.rve.spec import RVESpec
    from itr_surrogate.engine import SolveEngine
    from itr_surrogate.requests import RVEData, SolveRequest

    with pytest.warns(UserWarning, match="under-represents its coarse particles"):
        ms = generate_rve(RVESpec(5.0, 0.25, max_diameter_box_ratio=0.45),
                          [FillerSpec("Al2O3", mu=1.02, sigma=0.35, volume_fraction=0.5)], 7,
                          matrix="silicone", progress=False)
    mat = Materials({"Al2O3": 30.0, "silicone": 0.18}, {("Al2O3", "silicone"): 1e-8},
                    matrix="silicone")
    req = SolveRequest.for_materials(RVEData.of(ms), mat, 1e-9)
    side = SolveEngine(tmp_path)
    first = side.solve_one(req)
    main = SolveEngine(tmp_path)
    main.absorb(side.counts())
    again = main.solve_one(req)
    np.testing.assert_array_equal(again.k_eff, first.k_eff)
    assert (main.solved, main.repeated, main.earlier) == (1, 1, 0)
    assert main.summary().startswith("1 full solve in this process and 1 side process (1 "
                                     "request repeated a solve of this run), none from an "
                                     "earlier run")
