"""Campaigns on a real Dask cluster with real Parquet files (issue 10)."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from itr_surrogate.campaign import Campaign, CampaignError
from itr_surrogate.store import RESULT_KEY, CampaignStore

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent

# 2 replicas x 6 parameter sets, one set per task: 12 tasks of 16^3 voxels
SMALL = """
name = "small"
box_um = 4.0
voxel_um = 0.25
replicas = 2
seed = 3
tol = 1e-6
block_size = 1
[[formulation]]
name = "Al2O3-30"
fractions = { Al2O3 = 0.30 }
psd = { Al2O3 = [0.2, 0.3] }
[design]
kind = "grid"
values = { R_Al2O3_silicone = [1e-8, 1e-7, 1e-6], k_Al2O3 = [20.0, 40.0] }
"""


def itr(*args, cwd, **kw):
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    return subprocess.run([str(BIN / "itr"), *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600, **kw)


def rows(folder: Path) -> list[dict]:
    """Every row but its wall time, sorted by (formulation, replica, set)."""
    table = CampaignStore(folder).results().drop_columns(["wall_s"])
    return table.to_pylist()


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The campaign run once without interruption on a 2-worker LocalCluster."""
    d = tmp_path_factory.mktemp("campaign")
    (d / "small.toml").write_text(SMALL)
    r = itr("campaign", "run", "small.toml", "--out", "ref", "--workers", "2", "--no-progress",
            cwd=d)
    assert r.returncode == 0, r.stderr
    out = rows(d / "ref")
    assert len(out) == 12
    return d, out


@pytest.mark.slow
def test_sigkill_part_way_then_resume_equals_an_uninterrupted_run(reference):
    d, expected = reference
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    p = subprocess.Popen([str(BIN / "itr"), "campaign", "run", "small.toml", "--out", "killed",
                          "--workers", "2", "--no-progress"], cwd=d, env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         start_new_session=True)
    parts = d / "killed" / "parts"

    def finished() -> int:  # part files under their final names (not the temporary ones)
        return sum(1 for f in parts.glob("*.parquet") if not f.name.startswith("."))

    deadline = time.time() + 300
    while time.time() < deadline and p.poll() is None and not finished():
        time.sleep(0.02)
    os.killpg(p.pid, signal.SIGKILL)  # the driver, its scheduler and its workers
    p.wait()
    done = finished()
    assert 1 <= done < 12, f"killed after {done} of 12 tasks"
    status = itr("campaign", "status", "killed", cwd=d)
    assert f"{done}/12 tasks done" in status.stdout
    r = itr("campaign", "run", "small.toml", "--out", "killed", "--workers", "2",
            "--no-progress", cwd=d)
    assert r.returncode == 0, r.stderr
    assert f"{12 - done} of 12 tasks to run" in r.stdout
    assert not list(parts.glob(".itr-partial-*"))  # what the kill left half-written is gone
    got = rows(d / "killed")
    keys = [tuple(row[k] for k in RESULT_KEY) for row in got]
    assert len(keys) == len(set(keys)) == 12  # no duplicates, nothing missing
    assert got == expected  # same rows, same bits


