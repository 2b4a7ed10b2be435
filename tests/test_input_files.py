"""Input files as labs save them (issue 37, item 4): a spreadsheet's "CSV UTF-8" (a byte-order
mark, CRLF line ends) is read as the plain file; formulation names in any letter case; a near
miss (O for 0, l or I for 1) refused with a "did you mean", in one line, on the command line
with exit status 2."""

import os
import re
import subprocess
import sys

import numpy as np
import pytest
from refusals import refused, refused_on_cli

from itr_fv.checks import unknown_key
from itr_fv.materials import paper_data
from itr_identify.cli import main
from itr_identify.inference.formulations import formulation_name
from itr_identify.inference.measurements import read_measurements, read_tester_readings

TABLE = "formulation,replicate,k_W_per_mK\n"
TINY = ["--box-um", "12", "--voxel-um", "0.5", "--replicas", "2", "--no-progress",
        "--fidelity", "quick"]


def spreadsheet_bytes(text: str) -> bytes:
    """``text`` as a spreadsheet's "CSV UTF-8" saves it: a byte-order mark, CRLF line ends."""
    return b"\xef\xbb\xbf" + text.replace("\n", "\r\n").encode("utf-8")


def test_a_byte_order_mark_reads_as_the_plain_file(tmp_path):
    shipped = paper_data.table_text("measured_tc")
    (tmp_path / "plain.csv").write_text(shipped, encoding="utf-8")
    (tmp_path / "excel.csv").write_bytes(spreadsheet_bytes(shipped))
    plain = read_measurements(tmp_path / "plain.csv")
    excel = read_measurements(tmp_path / "excel.csv")
    assert excel.formulations == plain.formulations == read_measurements().formulations
    for f in plain.formulations:
        np.testing.assert_array_equal(excel.values[f], plain.values[f])


def test_a_byte_order_mark_in_tester_readings(tmp_path):
    lines = ["formulation,replicate,thickness_mm,impedance_K_mm2_per_W"]
    for rep, k in ((1, 1.5), (2, 1.6)):
        lines += [f"Al2O3-60,{rep},{t},{t / k * 1e3 + 20.0}" for t in (0.5, 1.0, 1.5)]
    (tmp_path / "r.csv").write_bytes(spreadsheet_bytes("\n".join(lines) + "\n"))
    m = read_tester_readings(tmp_path / "r.csv")
    np.testing.assert_allclose(m.values["Al2O3-60"], [1.5, 1.6], rtol=1e-12)


def test_utf16_says_how_to_save_it(tmp_path):
    (tmp_path / "u.csv").write_bytes((TABLE + "Al2O3-60,1,1.5\n").encode("utf-16"))
    with pytest.raises(ValueError, match="not a UTF-8 text file .it is UTF-16.*save it as "
                                         "'CSV UTF-8'"):
        read_measurements(tmp_path / "u.csv")


def test_letter_case_is_free_and_the_canonical_name_is_kept(tmp_path):
    (tmp_path / "m.csv").write_text(TABLE + "al2o3-55,1,1.29\nAL2O3-55,2,1.30\n"
                                    "al2o3-30-aln-30,1,2.0\nAl2O3-30-AlN-30,2,2.1\n")
    m = read_measurements(tmp_path / "m.csv")
    assert m.formulations == ["Al2O3-55", "Al2O3-30-AlN-30"]
    np.testing.assert_array_equal(m.values["Al2O3-55"], [1.29, 1.30])
    # one formulation however it is written: a replicate under two spellings is a duplicate
    (tmp_path / "d.csv").write_text(TABLE + "Al2O3-55,1,1.29\nal2o3-55,1,1.30\n")
    with pytest.raises(ValueError, match="line 3: replicate '1' of 'Al2O3-55' given twice"):
        read_measurements(tmp_path / "d.csv")


