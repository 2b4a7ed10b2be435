"""``itr solve VOLUME``: a labelled TIFF written by tifffile solved end to end, its tensor the
Python API's on the same labels; a BCC sphere array against the multipole reference; the
resistances' sources and precedence; every bad input refused in one line before any work."""

import json
import math

import numpy as np
import pytest
import pyvista as pv
import tifffile

from itr_fv import Materials, Microstructure, analytic, homogenize
from itr_identify.cli import main
from tests.refusals import refused_on_cli

K = {"silicone": 0.18, "Al2O3": 30.0, "AlN": 200.0}   # the paper's system (examples/paper)


def balls(n: int, centres, radius: float) -> np.ndarray:
    """Particle ids of periodic balls (voxel centres at i + 1/2, in voxels): ball ``i`` is
    particle ``i + 1``, 0 elsewhere."""
    g = np.indices((n, n, n)) + 0.5
    out = np.zeros((n, n, n), dtype=np.int32)
    for i, c in enumerate(centres):
        d = g - np.reshape(c, (3, 1, 1, 1))
        d -= n * np.round(d / n)
        out[(d * d).sum(axis=0) <= radius ** 2] = i + 1
    return out


def imagej_tiff(path, labels, voxel_um):
    """A label stack as Fiji writes one (tifffile, not the package's writer)."""
    tifffile.imwrite(path, labels, imagej=True, resolution=(1 / voxel_um, 1 / voxel_um),
                     metadata={"spacing": voxel_um, "unit": "um", "axes": "ZYX"})


def two_filler_image(n=28):
    """Six balls in a 28^3 box, Al2O3 (label 1) and AlN (label 2), one cut by the box's
    faces; no two touch."""
    centres = [(6, 6, 6), (20, 8, 18), (0.5, 20, 10), (14, 22, 24), (22, 22, 4), (10, 14, 16)]
    pid = balls(n, centres, 4.2)
    phase = np.array([0, 1, 1, 2, 1, 2, 2], dtype=np.uint8)
    return phase[pid], pid


def solved(tmp_path, *args):
    status = main(["solve", *map(str, args)])
    return status, json.loads((tmp_path / "out" / "result.json").read_text())


def test_tiff_of_tifffile_solved_as_the_api_solves_its_labels(tmp_path, capsys):
    labels, pid = two_filler_image()
    h_um = 0.25
    imagej_tiff(tmp_path / "scan.tif", labels, h_um)
    status, res = solved(tmp_path, tmp_path / "scan.tif", "--phase", "0=matrix",
                         "--phase", "1=Al2O3", "--phase", "2=AlN",
                         "--resistance", "Al2O3-matrix=1e-8", "--resistance",
                         "AlN-silicone=2e-8", "--tol", "1e-10", "--out", tmp_path / "out")
    out = capsys.readouterr().out
    assert status == 0 and "k_eff" in out and "percolation" in out
    # the API on the same labels, particles and phases taken from the test's own balls
    ms = Microstructure.from_labels(labels.astype(np.int32), pid, h_um * 1e-6,
                                    ("silicone", "Al2O3", "AlN"))
    mat = Materials(K, {("Al2O3", "silicone"): 1e-8, ("AlN", "silicone"): 2e-8},
                    matrix="silicone", contact="area")
    api = homogenize(ms, mat, tol=1e-10)
    assert np.abs(np.array(res["k_eff_W_per_mK"]) - api.k_eff).max() <= 1e-10
    assert [c["iterations"] for c in res["load_cases"]] == api.iterations
    # what ran
    assert res["input"]["voxel_um"] == pytest.approx(h_um)
    assert "ImageJ" in res["input"]["voxel_source"] and len(res["input"]["sha256"]) == 64
    assert res["phase_table"]["labels"] == {"0": "silicone", "1": "Al2O3", "2": "AlN"}
    assert res["particles"] == 6
    assert res["particle_sizes"]["Al2O3"]["count"] == 3
    assert res["resistances_m2K_per_W"]["pairs"]["Al2O3-silicone"]["source"] == "command line"
    assert res["solver"]["tol"] == 1e-10 and res["solver"]["device"] == "cpu"
    # the phase fractions are the voxel counts of the balls
    counts = np.bincount(labels.ravel(), minlength=3) / labels.size
    assert res["phase_fractions"]["AlN"] == pytest.approx(counts[2])
    files = [f["path"] for f in json.loads((tmp_path / "out" / "manifest.json")
                                           .read_text())["files"]]
    assert files == ["result.json", "image.vti", "slice.png"]
    grid = pv.read(tmp_path / "out" / "image.vti")
    assert {"material", "particle_id", "temperature_e1", "flux_e3"} <= set(grid.cell_data)


