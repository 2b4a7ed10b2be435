"""Implausible inputs are refused or warned about in one line before any solve (issue 26).

Each case runs the real command or reader; "before any solve" is shown by the run ending
in well under the time of one solve and by no output folder being left behind.
"""

import json
import math
import time
import warnings

import numpy as np
import pytest
from refusals import refused, refuses

from itr_fv import Microstructure
from itr_fv.analytic import hashin_shtrikman, hashin_shtrikman_multiphase
from itr_fv.checks import slip_hint, unit_slip
from itr_fv.materials import default_system
from itr_fv.materials.material_system import check_density
from itr_fv.rve.spec import RVESpec
from itr_identify.cli import main
from itr_identify.inference.formulations import fractions_of
from itr_identify.inference.measurements import read_measurements, read_tester_readings
from itr_identify.inference.plausibility import (
    ImplausibleMeasurementWarning,
    conductivity_range,
)

TABLE = "formulation,replicate,k_W_per_mK\n"
QUICK = ["--box-um", "12", "--voxel-um", "0.5", "--replicas", "2", "--no-progress",
         "--fidelity", "quick"]

PAPER = default_system()


def _one_line_refusal(capsys, argv, expected, out=None):
    t0 = time.perf_counter()
    status = main(argv)
    seconds = time.perf_counter() - t0
    err = capsys.readouterr().err
    assert status == 2, err
    lines = err.strip().splitlines()
    assert lines[-1].startswith("itr: error: ") and expected in lines[-1], err
    assert all(line.startswith("itr: ") for line in lines)
    assert seconds < 30          # nothing was packed or solved (one solve takes minutes)
    if out is not None:
        assert not out.exists()
    return lines


def test_multiphase_bounds_are_the_two_phase_bounds_and_order_the_phases():
    lo, hi = hashin_shtrikman_multiphase([0.4, 0.6], [0.18, 30.0])
    lo2, hi2 = hashin_shtrikman(0.6, 30.0 / 0.18)
    assert lo == pytest.approx(0.18 * lo2, rel=1e-12)
    assert hi == pytest.approx(0.18 * hi2, rel=1e-12)
    # three phases: between the two-phase bounds with the second filler replaced by
    # either of the two fillers
    lo3, hi3 = hashin_shtrikman_multiphase([0.4, 0.3, 0.3], [0.18, 30.0, 200.0])
    assert hashin_shtrikman_multiphase([0.4, 0.6], [0.18, 30.0])[1] < hi3
    assert hi3 < hashin_shtrikman_multiphase([0.4, 0.6], [0.18, 200.0])[1]
    assert lo3 < hi3
    with refuses(ValueError, "fractions"):
        hashin_shtrikman_multiphase([0.5, 0.6], [0.18, 30.0])


def test_the_reachable_range_is_the_matrix_and_the_perfect_interface_bound():
    k_m, k_up = conductivity_range("Al2O3-60", PAPER)
    # HS upper bound for 60 vol% of 30 W/(m K) in 0.18 W/(m K), by hand
    by_hand = 1.0 / (0.4 / (0.18 + 60.0) + 0.6 / (30.0 + 60.0)) - 60.0
    assert k_m == 0.18 and k_up == pytest.approx(by_hand, rel=1e-12)
    assert 15.0 < k_up < 15.3
    # every measured value of Table 3 lies inside its formulation's range
    m = read_measurements()
    for f in m.formulations:
        lo, hi = conductivity_range(f, PAPER)
        assert np.all((m.values[f] > lo) & (m.values[f] < hi))


def test_k_in_milliwatts_is_refused_before_any_solve(tmp_path, capsys):
    csv = tmp_path / "mw.csv"
    csv.write_text(TABLE + "Al2O3-55,1,1290\nAl2O3-55,2,1300\nAl2O3-62,1,1700\n"
                   "Al2O3-62,2,1750\n")
    out = tmp_path / "o"
    lines = _one_line_refusal(capsys, ["identify", str(csv), "--out", str(out), *QUICK],
                              "mw.csv line 2: k_W_per_mK 1290 W/(m K) is above", out)
    assert lines[-1].endswith("; is it in mW/(m K)? (that would be 1.29 W/(m K))")


