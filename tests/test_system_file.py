"""A lab's own composite (issue 48): the material-system file, read and checked once.

Refusals are one line naming the key, before anything is packed or solved; a file naming a
handbook phase without a value takes the handbook's; sizes are taken as labs state them;
formulations by volume or by mass; the paper's system written as a file is the default.
"""

from __future__ import annotations

import math
import textwrap
import time

import numpy as np
import pytest
from scipy import special

from itr_fv.materials import default_system, is_default_system
from itr_fv.materials.formulation_names import fractions_of
from itr_fv.materials.handbook import handbook
from itr_fv.materials.paper_data import read_table
from itr_fv.materials.system_file import read_system
from itr_identify.cli import main

GOOD = """\
name = "ZnO in epoxy"
[matrix]
name = "epoxy"
conductivity_W_per_mK = 0.19
conductivity_sd = 0.10
density_g_per_cm3 = 1.15
[[fillers]]
name = "ZnO"
density_g_per_cm3 = 5.61
size = { d10_um = 1.6, d50_um = 2.6, d90_um = 4.2, basis = "volume" }
"""


def write(tmp_path, text, name="system.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


# (what is wrong, the file's text, words the one-line refusal holds)
BAD = [
    ("a d50 in metres", GOOD.replace("d50_um = 2.6", "d50_um = 2.6e-6"),
     "fillers[0].size.d50_um: 2.6e-06 um is outside 0.01 - 1000 um, the sizes of filler "
     "powders; is it in m? (that would be 2.6 um)"),
    ("a d50 in nm", GOOD.replace("d50_um = 2.6", "d50_um = 2600"),
     "fillers[0].size.d50_um: 2600 um is outside 0.01 - 1000 um"),
    ("a negative conductivity", GOOD.replace("conductivity_W_per_mK = 0.19",
                                             "conductivity_W_per_mK = -0.19"),
     "matrix.conductivity_W_per_mK: a conductivity is > 0 W/(m K), got -0.19"),
    ("a missing conductivity of a phase the handbook lacks",
     GOOD.replace('name = "ZnO"', 'name = "ZnS"'),
     "fillers[0].conductivity_W_per_mK: missing, and 'ZnS' is not in the handbook of phases"),
    ("an sd larger than its value", GOOD.replace("conductivity_sd = 0.10",
                                                 "conductivity_sd = 1.5"),
     "matrix.conductivity_sd: a relative sd of 1.5 is as large as the value itself"),
    ("a basis not named", GOOD.replace(
        'size = { d10_um = 1.6, d50_um = 2.6, d90_um = 4.2, basis = "volume" }',
        "size = { mu_ln_um = 0.95, sigma_ln = 0.38 }"),
     "fillers[0].size.basis: name the basis of the distribution"),
    ("a density in kg/m^3", GOOD.replace("density_g_per_cm3 = 5.61",
                                         "density_g_per_cm3 = 5610"),
     "fillers[0].density_g_per_cm3: 5610 g/cm^3 is outside 0.5 - 25 g/cm^3"),
    ("an unknown key", GOOD.replace("conductivity_W_per_mK = 0.19",
                                    "conductivity_W_per_K = 0.19"),
     "matrix: unknown key 'conductivity_W_per_K' (did you mean 'conductivity_W_per_mK'?"),
    ("quantiles that do not increase", GOOD.replace("d10_um = 1.6", "d10_um = 3.0"),
     "fillers[0].size: expected d10_um < d50_um < d90_um, got 3, 2.6, 4.2 um"),
    ("a value outside its own range", GOOD.replace(
        "conductivity_W_per_mK = 0.19\nconductivity_sd = 0.10",
        "conductivity_W_per_mK = 0.5\nconductivity_range_W_per_mK = [0.17, 0.25]"),
     "matrix.conductivity_W_per_mK: 0.5 lies outside its range 0.17 - 0.25 W/(m K)"),
    ("a sigma of zero", GOOD.replace(
        'size = { d10_um = 1.6, d50_um = 2.6, d90_um = 4.2, basis = "volume" }',
        'size = { mu_ln_um = 0.95, sigma_ln = 0.0, basis = "number" }'),
     "fillers[0].size.sigma_ln: expected a value in (0, 1.5]"),
    ("a filler named twice", GOOD + '[[fillers]]\nname = "ZnO"\n'
     'size = { mu_ln_um = 0.5, sigma_ln = 0.3, basis = "number" }\n',
     "fillers: 'ZnO' is named twice"),
    ("no matrix", GOOD.split("[[fillers]]")[0].split("[matrix]")[0] + "[[fillers]]"
     + GOOD.split("[[fillers]]")[1], "matrix: missing"),
    ("not TOML", GOOD.replace("[matrix]", "[matrix"), "not TOML (Expected ']'"),
    ("a matrix given as a filler", GOOD.replace('name = "ZnO"', 'name = "paraffin"'),
     "fillers[0].name: 'paraffin' is a matrix in the handbook of phases, not a filler"),
    ("a histogram in fractions", GOOD.replace(
        'size = { d10_um = 1.6, d50_um = 2.6, d90_um = 4.2, basis = "volume" }',
        "size = { edges_um = [1, 2, 4, 8], volume_percent = [0.2, 0.6, 0.2] }"),
     "fillers[0].size.volume_percent: the bins sum to 1 %, expected 100 %"),
    ("a resistance in mm^2 K/W", GOOD + "[resistances]\nR_ZnO_epoxy = 0.02\n",
     "resistances.R_ZnO_epoxy: 0.02 m^2 K/W is outside 1e-12 - 0.0001 m^2 K/W; is it in "
     "mm^2 K/W? (that would be 2e-08 m^2 K/W)"),
    ("no lognormal meets the quantiles", GOOD.replace("d90_um = 4.2", "d90_um = 40"),
     "fillers[0].size: no lognormal meets d10/d50/d90 = 1.6/2.6/40 um"),
]


@pytest.mark.parametrize("what, text, expected", BAD, ids=[b[0] for b in BAD])
def test_a_bad_system_file_is_refused_in_one_line_naming_the_key(tmp_path, what, text,
                                                                 expected):
    path = write(tmp_path, text)
    with pytest.raises(ValueError) as info:
        read_system(path)
    msg = str(info.value)
    assert msg.startswith("system system.toml: ") and expected in msg, msg
    assert "\n" not in msg


@pytest.mark.parametrize("name, expected", [
    ("ZnO-120wt", "formulation 'ZnO-120wt': 120 wt% of filler in all; a mass share is below "
                  "100 wt%"),
    ("AlN-50", "formulation 'AlN-50': AlN is not a filler of the material system 'ZnO in "
               "epoxy' (fillers: ZnO)"),
    ("ZnO-75", "formulation 'ZnO-75': 75 vol% of filler in all"),
    ("ZnO-50wt-ZnO-10wt", "formulation 'ZnO-50wt-ZnO-10wt': each filler once"),
])
def test_a_formulation_the_system_cannot_hold_is_refused(tmp_path, name, expected):
    system = read_system(write(tmp_path, GOOD))
    with pytest.raises(ValueError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        fractions_of(name, system)


def test_the_command_line_refuses_a_bad_system_file_before_any_work(tmp_path, capsys):
    csv = tmp_path / "m.csv"
    csv.write_text("formulation,replicate,k_W_per_mK\nZnO-50,1,1.5\nZnO-50,2,1.6\n")
    out = tmp_path / "out"
    for text, words in ((BAD[0][1], "d50_um: 2.6e-06 um"), (BAD[6][1], "5610 g/cm^3")):
        path = write(tmp_path, text, "bad.toml")
        t0 = time.perf_counter()
        status = main(["identify", str(csv), "--system", str(path), "--out", str(out)])
        err = capsys.readouterr().err.strip().splitlines()
        assert status == 2 and len(err) == 1, err
        assert err[0].startswith("itr: error: --system: system bad.toml: ") and words in err[0]
        assert time.perf_counter() - t0 < 20 and not out.exists()
    # a measurement file naming a filler the system lacks: MEASUREMENTS, one line
    good = write(tmp_path, GOOD)
    csv.write_text("formulation,replicate,k_W_per_mK\nAlN-50,1,1.5\nAlN-50,2,1.6\n")
    assert main(["identify", str(csv), "--system", str(good), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(
        "itr: error: MEASUREMENTS: m.csv line 2: formulation 'AlN-50': "), err


def test_a_handbook_phase_without_a_value_takes_the_handbook_value_and_range(tmp_path):
    system = read_system(write(tmp_path, GOOD))
    zno = system.filler("ZnO")
    book = handbook()["ZnO"]
    assert zno.conductivity == book.conductivity == 50.0
    # the published range 20 - 120 W/(m K) as the 90 % interval of a lognormal
    assert zno.conductivity_sd == pytest.approx(math.log(120 / 20) / (2 * 1.6448536), rel=1e-6)
    # stated values win over the handbook's
    assert system.matrix_conductivity == 0.19 and system.matrix_conductivity_sd == 0.10
    assert system.matrix_density == 1.15


def test_the_handbook_holds_the_paper_values_and_ranges_that_contain_them():
    book = handbook()
    assert len(book) == 16
    for p in book.values():
        assert p.low < p.conductivity < p.high or p.low <= p.conductivity <= p.high
        assert 0.5 <= p.density <= 25 and p.conductivity_source and p.density_source
    # the paper's phases agree with the paper's own tables (read independently)
    k = {r["material"]: float(r["k_W_per_mK"]) for r in read_table("conductivities")}
    rho = {r["material"]: float(r["density_g_per_cm3"]) for r in read_table("densities")}
    for phase in ("silicone", "Al2O3", "AlN"):
        assert book[phase].conductivity == k[phase] and book[phase].density == rho[phase]


def test_quantiles_of_a_lognormal_give_it_back_and_a_histogram_is_fitted(tmp_path):
    mu, sigma = math.log(2.6), 0.377
    z = special.ndtri([0.1, 0.9])
    d10, d90 = np.exp(mu + sigma * z)
    text = GOOD.replace("d10_um = 1.6", f"d10_um = {d10:.10f}").replace(
        "d90_um = 4.2", f"d90_um = {d90:.10f}")
    psd = read_system(write(tmp_path, text)).filler("ZnO").psd
    assert psd.basis == "volume"
    assert psd.mu == pytest.approx(mu, abs=1e-9) and psd.sigma == pytest.approx(sigma, rel=1e-9)
    # the rounded d10/d50/d90 of the example: a lognormal within 1 % of each quantile
    system = read_system(write(tmp_path, GOOD))
    f = system.filler("ZnO")
    assert "largest quantile miss" in f.size_note
    assert np.allclose(f.psd.ppf([0.1, 0.5, 0.9]), [1.6, 2.6, 4.2], rtol=0.01)
    # a volume histogram of the same lognormal
    edges = np.geomspace(0.5, 15, 16)
    pct = 100 * np.diff(special.ndtr((np.log(edges) - mu) / sigma))
    pct *= 100 / pct.sum()
    hist = GOOD.replace(
        'size = { d10_um = 1.6, d50_um = 2.6, d90_um = 4.2, basis = "volume" }',
        f"size = {{ edges_um = {[float(x) for x in edges]}, "
        f"volume_percent = {[float(x) for x in pct]} }}")
    h = read_system(write(tmp_path, hist)).filler("ZnO").psd
    assert h.basis == "volume" and h.mu == pytest.approx(mu, abs=2e-3)
    assert h.sigma == pytest.approx(sigma, rel=1e-2)


def test_a_mass_share_is_converted_with_the_densities(tmp_path):
    system = read_system(write(tmp_path, GOOD))
    # 80 wt% ZnO (5.61 g/cm^3) in epoxy (1.15 g/cm^3), by hand: 0.8/5.61 of 0.8/5.61+0.2/1.15
    assert fractions_of("ZnO-80wt", system)["ZnO"] == pytest.approx(0.450539, rel=1e-5)
    assert fractions_of("ZnO-45", system) == {"ZnO": 0.45}
    # the paper's system reads its Table 2 names as before
    assert fractions_of("Al2O3-30-AlN-30") == {"Al2O3": 0.30, "AlN": 0.30}


def test_the_paper_system_file_is_the_default():
    system = read_system("examples/paper/system.toml")
    assert is_default_system(system)
    paper = default_system()
    assert system.conductivity_sds() == paper.conductivity_sds()
    assert system.conductivities() == paper.conductivities()
    assert system.densities() == paper.densities()