@pytest.mark.parametrize("name, suggestion, why", [
    ("Al203-60", "Al2O3-60", "the digit 0 for the letter O at character 4"),
    ("AlN-6O", "AlN-60", "the letter O for the digit 0 at character 6"),
    ("A12O3-60", "Al2O3-60", "the digit 1 for the letter l at character 2"),
    ("AIN-55", "AlN-55", "the letter I for the letter l at character 2"),
    ("al203-62", "Al2O3-62", "the digit 0 for the letter O"),
    ("Al2O3 60", "Al2O3-60", None),
    ("Al2O-58", "Al2O3-58", None),
])
def test_a_near_miss_is_refused_with_did_you_mean(tmp_path, name, suggestion, why):
    (tmp_path / "m.csv").write_text(TABLE + f"Al2O3-55,1,1.29\nAl2O3-55,2,1.3\n{name},1,1.5\n"
                                    f"{name},2,1.6\n")
    with pytest.raises(ValueError) as info:
        read_measurements(tmp_path / "m.csv")
    msg = str(info.value)
    assert msg.startswith(f"m.csv line 4: formulation {name!r} is unknown; did you mean "
                          f"{suggestion!r}?")
    assert "\n" not in msg and (why is None or why in msg)


def test_no_suggestion_where_nothing_is_near():
    for name, why in (("SiC-50", "SiC is not a filler of the material system 'paper' "
                                  "(fillers: Al2O3, AlN)"),
                      ("Al2O3-80", "80 vol% of filler in all; expected"),
                      ("x", "expected a named formulation or <filler>-<vol%>")):
        with pytest.raises(ValueError, match=re.escape(f"formulation {name!r}: {why}")) as info:
            formulation_name(name)
        assert "did you mean" not in str(info.value)
    with pytest.raises(ValueError, match="looks like a volume fraction"):
        formulation_name("al2o3-0.55")


def test_a_list_of_names_matches_the_same_way():
    known = {"Al2O3-40", "mix-A"}
    assert formulation_name("AL2O3-40", known) == "Al2O3-40"
    assert formulation_name("MIX-a", known) == "mix-A"
    with pytest.raises(ValueError, match="did you mean 'Al2O3-40'") as info:
        formulation_name("Al2O3-4O", known)
    assert info.value.suggestion == "Al2O3-40"
    with pytest.raises(ValueError, match="unknown formulation 'SiC' .known: Al2O3-40, mix-A."):
        formulation_name("SiC", known)


def test_identify_reads_a_byte_order_mark_file_past_its_header(tmp_path, capsys):
    """The header of a "CSV UTF-8" file is read (the error is the value on line 3, not a
    missing 'formulation' column); no solve is made."""
    (tmp_path / "m.csv").write_bytes(spreadsheet_bytes(TABLE + "Al2O3-55,1,1.29\n"
                                                       "Al2O3-55,2,-1\n"))
    assert main(["identify", str(tmp_path / "m.csv"), "--out", str(tmp_path / "o"), *TINY]) == 2
    err = capsys.readouterr().err
    refused(refused_on_cli(err, "MEASUREMENTS").split(": ", 1)[1], "m.csv line 3")


def test_identify_refuses_a_near_miss_in_one_line_with_exit_2(tmp_path):
    """The console command as a user runs it: status 2, one line, no traceback, the
    suggestion, no output folder."""
    (tmp_path / "m.csv").write_bytes(spreadsheet_bytes(
        TABLE + "Al2O3-55,1,1.29\nAl2O3-55,2,1.30\nAl203-60,1,1.56\nAl203-60,2,1.50\n"))
    env = dict(os.environ)
    env.pop("ITR_DEBUG", None)
    r = subprocess.run([sys.executable, "-m", "itr_identify.cli", "identify", "m.csv",
                        "--out", "o", *TINY], cwd=tmp_path, env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr == ("itr: error: MEASUREMENTS: m.csv line 4: formulation 'Al203-60' is "
                        "unknown; did you mean 'Al2O3-60'? (the digit 0 for the letter O at "
                        "character 4)\n")
    assert not (tmp_path / "o").exists()


def test_an_unknown_key_of_a_settings_file_gets_a_did_you_mean_and_the_known_keys():
    known = ("voxel_um", "box_um", "seed")
    assert unknown_key({"box_um": 6.0, "voxl_um": 0.25}, known) == \
        "unknown key 'voxl_um' (did you mean 'voxel_um'? known: box_um, seed, voxel_um)"
    assert unknown_key({"zzz": 1, "bogus": 1}, known, detail=" for kind 'grid'") == \
        "unknown key 'bogus' for kind 'grid' (known: box_um, seed, voxel_um)"
    assert unknown_key({"seed": 1}, known) is None