def test_tiff_of_pillow_solved_as_the_api_solves_its_labels(tmp_path, capsys):
    """A multi-page TIFF written by Pillow (an encoder that shares no code with tifffile),
    one 8-bit page per slice, no voxel metadata: the tensor the API's on the same labels."""
    from PIL import Image

    labels, pid = two_filler_image()
    pages = [Image.fromarray(page) for page in labels]
    pages[0].save(tmp_path / "pil.tif", save_all=True, append_images=pages[1:])
    status, res = solved(tmp_path, tmp_path / "pil.tif", "--phase", "0=matrix",
                         "--phase", "1=Al2O3", "--phase", "2=AlN", "--voxel-um", "0.25",
                         "--resistance", "Al2O3-matrix=1e-8", "--resistance",
                         "AlN-silicone=2e-8", "--tol", "1e-10", "--out", tmp_path / "out")
    assert status == 0
    ms = Microstructure.from_labels(labels.astype(np.int32), pid, 0.25e-6,
                                    ("silicone", "Al2O3", "AlN"))
    mat = Materials(K, {("Al2O3", "silicone"): 1e-8, ("AlN", "silicone"): 2e-8},
                    matrix="silicone", contact="area")
    api = homogenize(ms, mat, tol=1e-10)
    assert np.abs(np.array(res["k_eff_W_per_mK"]) - api.k_eff).max() <= 1e-10
    assert res["particles"] == 6 and res["input"]["shape"] == [28, 28, 28]


def test_bcc_sphere_array_image_against_the_multipole_reference(tmp_path, capsys):
    """A BCC array at f = 0.4 (the paper's Al2O3 in silicone, R = 2e-7 m^2 K/W) as a 64^3
    label image: its tensor within 1 % of the multipole value of the continuum problem,
    its filler fraction within 1 % of the spheres'."""
    n, f, box_um, R = 64, 0.4, 4.0, 2e-7
    a_vox = (3 * f / (8 * math.pi)) ** (1 / 3) * n         # two spheres per cell
    labels = (balls(n, [(0, 0, 0), (n / 2, n / 2, n / 2)], a_vox) > 0).astype(np.uint8)
    imagej_tiff(tmp_path / "bcc.tif", labels, box_um / n)
    status, res = solved(tmp_path, tmp_path / "bcc.tif", "--phase", "0=matrix",
                         "--phase", "1=Al2O3", "--resistance", "Al2O3-matrix=2e-7",
                         "--out", tmp_path / "out")
    assert status == 0
    a_m = a_vox * box_um / n * 1e-6
    ref = K["silicone"] * analytic.sphere_array("bcc", f, K["Al2O3"] / K["silicone"],
                                                R * K["silicone"] / a_m)
    k = np.array(res["k_eff_W_per_mK"])
    assert np.diag(k) == pytest.approx([ref] * 3, rel=0.01)
    assert res["phase_fractions"]["Al2O3"] == pytest.approx(f, rel=0.01)
    assert res["particles"] == 2
    assert res["percolation"]["spans"] == [False, False, False]   # the spheres do not touch