def test_a_filler_like_conductivity_is_refused_with_the_range_and_no_unit_hint(tmp_path):
    # 25 W/(m K) is above what Al2O3-60 can reach, but 25 mW/(m K) is below its matrix: no
    # unit slip explains it, so the message states the range instead of asking about mW
    csv = _write(tmp_path / "k25.csv", TABLE + "Al2O3-60,1,25\nAl2O3-60,2,24\n")
    lo, hi = conductivity_range("Al2O3-60", PAPER)
    with pytest.raises(ValueError) as err:
        read_measurements(csv)
    msg = refused(err, "k25.csv line 2")
    assert f"can conduct {lo:g} - {hi:.3g} W/(m K)" in msg
    assert "mW" not in str(err.value)


def test_a_unit_hint_only_where_the_unit_makes_the_value_plausible():
    mw = {"mW/(m K)": 1e-3}
    assert unit_slip(180.0, (0.1, 0.5), mw) == ("mW/(m K)", 0.18)   # a matrix in mW/(m K)
    assert unit_slip(25.0, (0.18, 15.1), mw) is None               # a filler-like value
    assert unit_slip(0.3, (0.1, 0.5), mw) is None                  # plausible as it is
    # a resistance written in K mm^2/W where m^2 K/W is asked for: 1e6 times too big
    assert slip_hint(2.2e-2, (1e-9, 1e-6), {"K m^2/W": 1e-3, "K mm^2/W": 1e-6}, "m^2 K/W") \
        == "is it in K mm^2/W? (that would be 2.2e-08 m^2 K/W)"
    assert slip_hint(1290.0, (0.18, 13.6), mw, "W/(m K)") == \
        "is it in mW/(m K)? (that would be 1.29 W/(m K))"
    with pytest.raises(ValueError, match=r"2500 g/cm\^3 is outside 0.5 - 25 g/cm\^3, the range "
                                         r"of a solid phase; is it in kg/m\^3\? \(that would "
                                         r"be 2.5 g/cm\^3\)$"):
        check_density("density of X", 2500.0)
    with pytest.raises(ValueError, match=r"1e\+06 g/cm\^3 is outside 0.5 - 25 g/cm\^3, the "
                                         r"range of a solid phase$"):
        check_density("density of X", 1e6)


def test_k_above_the_bound_of_a_hybrid_is_refused(tmp_path):
    csv = tmp_path / "h.csv"
    bound = conductivity_range("Al2O3-30-AlN-30", PAPER)[1]
    csv.write_text(TABLE + f"Al2O3-30-AlN-30,1,1.7\nAl2O3-30-AlN-30,2,{1.01 * bound:.4f}\n")
    with pytest.raises(ValueError, match=r"line 3: k_W_per_mK .* W/\(m K\) is above .*; a "
                                         r"sample of Al2O3-30-AlN-30 can conduct 0.18 - "):
        read_measurements(csv)


def test_k_below_the_matrix_is_one_warning_line_before_anything_else(tmp_path, capsys):
    # the warning of line 2 is printed, then line 4's refusal stops the run before a solve
    csv = tmp_path / "low.csv"
    csv.write_text(TABLE + "Al2O3-55,1,0.15\nAl2O3-55,2,0.16\nAl2O3-62,1,xx\n")
    lines = _one_line_refusal(capsys, ["identify", str(csv), "--out", str(tmp_path / "o"),
                                       *QUICK], "line 4: k_W_per_mK is not a number")
    assert lines[0].startswith("itr: warning: low.csv line 2: k_W_per_mK 0.15")
    assert "below the matrix's own 0.18 W/(m K)" in lines[0]
    assert lines[0].endswith(f"reach it; a sample of Al2O3-55 can conduct 0.18 - "
                             f"{conductivity_range('Al2O3-55', PAPER)[1]:.3g} W/(m K)")
    with pytest.warns(ImplausibleMeasurementWarning, match="line 3"):
        read_measurements(_write(tmp_path / "l2.csv", TABLE + "AlN-55,1,1.2\nAlN-55,2,0.1\n"))


def _write(path, text):
    path.write_text(text)
    return path


