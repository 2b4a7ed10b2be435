"""``itr predict`` and ``itr design`` end to end at a tiny size, and their refusals.

One tiny identification (Al2O3-55 and Al2O3-62 of Table 3, 12 um at 0.5 um, two replicas,
fidelity quick, with the film-thinning effect fitted beside it) is shared by the module; its
posterior records (the base model's and the one with the effect) are what both commands read.
"""

import json
import shutil

import numpy as np
import pyarrow.parquet as pq
import pytest
from refusals import refused_on_cli, refuses

from itr_identify.cli import main
from itr_identify.inference.predictive import read_record

TINY = ["--box-um", "12", "--voxel-um", "0.5", "--replicas", "2", "--no-progress",
        "--fidelity", "quick"]
TABLE3 = {"Al2O3-55": [1.29, 1.30, 1.22, 1.32], "Al2O3-58": [1.57, 1.46, 1.47, 1.42],
          "Al2O3-62": [1.70, 1.75, 1.66]}


@pytest.fixture(scope="module")
def identified(tmp_path_factory):
    base = tmp_path_factory.mktemp("ident")
    rows = ["formulation,replicate,k_W_per_mK"] + [
        f"{f},{i + 1},{v}" for f in ("Al2O3-55", "Al2O3-62") for i, v in enumerate(TABLE3[f])]
    (base / "m.csv").write_text("\n".join(rows) + "\n")
    out = base / "ident"
    assert main(["identify", str(base / "m.csv"), "--out", str(out), "--parametrisation",
                 "gap", "--effect", "film", *TINY]) == 0
    return out


def test_the_identification_writes_its_posterior_record(identified):
    data = json.loads((identified / "identified.json").read_text())
    block = data["gap"]["predictive"]
    table = pq.read_table(identified / block["draws_file"])
    assert table.column_names == block["space"]["names"]
    assert table.num_rows == block["draws"] >= 10000
    assert "log10 R_Al2O3_silicone" in table.column_names
    assert block["measured"] == ["Al2O3-55", "Al2O3-62"]
    rec = read_record(identified / "identified.json", effect=False)
    assert rec.effect is None
    # the quoted resistance is the draws' median of log10 R (the posterior's point)
    col = rec.draws[:, rec.space["names"].index("log10 R_Al2O3_silicone")]
    quoted = data["gap"]["parameters"]["R_Al2O3_silicone"]["best"]
    assert abs(np.median(col) - np.log10(quoted)) < 0.05
    manifest = json.loads((identified / "manifest.json").read_text())
    assert block["draws_file"] in {f["path"] for f in manifest["files"]}


def _predict(identified, tmp_path, *names, extra=("--no-effect",)):
    out = tmp_path / "p"
    assert main(["predict", str(identified / "identified.json"), *names, "--out", str(out),
                 "--store", str(identified / "solves"), "--no-progress", *extra]) == 0
    data = json.loads((out / "predicted.json").read_text())
    assert data["effect"] == (None if "--no-effect" in extra else "film")
    return {p["formulation"]: p for p in data["predictions"]}


def test_predict_brackets_the_measured_and_orders_by_fraction(identified, tmp_path, capsys):
    preds = _predict(identified, tmp_path, "Al2O3-55", "Al2O3-58", "Al2O3-62")
    for name in ("Al2O3-55", "Al2O3-62"):              # the two it was fitted on
        lo, hi = preds[name]["interval"]
        assert lo < np.mean(TABLE3[name]) < hi
    # k rises with the filler fraction: the unmeasured 58 % lies between the two
    assert preds["Al2O3-55"]["median"] < preds["Al2O3-58"]["median"] \
        < preds["Al2O3-62"]["median"]
    assert all(p["system_identified"] and p["replicates"] == 4 for p in preds.values())
    out = capsys.readouterr().out
    assert "| Al2O3-58 |" in out and "90 % predictive interval" in out
    assert (tmp_path / "p" / "predicted.md").is_file()


def test_a_single_sample_is_predicted_more_widely_than_a_mean_of_four(identified, tmp_path):
    four = _predict(identified, tmp_path / "a", "Al2O3-60")["Al2O3-60"]
    one = _predict(identified, tmp_path / "b", "Al2O3-60",
                   extra=["--replicates", "1", "--no-effect"])["Al2O3-60"]
    w4 = four["interval"][1] - four["interval"][0]
    w1 = one["interval"][1] - one["interval"][0]
    assert w1 > w4
    assert one["model_median"] == pytest.approx(four["model_median"], rel=1e-12)