def test_resistances_from_identified_json_and_system_file_with_precedence(tmp_path, capsys):
    """identified.json's quoted values over the system file's, the command line over both;
    every pair's source and what it overrode in result.json."""
    labels, _ = two_filler_image(20)
    np.save(tmp_path / "v.npy", labels)
    ident = {"headline": {"quote": "area", "parameters": {
        "area": {"R_Al2O3_silicone": {"best": 3e-8}, "R_AlN_silicone": {"best": 4e-8},
                 "Rff_Al2O3_AlN": {"best": 9e-8}},
        "gap": {"R_Al2O3_silicone": {"best": 1e-8}, "R_AlN_silicone": {"best": 2e-8}}}}}
    (tmp_path / "identified.json").write_text(json.dumps(ident))
    system = (tmp_path / "system.toml")
    system.write_text('name = "s"\n[matrix]\nname = "silicone"\nconductivity_W_per_mK = 0.18\n'
                      '[[fillers]]\nname = "Al2O3"\nconductivity_W_per_mK = 30.0\n'
                      'size = { mu_ln_um = 1.0, sigma_ln = 0.3, basis = "number" }\n'
                      '[[fillers]]\nname = "AlN"\nconductivity_W_per_mK = 200.0\n'
                      'size = { mu_ln_um = 1.0, sigma_ln = 0.3, basis = "number" }\n'
                      '[resistances]\nR_Al2O3_silicone = 5e-8\nR_AlN_silicone = 6e-8\n')
    status, res = solved(tmp_path, tmp_path / "v.npy", "--voxel-um", "0.5", "--phase",
                         "0=matrix", "--phase", "1=Al2O3", "--phase", "2=AlN", "--system",
                         system, "--resistances", tmp_path / "identified.json",
                         "--resistance", "AlN-matrix=7e-8", "--out", tmp_path / "out")
    assert status == 0
    pairs = res["resistances_m2K_per_W"]["pairs"]
    assert pairs["Al2O3-silicone"] == {"value": 3e-8, "source": "identified", "overridden": [
        {"source": "system file", "value": 5e-8}]}
    assert pairs["AlN-silicone"]["value"] == 7e-8
    assert pairs["AlN-silicone"]["source"] == "command line"
    assert [o["source"] for o in pairs["AlN-silicone"]["overridden"]] == ["identified",
                                                                         "system file"]
    assert res["resistances_m2K_per_W"]["identified"]["parametrisation"] == "area"
    assert res["resistances_m2K_per_W"]["precedence"] == ["command line", "identified",
                                                          "system file"]


# ---------------------------------------------------------------------------- refusals
PHASES = ["--phase", "0=matrix", "--phase", "1=Al2O3"]
R = ["--resistance", "Al2O3-matrix=1e-8"]


def _bad(tmp_path):
    """Bad volumes of every kind, each next to a good one."""
    good = (balls(12, [(6, 6, 6)], 3.0) > 0).astype(np.uint8)
    np.save(tmp_path / "good.npy", good)
    np.save(tmp_path / "float.npy", good.astype(np.float64))
    np.save(tmp_path / "flat.npy", good[0])
    np.save(tmp_path / "three.npy", good * 3)
    (tmp_path / "empty.tif").write_bytes(b"")
    (tmp_path / "scan.png").write_bytes(b"\x89PNG\r\n")
    tifffile.imwrite(tmp_path / "aniso.tif", good, imagej=True, resolution=(4.0, 4.0),
                     metadata={"spacing": 0.5, "unit": "um"})
    return good


