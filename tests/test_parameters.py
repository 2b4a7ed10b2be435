"""The flat parameter naming (k_, R_, Gc_, Rff_) and its round trip through Materials."""

import pytest

from itr_fv import Materials
from itr_fv.materials.parameters import is_log_scaled, parameter_name, parse_parameter


def test_names_sort_the_pair_and_parse_back():
    assert parameter_name("R", "silicone", "Al2O3") == "R_Al2O3_silicone"
    assert parameter_name("k", "AlN") == "k_AlN"
    assert parse_parameter("Gc_Al2O3_AlN") == ("Gc", ("Al2O3", "AlN"))
    assert is_log_scaled("Rff_AlN_AlN") and not is_log_scaled("k_AlN")


@pytest.mark.parametrize("name", ["R_silicone_Al2O3", "k_", "X_Al2O3", "R_Al2O3", "k_a_b",
                                  "Gc__AlN", 3])
def test_malformed_names_are_refused_by_name(name):
    with pytest.raises(ValueError, match="parameter"):
        parse_parameter(name)


def test_gap_materials_round_trip():
    mat = Materials({"silicone": 0.18, "Al2O3": 30.0, "AlN": 200.0},
                    {("Al2O3", "silicone"): 2.2e-8, ("silicone", "AlN"): 3e-8}, "silicone",
                    contact_conductance={("AlN", "Al2O3"): 1e-6})
    p = mat.to_parameters()
    assert p == {"k_silicone": 0.18, "k_Al2O3": 30.0, "k_AlN": 200.0,
                 "R_Al2O3_silicone": 2.2e-8, "R_AlN_silicone": 3e-8, "Gc_Al2O3_AlN": 1e-6}
    again = Materials.from_parameters(p, "silicone")
    assert again.to_parameters() == p and again.contact == "gap"


def test_area_materials_use_rff_and_with_parameters_replaces_one_value():
    mat = Materials({"silicone": 0.18, "Al2O3": 30.0},
                    {("Al2O3", "silicone"): 2.2e-8, ("Al2O3", "Al2O3"): 2e-7}, "silicone",
                    contact="area")
    assert mat.to_parameters()["Rff_Al2O3_Al2O3"] == 2e-7
    new = mat.with_parameters({"Rff_Al2O3_Al2O3": 1e-7, "k_Al2O3": 25.0})
    assert new.resistance_between("Al2O3", "Al2O3") == 1e-7
    assert new.conductivity["Al2O3"] == 25.0 and new.contact == "area"
    assert mat.resistance_between("Al2O3", "Al2O3") == 2e-7  # unchanged


@pytest.mark.parametrize("params,contact,match", [
    ({"k_silicone": 0.18, "k_Al2O3": 30.0, "R_Al2O3_Al2O3": 1e-7}, "gap", "names the matrix"),
    ({"k_silicone": 0.18, "k_Al2O3": 30.0, "Rff_Al2O3_Al2O3": 1e-7}, "gap", "contact='area'"),
    ({"k_silicone": 0.18, "R_Al2O3_silicone": 1e-8}, "gap", "k_Al2O3"),
    ({"k_silicone": 0.18, "k_Al2O3": 30.0, "Gc_Al2O3_Al2O3": 1e-6}, "area", "contact='gap'"),
    ({"k_silicone": -1.0}, "gap", r"k_silicone' must be finite and > 0 W/\(m K\)"),
    ({"k_silicone": 0.18, "k_Al2O3": 30.0, "Gc_Al2O3_Al2O3": float("inf")}, "gap", "finite"),
    ({"k_silicone": True}, "gap", "boolean"),
])
def test_bad_parameter_sets_name_the_parameter(params, contact, match):
    with pytest.raises(ValueError, match=match):
        Materials.from_parameters(params, "silicone", contact=contact)
