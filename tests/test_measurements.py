"""Measurement tables and the tester's data reduction (issue 12, first part)."""

import math

import numpy as np
import pytest
from refusals import refuses

from itr_identify.inference.measurements import (
    conductivity_from_impedance,
    read_measurements,
    read_tester_readings,
)


def test_table3_is_shipped_and_its_statistics_are_the_papers():
    m = read_measurements()
    assert len(m.formulations) == 12
    assert all(m.values[f].size == 4 for f in m.formulations)
    # Table 3, Al2O3-60: 1.56, 1.56, 1.50, 1.48 (the paper quotes 1.53)
    assert m.mean("Al2O3-60") == pytest.approx(1.525)
    assert m.variance("Al2O3-60") == pytest.approx(np.var([1.56, 1.56, 1.50, 1.48], ddof=1))
    assert m.standard_error("Al2O3-60") == pytest.approx(
        np.std([1.56, 1.56, 1.50, 1.48], ddof=1) / 2)
    assert "Al2O3-60" not in m.without("Al2O3-60").formulations


def test_slope_of_impedance_gives_k_without_the_bar_contact():
    t = np.array([0.5e-3, 1.0e-3, 1.5e-3])
    imp = t / 1.53 + 2.0e-5  # Eq. 8 with a contact resistance of 2e-5 m^2 K/W
    k, sk = conductivity_from_impedance(t, imp)
    assert k == pytest.approx(1.53, rel=1e-12) and sk == pytest.approx(0.0, abs=1e-9)
    k2, s2 = conductivity_from_impedance(t[:2], imp[:2])
    assert k2 == pytest.approx(1.53, rel=1e-12) and math.isnan(s2)


def test_the_standard_error_of_k_follows_the_slope():
    rng = np.random.default_rng(0)
    t = np.linspace(0.5e-3, 1.5e-3, 3)
    ks = [conductivity_from_impedance(t, t / 1.5 + 1e-5 + rng.normal(0, 5e-6, 3))
          for _ in range(4000)]
    values = np.array([k for k, _ in ks])
    errors = np.array([s for _, s in ks])
    # sigma_a = 5e-6 / sqrt(sum (t - mean)^2) = 5e-6 / 7.07e-4; sigma_K = sigma_a K^2
    expected = 5e-6 / math.sqrt(np.sum((t - t.mean()) ** 2)) * 1.5 ** 2
    assert values.std() == pytest.approx(expected, rel=0.1)
    assert np.sqrt(np.mean(errors ** 2)) == pytest.approx(expected, rel=0.1)


def test_tester_readings_reduce_to_one_k_per_sample(tmp_path):
    lines = ["formulation,replicate,thickness_mm,impedance_K_mm2_per_W"]
    for rep, k in ((1, 1.5), (2, 1.6)):
        for t in (0.5, 1.0, 1.5):
            lines.append(f"Al2O3-60,{rep},{t},{t / k * 1e3 + 20.0}")  # K mm^2/W
    (tmp_path / "r.csv").write_text("\n".join(lines) + "\n")
    m = read_tester_readings(tmp_path / "r.csv")
    np.testing.assert_allclose(m.values["Al2O3-60"], [1.5, 1.6], rtol=1e-12)


TABLE = "formulation,replicate,k_W_per_mK\n"
READ = "formulation,replicate,thickness_mm,impedance_K_mm2_per_W\n"
BAD = [
    ("table", "formulation,k_W_per_mK\nAl2O3-60,1.5\n", "missing column 'replicate'"),
    ("table", TABLE + "Al2O3-60,1,-1.5\nAl2O3-60,2,1.5\n", "line 2: k_W_per_mK must be"),
    ("table", TABLE + "Al2O3-60,1,nan\nAl2O3-60,2,1.5\n", "line 2: k_W_per_mK must be"),
    ("table", TABLE + "Al2O3-60,1,abc\n", "is not a number: 'abc'"),
    ("table", TABLE + "SiC-61,1,1.5\nSiC-61,2,1.6\n",
     "line 2: formulation 'SiC-61': SiC is not a filler of the material system"),
    ("table", TABLE + "Al2O3-60,1,1.5\n", "has 1 replicate"),
    ("table", TABLE + "Al2O3-60,1,1.5\nAl2O3-60,1,1.6\n", "given twice"),
    ("table", TABLE, "no data rows"),
    ("table", b"\xff\xfe\x00", "not a UTF-8 text file"),
    ("readings", READ + "Al2O3-60,1,1.0,700\nAl2O3-60,1,0.5,350\n", "do not increase"),
    ("readings", READ + "Al2O3-60,1,1.0,700\n", "one thickness"),
    ("readings", READ + "Al2O3-60,1,0.5,700\nAl2O3-60,1,1.0,350\n", "positive slope"),
    ("readings", READ + "Al2O3-60,1,0,700\n", "thickness_mm must be"),
]


@pytest.mark.parametrize("kind,text,match", BAD)
def test_bad_files_are_one_line_errors(tmp_path, kind, text, match):
    path = tmp_path / "m.csv"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    read = read_measurements if kind == "table" else read_tester_readings
    with pytest.raises(ValueError, match=match) as info:
        read(path)
    assert "\n" not in str(info.value) and "m.csv" in str(info.value)


def test_a_missing_file_names_the_path(tmp_path):
    with refuses(ValueError, "path"):
        read_measurements(tmp_path / "none.csv")
