"""Campaigns and solves on a Dask scheduler and workers started as their own processes, in
another working directory than the client's (issue 37): every result lands in the client's
folder (the workers write nothing), a worker killed mid-run loses nothing, and a GPU solver
is refused at once where no worker has a GPU (never a silent wait)."""

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

import numpy as np
import pyarrow.csv as pacsv
import pytest

from itr_surrogate.campaign import Campaign
from itr_surrogate.store import RESULT_KEY, CampaignStore

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "examples" / "campaign-tiny.toml"
ENV = dict(os.environ, PYTHONWARNINGS="ignore")


class Processes:
    """A ``dask scheduler`` and ``dask worker`` processes, each in its own session (so a
    SIGKILL of its group takes a worker's nanny and its worker process together)."""

    def __init__(self, logs: Path) -> None:
        self.logs = logs
        self.procs: list[subprocess.Popen] = []
        self.address = ""

    def _start(self, args: list[str], cwd: Path, log: str) -> subprocess.Popen:
        with open(self.logs / log, "w") as out:
            p = subprocess.Popen([sys.executable, "-m", *args], cwd=cwd, env=ENV, stdout=out,
                                 stderr=subprocess.STDOUT, start_new_session=True)
        self.procs.append(p)
        return p

    def scheduler(self, cwd: Path) -> str:
        sched_file = self.logs / "scheduler.json"
        # port 0: the system picks a free port; the scheduler file says which
        p = self._start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port",
                         "0", "--no-dashboard", "--scheduler-file", str(sched_file)], cwd,
                        "scheduler.log")
        deadline = time.time() + 60
        while time.time() < deadline and p.poll() is None:
            try:
                self.address = json.loads(sched_file.read_text())["address"]
                return self.address
            except (OSError, ValueError, KeyError):
                time.sleep(0.1)
        raise RuntimeError("the dask scheduler did not start: "
                           + (self.logs / "scheduler.log").read_text()[-2000:])

    def worker(self, cwd: Path, *extra: str) -> subprocess.Popen:
        n = sum(1 for _ in self.logs.glob("worker-*.log"))
        return self._start(["distributed.cli.dask_worker", self.address, "--nthreads", "1",
                            "--nworkers", "1", "--no-dashboard", *extra], cwd,
                           f"worker-{n}.log")

    def wait_for_workers(self, n: int) -> None:
        from dask.distributed import Client

        with Client(self.address, timeout="30s") as client:
            client.wait_for_workers(n, timeout=120)

    @staticmethod
    def kill(p: subprocess.Popen) -> None:
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        p.wait(timeout=30)

    def close(self) -> None:
        for p in self.procs[::-1]:  # workers first, then the scheduler
            if p.poll() is None:
                try:
                    os.killpg(p.pid, signal.SIGTERM)
                except ProcessLookupError:
                    continue
        for p in self.procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.kill(p)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A scheduler and one worker whose working directory is its own (empty) folder."""
    base = tmp_path_factory.mktemp("cluster")
    dirs = {name: base / name for name in ("logs", "scheduler", "worker")}
    for d in dirs.values():
        d.mkdir()
    procs = Processes(dirs["logs"])
    try:
        procs.scheduler(dirs["scheduler"])
        procs.worker(dirs["worker"])
        procs.wait_for_workers(1)
        yield procs.address, dirs["worker"]
    finally:
        procs.close()


@pytest.fixture(scope="module")
def rve():
    """A small packed RVE (16^3) as the engine's sphere data, and its materials."""
    import warnings

    from itr_fv import Materials
    from itr_fv.rve import FillerSpec, RVESpec, generate_rve
    from itr_surrogate.requests import RVEData

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the box cut of the coarse tail
        ms = generate_rve(RVESpec(4.0, 0.25, max_diameter_box_ratio=0.45),
                          [FillerSpec("Al2O3", mu=1.02, sigma=0.35, volume_fraction=0.4)], 5,
                          matrix="silicone")
    return RVEData.of(ms), Materials({"silicone": 0.18, "Al2O3": 30.0},
                                     {("Al2O3", "silicone"): 2e-8}, matrix="silicone")


