"""Any lab's composite end to end (issue 48): the RVE and its cost from the powders, a
system's own corrections table, and an identification of a system that is not the paper's.
"""

from __future__ import annotations

import json

import pytest

from itr_fv.materials import default_system
from itr_fv.materials.system_file import read_system
from itr_fv.rve.from_powders import box_volume_cut, cheap_rve, faithful_box, voxel_for
from itr_identify.cli import main
from itr_identify.forward.fidelity import CHEAP_RVE, faithful_for
from itr_identify.forward.shipped import ShippedCorrections

ZNO = "examples/zno_epoxy/system.toml"


def test_the_powder_rules_give_the_paper_its_measured_rves():
    paper = default_system()
    al2o3, aln = (paper.filler(f).psd for f in ("Al2O3", "AlN"))
    # the cheap RVE the shipped corrections were made for: 12 um at 0.25 um
    assert cheap_rve([al2o3, aln]) == CHEAP_RVE
    # validation/results/box_size.md: Al2O3-60 converged (within 0.5 % of every larger box)
    # at 24 um and not at 16 um; box_study.md: AlN-60 at 80 um and not at 64 um
    assert 16 < faithful_box(al2o3, 0.25) <= 24
    assert 64 < faithful_box(aln, 0.25) <= 80
    assert box_volume_cut(al2o3, 16) > 0.015 > box_volume_cut(al2o3, 24)
    assert box_volume_cut(aln, 64) > 0.015 > box_volume_cut(aln, 80)


def test_another_powder_gets_its_own_voxel_and_boxes():
    zno = read_system(ZNO)
    psd = zno.filler("ZnO").psd
    h = voxel_for([psd])
    # the Sauter diameter of the ZnO powder (number median 1.70 um, sigma 0.377) is 2.42 um:
    # 15 voxels of 0.16 um
    assert h == 0.16
    fa = faithful_for("standard", zno)
    assert fa.voxel_um == pytest.approx(0.128) and fa.coarse_voxel_um == 0.16
    box = dict(fa.boxes_um)["ZnO"]
    assert box_volume_cut(psd, box) <= 0.015 < box_volume_cut(psd, box - 0.64)
    # the paper's system keeps its levels' measured boxes
    assert dict(faithful_for("standard", default_system()).boxes_um) == {"Al2O3": 24.0,
                                                                         "AlN": 24.0}


def test_a_corrections_table_holds_for_the_system_it_was_built_for():
    zno = read_system(ZNO)
    shipped = ShippedCorrections.load()
    assert shipped.why_not_for(default_system(), CHEAP_RVE) == ""
    assert "built for the material system 'paper'" in shipped.why_not_for(zno, cheap_rve(
        [zno.filler("ZnO").psd]))
    own = ShippedCorrections({**shipped.data, "provenance": {
        **shipped.provenance, "material_system": zno.to_dict(),
        "cheap_rve": {**cheap_rve([zno.filler("ZnO").psd]).to_dict()}}})
    assert own.why_not_for(zno, cheap_rve([zno.filler("ZnO").psd])) == ""
    assert "built for the material system 'ZnO in epoxy'" in own.why_not_for(
        default_system(), CHEAP_RVE)


@pytest.mark.slow
def test_identify_runs_on_another_system_and_reports_it(tmp_path, capsys):
    """ZnO in epoxy, two formulations (one by mass), a coarse RVE: the plan names the
    system and its RVEs, the identified resistance is R_ZnO_epoxy, the report and
    identified.json record the system."""
    csv = tmp_path / "m.csv"
    csv.write_text("formulation,replicate,k_W_per_mK\nZnO-35,1,0.80\nZnO-35,2,0.83\n"
                   "ZnO-80wt,1,1.21\nZnO-80wt,2,1.26\n")
    out = tmp_path / "out"
    argv = ["identify", str(csv), "--system", ZNO, "--out", str(out), "--parametrisation",
            "gap", "--fidelity", "quick", "--box-um", "8", "--voxel-um", "0.25",
            "--replicas", "2", "--no-progress"]
    assert main([*argv, "--plan"]) == 0
    plan = capsys.readouterr().out
    assert "system ZnO in epoxy" in plan and "8 um at 0.25 um" in plan
    assert "on a CUDA device" in plan and not out.exists()
    assert main(argv) == 0
    data = json.loads((out / "identified.json").read_text())
    gap = data["gap"]
    assert list(gap["parameters"]) == ["R_ZnO_epoxy"]
    lo, hi = gap["parameters"]["R_ZnO_epoxy"]["interval_90"]
    assert 1e-9 <= lo < hi <= 1e-5
    system = gap["settings"]["system"]
    assert system["name"] == "ZnO in epoxy" and system["matrix"]["name"] == "epoxy"
    assert "k_ZnO" in gap["inputs"]["inputs"] and "k_epoxy" in gap["inputs"]["inputs"]
    report = (out / "report.md").read_text()
    assert "material system 'ZnO in epoxy'" in report
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["inputs"]["forward"]["system"]["fillers"][0]["name"] == "ZnO"


def test_a_campaign_and_the_discrepancy_settings_take_the_system():
    """A campaign file names formulations by composition in the system: its matrix, size
    distributions and base conductivities are the system's; the discrepancy workflow's
    settings, effects and workload are about the system's phases."""
    from itr_identify.discrepancy.effects import default_effects
    from itr_identify.discrepancy.settings import DiscrepancySettings
    from itr_identify.discrepancy.tables import n_solves
    from itr_identify.forward.fidelity import cheap_rve_for
    from itr_identify.forward.work_estimate import tables_workload
    from itr_surrogate.campaign import Campaign

    zno = read_system(ZNO)
    camp = Campaign.from_dict({"box_um": 8.0, "voxel_um": 0.25,
                               "formulation": [{"name": "ZnO-80wt"}],
                               "design": {"kind": "grid",
                                          "values": {"R_ZnO_epoxy": [1e-8, 3e-8]}}}, zno)
    (form,) = camp.formulations
    psd = zno.filler("ZnO").psd.to_number()
    assert camp.matrix == "epoxy" and form.psd == {"ZnO": (psd.mu, psd.sigma)}
    assert form.fractions["ZnO"] == pytest.approx(0.450539, rel=1e-5)
    assert camp.base == {"k_epoxy": 0.19, "k_ZnO": 50.0}
    # read back as a worker reads the stored campaign: the same campaign
    assert Campaign.from_dict(camp.to_dict()) == camp
    base = DiscrepancySettings().forward.with_(system=zno, rve=cheap_rve_for(zno))
    settings = DiscrepancySettings(forward=base, faithful=faithful_for("standard", zno))
    effects = default_effects(zno)
    assert effects[0].nominal == 0.19 and max(effects[0].values) == pytest.approx(0.38)
    singles = {"ZnO-35": {"ZnO": 0.35}, "ZnO-45": {"ZnO": 0.45}, "ZnO-55": {"ZnO": 0.55}}
    work = tables_workload(settings, singles, solves=n_solves(3, settings, effects))
    assert {round(g.voxel_um, 6) for g in work.grids} == {0.16, 0.128}
