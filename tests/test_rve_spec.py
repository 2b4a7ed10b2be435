"""One RVE specification: one box/voxel rule and message, one way to build an RVE (with the
retry policy), one material system read by every user of the paper's data."""

import numpy as np
import pytest
from refusals import refuses

import itr_fv.rve.generate as rve_module
from itr_fv.materials import paper_data
from itr_fv.rve import FillerSpec, build_rve, generate_rve
from itr_fv.rve.spec import RVESpec, voxels_per_edge
from itr_identify.cli.dispatch import main

pytestmark = pytest.mark.filterwarnings("ignore:.*box limits diameters:UserWarning")

BAD_BOX = ("box_um/voxel_um: a 10 um box holds 33.3333 voxels of 0.3 um; it must hold a whole "
           "number >= 8 of them")


@pytest.mark.parametrize("box, voxel, n", [(12.0, 0.25, 48), (1.6, 0.2, 8), (40.0, 0.1, 400),
                                           (3.0, 0.1, 30)])
def test_whole_number_of_voxels_is_accepted(box, voxel, n):
    # 3.0 / 0.1 = 29.999999999999996 in floating point: within the rule's 1e-6
    assert voxels_per_edge(box, voxel) == n
    assert RVESpec(box, voxel).shape == (n, n, n)


@pytest.mark.parametrize("box, voxel, words", [
    (10.0, 0.3, "box_um/voxel_um"), (1.4, 0.2, "box_um/voxel_um"), (-1.0, 0.2, "box_um"),
    (1.0, float("nan"), "voxel_um"), (True, 0.1, "box_um")])
def test_bad_box_or_voxel_is_refused_with_the_argument_named(box, voxel, words):
    with refuses(ValueError, words):
        RVESpec(box, voxel)


def test_other_fields_are_checked_by_name():
    for change, name in [({"max_diameter_box_ratio": 0.5}, "max_diameter_box_ratio"),
                         ({"min_gap_um": -0.1}, "min_gap_um"),
                         ({"tail_quantile": 0.1}, "tail_quantile"),
                         ({"seed": -1}, "seed"), ({"seed": 1.5}, "seed")]:
        with refuses(ValueError, name):
            RVESpec(12.0, 0.25, **change)
    spec = RVESpec(12.0, 0.25, seed=4)
    assert RVESpec.from_dict(spec.to_dict()) == spec
    with pytest.raises(ValueError, match=r"^unknown key 'colour' of an RVE specification "
                                         r"\(known: box_um, cut_voxel_um, "):
        RVESpec.from_dict({**spec.to_dict(), "colour": 1})
    with pytest.raises(ValueError, match=r"^unknown key 'voxel' of an RVE specification "
                                         r"\(did you mean 'voxel_um'\? known: "):
        RVESpec.from_dict({**spec.to_dict(), "voxel": 0.25})


def test_build_rve_packs_replica_r_with_seed_plus_r():
    spec = RVESpec(6.0, 0.25, seed=7)
    filler = [FillerSpec.from_table1("Al2O3", 0.3)]
    ms, seed = build_rve(spec, filler, 2)
    assert seed == 9
    ref = generate_rve(RVESpec(6.0, 0.25, max_diameter_box_ratio=spec.max_diameter_box_ratio),
                       filler, 9)
    np.testing.assert_array_equal(ms.particles.centers_m, ref.particles.centers_m)
    np.testing.assert_array_equal(ms.material_ids, ref.material_ids)


def test_build_rve_redraws_a_failed_packing_with_the_next_seed(monkeypatch):
    tried = []
    real = rve_module.generate_rve

    def flaky(*args, seed, **kwargs):
        tried.append(seed)
        if len(tried) < 3:
            raise RuntimeError("packing did not converge (test)")
        return real(*args, seed=seed, **kwargs)

    monkeypatch.setattr(rve_module, "generate_rve", flaky)
    _, seed = build_rve(RVESpec(6.0, 0.25, seed=1), [FillerSpec.from_table1("Al2O3", 0.3)], 1)
    assert tried == [2, 102, 202] and seed == 202

    def never(*args, seed, **kwargs):
        raise RuntimeError("packing did not converge (test)")

    monkeypatch.setattr(rve_module, "generate_rve", never)
    with pytest.raises(RuntimeError, match="packing"):
        build_rve(RVESpec(6.0, 0.25), [FillerSpec.from_table1("Al2O3", 0.3)], 0)


