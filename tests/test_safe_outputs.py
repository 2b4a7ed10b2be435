"""Silent wrong answers and silent non-outputs, each refused or made loud (issue 8, point 3)."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
import warnings

import numpy as np
import pytest
from conftest import sc_sphere
from refusals import refuses

from itr_fv import Materials, Microstructure, homogenize
from itr_fv.checks import PhysicalScaleWarning
from itr_fv.io import atomic_path, read_manifest, sha256, write_text
from itr_fv.run_folder import begin_run, write_manifest


@pytest.fixture(scope="module")
def small_result():
    mat = Materials({"matrix": 1.0, "filler": 10.0}, {("filler", "matrix"): 0.02}, "matrix")
    return homogenize(sc_sphere(12, 0.2), mat, solver="fv", tol=1e-10)


# ------------------------------------------------------------------- micrometres as metres
def _rve(voxel_m: float) -> Microstructure:
    n = 16
    box = n * voxel_m
    return Microstructure.from_spheres(np.full((1, 3), 0.5 * box), np.array([0.3 * box]),
                                       "Al2O3", box_m=box, shape=n, matrix="silicone")


def test_micrometres_passed_as_metres_warn_and_name_the_unit():
    mat = Materials({"silicone": 0.18, "Al2O3": 30.0}, {("Al2O3", "silicone"): 2e-6},
                    matrix="silicone")
    with pytest.warns(PhysicalScaleWarning, match=r"voxel_m.*metres.*micrometres"):
        wrong = homogenize(_rve(0.3125), mat, solver="fv", tol=1e-8)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysicalScaleWarning)  # the right unit: no warning
        right = homogenize(_rve(0.3125e-6), mat, solver="fv", tol=1e-8)
    # what the warning protects against: taken as metres the interface vanishes (k_eff is
    # that of a perfect interface) and k_eff comes out too high
    perfect = homogenize(_rve(0.3125e-6), mat.with_values(resistance={("Al2O3", "silicone"): 0}),
                         solver="fv", tol=1e-8)
    assert wrong.k_eff[0, 0] == pytest.approx(perfect.k_eff[0, 0], rel=1e-4)
    assert wrong.k_eff[0, 0] > 1.05 * right.k_eff[0, 0]


def test_large_voxels_without_interface_resistance_do_not_warn():
    mat = Materials({"silicone": 0.18, "Al2O3": 30.0}, {("Al2O3", "silicone"): 0.0},
                    matrix="silicone")
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysicalScaleWarning)
        homogenize(_rve(0.01), mat, solver="fv", tol=1e-8)


# ---------------------------------------------------------------------- booleans, names
@pytest.mark.parametrize("value", [True, False, np.bool_(True)])
def test_booleans_are_not_conductivities_or_resistances(value):
    with refuses(ValueError, "conductivity['A']"):
        Materials({"m": 1.0, "A": value}, matrix="m")
    with refuses(ValueError, "resistance[('A', 'm')]"):
        Materials({"m": 1.0, "A": 2.0}, {("A", "m"): value}, matrix="m")


@pytest.mark.parametrize("name", ["Al₂O₃", "sílice", "Al2O3_coated", "2phase", " A", ""])
def test_phase_names_are_checked_before_any_work(name):
    with refuses(ValueError, "conductivity"):
        Materials({"m": 1.0, name: 2.0}, matrix="m")
    with refuses(ValueError, "materials"):
        Microstructure.from_spheres(np.full((1, 3), 0.5), np.array([0.2]), name, box_m=1.0,
                                    shape=8, matrix="m")
    with refuses(ValueError, "names"):
        Microstructure.from_labels(np.zeros((4, 4, 4), int), np.zeros((4, 4, 4), int),
                                   voxel_m=1e-6, names=(name,))


def test_accepted_phase_names():
    mat = Materials({"silicone": 0.18, "Al2O3": 30.0, "AlN": 200.0, "h-BN": 300.0,
                     "Cu+Ag.1": 400.0}, matrix="silicone")
    assert set(mat.phases) == {"silicone", "Al2O3", "AlN", "h-BN", "Cu+Ag.1"}


# ------------------------------------------------------------------------ atomic output
def test_atomic_path_keeps_the_old_file_when_the_writer_fails(tmp_path):
    target = tmp_path / "field.vti"
    target.write_text("old complete file")
    with pytest.raises(RuntimeError, match="disk died"):
        with atomic_path(target) as tmp:
            tmp.write_text("half of the new")
            raise RuntimeError("disk died")
    assert target.read_text() == "old complete file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["field.vti"]  # no temp file left


def test_atomic_path_refuses_an_empty_output(tmp_path):
    with pytest.raises(OSError, match="no output"):
        with atomic_path(tmp_path / "x.png"):
            pass  # the writer wrote nothing
    assert list(tmp_path.iterdir()) == []


def test_vti_writer_failure_leaves_no_partial_file(small_result, tmp_path, monkeypatch):
    import pyvista as pv

    def broken_save(self, filename, *args, **kwargs):
        with open(filename, "wb") as fh:
            fh.write(b"<VTKFile truncated")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pv.ImageData, "save", broken_save)
    with pytest.raises(OSError, match="No space"):
        small_result.to_vtk(tmp_path / "demo.vti")
    assert list(tmp_path.iterdir()) == []


_SIGTERM_WRITER = textwrap.dedent("""
    import sys, time
    from itr_fv.io import atomic_path
    with atomic_path(sys.argv[1]) as tmp:
        with open(tmp, "w") as fh:
            fh.write("partial")
            fh.flush()
            print("writing", flush=True)
            time.sleep(60)
