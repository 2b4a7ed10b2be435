"""Every full solve of ``itr reproduce`` / ``itr discrepancy`` runs on the solve engine:
killed with SIGKILL part-way and run again, a command redoes no finished solve and writes
what an uninterrupted run writes; ``--workers`` and ``--scheduler`` give the serial numbers.
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from itr_identify.cli import main
from itr_surrogate.store import SolveStore
from itr_surrogate.worker import clear_problem_cache

BIN = Path(sys.executable).parent
#: CI size: gap parametrisation only, 24^3 voxels, two replicas, no leave-one-out.
TINY = ["--box-um", "12", "--voxel-um", "0.5", "--replicas", "2", "--no-progress",
        "--fidelity", "quick", "--parametrisation", "gap"]
REPRODUCE = ["reproduce", *TINY, "--no-leave-one-out"]
DISCREPANCY = ["discrepancy", "--box-um", "12", "--voxel-um", "0.5", "--replicas", "2",
               "--effects", "matrix", "--no-progress"]
#: The engine's summary line: full solves, where, requests that repeated a solve of the same
#: run (absent: none), requests answered by an earlier run's store ("none"), geometry builds.
ENGINE_LINE = re.compile(
    r"engine: (\d+) full solves? (?:in|on) (.+?)(?: \((\d+) requests? repeated a solve of this "
    r"run\))?, (none|\d+ requests?) from (?:an|the store of an) earlier run, "
    r"(\d+) geometry builds?")


def _engine_counts(text: str) -> tuple[int, int, int]:
    """(full solves, requests answered from an earlier run's store, geometry builds) of the
    last engine line in ``text``."""
    m = ENGINE_LINE.findall(text)
    assert m, text[-2000:]
    solved, _, _, earlier, builds = m[-1]
    return int(solved), 0 if earlier == "none" else int(earlier.split()[0]), int(builds)


def _strip(d):
    """identified.json without the wall times."""
    if isinstance(d, dict):
        return {k: _strip(v) for k, v in d.items() if k != "seconds"}
    if isinstance(d, list):
        return [_strip(v) for v in d]
    return d


def assert_close(a, b, rel=1e-8, path="$"):
    """Same structure; numbers equal to ``rel`` relative."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            assert_close(a[k], b[k], rel, f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            assert_close(x, y, rel, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert math.isclose(a, b, rel_tol=rel, abs_tol=1e-300) or a == b, (path, a, b)
    else:
        assert a == b, (path, a, b)


def _env() -> dict:
    return {**os.environ, "MPLBACKEND": "Agg", "PYVISTA_OFF_SCREEN": "true"}


def _run_and_kill(args: list[str], out: Path, after_solves: int) -> int:
    """Start ``itr ARGS --out OUT`` in its own process group, SIGKILL the whole group once
    the store holds ``after_solves`` finished solves; returns how many it holds then."""
    p = subprocess.Popen([str(BIN / "itr"), *args, "--out", str(out)], env=_env(),
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         start_new_session=True)
    store = SolveStore(out / "solves")
    deadline = time.monotonic() + 600
    try:
        while store.count() < after_solves and p.poll() is None \
                and time.monotonic() < deadline:
            time.sleep(0.2)
        assert p.poll() is None, "the command finished before it could be killed"
    finally:
        os.killpg(p.pid, signal.SIGKILL)
        p.wait()
    return store.count()


@pytest.fixture(scope="module")
def serial_reproduce(tmp_path_factory):
    out = tmp_path_factory.mktemp("serial") / "rep"
    clear_problem_cache()  # earlier tests of this process may have built the same RVEs
    assert main([*REPRODUCE, "--out", str(out)]) == 0
    return out, _strip(json.loads((out / "identified.json").read_text()))


@pytest.mark.slow
def test_reproduce_killed_part_way_redoes_no_finished_solve(serial_reproduce, tmp_path,
                                                            capsys):
    ref_out, ref = serial_reproduce
    total = SolveStore(ref_out / "solves").count()
    out = tmp_path / "killed"
    before = _run_and_kill(REPRODUCE, out, after_solves=total // 3)
    assert 0 < before < total
    capsys.readouterr()
    assert main([*REPRODUCE, "--out", str(out)]) == 0
    solved, earlier, _ = _engine_counts(capsys.readouterr().out)
    # every solve that had finished is taken from the store, none is solved again
    assert earlier >= before and solved == total - before
    assert SolveStore(out / "solves").count() == total
    assert_close(_strip(json.loads((out / "identified.json").read_text())), ref)


@pytest.mark.slow
def test_reproduce_geometry_is_built_once_per_rve(serial_reproduce):
    out, _ = serial_reproduce
    manifest = json.loads((out / "manifest.json").read_text())
    line = "engine: " + manifest["inputs"]["engine"]
    solved, earlier, builds = _engine_counts(line)
    # 12 formulations x 2 replicas, one contact model: one geometry per RVE (before the
    # engine, every full solve of a replica built its own), and one per formulation for the
    # film elasticity (the first replica's particles meeting at 2.5 nm: other contacts, so
    # another discrete problem; issue 47's marginalised film, gap model only)
    assert builds == 24 + 12 and solved > 3 * builds
    # a fresh folder: what the store answered repeated solves of this same run
    assert earlier == 0 and ", none from an earlier run, " in line
    assert re.search(r"full solves in this process \(\d+ requests repeated a solve of this "
                     r"run\), none", line), line
    assert solved == SolveStore(out / "solves").count()


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="known defect, found when CI first ran the slow tier "
                   "(issue 62; fails the same on a4ee0f4): with --workers 2 the fit with the "
                   "inputs free ($.gap.fit.free_inputs) differs from the serial run by up to "
                   "1.2e-5 relative; everything else within 1e-8")
def test_workers_and_an_external_scheduler_give_the_serial_numbers(serial_reproduce,
                                                                   tmp_path, capsys):
    _, ref = serial_reproduce
    out = tmp_path / "workers"
    assert main([*REPRODUCE, "--out", str(out), "--workers", "2"]) == 0
    solved, _, builds = _engine_counts(capsys.readouterr().out)
    assert builds <= (24 + 12) * 2
    assert_close(_strip(json.loads((out / "identified.json").read_text())), ref)

    sched_file = tmp_path / "scheduler.json"
    env = _env()
    procs = [subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1",
                               "--port", "0", "--no-dashboard",
                               "--scheduler-file", str(sched_file)], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not sched_file.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(sched_file.read_text())["address"]
        for _ in range(2):
            procs.append(subprocess.Popen(
                [str(BIN / "dask"), "worker", "--scheduler-file", str(sched_file),
                 "--nthreads", "1", "--no-dashboard"], env=env,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        out = tmp_path / "scheduler"
        assert main([*REPRODUCE, "--out", str(out), "--scheduler", address]) == 0
        m = ENGINE_LINE.findall(capsys.readouterr().out)
        assert m and m[-1][1] == f"scheduler {address}" and int(m[-1][0]) == solved
        assert m[-1][3] == "none"
        assert_close(_strip(json.loads((out / "identified.json").read_text())), ref)
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


@pytest.mark.slow
def test_discrepancy_killed_part_way_redoes_no_finished_solve(tmp_path, capsys):
    # slow (about 5 min on 2 cores): the same solve engine and store as the reproduce
    # test above it in the default run, which kills and resumes a run end to end
    table = tmp_path / "m.csv"
    table.write_text("formulation,replicate,k_W_per_mK\n" + "".join(
        f"{f},{i + 1},{k}\n" for f, ks in (("Al2O3-55", (1.21, 1.25, 1.23)),
                                            ("Al2O3-60", (1.45, 1.50, 1.47)),
                                            ("AlN-55", (1.38, 1.42, 1.36)))
        for i, k in enumerate(ks)))
    args = [DISCREPANCY[0], str(table), *DISCREPANCY[1:]]
    ref_out = tmp_path / "ref"
    assert main([*args, "--out", str(ref_out)]) == 0
    total, _, _ = _engine_counts(capsys.readouterr().out)
    out = tmp_path / "killed"
    before = _run_and_kill(args, out, after_solves=total // 3)
    assert 0 < before < total
    assert main([*args, "--out", str(out)]) == 0
    line = capsys.readouterr().out
    solved, earlier, _ = _engine_counts(line)
    assert earlier == before and solved == total - before
    assert f", {before} requests from the store of an earlier run, " in line
    assert_close(json.loads((out / "discrepancy.json").read_text()),
                 json.loads((ref_out / "discrepancy.json").read_text()))


def test_an_unreachable_scheduler_is_one_line_before_any_work(tmp_path, capsys):
    assert main([*REPRODUCE, "--out", str(tmp_path / "o"), "--scheduler",
                 "tcp://127.0.0.1:9"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("itr: error: --scheduler: cannot reach") and err.count("\n") == 1
