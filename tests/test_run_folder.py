"""An output folder is a run's only when its own manifest says so: a folder holding a user's
``manifest.json``, another command's output, or one file the run did not write is refused in
one line before anything is touched, every file byte-identical after; a killed run's folder
is its own and resumes."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from itr_fv.io import read_manifest, write_text
from itr_fv.run_folder import FolderRefused, begin_run, claimed, release, write_manifest

SHIPPED_TABLE = str(Path(__file__).resolve().parents[1] / "itr_fv" / "data" / "measured_tc.csv")
#: The cheapest settings of each command that refuses a folder (the refusal comes first).
TINY_RVE = ["--box-um", "12", "--voxel-um", "0.5", "--replicas", "2", "--no-progress",
            "--fidelity", "quick"]
COMMANDS = {
    "demo": ["demo", "--box-um", "6", "--voxel-um", "0.25", "--fraction", "0.4"],
    "identify": ["identify", SHIPPED_TABLE, *TINY_RVE],
    "reproduce": ["reproduce", *TINY_RVE, "--no-leave-one-out"],
    "discrepancy": ["discrepancy", "--box-um", "12", "--voxel-um", "0.5", "--replicas", "2",
                    "--effects", "matrix", "--no-progress"],
}


def run_itr(*args, cwd, timeout=300):
    env = dict(os.environ)
    env.pop("ITR_DEBUG", None)
    return subprocess.run([sys.executable, "-m", "itr_identify.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def snapshot(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` with the SHA-256 of its bytes."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def one_line_refusal(r) -> str:
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and lines[0].startswith("itr: error: --out: "), r.stderr
    assert "Traceback" not in r.stderr
    return lines[0]


@pytest.fixture(scope="module")
def demo_folder(tmp_path_factory) -> Path:
    """A finished ``itr demo`` output folder (copied per test)."""
    root = tmp_path_factory.mktemp("demo")
    r = run_itr(*COMMANDS["demo"], "--out", "d", cwd=root)
    assert r.returncode == 0, r.stderr
    return root / "d"


def _copy(src: Path, dst: Path) -> Path:
    import shutil
    shutil.copytree(src, dst)
    return dst


def user_project(folder: Path) -> Path:
    """A user's folder: a web app's manifest.json, a report.md and a thesis.tex."""
    folder.mkdir()
    (folder / "manifest.json").write_text(json.dumps({"name": "my-web-app", "version": "1.0",
                                                      "icons": []}))
    (folder / "report.md").write_text("# my lab report\n")
    (folder / "thesis.tex").write_text("\\documentclass{article}\n")
    return folder


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_foreign_manifest_is_refused_and_nothing_changes(command, tmp_path):
    proj = user_project(tmp_path / "userproj")
    before = snapshot(proj)
    r = run_itr(*COMMANDS[command], "--out", "userproj", cwd=tmp_path, timeout=60)
    line = one_line_refusal(r)
    assert "'userproj'" in line and "not written by itr" in line and "nothing was changed" in line
    assert snapshot(proj) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["userproj"]


@pytest.mark.parametrize("command", ["identify", "reproduce", "discrepancy"])
def test_another_commands_output_is_refused_and_nothing_changes(command, demo_folder,
                                                                tmp_path):
    d = _copy(demo_folder, tmp_path / "d")
    before = snapshot(d)
    r = run_itr(*COMMANDS[command], "--out", "d", cwd=tmp_path, timeout=60)
    line = one_line_refusal(r)
    assert "holds the output of 'itr demo', not of 'itr " + command + "'" in line
    assert snapshot(d) == before


def test_one_foreign_file_in_a_runs_own_folder_is_refused(demo_folder, tmp_path):
    d = _copy(demo_folder, tmp_path / "d")
    (d / "thesis.tex").write_text("mine")
    before = snapshot(d)
    r = run_itr(*COMMANDS["demo"], "--out", "d", cwd=tmp_path)
    line = one_line_refusal(r)
    assert "holds files the earlier 'itr demo' run did not write: thesis.tex" in line
    assert snapshot(d) == before


def test_a_listed_file_changed_by_the_user_is_refused(demo_folder, tmp_path):
    d = _copy(demo_folder, tmp_path / "d")
    (d / "demo.json").write_text('{"edited": true}')
    before = snapshot(d)
    line = one_line_refusal(run_itr(*COMMANDS["demo"], "--out", "d", cwd=tmp_path))
    assert "demo.json (changed since itr wrote it)" in line
    assert snapshot(d) == before


def test_a_plain_folder_with_one_file_is_refused(tmp_path):
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "lab-book.txt").write_text("someone's")
    before = snapshot(tmp_path / "notes")
    line = one_line_refusal(run_itr(*COMMANDS["demo"], "--out", "notes", cwd=tmp_path))
    assert "is not empty and it holds no itr manifest (lab-book.txt)" in line
    assert snapshot(tmp_path / "notes") == before


def test_the_same_command_again_replaces_only_its_listed_files(demo_folder, tmp_path):
    d = _copy(demo_folder, tmp_path / "d")
    r = run_itr(*COMMANDS["demo"], "--seed", "2", "--out", "d", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "holds an earlier 'itr demo' run: the files its manifest lists are replaced" \
        in r.stderr
    m = read_manifest(d)
    assert m["inputs"]["seed"] == 2 and m["state"] == "complete"
    assert sorted(p.name for p in d.iterdir()) == sorted(
        ["manifest.json"] + [f["path"] for f in m["files"]])


# ------------------------------------------------------------------ the library's rules
def test_a_killed_run_is_its_own_folder_and_lists_what_it_wrote(tmp_path):
    out = tmp_path / "run"
    begin_run(out, "reproduce", folders=("solves",))
    assert claimed(out) == "itr reproduce"
    write_text(out / "fig2_psd.png", "png")
    write_text(out / "solves" / "solves" / "abc.parquet", "row")
    m = read_manifest(out)
    assert m["state"] == "running" and [f["path"] for f in m["files"]] == ["fig2_psd.png"]
    assert m["folders"] == ["solves"]
    release(out)                      # the process died here: no complete manifest
    # the same command claims it again: the listed file goes, the store stays
    begin_run(out, "reproduce", folders=("solves",))
    assert not (out / "fig2_psd.png").exists()
    assert (out / "solves" / "solves" / "abc.parquet").read_text() == "row"
    f = write_text(out / "report.md", "done")
    write_manifest(out, [f], {"seed": 1}, job="reproduce")
    assert claimed(out) is None
    assert read_manifest(out)["state"] == "complete"
    # another command, and a stray folder, are refused
    with pytest.raises(FolderRefused, match="holds the output of 'itr reproduce'"):
        begin_run(out, "identify")
    (out / "extra").mkdir()
    with pytest.raises(FolderRefused, match="did not write: extra"):
        begin_run(out, "reproduce", folders=("solves",))


def test_a_write_the_run_did_not_report_is_still_listed(tmp_path):
    begin_run(tmp_path / "r", "demo")
    a = write_text(tmp_path / "r" / "a.txt", "a")
    write_text(tmp_path / "r" / "b.txt", "b")           # not passed to write_manifest
    write_manifest(tmp_path / "r", [a], {}, job="demo")
    assert [f["path"] for f in read_manifest(tmp_path / "r")["files"]] == ["a.txt", "b.txt"]
    begin_run(tmp_path / "r", "demo")                   # so the re-run is not refused
    assert sorted(p.name for p in (tmp_path / "r").iterdir()) == ["manifest.json"]
