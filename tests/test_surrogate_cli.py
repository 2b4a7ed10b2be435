"""``itr surrogate fit|show`` on a real campaign (issue 11): both models, bad invocations."""

from pathlib import Path

import numpy as np
import pytest

from itr_identify.cli import main
from itr_surrogate.campaign import Campaign
from itr_surrogate.prototype import PrototypeRegressor
from itr_surrogate.reduced_basis import ReducedBasis
from itr_surrogate.runner import run_campaign
from itr_surrogate.store import CampaignStore

TINY = Path(__file__).resolve().parents[1] / "examples" / "campaign-tiny.toml"


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tiny") / "run"
    summary = run_campaign(Campaign.from_toml(TINY), folder, workers=2, progress=False)
    assert summary.tasks_failed == 0
    return folder


def columns(folder):
    t = CampaignStore(folder).results()
    return {c: np.asarray(t.column(c).to_numpy()) for c in
            ("replica", "k_Al2O3", "R_Al2O3_silicone", "k_xx", "k_yy", "k_zz", "k_iso")}


def test_fit_prototype_writes_json_that_reproduces_the_campaign(campaign, tmp_path, capsys):
    out = tmp_path / "proto.json"
    assert main(["surrogate", "fit", str(campaign), "--out", str(out)]) == 0
    assert "k_eff =" in capsys.readouterr().out
    model = PrototypeRegressor.load(out)
    c = columns(campaign)
    X = np.column_stack([c[n] for n in model.feature_names_in_])
    assert set(model.feature_names_in_) == {"k_Al2O3", "R_Al2O3_silicone"}
    assert model.score(X, c["k_iso"]) > 0.99
    assert main(["surrogate", "show", str(out)]) == 0
    assert "training R^2" in capsys.readouterr().out


def test_fit_reduced_basis_matches_the_campaigns_full_solves(campaign, tmp_path, capsys):
    out = tmp_path / "rb.npz"
    assert main(["surrogate", "fit", str(campaign), "--model", "reduced-basis", "--out",
                 str(out), "--no-progress"]) == 0
    rb = ReducedBasis.load(out)
    c = columns(campaign)
    rows = c["replica"] == 0
    K = rb.predict({"k_Al2O3": c["k_Al2O3"][rows],
                    "R_Al2O3_silicone": c["R_Al2O3_silicone"][rows]})
    truth = np.column_stack([c["k_xx"][rows], c["k_yy"][rows], c["k_zz"][rows]])
    assert np.max(np.abs(np.diagonal(K, axis1=1, axis2=2) - truth) / truth) < 1e-3
    capsys.readouterr()
    assert main(["surrogate", "show", str(out)]) == 0
    shown = capsys.readouterr().out
    assert "R_Al2O3_silicone: [1e-08, 1e-06]" in shown and "full solves" in shown


@pytest.mark.parametrize("args,match", [
    (["fit", "{c}", "--out", "{t}/m.txt"], "--out: expected a .json file name"),
    (["fit", "{t}", "--out", "{t}/m.json"], "holds no campaign"),
    (["fit", "{c}", "--out", "{t}/m.json", "--formulation", "AlN-60"], "--formulation"),
    (["fit", "{c}", "--out", "{t}/m.json", "--formulation", "Al2O3-4O"],
     "--formulation: 'Al2O3-4O' is not in the campaign (it holds ['Al2O3-40']); did you mean "
     "'Al2O3-40'?"),
    (["fit", "{c}", "--model", "reduced-basis", "--out", "{t}/m.npz", "--replica", "5"],
     "--replica: 5 is not solved"),
    (["fit", "{c}", "--model", "kriging", "--out", "{t}/m.json"], "invalid choice"),
    (["show", "{t}/none.json"], "is not a file"),
    (["show", "{t}/bad.json"], "is not a surrogate file"),
    (["show", "{t}/bad.npz"], "not a reduced-basis file"),
])
def test_bad_invocations_are_one_line(campaign, tmp_path, capsys, args, match):
    (tmp_path / "bad.json").write_text("[1, 2]")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    argv = ["surrogate"] + [a.format(c=campaign, t=tmp_path) for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0] and "Traceback" not in err[0]