@pytest.mark.parametrize("volume, extra, argument, words", [
    ("float.npy", [], "VOLUME", "float64"),
    ("flat.npy", [], "VOLUME", "3-D"),
    ("empty.tif", [], "VOLUME", "empty"),
    ("scan.png", [], "VOLUME", "unknown file type"),
    ("missing.tif", [], "VOLUME", "no such file"),
    ("aniso.tif", ["--voxel-um", "0.25"], "VOLUME", "non-cubic"),
    ("three.npy", [], "VOLUME", "label 3"),                          # not in the table
    ("good.npy", ["--phase", "2=AlN"], "--phase", "label 2"),        # no voxels: empty phase
    ("good.npy", ["--phase", "2=SiC"], "--phase", "SiC"),            # not in the system
    ("good.npy", ["--resistance", "Al2O3-matrix=-1"], "--resistance", "resistance >= 0"),
])
def test_bad_volumes_refused_in_one_line_before_any_work(tmp_path, capsys, volume, extra,
                                                         argument, words):
    _bad(tmp_path)
    voxel = [] if "--voxel-um" in extra or volume.endswith(".tif") else ["--voxel-um", "0.5"]
    status = main(["solve", str(tmp_path / volume), *voxel, *PHASES, *R, *extra,
                   "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert status == 2 and captured.out == ""
    assert words in refused_on_cli(captured.err, argument)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("args, argument", [
    (["--phase", "0=matrix", "--phase", "1=Al2O3"], "--voxel-um"),          # npy: no voxel
    (["--voxel-um", "0.5"], "--phase"),                                      # no table
    (["--voxel-um", "0.5", *PHASES, "--resistance", "AlN-matrix=1e-8"], "--resistance"),
    (["--voxel-um", "0.5", *PHASES], "--resistance"),                        # none given
    (["--voxel-um", "0.5", *PHASES, *R, "--particles", "good.npy", "--split", "watershed"],
     "--split"),
    (["--voxel-um", "0.5", *PHASES, *R, "--device", "cuda"], "--device"),
    (["--voxel-um", "0.5", *PHASES, *R, "--resistances", "none.json"], "--resistances"),
])
def test_bad_settings_refused_in_one_line(tmp_path, capsys, monkeypatch, args, argument):
    from itr_fv.solvers import choice
    monkeypatch.setattr(choice, "cuda_device_count", lambda: 0)       # no GPU seen
    monkeypatch.setattr("itr_fv.solvers.devices.cuda_device_count", lambda: 0)
    _bad(tmp_path)
    monkeypatch.chdir(tmp_path)
    status = main(["solve", "good.npy", *args, "--out", "out"])
    captured = capsys.readouterr()
    assert status == 2
    refused_on_cli(captured.err, argument)
    assert not (tmp_path / "out").exists()


def test_voxel_given_against_the_file_refused(tmp_path, capsys):
    good = _bad(tmp_path)
    imagej_tiff(tmp_path / "s.tif", good, 0.25)
    status = main(["solve", str(tmp_path / "s.tif"), "--voxel-um", "0.3", *PHASES, *R,
                   "--out", str(tmp_path / "out")])
    assert status == 2
    assert "disagrees" in refused_on_cli(capsys.readouterr().err, "--voxel-um")


def test_plan_stops_before_solving(tmp_path, capsys):
    _bad(tmp_path)
    status = main(["solve", str(tmp_path / "good.npy"), "--voxel-um", "0.5", *PHASES, *R,
                   "--plan", "--out", str(tmp_path / "out")])
    out = capsys.readouterr().out
    assert status == 0 and out.startswith("plan: one solve") and "12x12x12" in out
    assert not (tmp_path / "out").exists()


def test_memory_refusal_before_any_work(tmp_path, capsys, monkeypatch):
    from itr_identify.workflows import image_solve
    _bad(tmp_path)
    monkeypatch.setattr(image_solve, "available_memory", lambda: 10**6)
    status = main(["solve", str(tmp_path / "good.npy"), "--voxel-um", "0.5", *PHASES, *R,
                   "--out", str(tmp_path / "out")])
    assert status == 2
    assert "crop or downsample" in refused_on_cli(capsys.readouterr().err, "memory")
    assert not (tmp_path / "out").exists()


def test_the_progress_bar_counts_residual_decades_of_each_load_case():
    from itr_identify.workflows.image_solve import residual_bar

    bar, callback = residual_bar(1e-8, progress=True)
    assert bar.total == 3 * 8
    for res in (0.5, 0.05, 2e-3, 1e-9):        # direction 0 reaches the tolerance
        callback(0, 1, res)
    callback(1, 1, 0.009)                      # direction 1: two decades so far
    callback(1, 2, 0.02)                       # a residual that rises counts nothing back
    assert bar.n == 8 + 2
    bar.close()