def test_the_named_effect_is_inside_the_prediction_by_default(identified, tmp_path,
                                                             capsys):
    data = json.loads((identified / "identified.json").read_text())
    block = data["discrepancy"]["predictive"]
    assert block["effect"] == "film" and "film_end_fraction" in block["space"]["names"]
    assert (identified / block["draws_file"]).is_file()
    rec = read_record(identified / "identified.json")
    assert rec.effect == "film"
    preds = _predict(identified, tmp_path, "Al2O3-55", "Al2O3-62", extra=())
    assert "with the effect 'film'" in capsys.readouterr().out
    for name, p in preds.items():                       # the two it was fitted on
        assert p["interval"][0] < np.mean(TABLE3[name]) < p["interval"][1]


def test_design_reaches_its_target_and_checks_the_choice(identified, tmp_path, capsys):
    out = tmp_path / "d"
    assert main(["design", str(identified / "identified.json"), "--fillers", "Al2O3",
                 "--total", "55-62", "--target", "1.5", "--check", "1", "--out", str(out),
                 "--store", str(identified / "solves"), "--no-progress", "--no-effect"]) == 0
    data = json.loads((out / "design.json").read_text())
    ch = data["choice"]
    assert ch["probability"] >= 0.95 and ch["interval_90"][0] >= 1.5 - 1e-12
    assert 55 <= ch["total_vol_pct"] <= 62
    # one step less filler no longer reaches it with 95 %
    check = data["checks"][0]
    assert check["formulation"] == ch["formulation"]
    assert check["full_solve_k"] > 0 and "full_solve_inside" in check
    assert (out / "design.png").stat().st_size > 10000
    assert "Cheapest formulation reaching 1.5" in capsys.readouterr().out


def data_effect(out):
    return json.loads((out / "design.json").read_text())["effect"]


def test_design_says_when_nothing_reaches_the_target(identified, tmp_path):
    out = tmp_path / "d"
    assert main(["design", str(identified / "identified.json"), "--fillers", "Al2O3",
                 "--total", "55-62", "--target", "9", "--out", str(out), "--check", "0",
                 "--store", str(identified / "solves"), "--no-progress"]) == 0
    assert data_effect(out) == "film"
    data = json.loads((out / "design.json").read_text())
    assert data["choice"] is None and data["checks"] == []
    assert data["max_probability"] == 0.0


@pytest.mark.parametrize("args, argument", [
    (["predict", "{i}", "AlN-60"], "FORMULATION"),          # R_AlN_silicone not identified
    (["predict", "{i}", "SiC-50"], "FORMULATION"),
    (["predict", "{i}", "Al2O3-60", "Al2O3-60"], "FORMULATION"),
    (["predict", "{i}", "Al2O3-60", "--replicates", "0"], "argument --replicates"),
    (["predict", "missing.json", "Al2O3-60"], "IDENTIFIED"),
    (["design", "{i}", "--fillers", "ZnO", "--total", "50-60", "--target", "2"],
     "--fillers"),
    (["design", "{i}", "--fillers", "Al2O3,AlN", "--total", "50-60", "--target", "2"],
     "--fillers"),                                          # AlN not identified
    (["design", "{i}", "--fillers", "Al2O3", "--total", "60-50", "--target", "2"], "--total"),
    (["design", "{i}", "--fillers", "Al2O3", "--total", "5x", "--target", "2"],
     "argument --total"),
    (["design", "{i}", "--fillers", "Al2O3", "--total", "50-60", "--target", "2",
      "--cost", "Al2O3=-1"], "--cost"),
])
def test_bad_input_is_refused_in_one_line_before_any_work(identified, tmp_path, capsys,
                                                          args, argument):
    args = [a.replace("{i}", str(identified / "identified.json")) for a in args]
    out = tmp_path / "o"
    assert main([*args, "--out", str(out)]) == 2
    refused_on_cli(capsys.readouterr().err, argument)
    assert not out.exists()


def test_a_record_that_is_missing_or_changed_is_refused(identified, tmp_path, capsys):
    copy = tmp_path / "ident"
    shutil.copytree(identified, copy, ignore=shutil.ignore_patterns("solves"))
    data = json.loads((copy / "identified.json").read_text())
    parquet = copy / data["gap"]["predictive"]["draws_file"]
    parquet.write_bytes(parquet.read_bytes()[:-8] + b"\0" * 8)
    with refuses(ValueError, "identified"):
        read_record(copy / "identified.json", effect=False)
    parquet.unlink()
    assert main(["predict", str(copy / "identified.json"), "Al2O3-60", "--no-effect",
                 "--out", str(tmp_path / "o")]) == 2
    assert "missing" in refused_on_cli(capsys.readouterr().err, "IDENTIFIED")
    del data["gap"]["predictive"]
    del data["discrepancy"]
    (copy / "identified.json").write_text(json.dumps(data))
    with refuses(ValueError, "identified") as info:
        read_record(copy / "identified.json")
    assert "identify again" in str(info.value)
    (copy / "identified.json").write_text("{not json")
    with refuses(ValueError, "identified"):
        read_record(copy / "identified.json")