def itr_main(capsys, *args: str) -> tuple[int, str, str]:
    """``itr ARGS`` in this process: (exit status, stdout, stderr)."""
    from itr_identify.cli import main

    capsys.readouterr()
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def _files(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def test_a_campaign_on_workers_in_another_directory_writes_into_the_clients_folder(
        cluster, tmp_path, monkeypatch, capsys):
    address, worker_cwd = cluster
    monkeypatch.chdir(tmp_path)
    camp = Campaign.from_toml(TINY)
    code, out, err = itr_main(capsys, "campaign", "run", str(TINY), "--out", "tiny",
                              "--scheduler", address, "--no-progress")
    assert code == 0, err
    assert "4 tasks (12 solves)" in out and "on 1 worker; 0 failed" in out
    # the parts are in the client's folder, and nothing at all in the worker's
    parts = sorted(p.stem for p in (tmp_path / "tiny" / "parts").glob("*.parquet"))
    assert parts == sorted(t.task_id for t in camp.tasks()) and len(parts) == 4
    assert len(list((tmp_path / "tiny" / "rves").glob("*.parquet"))) == 2  # two replicas
    assert _files(worker_cwd) == []
    code, out, _ = itr_main(capsys, "campaign", "status", "tiny")
    assert code == 0 and out.strip() == "campaign tiny: 4/4 tasks done, 12/12 solves"
    code, out, _ = itr_main(capsys, "campaign", "export", "tiny", "--csv", "x.csv")
    assert code == 0 and "(12 rows)" in out
    table = pacsv.read_csv(tmp_path / "x.csv").to_pylist()
    assert len(table) == 12
    assert len({tuple(r[k] for k in RESULT_KEY) for r in table}) == 12
    assert {r["R_Al2O3_silicone"] for r in table} == {1e-8, 1e-7, 1e-6}
    assert {r["k_Al2O3"] for r in table} == {20.0, 40.0}
    for r in table:  # between the silicone (0.18) and the filler, below Maxwell's bound
        assert math.isfinite(r["k_iso"]) and 0.18 < r["k_iso"] < 1.0 and r["residual"] < 1e-6
    # a larger resistance conducts less, everything else equal
    for rep in (0, 1):
        for k in (20.0, 40.0):
            line = sorted((r["R_Al2O3_silicone"], r["k_iso"]) for r in table
                          if r["replica"] == rep and r["k_Al2O3"] == k)
            assert [v for _, v in line] == sorted((v for _, v in line), reverse=True)
    # the worker's numbers are this process's numbers (the same task solved here)
    from itr_surrogate.runner import run_task

    task = camp.tasks()[0]
    here = run_task(camp, task)
    stored = CampaignStore(tmp_path / "tiny").results().to_pylist()
    for row in here["rows"]:
        twin = next(s for s in stored if all(s[k] == row[k] for k in RESULT_KEY))
        assert twin["k_iso"] == row["k_iso"] and twin["rve_id"] == row["rve_id"]
    # a re-run on the cluster finds everything done in the client's folder
    code, out, _ = itr_main(capsys, "campaign", "run", str(TINY), "--out", "tiny",
                            "--scheduler", address, "--no-progress")
    assert code == 0 and "all 4 tasks are done; nothing to solve" in out


@pytest.mark.slow
def test_itr_identify_on_workers_in_another_directory_keeps_every_solve_on_the_client(
        cluster, tmp_path, monkeypatch, capsys):
    """``itr identify --scheduler`` with a relative ``--out``: every full solve the engine
    reports is a row in the client's ``out/solves``, the worker's folder stays empty, and a
    second run into the same folder solves nothing (it reads the client's store)."""
    address, worker_cwd = cluster
    monkeypatch.chdir(tmp_path)
    Path("m.csv").write_text("formulation,replicate,k_W_per_mK\n"
                             "Al2O3-55,1,1.29\nAl2O3-55,2,1.30\nAl2O3-55,3,1.22\n"
                             "Al2O3-62,1,1.70\nAl2O3-62,2,1.75\nAl2O3-62,3,1.66\n")
    args = ["identify", "m.csv", "--out", "out", "--parametrisation", "gap", "--box-um", "12",
            "--voxel-um", "0.5", "--replicas", "2", "--no-progress", "--fidelity", "quick",
            "--scheduler", address, "--keep-fields"]   # the snapshots' fields stay: nothing again
    code, out, err = itr_main(capsys, *args)
    assert code == 0, err
    solved = re.search(r"engine: (\d+) full solves on scheduler .*, none from an earlier run",
                       out)
    assert solved and int(solved.group(1)) > 0, out  # (a run reuses its own repeats)
    rows = sorted(Path("out", "solves").rglob("*.parquet"))
    assert len(rows) == int(solved.group(1))
    first = json.loads(Path("out", "identified.json").read_text())
    r = first["gap"]["parameters"]["R_Al2O3_silicone"]
    assert 1e-9 <= r["interval_90"][0] <= r["best"] <= r["interval_90"][1] <= 1e-5
    assert _files(worker_cwd) == []
    code, out, err = itr_main(capsys, *args)
    assert code == 0, err
    again = re.search(r"engine: (\d+) full solves on scheduler \S+, (\d+) requests from the "
                      r"store of an earlier run", out)
    assert again and int(again.group(1)) == 0 and int(again.group(2)) >= len(rows), out
    second = json.loads(Path("out", "identified.json").read_text())
    assert second["gap"]["parameters"]["R_Al2O3_silicone"]["best"] == r["best"]


def test_the_solve_engine_on_an_external_cluster_keeps_its_store_on_the_client(
        cluster, rve, tmp_path, monkeypatch):
    from itr_surrogate.engine import SolveEngine
    from itr_surrogate.requests import SolveRequest
    from itr_surrogate.store import SolveStore

    address, worker_cwd = cluster
    monkeypatch.chdir(tmp_path)
    data, mat = rve
    reqs = [SolveRequest.for_materials(data, mat.with_parameters(
        {"R_Al2O3_silicone": r}), 1e-8, purpose="anchor", replica=0) for r in (1e-8, 1e-6)]
    with SolveEngine("store", scheduler=address, echo=lambda s: None) as engine:
        got = engine.solve(reqs)
        assert engine.solved == 2 and engine.geometry_builds == 1  # built once, on the worker
        monkeypatch.chdir(worker_cwd.parent)  # a change of directory moves nothing
        again = engine.solve(reqs)
        assert engine.reused == 2 and (engine.repeated, engine.earlier) == (2, 0)
    assert _files(worker_cwd) == []
    table = SolveStore(tmp_path / "store").table().to_pylist()
    assert len(table) == 2 and {r["purpose"] for r in table} == {"anchor"}
    serial = SolveEngine().solve(reqs)
    for a, b, c in zip(got, again, serial):
        assert np.array_equal(a.k_eff, c.k_eff) and np.array_equal(b.k_eff, c.k_eff)
    assert 0.18 < got[1].k_eff[0, 0] < got[0].k_eff[0, 0] < 1.0


def test_a_gpu_solver_is_refused_before_submitting_when_no_worker_declares_a_gpu(
        cluster, rve, tmp_path, monkeypatch, capsys):
    from itr_surrogate.engine import SolveEngine
    from itr_surrogate.requests import SolveRequest

    address, _ = cluster
    monkeypatch.chdir(tmp_path)
    Path("gpu.toml").write_text(TINY.read_text().replace('solver = "fft"', 'solver = "gpu"'))
    t0 = time.perf_counter()
    code, out, err = itr_main(capsys, "campaign", "run", "gpu.toml", "--out", "g",
                              "--scheduler", address, "--no-progress")
    assert code == 2 and err.count("\n") == 1 and time.perf_counter() - t0 < 30
    assert "solver 'gpu'" in err and f"dask worker {address} --resources GPU=1" in err
    assert not Path("g").exists()  # refused before the folder, before any task
    # on a local cluster (no GPU here): the same one line, nothing started
    from itr_fv.solvers.devices import cuda_device_count

    if cuda_device_count() == 0:
        code, out, err = itr_main(capsys, "campaign", "run", "gpu.toml", "--out", "g",
                                  "--no-progress")
        assert code == 2 and err.count("\n") == 1 and not Path("g").exists()
        assert "solver 'gpu' solves on a GPU, but this machine has no CUDA device" in err
    req = SolveRequest.for_materials(rve[0], rve[1], 1e-8, solver="gpu")
    with SolveEngine("store", scheduler=address, echo=lambda s: None) as engine:
        with pytest.raises(ValueError, match="declares the resource GPU"):
            engine.solve([req])
        assert engine.solved == 0


def test_a_task_no_worker_has_the_memory_for_is_refused_before_submitting(
        cluster, tmp_path, monkeypatch, capsys):
    """1200^3 voxels on the external workers: their memory limit (the machine's, a few tens
    of GB) cannot hold one task; refused in one line before the folder or any task."""
    address, _ = cluster
    monkeypatch.chdir(tmp_path)
    Path("huge.toml").write_text(TINY.read_text().replace("voxel_um = 0.25", "voxel_um = 0.005"))
    code, out, err = itr_main(capsys, "campaign", "run", "huge.toml", "--out", "h",
                              "--scheduler", address, "--no-progress")
    assert code == 2 and err.count("\n") == 1, err
    assert f"--scheduler: no worker of '{address}' has the memory one task needs" in err
    assert not Path("h").exists()


# campaign-tiny with 4 replicas, one parameter set per task: 24 tasks of 24^3
MANY = TINY.read_text().replace("replicas = 2", "replicas = 4") \
    .replace("block_size = 3", "block_size = 1").replace('name = "tiny"', 'name = "many"')


@pytest.mark.slow
def test_a_worker_killed_mid_run_loses_no_result(tmp_path):
    base = tmp_path
    dirs = {name: base / name for name in ("logs", "scheduler", "w0", "w1", "client")}
    for d in dirs.values():
        d.mkdir()
    (dirs["client"] / "many.toml").write_text(MANY)
    camp = Campaign.from_toml(dirs["client"] / "many.toml")
    assert len(camp.tasks()) == 24
    procs = Processes(dirs["logs"])
    try:
        address = procs.scheduler(dirs["scheduler"])
        victim = procs.worker(dirs["w0"])
        procs.worker(dirs["w1"])
        procs.wait_for_workers(2)
        cmd = [str(Path(sys.executable).parent / "itr"), "campaign", "run", "many.toml",
               "--out", "many", "--scheduler", address, "--no-progress"]
        run = subprocess.Popen(cmd, cwd=dirs["client"], env=ENV, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
        parts = dirs["client"] / "many" / "parts"
        deadline = time.time() + 120
        while time.time() < deadline and run.poll() is None and not any(
                p for p in parts.glob("*.parquet") if not p.name.startswith(".")):
            time.sleep(0.05)
        done_at_kill = len(CampaignStore(dirs["client"] / "many").done_tasks())
        running_at_kill = run.poll() is None
        procs.kill(victim)  # nanny and worker, SIGKILL, tasks in flight
        out, err = run.communicate(timeout=300)
        assert running_at_kill and 1 <= done_at_kill < 24, \
            f"killed after {done_at_kill} of 24 tasks"
        if run.returncode != 0:  # failures recorded: a re-run on the survivor completes
            again = subprocess.run(cmd, cwd=dirs["client"], env=ENV, capture_output=True,
                                   text=True, timeout=300)
            assert again.returncode == 0, again.stderr
            out += again.stdout
        print(f"killed a worker after {done_at_kill}/24 tasks; the run said: {out.strip()}")
    finally:
        procs.close()
    status = CampaignStore(dirs["client"] / "many").status()
    assert status.complete and (status.tasks_done, status.solves_done) == (24, 24)
    assert status.failures == {}
    rows = CampaignStore(dirs["client"] / "many").results().to_pylist()
    keys = [tuple(r[k] for k in RESULT_KEY) for r in rows]
    assert len(rows) == len(set(keys)) == 24  # every row, exactly once
    assert all(math.isfinite(r["k_iso"]) and 0.18 < r["k_iso"] < 1.0 for r in rows)
    for w in ("w0", "w1"):
        assert _files(dirs[w]) == []