def test_the_same_bad_box_gives_the_same_line_from_every_command(tmp_path, capsys):
    camp = tmp_path / "bad.toml"
    camp.write_text('box_um = 10.0\nvoxel_um = 0.3\n[[formulation]]\nname = "Al2O3-60"\n'
                    '[design]\nkind = "table4"\n')
    meas = tmp_path / "m.csv"
    meas.write_text("formulation,replicate,k_W_per_mK\nAl2O3-60,1,1.5\n")
    box = ["--box-um", "10", "--voxel-um", "0.3"]
    commands = {"campaign": ["campaign", "run", str(camp), "--out", str(tmp_path / "c")],
                "reproduce": ["reproduce", *box, "--out", str(tmp_path / "r")],
                "identify": ["identify", str(meas), *box, "--out", str(tmp_path / "i")],
                "discrepancy": ["discrepancy", *box, "--out", str(tmp_path / "d")],
                "demo": ["demo", *box, "--out", str(tmp_path / "e")]}
    for name, argv in commands.items():
        assert main(argv) == 2, name
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, (name, err)
        # the campaign names its file first; the message is the same
        assert err[0].endswith(BAD_BOX), (name, err[0])
        assert not any((tmp_path / d).exists() for d in "cride"), name


def test_the_paper_material_system_is_read_once_by_every_user():
    from itr_identify.discrepancy.effects import MatrixConductivity
    from itr_identify.forward.model import ForwardSettings
    from validation import gallery

    system = paper_data.PAPER_SYSTEM
    # the paper's figures (Sec. 2.4 / 3.2 and Table 1), as transcribed in itr_fv/data
    assert system.conductivities() == {"silicone": 0.18, "Al2O3": 30.0, "AlN": 200.0}
    assert (paper_data.TABLE1["AlN"].mu, paper_data.TABLE1["AlN"].sigma) == (1.25, 0.59)
    assert paper_data.PAPER_CONDUCTIVITY == system.conductivities()
    assert (gallery.K_SILICONE, gallery.K_AL2O3, gallery.K_ALN) == (0.18, 30.0, 200.0)
    assert gallery.PSD["Al2O3"] == (1.02, 0.35)
    assert MatrixConductivity().nominal == system.matrix_conductivity
    assert ForwardSettings().system is system
    assert system.describe() == "silicone 0.18, Al2O3 30, AlN 200 W/(m K)"
    with refuses(ValueError, "filler"):
        system.filler("ZnO")


def test_film_and_psd_basis_are_stated_inputs_of_the_identification():
    from itr_identify.cli.core import reproduce_settings
    from itr_identify.cli.dispatch import build_parser
    from itr_identify.forward.model import PARAMETRISATIONS, ForwardModel, ForwardSettings

    args = build_parser().parse_args(["reproduce", "--film-nm", "2", "--psd-basis", "volume"])
    fw = reproduce_settings(args).forward
    # issue 47: the film is the one touching particles meet at; the packing does not change
    assert fw.rve.film_um == pytest.approx(0.002) and fw.psd_basis == "volume"
    assert fw.rve.contact_film_um == pytest.approx(0.002) and fw.rve.min_gap_um == 0.0
    assert fw.to_dict()["film_um"] == pytest.approx(0.002)
    assert fw.to_dict()["psd_basis"] == "volume"
    with refuses(ValueError, "psd_basis"):
        ForwardSettings(psd_basis="mass")
    # read as volume-weighted, Table 1's AlN is a powder of smaller particles (number median
    # smaller by exp(3 sigma^2) = 2.84): more of them in the same box, and the film holds
    # (0.2 um voxels: at 0.25 um the volume reading's smallest AlN are not resolved)
    small = ForwardSettings(RVESpec(12.0, 0.2, min_gap_um=0.002), replicas=2)
    models = {basis: ForwardModel("AlN-50", {"AlN": 0.5}, PARAMETRISATIONS["gap"],
                                  small.with_(psd_basis=basis)) for basis in ("number", "volume")}
    packed = {basis: m.pack(0) for basis, m in models.items()}
    n = {basis: ms.n_particles for basis, ms in packed.items()}
    assert n["volume"] > 5 * n["number"]
    from itr_fv.rve.packing import pairs_within_gap
    t = packed["number"].particles
    _, _, gaps = pairs_within_gap(t.centers_m * 1e6, t.radii_m * 1e6, 12.0, 0.01)
    assert gaps.size and gaps.min() >= 0.002 - 1e-9


def test_cut_voxel_is_checked_and_kept_only_where_set():
    spec = RVESpec(box_um=16.0, voxel_um=0.25)
    assert spec.min_diameter_voxels == 2.0 and "cut_voxel_um" not in spec.to_dict()
    fine_cut = spec.with_(cut_voxel_um=0.2)
    assert fine_cut.min_diameter_voxels == pytest.approx(1.6)   # 0.4 um in 0.25 um voxels
    assert RVESpec.from_dict(fine_cut.to_dict()) == fine_cut
    for bad in (0.0, -0.1, "0.2", True):
        with refuses(ValueError, "cut_voxel_um"):
            spec.with_(cut_voxel_um=bad)