@pytest.mark.parametrize("name", ["Al2O3-0.55", "AlN-0.6", "Al2O3-0.3-AlN-0.3"])
def test_fraction_like_names_are_refused(tmp_path, capsys, name):
    csv = _write(tmp_path / "f.csv", TABLE + f"{name},1,1.3\n{name},2,1.4\n")
    _one_line_refusal(capsys, ["identify", str(csv), "--out", str(tmp_path / "o"), *QUICK],
                      "looks like a volume fraction")
    with pytest.raises(ValueError, match="-55 for 55 vol%|-60 for 60 vol%|-30 for 30 vol%"):
        fractions_of(name)


def test_thickness_in_micrometres_is_refused_in_tester_readings(tmp_path, capsys):
    text = ("formulation,replicate,thickness_mm,impedance_K_mm2_per_W\n"
            "Al2O3-55,1,500,420\nAl2O3-55,1,1000,810\nAl2O3-55,2,500,400\n"
            "Al2O3-55,2,1000,800\n")
    csv = _write(tmp_path / "r.csv", text)
    _one_line_refusal(capsys, ["identify", str(csv), "--readings", "--out",
                               str(tmp_path / "o"), *QUICK],
                      "r.csv line 2: thickness_mm 500 mm is outside the 0.01 - 20 mm of a "
                      "thermal-interface sample; is it in um? (that would be 0.5 mm)")


def test_thickness_in_metres_is_refused_in_a_measurement_table(tmp_path):
    csv = _write(tmp_path / "t.csv", TABLE.strip() + ",thickness_mm\n"
                 "Al2O3-55,1,1.2,0.0005\nAl2O3-55,2,1.3,0.0005\n")
    with pytest.raises(ValueError, match=r"t.csv line 2: thickness_mm 0.0005 mm .*; is it in "
                                         r"m\? \(that would be 0.5 mm\)$"):
        read_measurements(csv)
    far = _write(tmp_path / "far.csv", TABLE.strip() + ",thickness_mm\n"
                 "Al2O3-55,1,1.2,5e6\nAl2O3-55,2,1.3,1\n")
    with pytest.raises(ValueError, match=r"thickness_mm 5e\+06 mm is outside the 0.01 - 20 mm "
                                         r"of a thermal-interface sample$"):
        read_measurements(far)      # not in um (5 m) nor in m: no unit hint


def test_impedance_in_square_metres_is_refused_through_the_conductivity(tmp_path):
    # K m^2/W written under impedance_K_mm2_per_W: the slope gives K ~ 1e6 W/(m K)
    csv = _write(tmp_path / "i.csv", "formulation,replicate,thickness_mm,"
                 "impedance_K_mm2_per_W\nAl2O3-55,1,0.5,4.2e-4\nAl2O3-55,1,1.0,8.1e-4\n"
                 "Al2O3-55,2,0.5,4.0e-4\nAl2O3-55,2,1.0,8.0e-4\n")
    with pytest.raises(ValueError, match=r"lines 2-3: K = 1/slope of impedance_K_mm2_per_W .*; "
                                         r"is impedance_K_mm2_per_W in K m\^2/W\? \(the "
                                         r"conductivity would be 1.28 W/\(m K\)\)$"):
        read_tester_readings(csv)


def test_identical_replicates_are_refused(tmp_path):
    csv = _write(tmp_path / "same.csv", TABLE + "Al2O3-55,1,1.3\nAl2O3-55,2,1.3\n")
    with pytest.raises(ValueError, match="replicates of 'Al2O3-55' are all 1.3"):
        read_measurements(csv)


def test_a_semicolon_file_is_named_as_such(tmp_path, capsys):
    csv = _write(tmp_path / "semi.csv", "formulation;replicate;k_W_per_mK\n"
                 "Al2O3-55;1;1,29\nAl2O3-55;2;1,30\n")
    _one_line_refusal(capsys, ["identify", str(csv), "--out", str(tmp_path / "o"), *QUICK],
                      "separated by semicolons")


