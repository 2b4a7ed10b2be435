"""``itr identify`` and ``itr reproduce`` end to end at a tiny size, and their bad input."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from itr_identify.cli import main
from itr_identify.inference.measurements import read_measurements
from itr_identify.reporting.headline import FLAGS

TINY = ["--box-um", "12", "--voxel-um", "0.5", "--replicas", "2", "--no-progress",
        "--fidelity", "quick"]


def write(path, text):
    path.write_text(text)
    return str(path)


def test_identify_writes_identified_json(tmp_path, capsys):
    csv = write(tmp_path / "m.csv", "formulation,replicate,k_W_per_mK\n"
                "Al2O3-55,1,1.29\nAl2O3-55,2,1.30\nAl2O3-55,3,1.22\n"
                "Al2O3-62,1,1.70\nAl2O3-62,2,1.75\nAl2O3-62,3,1.66\n")
    out = tmp_path / "out"
    assert main(["identify", csv, "--out", str(out), "--parametrisation", "gap", *TINY]) == 0
    data = json.loads((out / "identified.json").read_text())
    p = data["gap"]["parameters"]["R_Al2O3_silicone"]
    lo, hi = p["interval_90"]
    assert 1e-9 <= lo <= p["median"] <= hi <= 1e-5
    assert p["unit"] == "m^2 K/W"
    assert data["gap"]["formulations"] == 2
    report = (out / "report.md").read_text()
    assert "R_Al2O3_silicone" in report and "Al2O3-62" in report
    manifest = json.loads((out / "manifest.json").read_text())
    assert {f["path"] for f in manifest["files"]} >= {"identified.json", "report.md"}
    stdout = capsys.readouterr().out
    assert "identify: done" in stdout
    # the last line names the folder and every file written, the report first
    assert stdout.splitlines()[-1].endswith(f"wrote {out}/: report.md, identified.json, "
                                            "posterior_gap.parquet, figure posterior_gap.png, "
                                            "manifest.json")
    # the headline: on the terminal with interval and flag, at the top of the report, in json
    head = data["headline"]
    e = head["parameters"]["gap"]["R_Al2O3_silicone"]
    assert e["interval_90"] == [lo, hi] and e["flag"] in FLAGS
    assert head["quote"] == "gap" and head["fidelity"] == "quick"
    assert f"R_Al2O3_silicone = {e['best']:.2e} m^2 K/W (90 % interval {lo:.2e} - " \
           f"{hi:.2e}; {e['flag']})" in stdout
    assert report.split("\n## ")[1].startswith("Headline")


@pytest.mark.parametrize("text, expected", [
    ("formulation,replicate\nAl2O3-55,1\n", "k_W_per_mK"),
    ("formulation,replicate,k_W_per_mK\nAl2O3-55,1,-1.2\nAl2O3-55,2,1.3\n", "line 2"),
    ("formulation,replicate,k_W_per_mK\nSiC-50,1,1.2\nSiC-50,2,1.3\n",
     "formulation 'SiC-50': SiC is not a filler of the material system 'paper'"),
    ("formulation,replicate,k_W_per_mK\nAl2O3-55,1,1.2\n", "replicate"),
    ("formulation,replicate,k_W_per_mK\nAl2O3-55,1,nan\nAl2O3-55,2,1.3\n", "k_W_per_mK"),
])
def test_identify_bad_tables_fail_in_one_line(tmp_path, capsys, text, expected):
    csv = write(tmp_path / "bad.csv", text)
    assert main(["identify", csv, "--out", str(tmp_path / "o"), *TINY]) == 2
    err = capsys.readouterr().err
    assert err.startswith("itr: error: ") and err.count("\n") == 1
    assert expected in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("args, expected", [
    (["identify", "missing.csv"], "MEASUREMENTS"),
    (["identify"], "MEASUREMENTS: give a CSV file of your measurements, or --example"),
    (["identify", "mine.csv", "--example"], "MEASUREMENTS: give a CSV file"),
    (["identify", "--example", "--readings"], "--readings: the shipped Table 3"),
    # --example reads the shipped Table 3: its 12 formulations reach the memory estimate
    (["identify", "--example", "--voxel-um", "0.005"], "memory: the run on 2400^3 voxels"),
    (["reproduce", "--voxel-um", "0.3", "--box-um", "8"], "box_um/voxel_um: a 8 um box"),
    (["reproduce", "--replicas", "1"], "--replicas"),
    (["reproduce", "--parametrisation", "spots"], "--parametrisation"),
    (["reproduce", "--box-um", "-2"], "--box-um"),
    (["reproduce", "--fidelity", "best"], "--fidelity"),
    (["reproduce", "--store", "/dev/null"], "--store: '/dev/null' is a file"),
])
def test_bad_invocations_fail_in_one_line(tmp_path, capsys, args, expected):
    assert main([*args, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("itr: error: ") and err.count("\n") == 1
    assert expected in err


@pytest.mark.slow
def test_reproduce_end_to_end_at_tiny_size(tmp_path):
    """Every stage of the pipeline on the shipped Table 3: RVEs of all 12 formulations,
    reduced bases, calibration, screening, full-solver validation, leave-one-out, figures,
    fields, Parquet and manifest."""
    out = tmp_path / "rep"
    assert main(["reproduce", "--out", str(out), *TINY]) == 0
    data = json.loads((out / "identified.json").read_text())
    for par in ("area", "gap"):
        d = data[par]
        assert len(d["validation"]) == 12 and len(d["leave_one_out"]) == 12
        for row in d["validation"]:
            assert row["predicted"] > 0.18                        # above the matrix
            assert abs(row["error_pct"]) < 60
        for name, p in d["parameters"].items():
            assert p["interval_90"][0] <= p["best"] * 1.2 and p["unit"] == "m^2 K/W"
    assert set(data["gap"]["parameters"]) == {"R_Al2O3_silicone", "R_AlN_silicone"}
    assert "Rff_Al2O3_AlN" in data["area"]["parameters"]
    head = data["headline"]
    assert head["quote"] in ("area", "gap")
    for par in ("area", "gap"):
        for name, e in head["parameters"][par].items():
            assert e["interval_90"] == data[par]["parameters"][name]["interval_90"]
            assert e["flag"] in FLAGS
    # a per-area contact value is never quoted as plainly determined
    assert head["parameters"]["area"]["Rff_Al2O3_AlN"]["flag"] != "determined"
    for par in ("area", "gap"):
        # the joint posterior (issue 59): the gap hybrids vary both resistances, none held;
        # the area hybrids vary their own contact resistance and hold the rest at one point
        # of the single-filler posterior, inside its 90 % intervals
        held = data[par]["two_filler_held"]
        if par == "gap":
            assert held == {}
        else:
            assert len(held) == 4
            for h in held.values():
                assert h["held_at"] == next(iter(held.values()))["held_at"]
                for name, v in h["held_at"].items():
                    lo, hi = data[par]["parameters"][name]["interval_90"]
                    assert lo <= v <= hi
        assert {r["formulation"] for r in data[par]["validation"]} >= {
            "Al2O3-29-AlN-29", "Al2O3-30-AlN-30", "Al2O3-31-AlN-31", "Al2O3-32.5-AlN-32.5"}
        assert data[par]["inputs"]["sampler"]["library"] == "emcee"
        for row in data[par]["validation"]:
            lo, hi = row["predictive_90"]
            assert lo < hi and row["inside"] == (lo <= row["measured"] <= hi)
    assert data["selection"]["bic"].keys() == {"area", "gap"}
    report = (out / "report.md").read_text()
    table3 = read_measurements()
    for heading in ("Table 1", "Table 3", "Table 5", "Table 6", "Leave one formulation out",
                    "Identifiability", "Error budget, gap parametrisation (fidelity `quick`)"):
        assert heading in report
    for par in ("area", "gap"):
        budget = data[par]["error_budget"]
        assert budget["fidelity"] == "quick" and data[par]["settings"]["faithful"] is None
        for f, d in budget["formulations"].items():
            # Table 3's replicates: standard error of the mean over the mean
            k = table3.values[f]
            assert d["items"]["measurement noise"]["value"] == pytest.approx(
                k.std(ddof=1) / np.sqrt(k.size) / k.mean())
            assert d["numerical_rss"] > 0
            # no faithful correction at the quick level: the voxel bias stays in the budget
            assert "voxel bias (not corrected)" in d["items"]
        assert set(budget["parameters"]) <= set(data[par]["parameters"])
    # every identified value against the paper's Table 5 names the reasons that bear on it
    against = report.split("### Against the paper's Table 5")[1].split("\n\n")[1]
    rows = against.splitlines()[2:]
    assert len(rows) == 7 and all("reasons " in r for r in rows)
    solves = pq.read_table(out / "full_solves.parquet").to_pydict()
    assert set(solves["purpose"]) >= {"reduced basis", "RVE scatter", "validation"}
    # insulating corners of the reduced-basis box (R = 1e-5) fall below the matrix, 0.18
    assert np.all(np.array(solves["k_xx"]) > 0.05) and max(solves["k_xx"]) > 1.0
    # one record format: full_solves.parquet lists rows of the solve store (OUT/solves),
    # the same keys, tensors and iterations, with this run's labels
    from itr_surrogate.store import SolveStore
    stored = {r["key"]: r for r in SolveStore(out / "solves").table().to_pylist()}
    assert set(solves["key"]) <= set(stored)
    assert "conductivities silicone 0.18, Al2O3 30, AlN 200 W/(m K)" in report
    # the intervals say the fidelity they hold at
    assert "The 90 % intervals hold at this fidelity only: 12 um box, 0.5 um voxels" in report
    for i, key in enumerate(solves["key"]):
        for col in ("rve_id", "k_xx", "k_yz", "k_iso", "iterations", "tol", "contact"):
            assert solves[col][i] == stored[key][col], (key, col)
    names = {f["path"] for f in json.loads((out / "manifest.json").read_text())["files"]}
    assert {"fig2_psd.png", "fig4_rves.png", "fig6_parity.png", "fig8_screening.png",
            "report.md", "identified.json", "full_solves.parquet"} <= names
    assert any(n.endswith(".vti") for n in names)
    for n in names:
        if n.endswith(".png"):
            assert (out / n).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # every number says whether it is raw or at the level: at `quick` no model is corrected,
    # so the level's factor is 1 and the two columns agree; the record says no solve ran
    assert set(solves["level"]) == {"none"}
    assert np.allclose(solves["k_iso_at_level"], solves["k_iso"])
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["written_by"]["command"] == "itr reproduce"
    for par in ("area", "gap"):
        rec = data[par]["fidelity"]
        assert rec["level"] == "quick" and rec["faithful_solves_this_run"] == 0
        assert {r["source"] for r in rec["models"].values()} == {"none"}
        assert data[par]["corrections"] == {}
        assert manifest["inputs"]["fidelity_ran"][par] == rec
        for row in data[par]["validation"]:
            assert row["predicted"] == pytest.approx(row["predicted_raw"] * row["level_factor"])
        # fig6's left panel compares raw with raw: each full solve inside its certified bounds
        assert all(p["inside"] for p in data["surrogate_check"][par])
    assert "0 faithful full solves ran in this run" in report
    # the field file holds the whole tensor of its RVE (three load cases solved)
    import pyvista as pv
    grid = pv.read(next(out.glob("temperature_*.vti")))
    assert np.all(np.isfinite(np.asarray(grid.field_data["k_eff"])))
    # the snapshot fields left the store at the end of the run (rows stay)
    assert not list((out / "solves" / "fields").glob("*.npz"))
    assert "snapshot fields removed" in manifest["inputs"]["store_fields"]


@pytest.mark.slow
def test_identify_with_an_effect_writes_it_beside_the_base(tmp_path, capsys):
    """``--effect tester``: the identification with the tester's contact beside the base
    model, in the report, identified.json and a residual figure (the verdict over the
    library, ``--discrepancy``, is tested in tests/test_effects_on_identification.py)."""
    csv = write(tmp_path / "m.csv", "formulation,replicate,k_W_per_mK\n"
                "Al2O3-55,1,1.29\nAl2O3-55,2,1.30\nAl2O3-55,3,1.22\n"
                "Al2O3-62,1,1.70\nAl2O3-62,2,1.75\nAl2O3-62,3,1.66\n"
                "AlN-55,1,1.50\nAlN-55,2,1.46\nAlN-55,3,1.55\n")
    out = tmp_path / "out"
    assert main(["identify", csv, "--out", str(out), "--parametrisation", "gap",
                 "--effect", "tester", *TINY]) == 0
    data = json.loads((out / "identified.json").read_text())
    d = data["discrepancy"]
    assert "verdict" not in d
    fit = d["effect_fit"]
    assert fit["effect"]["key"] == "tester" and fit["base"]["key"] == "base"
    lo, hi = fit["effect"]["value"][1:]
    assert 0.0 <= lo <= hi <= 1e-4
    assert set(fit["residuals"]) == {"Al2O3-55", "Al2O3-62", "AlN-55"}
    report = (out / "report.md").read_text()
    assert "## Discrepancy" in report and "### With tester contact resistance" in report
    assert "not named by the rule" not in report
    assert (out / "effect_residuals.png").stat().st_size > 1000
    # the headline carries R under the base model and with the effect, without the model form
    head = data["headline"]["discrepancy"]["effect"]
    assert set(head["resistances"]) == {"R_Al2O3_silicone", "R_AlN_silicone"}
    assert head["resistances"]["R_AlN_silicone"]["with_effect"] == fit["effect"][
        "resistances"]["R_AlN_silicone"]
    assert head["chi_square"]["base"][0] == fit["base"]["chi_square"]
    printed = capsys.readouterr().out
    assert "discrepancy: " in printed and "with tester contact resistance" in printed
