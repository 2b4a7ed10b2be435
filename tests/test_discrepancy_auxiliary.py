"""A lab's second measurements in the discrepancy workflow (issue 40): the density and filler
mass fraction a model predicts, the likelihood that joins them with k, and the refusal of
values no sample can have (one line, before any solve, no output folder left)."""

import math

import numpy as np
import pytest
from scipy import stats

from itr_fv.materials.paper_data import PAPER_SYSTEM
from itr_identify.cli import main
from itr_identify.discrepancy import effects as fx
from itr_identify.discrepancy.fit import _gaussian_low_rank
from itr_identify.discrepancy.observables import (
    auxiliary_groups,
    fraction_derivatives,
    predict,
)
from itr_identify.inference.formulations import fractions_of
from itr_identify.inference.measurements import Measurements, read_measurements


def test_density_and_mass_fraction_of_a_mixture_by_hand():
    # 60 vol% Al2O3 (3.95) in silicone (0.97): 2.37 + 0.388 g/cm^3
    rho = predict("density_g_per_cm3", PAPER_SYSTEM, "Al2O3", 0.6, 0.0)
    assert rho == pytest.approx(0.6 * 3.95 + 0.4 * 0.97, rel=1e-12)
    w = predict("filler_mass_fraction", PAPER_SYSTEM, "Al2O3", 0.6, 0.0)
    assert w == pytest.approx(2.37 / 2.758, rel=1e-12)
    # 3 % voids replace matrix: the density falls by 0.03 * 0.97, the mass fraction rises
    assert predict("density_g_per_cm3", PAPER_SYSTEM, "Al2O3", 0.6, 0.03) == \
        pytest.approx(rho - 0.03 * 0.97, rel=1e-12)
    assert predict("filler_mass_fraction", PAPER_SYSTEM, "Al2O3", 0.6, 0.03) > w


@pytest.mark.parametrize("obs", ["density_g_per_cm3", "filler_mass_fraction"])
def test_fraction_derivatives_match_finite_differences(obs):
    h = 1e-6
    num = (predict(obs, PAPER_SYSTEM, "AlN", 0.55 + h, 0.02)
           - predict(obs, PAPER_SYSTEM, "AlN", 0.55 - h, 0.02)) / (2 * h)
    assert fraction_derivatives(obs, PAPER_SYSTEM, "AlN", 0.55, 0.02) == \
        pytest.approx(num, rel=1e-6)


def test_each_effect_says_what_it_does_to_the_composition():
    # porosity keeps the filler and adds voids; a fraction factor scales the filler;
    # conductivities and resistances change neither (so no density can see them)
    assert fx.Porosity().composition(0.6, 0.03) == (pytest.approx(0.6), pytest.approx(0.03))
    phi, p = fx.FillerFraction().composition(0.6, 0.9)
    assert phi == pytest.approx(0.54) and p == 0
    for e in (fx.MatrixConductivity(), fx.FillerConductivity(), fx.ContactSpots(),
              fx.TesterContact()):
        assert e.composition(0.6, e.values[0]) == (pytest.approx(0.6), pytest.approx(0.0))
    assert fx.BatchFraction().fraction_sd(0.01) == pytest.approx(0.01)
    assert fx.ContactSpots().size_equivalent(1e-5, 2.0) == pytest.approx(5e-6)
    assert fx.FillerConductivity().size_equivalent(0.4, 2.0) == 0.4


def test_low_rank_gaussian_equals_the_dense_multivariate_normal():
    rng = np.random.default_rng(3)
    r = rng.normal(size=5)
    d = rng.uniform(0.5, 2.0, size=5)
    c1, c2 = rng.normal(size=5), np.r_[rng.normal(size=3), 0.0, 0.0]
    ll, quad = _gaussian_low_rank(list(r), list(d), [list(c1), list(c2)])
    cov = np.diag(d) + np.outer(c1, c1) + np.outer(c2, c2)
    assert float(ll) == pytest.approx(stats.multivariate_normal(np.zeros(5), cov).logpdf(r),
                                      rel=1e-10)
    assert float(quad) == pytest.approx(r @ np.linalg.solve(cov, r), rel=1e-10)


def test_auxiliary_noise_is_pooled_over_a_fillers_formulations():
    nan = math.nan
    m = Measurements({"Al2O3-55": np.array([1.2, 1.3, 1.25]),
                      "Al2O3-60": np.array([1.5, 1.6])},
                     "hand", None,
                     {"density_g_per_cm3": {"Al2O3-55": np.array([2.6, 2.62, nan]),
                                            "Al2O3-60": np.array([2.75, 2.77])}})
    groups = auxiliary_groups(m, {f: fractions_of(f) for f in m.values})
    dev = [2.6 / 2.61 - 1, 2.62 / 2.61 - 1, 2.75 / 2.76 - 1, 2.77 / 2.76 - 1]
    sd = math.sqrt(sum(x * x for x in dev) / 2)          # two degrees of freedom
    g55, g60 = groups
    assert (g55.n, g60.n) == (2, 2)
    assert g55.mean == pytest.approx(2.61)
    assert g55.standard_error == pytest.approx(sd * 2.61 / math.sqrt(2), rel=1e-12)
    assert g60.standard_error == pytest.approx(sd * 2.76 / math.sqrt(2), rel=1e-12)