def test_an_external_scheduler_with_two_workers_gives_identical_rows(reference):
    d, expected = reference
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    sched_file = d / "scheduler.json"
    procs = [subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1",
                               "--port", "0", "--dashboard-address", ":0",
                               "--scheduler-file", str(sched_file)], cwd=d, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.time() + 60
        while not sched_file.exists() and time.time() < deadline:
            time.sleep(0.1)
        import json
        time.sleep(0.5)
        address = json.loads(sched_file.read_text())["address"]
        for _ in range(2):
            procs.append(subprocess.Popen(
                [str(BIN / "dask"), "worker", "--scheduler-file", str(sched_file),
                 "--nthreads", "1", "--nworkers", "1", "--no-dashboard"], cwd=d, env=env,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from dask.distributed import Client
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=120)
        r = itr("campaign", "run", "small.toml", "--out", "external", "--scheduler", address,
                "--no-progress", cwd=d)
        assert r.returncode == 0, r.stderr
        assert "2 workers" in r.stdout
        assert rows(d / "external") == expected
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs:
            p.wait(timeout=60)


def test_tiny_example_runs_then_status_is_complete_and_a_rerun_solves_nothing(tmp_path):
    example = ROOT / "examples" / "campaign-tiny.toml"
    r = itr("campaign", "run", str(example), "--out", "tiny", "--no-progress", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    s = itr("campaign", "status", "tiny", cwd=tmp_path)
    assert s.returncode == 0 and "4/4 tasks done, 12/12 solves" in s.stdout
    parts = sorted((tmp_path / "tiny" / "parts").glob("*.parquet"))
    stamps = [p.stat().st_mtime_ns for p in parts]
    again = itr("campaign", "run", str(example), "--out", "tiny", "--no-progress", cwd=tmp_path)
    assert again.returncode == 0 and "nothing to solve" in again.stdout
    assert [p.stat().st_mtime_ns for p in parts] == stamps
    table = pq.read_table(parts[0])
    assert {"k_xx", "k_iso", "R_Al2O3_silicone", "k_Al2O3", "rve_id", "iterations",
            "residual", "package_version"} <= set(table.column_names)
    assert all(r < 1e-6 for r in table.column("residual").to_pylist())
    # every row can be re-solved: its RVE's particle table is stored
    rve = CampaignStore(tmp_path / "tiny").read_rve(table.column("rve_id")[0].as_py())
    assert rve[1]["seed"] == table.column("seed")[0].as_py() and rve[0].num_rows > 10
    e = itr("campaign", "export", "tiny", "--csv", "tiny.csv", cwd=tmp_path)
    assert e.returncode == 0 and len((tmp_path / "tiny.csv").read_text().splitlines()) == 13


def test_warm_start_and_geometry_reuse_give_the_cold_answer(tmp_path):
    """A task's warm-started solves equal independent cold solves to the tolerance."""
    import numpy as np

    from itr_fv import homogenize
    from itr_surrogate.runner import campaign_rve, run_task, write_task_result

    camp = Campaign.from_dict({**_small_dict(), "block_size": 6, "replicas": 1})
    CampaignStore(tmp_path).open_for(camp)
    task = camp.tasks()[0]
    # the task writes nothing itself: it returns its rows and RVE for the client to write
    result = run_task(camp, task)
    assert CampaignStore(tmp_path).done_tasks() == set()
    assert len(result["rows"]) == result["solves"] == 6
    write_task_result(CampaignStore(tmp_path), result)
    got = CampaignStore(tmp_path).results().to_pylist()
    assert [r["warm_start"] for r in got] == [False] + [True] * 5
    ms = campaign_rve(camp, task.formulation, task.replica).microstructure
    for r, pset in zip(got, camp.parameter_sets(camp.formulations[0])):
        cold = homogenize(ms, camp.materials(pset), solver="fft", tol=1e-10, store_fields=False)
        assert r["k_iso"] == pytest.approx(np.trace(cold.k_eff) / 3, rel=1e-5)


def _small_dict() -> dict:
    import tomllib
    return tomllib.loads(SMALL)


def _set_fraction(d: dict, value: float) -> None:
    d["formulation"][0]["fractions"]["Al2O3"] = value


# (change to the SMALL campaign, text the one error line must hold)
BAD = [
    (lambda d: d.update(bogus=1),
     ("unknown key 'bogus' (known: base, block_size, box_um, contact, cut_voxel_um, design, "
      "film_um, formulation, matrix, max_diameter_box_ratio, min_gap_um, name, replicas, "
      "seed, solver, tail_quantile, threads_per_worker, tol, voxel_um)")),
    (lambda d: d.update(voxl_um=0.25),
     "unknown key 'voxl_um' (did you mean 'voxel_um'? known: base, block_size, box_um, "),
    (lambda d: d["formulation"][0].update(fraction={"Al2O3": 0.4}),
     ("formulation 0: unknown key 'fraction' (did you mean 'fractions'? known: fractions, name, "
      "psd)")),
    (lambda d: d.pop("formulation"), "missing key 'formulation'"),
    (lambda d: d.pop("box_um"), "missing key 'box_um'"),
    (lambda d: d.update(base={"R_Al2O3_silicone": -1e-8}), "R_Al2O3_silicone' must be >= 0"),
    (lambda d: _set_fraction(d, 0.75), "beyond what can be packed"),
    (lambda d: d.update(design={"kind": "sobol"}), "design.kind"),
    (lambda d: d.update(voxel_um=0.3), "whole number"),
    (lambda d: d.update(tol=2.0), "tol: expected"),
    (lambda d: d.update(contact="glue"), "contact: expected"),
    (lambda d: d.update(formulation=[{"name": "BN-30", "fractions": {"BN": 0.3}}]),
     "no size distribution"),
    (lambda d: d.update(base={"Rff_Al2O3_Al2O3": 1e-7}), "contact='area'"),
    (lambda d: d.update(replicas=0), "replicas"),
    (lambda d: d.update(formulation=[{"name": "Al2O3-99"}]),
     "not a formulation of the system 'paper'"),
    (lambda d: d.update(formulation=[{"name": "Al203-60"}]),
     "not a formulation of the system 'paper'; did you mean 'Al2O3-60'?"),
    (lambda d: d.update(design={"kind": "grid", "values": {"R_silicone_Al2O3": [1e-8]}}),
     "sorted order"),
    (None, "not valid TOML"),
]


def _dump(d: dict) -> str:
    lines, tables = [], []
    for k, v in d.items():
        if k == "formulation":
            for f in v:
                tables.append("[[formulation]]\n" + "".join(f"{a} = {_val(b)}\n"
                                                          for a, b in f.items()))
        elif isinstance(v, dict):
            tables.append(f"[{k}]\n" + "".join(f"{a} = {_val(b)}\n" for a, b in v.items()))
        else:
            lines.append(f"{k} = {_val(v)}")
    return "\n".join(lines) + "\n" + "\n".join(tables)


def _val(v) -> str:
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{a} = {_val(b)}" for a, b in v.items()) + " }"
    if isinstance(v, list):
        return "[" + ", ".join(_val(x) for x in v) + "]"
    return repr(v)


@pytest.mark.parametrize("change,text", BAD, ids=[t for _, t in BAD])
def test_bad_campaign_files_are_one_line_before_any_work(change, text, tmp_path):
    if change is None:
        content = "box_um = = 4\n"
    else:
        d = _small_dict()
        change(d)
        content = _dump(d)
    (tmp_path / "c.toml").write_text(content)
    r = itr("campaign", "run", "c.toml", "--out", "out", "--no-progress", cwd=tmp_path)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("itr: error: ") and text in lines[0], lines
    assert "Traceback" not in r.stderr and not (tmp_path / "out").exists()


def test_unreachable_scheduler_and_a_folder_of_another_campaign_are_refused(tmp_path):
    (tmp_path / "c.toml").write_text(SMALL)
    r = itr("campaign", "run", "c.toml", "--out", "out", "--scheduler", "tcp://127.0.0.1:9",
            cwd=tmp_path)
    assert r.returncode == 2 and "--scheduler: cannot reach" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "out").exists()
    other = Campaign.from_dict({**_small_dict(), "seed": 99})
    CampaignStore(tmp_path / "held").open_for(other)
    r = itr("campaign", "run", "c.toml", "--out", "held", cwd=tmp_path)
    assert r.returncode == 2 and "holds another campaign" in r.stderr
    r = itr("campaign", "status", "nowhere", cwd=tmp_path)
    assert r.returncode == 2 and "holds no campaign" in r.stderr