""")


def test_sigterm_during_a_write_leaves_neither_a_truncated_file_nor_a_temp(tmp_path):
    # the command line's handler: SIGTERM -> SystemExit
    from itr_identify.cli.dispatch import _on_sigterm

    script = tmp_path / "writer.py"
    script.write_text("import signal\nfrom itr_identify.cli.dispatch import _on_sigterm\n"
                      "signal.signal(signal.SIGTERM, _on_sigterm)\n" + _SIGTERM_WRITER)
    out = tmp_path / "out"
    out.mkdir()
    target = out / "demo.vti"
    proc = subprocess.Popen([sys.executable, str(script), str(target)], stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout.readline().strip() == "writing"
    assert len(list(out.iterdir())) == 1  # the temporary file, under another name
    assert not target.exists()
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == 128 + signal.SIGTERM
    assert list(out.iterdir()) == []
    assert callable(_on_sigterm)


# ------------------------------------------------------------------------------ manifest
def test_manifest_lists_files_with_checksums_and_a_rerun_clears_the_old_run(tmp_path):
    begin_run(tmp_path, "demo")
    a = write_text(tmp_path / "a.json", '{"k": 1}\n')
    b = write_text(tmp_path / "b.txt", "second\n")
    write_manifest(tmp_path, [a, b], {"seed": 3}, job="demo")
    m = read_manifest(tmp_path)
    assert m["inputs"] == {"seed": 3} and m["state"] == "complete"
    assert m["written_by"]["package"] == "itr-composites"
    assert m["written_by"]["command"] == "itr demo"
    assert [f["path"] for f in m["files"]] == ["a.json", "b.txt"]
    assert m["files"][0]["sha256"] == sha256(a) and m["files"][1]["bytes"] == 7
    assert "numpy" in m["versions"] and "python" in m["versions"]
    # a new run of the same command first removes the files the manifest listed
    begin_run(tmp_path, "demo")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["manifest.json"]
    assert read_manifest(tmp_path)["state"] == "running"
    assert read_manifest(tmp_path)["files"] == []


def test_manifest_is_valid_json_written_last(tmp_path):
    begin_run(tmp_path, "demo")
    f = write_text(tmp_path / "x.txt", "x")
    time.sleep(0.01)
    path = write_manifest(tmp_path, [f], {}, job="demo")
    assert json.loads(path.read_text())["files"][0]["path"] == "x.txt"
    assert os.path.getmtime(path) >= os.path.getmtime(f)
