"""Candidate effects of the discrepancy workflow (issue 13): each changes the RVE model as
it says, and the measurement table's optional thickness column."""

import math

import numpy as np
import pytest
from refusals import refuses

from itr_fv.materials import default_system
from itr_fv.rve.spec import RVESpec
from itr_identify.discrepancy import effects as fx
from itr_identify.discrepancy.effects import (
    AIR_CONDUCTIVITY,
    Effect,
    FillerConductivity,
    FillerFraction,
    MatrixConductivity,
    Porosity,
    default_effects,
)
from itr_identify.discrepancy.fit import Group, groups_of
from itr_identify.forward.model import PARAMETRISATIONS, ForwardModel, ForwardSettings
from itr_identify.inference.formulations import fractions_of
from itr_identify.inference.measurements import Measurements, read_measurements

SMALL = ForwardSettings(RVESpec(box_um=12.0, voxel_um=0.5, seed=3), replicas=2)


@pytest.fixture(scope="module")
def rve():
    m = ForwardModel("Al2O3-55", fractions_of("Al2O3-55"), PARAMETRISATIONS["gap"], SMALL)
    return m, m.pack(0)


def test_the_library_holds_five_distinct_effects():
    lib = default_effects()
    assert len(lib) >= 5
    assert len({e.name for e in lib}) == len({e.key for e in lib}) == len(lib)
    assert [e.key for e in fx.by_key(["spots", "matrix"])] == ["spots", "matrix"]
    with refuses(ValueError, "effects"):
        fx.by_key(["shape"])
    assert {e.kind for e in lib} == {"material", "geometry", "measurement", "variance"}
    for e in lib:
        assert e.signature and e.separate_by
        assert e.nominal in e.values


def test_matrix_and_filler_conductivity_change_only_their_phases(rve):
    m, _ = rve
    base = m.materials({"R_Al2O3_silicone": 2e-8})
    mk = MatrixConductivity().materials(base, 0.27).conductivity
    assert mk["silicone"] == 0.27 and mk["Al2O3"] == base.conductivity["Al2O3"]
    fk = FillerConductivity().materials(base, 0.1).conductivity
    assert fk["silicone"] == base.conductivity["silicone"]
    assert fk["Al2O3"] == pytest.approx(0.1 * base.conductivity["Al2O3"])


def test_porosity_homogenises_air_into_the_matrix_at_its_share_of_the_matrix(rve):
    _, ms = rve
    por = Porosity()
    assert por.values[-1] >= 0.10                  # the grid reaches the physical range
    base = ForwardModel("Al2O3-55", {"Al2O3": 0.55}, PARAMETRISATIONS["gap"],
                        SMALL).materials({"R_Al2O3_silicone": 2e-8})
    assert por.materials_in(ms, base, 0.0) is base
    phi = np.mean(ms.material_ids > 0)
    k_m, k_air = base.conductivity["silicone"], AIR_CONDUCTIVITY
    for p in (0.02, 0.1):
        mat = por.materials_in(ms, base, p)
        share = p / (1 - phi)
        # Hashin-Shtrikman upper bound with the silicone as the continuous phase
        # k_m + share / (1 / (k_air - k_m) + (1 - share) / (3 k_m)), which Maxwell's
        # dispersed-sphere formula reaches
        hs = k_m + share / (1 / (k_air - k_m) + (1 - share) / (3 * k_m))
        assert mat.conductivity["silicone"] == pytest.approx(hs, rel=1e-12)
        assert mat.conductivity["Al2O3"] == base.conductivity["Al2O3"]
    # the same void fraction takes a larger share of the matrix at a higher filler fraction
    assert por.materials_in(ms, base, 0.1).conductivity["silicone"] < maxwell(k_m, 0.1)
    with refuses(ValueError, "value"):
        por.materials_in(ms, base, 0.4)


def maxwell(k_m, share):
    return k_m * (2 * k_m + AIR_CONDUCTIVITY - 2 * share * (k_m - AIR_CONDUCTIVITY)) / (
        2 * k_m + AIR_CONDUCTIVITY + share * (k_m - AIR_CONDUCTIVITY))