def test_campaign_checks_name_the_key():
    with pytest.raises(CampaignError, match=re.escape(
            "design: unknown key 'bounds' for kind 'grid' (known: kind, values)")):
        Campaign.from_dict({**_small_dict(), "design": {"kind": "grid", "values": {},
                                                         "bounds": {}}})
    table4 = Campaign.from_dict({**_small_dict(), "design": {"kind": "table4"}})
    assert len(table4.parameter_sets(table4.formulations[0])) == 40  # 5 k x 8 R (gap)
    area = Campaign.from_dict({**_small_dict(), "contact": "area",
                               "base": {"Rff_Al2O3_Al2O3": 2e-7},
                               "design": {"kind": "table4"}})
    assert len(area.parameter_sets(area.formulations[0])) == 320  # the paper's count


# solves each shipped example states in its comments: Table 4 under the gap model is
# 5 k x 8 R_fp = 40 sets per single-filler RVE and 8 x 8 = 64 per hybrid RVE
EXAMPLES = {"campaign-tiny.toml": 12, "campaign-paper-al2o3.toml": 4 * 3 * 40,
            "campaign-paper-aln.toml": 4 * 3 * 40, "campaign-paper-hybrid.toml": 4 * 3 * 64}


def test_a_campaign_file_as_a_spreadsheet_or_windows_editor_saves_it(tmp_path):
    """A UTF-8 byte-order mark and a Table 2 name in another letter case are accepted."""
    d = _small_dict()
    d["formulation"] = [{"name": "al2o3-60"}]
    (tmp_path / "c.toml").write_text(_dump(d), encoding="utf-8-sig")
    assert (tmp_path / "c.toml").read_bytes()[:3] == b"\xef\xbb\xbf"
    camp = Campaign.from_toml(tmp_path / "c.toml")
    [form] = camp.formulations
    assert form.name == "Al2O3-60" and form.fractions == {"Al2O3": pytest.approx(0.60)}


@pytest.mark.parametrize("name,solves", EXAMPLES.items(), ids=list(EXAMPLES))
def test_shipped_example_campaigns_are_valid(name, solves):
    camp = Campaign.from_toml(ROOT / "examples" / name)
    assert camp.n_solves() == solves and camp.contact == "gap"


def test_a_failed_task_is_recorded_and_the_others_finish(tmp_path, monkeypatch):
    """One task raising on the worker: the run goes on, status names the task and its error,
    and the next run solves only that task and clears the record."""
    from dask.distributed import LocalCluster

    import itr_surrogate.runner as runner

    camp = Campaign.from_dict({**_small_dict(), "replicas": 1, "block_size": 3})
    real = runner.run_task

    def flaky(camp, task):
        if task.block == 1:
            raise RuntimeError("injected failure")
        return real(camp, task)

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster:
        monkeypatch.setattr(runner, "run_task", flaky)
        first = runner.run_campaign(camp, tmp_path / "c", scheduler=cluster.scheduler_address,
                                    progress=False, echo=lambda m: None)
        status = CampaignStore(tmp_path / "c").status()
        assert (first.tasks_run, first.tasks_failed) == (1, 1)
        assert status.tasks_done == 1 and "injected failure" in status.failures[
            "Al2O3-30__r0__b0001"]
        monkeypatch.setattr(runner, "run_task", real)
        second = runner.run_campaign(camp, tmp_path / "c", scheduler=cluster.scheduler_address,
                                     progress=False, echo=lambda m: None)
    assert (second.tasks_run, second.tasks_skipped, second.solves) == (1, 1, 3)
    final = CampaignStore(tmp_path / "c").status()
    assert final.complete and final.failures == {}
