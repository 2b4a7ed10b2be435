"""The ``itr`` command line: one-line errors, exit statuses, no folder left behind, the demo."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import pyvista as pv

import itr_fv
from itr_identify.cli import main


def run_itr(*args, cwd, timeout=300):
    """Run ``python -m itr_identify.cli ARGS`` (the console script's entry point) in ``cwd``."""
    env = dict(os.environ, PYTHONWARNINGS="default")
    env.pop("ITR_DEBUG", None)
    return subprocess.run([sys.executable, "-m", "itr_identify.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


# (arguments, exit status, text the one line must hold). Each must fail before any work.
BAD = [
    ([], 2, "required: command"),
    (["nosuch"], 2, "invalid choice: 'nosuch'"),
    (["demo", "--n", "0"], 2, "argument --n"),
    (["demo", "--n", "1.5"], 2, "--n: not a whole number"),
    (["demo", "--n", "600"], 2, "argument --n"),
    (["demo", "--fraction", "0.9"], 2, "argument --fraction"),
    (["demo", "--fraction", "-0.1"], 2, "argument --fraction"),
    (["demo", "--fraction", "abc"], 2, "--fraction: not a number"),
    (["demo", "--tol", "1e-15"], 2, "argument --tol"),
    (["demo", "--tol", "2"], 2, "argument --tol"),
    (["demo", "--box-um", "-3"], 2, "argument --box-um"),
    (["demo", "--voxel-um", "nan"], 2, "--voxel-um: must be finite"),
    (["demo", "--voxel-um", "0.17"], 2, "box_um/voxel_um: a 16 um box holds 94.1176 voxels"),
    (["demo", "--voxel-um", "0.016"], 2, "beyond the demo's 512^3"),
    (["demo", "--seed", "-1"], 2, "argument --seed"),
    (["demo", "--solver", "quantum"], 2, "--solver: expected one of 'fft', 'mg', 'fv', 'gpu'"),
    (["demo", "--solver", "fv", "--device", "cuda"], 2, "--device: the solver 'fv' runs"),
    (["demo", "--device", "tpu"], 2, "argument --device: invalid choice: 'tpu'"),
    (["demo", "--bogus", "1"], 2, "unrecognized arguments: --bogus"),
    (["demo", "--out", "afile"], 2, "--out: 'afile' is a file"),
    (["demo", "--out", "afile/sub"], 2, "--out: 'afile' is a file"),
    (["demo", "--out", "/proc/itr-out"], 2, "--out: cannot write"),
    (["demo", "--out", "notes"], 2, "--out: 'notes' is not empty and it holds no itr manifest"),
    (["demo", "--voxel-um", "1.6", "--box-um", "16"], 2, "--voxel-um: 1.6 um voxels cannot"),
]


@pytest.mark.parametrize("args,status,text", BAD, ids=[" ".join(a) or "no-args" for a, _, _ in BAD])
def test_bad_invocations_are_one_line_with_status_and_leave_nothing(args, status, text, tmp_path):
    (tmp_path / "afile").write_text("not a folder")
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "lab-book.txt").write_text("someone's files, not a run's")
    before = sorted(p.name for p in tmp_path.iterdir())
    r = run_itr(*args, cwd=tmp_path)
    assert r.returncode == status, r.stderr
    lines = r.stderr.strip().splitlines()
    errors = [ln for ln in lines if not ln.startswith("itr: warning:")]
    assert len(errors) == 1 and errors[0].startswith("itr: error: "), r.stderr
    assert text in errors[0]
    assert "Traceback" not in r.stderr and r.stdout == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no output folder left


@pytest.mark.slow
def test_runtime_failures_are_one_line_status_1_and_remove_the_new_folder(tmp_path):
    # 0.672 passes the up-front check (below the jamming estimate) but the packer gives up
    r = run_itr("demo", "--fraction", "0.672", "--out", "packing", cwd=tmp_path)
    assert r.returncode == 1, r.stderr
    errors = [ln for ln in r.stderr.strip().splitlines() if not ln.startswith("itr: warning:")]
    assert len(errors) == 1 and errors[0].startswith("itr: error: --fraction 0.672: the packer")
    assert not (tmp_path / "packing").exists()


def test_convergence_failure_is_one_line(monkeypatch, tmp_path, capsys):
    from itr_fv.solvers import driver as solve
    real = solve.homogenize

    def capped(*args, **kwargs):
        return real(*args, **{**kwargs, "maxiter": 2})

    for module in (itr_fv, solve):  # the one door, by either of its import paths
        monkeypatch.setattr(module, "homogenize", capped)
    status = main(["demo", "--box-um", "4", "--voxel-um", "0.25", "--fraction", "0.3",
                   "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 1
    assert err[-1].startswith("itr: error: the solver did not reach --tol 1e-08")
    assert not (tmp_path / "run").exists()


def test_memory_refusal_is_one_line(monkeypatch, tmp_path, capsys):
    from itr_fv.solvers import resources
    monkeypatch.setattr(resources, "available_memory", lambda: 10**6)
    status = main(["demo", "--box-um", "4", "--voxel-um", "0.25", "--fraction", "0.3",
                   "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 1 and err[-1].startswith("itr: error: memory: itr_fft")
    assert "--voxel-um" in err[-1] and not (tmp_path / "run").exists()


def test_version(tmp_path):
    r = run_itr("--version", cwd=tmp_path)
    assert r.returncode == 0 and r.stdout.strip().startswith(f"itr {itr_fv.__version__}")


def test_demo_end_to_end_small(tmp_path):
    """The demo writes vti, png, json and a manifest (last) that matches them; a rerun
    into the same folder replaces the run (tests/test_run_folder.py: what is refused)."""
    args = ["demo", "--box-um", "6", "--voxel-um", "0.25", "--fraction", "0.4", "--out", "d"]
    r = run_itr(*args, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "voxel" in r.stdout and "discretisation bias" in r.stdout and "scatter" in r.stdout
    out = tmp_path / "d"
    manifest = json.loads((out / "manifest.json").read_text())
    names = [f["path"] for f in manifest["files"]]
    assert names == ["demo.vti", "demo.png", "demo.json"]
    for f in manifest["files"]:
        assert (out / f["path"]).stat().st_size == f["bytes"]
        assert (out / f["path"]).stat().st_mtime <= (out / "manifest.json").stat().st_mtime
    summary = json.loads((out / "demo.json").read_text())
    assert summary["solver"] == "itr_fft" and summary["settings"]["voxel_um"] == 0.25
    assert summary["contact_model"] == "gap"
    grid = pv.read(out / "demo.vti")
    assert grid.n_cells == 24**3 and "temperature_fluctuation_e1" in grid.cell_data
    k = summary["k_eff_W_per_mK"]
    assert 0.18 < k[0][0] < 30.0  # between the phases' conductivities
    r2 = run_itr(*args[:-2], "--seed", "2", "--out", "d", cwd=tmp_path)
    assert r2.returncode == 0, r2.stderr
    again = json.loads((out / "manifest.json").read_text())
    assert again["inputs"]["seed"] == 2 and again["written_by"]["command"] == "itr demo"
    assert "--out: 'd' holds an earlier 'itr demo' run: the files its manifest lists are " \
        "replaced" in r2.stderr


def test_sigterm_mid_run_leaves_no_output_folder(tmp_path):
    env = dict(os.environ)
    p = subprocess.Popen([sys.executable, "-m", "itr_identify.cli", "demo", "--box-um", "12",
                          "--voxel-um", "0.125", "--out", "run"], cwd=tmp_path, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while not (tmp_path / "run").exists() and time.time() < deadline and p.poll() is None:
        time.sleep(0.05)
    time.sleep(0.5)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=120)
    if p.returncode == 0:
        pytest.skip("the run finished before the signal arrived")
    assert p.returncode == 128 + signal.SIGTERM
    assert err.strip().splitlines()[-1].startswith("itr: error: stopped by signal")
    assert "Traceback" not in err
    assert not Path(tmp_path / "run").exists()