def test_filler_fraction_removes_particles_down_to_the_factor(rve):
    _, ms = rve
    phi0 = np.mean(ms.material_ids > 0)
    for factor in (0.9, 0.8):
        img = FillerFraction().microstructure(ms, factor, seed=5)
        assert np.mean(img.material_ids > 0) == pytest.approx(factor * phi0, rel=0.03)
        # only removed, never moved: every filler voxel left was filler before
        assert np.all(ms.material_ids[img.material_ids > 0] > 0)


def test_tester_contact_is_a_series_resistance():
    # a 1 mm sample of 1.5 W/(m K) read with 2e-5 m^2 K/W of contact: 1e-3 / (1e-3/1.5 + 2e-5)
    k = fx.TesterContact().apparent(np.array([1.5]), 1e-3, 2e-5)
    assert k[0] == pytest.approx(1e-3 / (1e-3 / 1.5 + 2e-5))
    assert fx.TesterContact().needs_thickness
    thin, thick = fx.TesterContact().apparent(np.array([1.5, 1.5]), np.array([0.5e-3, 1.5e-3]),
                                           2e-5)
    assert thin < thick < 1.5


@pytest.mark.parametrize("values, nominal, what", [
    ((0.1, 0.2), 0.1, "at least 3"), ((0.3, 0.2, 0.1), 0.2, "increasing"),
    ((0.1, 0.2, 0.3), 0.5, "nominal")])
def test_effect_grids_are_checked(values, nominal, what):
    with pytest.raises(ValueError, match=what):
        Effect("x", "x", "p", nominal, values, "s", "m")


def test_measurement_table_reads_an_optional_thickness(tmp_path):
    p = tmp_path / "m.csv"
    p.write_text("formulation,replicate,k_W_per_mK,thickness_mm\n"
                 "Al2O3-55,1,1.20,0.5\nAl2O3-55,2,1.22,0.5\nAl2O3-55,3,1.30,1.5\n"
                 "Al2O3-55,4,1.31,1.5\n")
    m = read_measurements(p, formulations=fractions_of)
    assert np.allclose(m.thickness_m["Al2O3-55"], [5e-4, 5e-4, 1.5e-3, 1.5e-3])
    g = groups_of(m, {"Al2O3-55": {"Al2O3": 0.55}}, system=default_system())
    assert [x.thickness_m for x in g] == [5e-4, 1.5e-3]
    assert g[0].mean == pytest.approx(1.21) and g[1].mean == pytest.approx(1.305)
    # relative scatter about the thickness means, 2 degrees of freedom
    rel = math.sqrt(((0.01 / 1.21) ** 2 * 2 + (0.005 / 1.305) ** 2 * 2) / 2)
    assert g[0].standard_error == pytest.approx(rel * 1.21 / math.sqrt(2))
    assert g[1].standard_error == pytest.approx(rel * 1.305 / math.sqrt(2))
    p.write_text("formulation,replicate,k_W_per_mK,thickness_mm\n"
                 "Al2O3-55,1,1.20,0.5\nAl2O3-55,2,1.22,\n")
    with pytest.raises(ValueError, match="line 3: thickness_mm"):
        read_measurements(p, formulations=fractions_of)


def test_groups_pool_the_relative_scatter_of_a_filler():
    m = Measurements({"Al2O3-55": np.array([1.2, 1.3]), "Al2O3-60": np.array([1.5, 1.5, 1.8]),
                      "Al2O3-29-AlN-29": np.array([2, 2.1])}, "t")
    comp = {"Al2O3-55": {"Al2O3": 0.55}, "Al2O3-60": {"Al2O3": 0.6},
            "Al2O3-29-AlN-29": {"Al2O3": 0.29, "AlN": 0.29}}
    g = groups_of(m, comp, system=default_system(), pool=False)
    assert [x.formulation for x in g] == ["Al2O3-55", "Al2O3-60"]     # two fillers: left out
    assert g[0] == Group("Al2O3-55", "Al2O3", 0.55, None, 1.25, g[0].standard_error, 2)
    assert g[0].standard_error == pytest.approx(0.05)              # sd 0.0707 / sqrt(2)
    pooled = groups_of(m, comp, system=default_system())
    ss = 2 * (0.05 / 1.25) ** 2 + 2 * (0.1 / 1.6) ** 2 + (0.2 / 1.6) ** 2
    rel = math.sqrt(ss / 3)
    assert pooled[0].standard_error == pytest.approx(rel * 1.25 / math.sqrt(2))
    assert pooled[1].standard_error == pytest.approx(rel * 1.6 / math.sqrt(3))
