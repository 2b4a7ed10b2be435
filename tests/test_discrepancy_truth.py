"""The discrepancy workflow against truths it does not share (issues 25, 40): the study
``validation/discrepancy_truth_study.py`` at its CI size, run as a user runs it.

Truth: full solves at a 14 um box and 0.25 um voxels (the workflow's tables: 12 um, 0.5 um;
its faithful correction: 14 um from 0.28 and 0.5 um), packing seeds the workflow never uses,
effects built with itr_fv's public API, Table 3's replicate noise, each sample's density
from the truth RVE's sphere volumes. With the density column (and a thickness series for the
tester) the workflow must stay silent on noise and name the tester's contact resistance
(porosity: named or leading a tie with a fraction loss) with the truth inside the interval;
k-only, porosity is tied and the measurement named to decide it must be one that does; every
interval it reports holds its best value.
"""

import json
import subprocess
import sys
from pathlib import Path

import pytest

# the slow tier (.ci/run runs it after the fast tier): the truth study at its CI size
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("truth")
    run = subprocess.run([sys.executable, str(ROOT / "validation" / "discrepancy_truth_study.py"),
                          "--size", "ci", "--out", str(out)], capture_output=True, text=True,
                         timeout=1800)
    assert run.returncode == 0, run.stderr[-3000:]
    data = json.loads((out / "discrepancy_truth.json").read_text())
    return data["cases"], out


def _rows(study, columns):
    cases, _ = study
    return {c["case"]: c for c in cases if (c["columns"] == "k only") == (columns == "k")}


def test_noise_alone_names_nothing(study):
    for columns in ("aux", "k"):
        c = _rows(study, columns)["null"]
        assert c["verdict"] == "none", c["statement"]


@pytest.mark.parametrize("case, name, value", [
    ("porosity", "porosity (air voids)", 0.03),
    ("tester", "tester contact resistance left in the data", 4e-5)])
def test_library_effects_are_named_with_the_truth_inside(study, case, name, value):
    c = _rows(study, "aux")[case]
    # issue 49: the acceptance as first written (issue 25), restored before the calibrated
    # rule's results were seen: named (not a tie), the gap there before and closed after
    assert c["verdict"] == "named" and c["winner"] == name, c["statement"]
    lo, hi = c["interval_90"]
    assert lo <= value <= hi
    assert c["chi2_dof_before"] > 2.0 and c["chi2_dof_after"] < 2.0


@pytest.mark.xfail(strict=True, reason=(
    "issue 49: restored as first written (one measurement, density or the mass fraction, "
    "decides); the workflow names density + powder; a miss reported, not loosened"))
def test_porosity_absorbed_on_k_alone_is_tied_and_density_decides(study):
    """k alone: 3 % voids hide in the resistances; the tied set holds porosity and the
    measurement named to decide is one that tells voids from their absence (density or
    the mass fraction); with the density column (above) porosity is named."""
    c = _rows(study, "k")["porosity"]
    assert c["verdict"] != "named", c["statement"]
    assert "porosity (air voids)" in c["tied"] and c["truth_in_tied"]
    assert c["deciding"] in ("density", "mass_fraction")
    assert c["deciding_separates_truth"]


def test_every_reported_interval_contains_its_best_value(study):
    cases, out = study
    n = 0
    for c in cases:
        for iv in c["intervals"]:
            lo, hi = iv["interval_90"]
            assert lo <= iv["best"] <= hi, (c["case"], iv)
            n += 1
    assert n >= 2 * len(cases)             # the candidates of every case were checked
    md = (out / "discrepancy_truth.md").read_text()
    assert "| null | noise only | density |" in md