def test_the_api_reads_what_the_command_line_reads(tmp_path):
    csv = _write(tmp_path / "m.csv", TABLE + "Al2O3-62,1,1.70\nAl2O3-62,2,1.75\n"
                 "Al2O3-30-AlN-30,1,1.6\nAl2O3-30-AlN-30,2,1.7\n")
    m = read_measurements(csv)
    assert m.formulations == ["Al2O3-62", "Al2O3-30-AlN-30"]


def test_campaign_lengths_in_metres_are_refused_before_dask(tmp_path, capsys):
    toml = tmp_path / "c.toml"
    toml.write_text('name = "m"\nbox_um = 6e-6\nvoxel_um = 2.5e-7\nreplicas = 2\n'
                    'contact = "gap"\nsolver = "fft"\n[[formulation]]\nname = "Al2O3-40"\n'
                    'fractions = { Al2O3 = 0.40 }\n[design]\nkind = "grid"\n'
                    'values = { R_Al2O3_silicone = [1e-8, 1e-7] }\n')
    lines = _one_line_refusal(capsys, ["campaign", "run", str(toml), "--out",
                                       str(tmp_path / "c")],
                              "box_um: 6e-06 um is below a nanometre")
    assert "it is 6 um" in lines[-1] and len(lines) == 1


@pytest.mark.parametrize("flags, expected", [
    (["--box-um", "16e-6"], "--box-um: 1.6e-05 um is below a nanometre"),
    (["--box-um", "16e-6", "--voxel-um", "1.6e-7"], "--box-um: 1.6e-05 um"),
    (["--voxel-um", "1.6e-7"], "--voxel-um: 1.6e-07 um is below a nanometre"),
    (["--box-um", "16000", "--voxel-um", "160"], "--box-um: 16000 um is above a centimetre"),
])
def test_demo_lengths_in_the_wrong_unit_name_the_right_flag(tmp_path, capsys, flags, expected):
    _one_line_refusal(capsys, ["demo", *flags, "--out", str(tmp_path / "d")], expected,
                      tmp_path / "d")


def test_the_physical_scale_rule_is_the_rve_specs():
    with pytest.raises(ValueError, match="voxel_um: 2.5e-07 um .* it is 0.25 um"):
        RVESpec(box_um=6.0, voxel_um=2.5e-7)
    assert RVESpec(box_um=6.0, voxel_um=0.25).n == 24


def _two_touching_spheres_as_phase_ids():
    n = 24
    x = np.indices((n, n, n)).transpose(1, 2, 3, 0) + 0.5
    mid = np.zeros((n, n, n), dtype=np.int32)
    for c in ((6.0, 12.0, 12.0), (17.5, 12.0, 12.0)):    # two separate spheres
        mid[np.sum((x - np.array(c)) ** 2, axis=-1) < 5.0 ** 2] = 1
    return mid


def test_a_label_image_with_phase_ids_as_particle_ids_is_warned_about():
    mid = _two_touching_spheres_as_phase_ids()
    with pytest.warns(UserWarning, match="particle 1 is 2 separate pieces"):
        Microstructure.from_labels(mid, mid, 1e-7, ["silicone", "Al2O3"])
    # labelled per particle: no warning
    from scipy import ndimage
    pid, count = ndimage.label(mid)
    assert count == 2
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Microstructure.from_labels(mid, pid.astype(np.int32), 1e-7, ["silicone", "Al2O3"])


def test_one_sphere_across_the_periodic_boundary_is_one_piece():
    n = 20
    x = np.indices((n, n, n)).transpose(1, 2, 3, 0) + 0.5
    d = np.abs(x - 0.0)
    d = np.minimum(d, n - d)                  # periodic distance to the corner
    mid = (np.sum(d ** 2, axis=-1) < 4.0 ** 2).astype(np.int32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Microstructure.from_labels(mid, mid, 1e-7, ["silicone", "Al2O3"])
    assert math.isclose(mid.mean(), 4 / 3 * math.pi * 4 ** 3 / n ** 3, rel_tol=0.1)


def test_an_accepted_table_is_written_unchanged_to_the_measurements(tmp_path):
    csv = _write(tmp_path / "ok.csv", TABLE + "AlN-55,1,1.44\nAlN-55,2,1.47\n")
    m = read_measurements(csv)
    assert json.dumps(m.values["AlN-55"].tolist()) == "[1.44, 1.47]"