def _table(tmp_path, column, values):
    rows = [f"{f},{i + 1},{k},{v}" for (f, k), v, i in zip(
        [("Al2O3-55", 1.28), ("Al2O3-55", 1.30), ("Al2O3-60", 1.52), ("Al2O3-60", 1.55),
         ("Al2O3-65", 1.95), ("Al2O3-65", 1.99)], values, range(6))]
    p = tmp_path / "m.csv"
    p.write_text(f"formulation,replicate,k_W_per_mK,{column}\n" + "\n".join(rows) + "\n")
    return p


def test_a_table_with_auxiliary_columns_reads_blank_cells_as_not_measured(tmp_path):
    p = _table(tmp_path, "density_g_per_cm3", ["2.61", "", "2.75", "2.76", "2.9", "2.91"])
    m = read_measurements(p)
    assert m.auxiliary_columns == ["density_g_per_cm3"]
    v = m.auxiliary_of("density_g_per_cm3", "Al2O3-55")
    assert v[0] == 2.61 and math.isnan(v[1])


@pytest.mark.parametrize("column, values, expected", [
    ("density_g_per_cm3", ["2.61", "2610", "2.75", "2.76", "2.9", "2.91"],
     ("density_g_per_cm3 2610 is outside 0.97 - 3.95 g/cm^3, what a sample of Al2O3-55 can "
      "have (its matrix's to its densest filler's density); is it in kg/m^3? (that would be "
      "2.61 g/cm^3)\n")),
    ("density_g_per_cm3", ["0.5", "2.6", "2.75", "2.76", "2.9", "2.91"],
     "density_g_per_cm3 0.5 is outside"),
    ("filler_mass_fraction", ["86", "0.86", "0.88", "0.88", "0.9", "0.9"],
     "filler_mass_fraction 86 is outside 0 - 1"),
    ("filler_mass_fraction", ["-0.1", "0.86", "0.88", "0.88", "0.9", "0.9"],
     "filler_mass_fraction -0.1 is outside 0 - 1"),
    ("d50_um", ["30", "", "", "", "", ""], "d50_um 30 um is"),
    ("density_g_per_cm3", ["heavy", "2.6", "2.75", "2.76", "2.9", "2.91"],
     "density_g_per_cm3 is not a number"),
])
def test_bad_auxiliary_values_are_refused_in_one_line_with_no_folder_left(
        tmp_path, capsys, column, values, expected):
    p = _table(tmp_path, column, values)
    out = tmp_path / "out"
    assert main(["discrepancy", str(p), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("itr: error: MEASUREMENTS: m.csv line ") and err.count("\n") == 1
    assert expected in err
    assert not out.exists()


@pytest.mark.parametrize("flag, expected", [
    ("Al2O3=3950", ("--density: density of Al2O3: 3950 g/cm^3 is outside 0.5 - 25 g/cm^3, "
                    "the range of a solid phase; is it in kg/m^3? (that would be 3.95 "
                    "g/cm^3)\n")),
    ("Cu=8.9", "--density: densities: 'Cu' is not a phase"),
    ("Al2O3", "--density: expected PHASE=G_PER_CM3"),
])
def test_bad_phase_densities_are_refused_in_one_line(tmp_path, capsys, flag, expected):
    out = tmp_path / "out"
    assert main(["discrepancy", "--density", flag, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and expected in err
    assert not out.exists()


def test_overridden_densities_move_the_readable_range(tmp_path):
    # an AlN-free system check: with Al2O3 at 4.1 g/cm^3 a 4.0 is readable
    p = _table(tmp_path, "density_g_per_cm3", ["2.61", "2.6", "2.75", "2.76", "2.9", "4.0"])
    with pytest.raises(ValueError, match="outside 0.97 - 3.95"):
        read_measurements(p)
    m = read_measurements(p, system=PAPER_SYSTEM.with_densities({"Al2O3": 4.1}))
    assert m.auxiliary_of("density_g_per_cm3", "Al2O3-65")[1] == 4.0


def test_a_density_column_without_replicates_is_refused_before_any_solve(tmp_path, capsys):
    # one density per formulation: no replicate scatter to take its noise from
    p = _table(tmp_path, "density_g_per_cm3", ["2.61", "", "2.75", "", "2.9", ""])
    out = tmp_path / "out"
    assert main(["discrepancy", str(p), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "MEASUREMENTS: density_g_per_cm3 of Al2O3 needs two samples" in err
    assert not out.exists()
