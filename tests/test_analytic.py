"""Tests of itr_fv.analytic: reference values, classical limits and identities, input checks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from itr_fv import analytic

LATTICES = ("sc", "bcc", "fcc")


# --------------------------------------------------------------------------- sphere arrays
def test_sc_reference_values_from_design_document():
    # DESIGN.md: Rayleigh multipole value 1.88774 and the ITR benchmark 1.17292
    assert analytic.sphere_array("sc", 0.3, 10.0, 0.0) == pytest.approx(1.88774, rel=1e-5)
    assert analytic.sphere_array("sc", 0.3, 10.0, 0.5) == pytest.approx(1.17292, rel=1e-5)


@pytest.mark.parametrize("lattice", LATTICES)
@pytest.mark.parametrize("k_ratio,f", [(10.0, 0.2), (170.0, 0.45), (3.0, 0.05)])
def test_neutral_inclusion_is_invisible(lattice, k_ratio, f):
    # alpha = 1 - 1/k_r makes the coated sphere dipole-neutral: k_eff = k_m exactly
    alpha = 1.0 - 1.0 / k_ratio
    assert abs(analytic.sphere_array(lattice, f, k_ratio, alpha) - 1.0) < 1e-10


def test_f_max_values():
    assert analytic.f_max("sc") == pytest.approx(math.pi / 6, rel=1e-14)
    assert analytic.f_max("bcc") == pytest.approx(math.sqrt(3) * math.pi / 8, rel=1e-14)
    assert analytic.f_max("fcc") == pytest.approx(math.sqrt(2) * math.pi / 6, rel=1e-14)


def test_rayleigh_lattice_sum_and_f10_3_coefficient():
    # Rayleigh's simple-cubic lattice sum S_4 = sum' P_4(cos t)/R^5 = 3.10823 (unit cube edge)
    assert analytic.lattice_sum_s4("sc") == pytest.approx(3.10823, abs=2e-5)
    # coefficient of beta_3 f^(10/3) in Rayleigh's formula: 1.305 (McKenzie, McPhedran & Derrick
    # 1978; Rayleigh's 1892 value 1.65 was wrong); bcc 0.129, fcc 0.0752 in the same papers
    assert analytic.rayleigh_sc_coefficient("sc") == pytest.approx(1.305, abs=1e-3)
    assert analytic.rayleigh_sc_coefficient("bcc") == pytest.approx(0.129, abs=1e-3)
    assert analytic.rayleigh_sc_coefficient("fcc") == pytest.approx(0.0752, abs=1e-3)


@pytest.mark.parametrize("k_ratio", [math.inf, 10.0])
def test_f10_3_coefficient_from_the_full_multipole_solution(k_ratio):
    # extract C from k_eff(f) at small f: 3f/(k-1) = 1/beta_1 - f - C beta_3 f^(10/3) + O(f^(14/3))
    if math.isinf(k_ratio):
        b1 = b3 = 1.0
    else:
        b1 = (k_ratio - 1) / (k_ratio + 2)
        b3 = (k_ratio - 1) / (k_ratio + 4 / 3)
    fs = np.array([0.004, 0.008, 0.016])
    est = []
    for f in fs:
        k = analytic.sphere_array("sc", f, k_ratio, 0.0)
        est.append((1 / b1 - f - 3 * f / (k - 1)) / (b3 * f ** (10 / 3)))
    slope, intercept = np.polyfit(fs ** (4 / 3), est, 1)
    assert intercept == pytest.approx(1.305, abs=1e-3)


@pytest.mark.parametrize("lattice", LATTICES)
def test_dipole_truncation_is_maxwell_garnett(lattice):
    # with dipoles only (order 1) the cubic lattice sum S_2 vanishes and the Lorentz local field
    # gives exactly the Clausius-Mossotti / Maxwell-Garnett (Hasselman-Johnson) formula
    for k_ratio, alpha in [(10.0, 0.0), (170.0, 0.3), (math.inf, 0.1), (0.2, 0.0)]:
        v = analytic.sphere_array(lattice, 0.3, k_ratio, alpha, order=1)
        assert v == pytest.approx(analytic.hasselman_johnson(0.3, k_ratio, alpha), rel=1e-13)


@pytest.mark.parametrize("lattice", LATTICES)
@pytest.mark.parametrize("k_ratio,alpha", [(10.0, 0.0), (170.0, 0.0), (170.0, 0.1), (10.0, 2.0),
                                           (math.inf, 0.5)])
def test_low_fraction_agrees_with_hasselman_johnson(lattice, k_ratio, alpha):
    f = 0.01
    exact = analytic.sphere_array(lattice, f, k_ratio, alpha)
    assert exact == pytest.approx(analytic.hasselman_johnson(f, k_ratio, alpha), rel=1e-4)


@pytest.mark.parametrize("lattice,fs", [("sc", (0.1, 0.3, 0.5)), ("bcc", (0.1, 0.4, 0.6)),
                                        ("fcc", (0.1, 0.4, 0.7))])
@pytest.mark.parametrize("k_ratio", [10.0, 170.0, 0.1])
def test_hashin_shtrikman_bounds_bracket_the_arrays(lattice, fs, k_ratio):
    for f in fs:
        lo, hi = analytic.hashin_shtrikman(f, k_ratio)
        v = analytic.sphere_array(lattice, f, k_ratio, 0.0)
        assert lo <= v <= hi


def test_perfectly_conducting_spheres():
    for lattice, f in [("sc", 0.5), ("bcc", 0.6), ("fcc", 0.7)]:
        v_inf = analytic.sphere_array(lattice, f, math.inf, 0.0)
        assert math.isfinite(v_inf)
        assert v_inf > analytic.sphere_array(lattice, f, 170.0, 0.0)
        assert v_inf == pytest.approx(analytic.sphere_array(lattice, f, 1e9, 0.0), rel=1e-6)
    # with an interface resistance the inf limit is finite and approached smoothly
    v = analytic.sphere_array("sc", 0.4, math.inf, 0.2)
    assert v == pytest.approx(analytic.sphere_array("sc", 0.4, 1e9, 0.2), rel=1e-6)
    # an insulating interface makes the spheres insulating whatever k_ratio
    assert analytic.sphere_array("sc", 0.3, math.inf, math.inf) == pytest.approx(
        analytic.sphere_array("sc", 0.3, 1e-12, 0.0), rel=1e-9)


def test_monotone_in_fraction_and_alpha():
    for lattice, fmax in [("sc", 0.5), ("bcc", 0.6), ("fcc", 0.7)]:
        fs = np.linspace(0.05, fmax, 8)
        up = [analytic.sphere_array(lattice, f, 170.0, 0.0) for f in fs]
        down = [analytic.sphere_array(lattice, f, 10.0, 2.0) for f in fs]  # kappa_l < 1: worse
        assert np.all(np.diff(up) > 0)
        assert np.all(np.diff(down) < 0)
        alphas = [0.0, 0.05, 0.1, 0.3, 0.5, 1.0, 2.0, 10.0]
        vals = [analytic.sphere_array(lattice, 0.4, 170.0, a) for a in alphas]
        assert np.all(np.diff(vals) < 0)


def test_lattice_dependence_at_equal_fraction():
    # at moderate f the three lattices nearly agree (differences start at f^(10/3));
    # sc, whose neighbours are closest at a given f, is the largest for conducting spheres
    for f in (0.1, 0.3):
        sc, bcc, fcc = (analytic.sphere_array(lat, f, 170.0, 0.0) for lat in LATTICES)
        assert sc > bcc > fcc
        assert sc - fcc < 0.03 * sc


def test_order_is_reported_and_converged():
    d = analytic.sphere_array_details("sc", 0.5, 170.0, 0.0)
    assert d.converged and d.order % 2 == 1 and d.order > d.previous_order
    assert d.last_change < 1e-6
    assert d.n_unknowns > 0
    ref = analytic.sphere_array("sc", 0.5, 170.0, 0.0, order=101)
    assert d.value == pytest.approx(ref, rel=1e-5)
    low = analytic.sphere_array_details("sc", 0.3, 10.0, 0.0)
    assert low.order < d.order  # more multipoles near touching
    fixed = analytic.sphere_array_details("sc", 0.3, 10.0, 0.0, order=9)
    assert fixed.order == 9 and fixed.previous_order == 7


def test_ewald_sums_do_not_depend_on_the_splitting():
    for lattice in LATTICES:
        a = analytic._lattice_sums(lattice, 32, 1.0)
        b = analytic._lattice_sums(lattice, 32, 0.7)
        np.testing.assert_allclose(a, b, atol=1e-12)


@pytest.mark.parametrize("kwargs,name", [
    (dict(lattice="hcp"), "lattice"),
    (dict(f=0.0), "f"),
    (dict(f=-0.1), "f"),
    (dict(f=math.pi / 6), "f"),
    (dict(f=0.6), "f"),
    (dict(f=float("nan")), "f"),
    (dict(k_ratio=0.0), "k_ratio"),
    (dict(k_ratio=-2.0), "k_ratio"),
    (dict(k_ratio=float("nan")), "k_ratio"),
    (dict(alpha=-0.1), "alpha"),
    (dict(alpha=float("nan")), "alpha"),
])
def test_sphere_array_rejects_bad_input(kwargs, name):
    args = dict(lattice="sc", f=0.3, k_ratio=10.0, alpha=0.1)
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        analytic.sphere_array(**args)


def test_fraction_limits_per_lattice():
    analytic.sphere_array("fcc", 0.6, 10.0, 0.0)  # allowed for fcc, beyond sc
    with pytest.raises(ValueError, match="f"):
        analytic.sphere_array("bcc", 0.7, 10.0, 0.0)
    with pytest.raises(ValueError, match="f"):
        analytic.sphere_array("fcc", 0.75, 10.0, 0.0)


# --------------------------------------------------------------------------- closed forms
def test_hasselman_johnson_formula():
    f, kr, a = 0.2, 30.0, 0.4
    # Hasselman & Johnson (1987) in their own variables (a_K / a = alpha)
    num = 2 * f * (kr - kr * a - 1) + kr + 2 * kr * a + 2
    den = f * (1 - kr + kr * a) + kr + 2 * kr * a + 2
    assert analytic.hasselman_johnson(f, kr, a) == pytest.approx(num / den, rel=1e-14)
    # alpha = 0: Maxwell-Garnett; neutral inclusion; k = inf limit
    assert analytic.hasselman_johnson(f, kr, 0.0) == pytest.approx(
        analytic.maxwell_garnett(f, kr), rel=1e-14)
    assert analytic.hasselman_johnson(f, kr, 1 - 1 / kr) == pytest.approx(1.0, abs=1e-14)
    assert analytic.hasselman_johnson(f, math.inf, a) == pytest.approx(
        analytic.maxwell_garnett(f, 1 / a), rel=1e-14)
    assert analytic.hasselman_johnson(f, math.inf, 0.0) == pytest.approx((1 + 2 * f) / (1 - f))
    with pytest.raises(ValueError, match="alpha"):
        analytic.hasselman_johnson(f, kr, -1.0)
    with pytest.raises(ValueError, match="k_ratio"):
        analytic.hasselman_johnson(f, float("nan"), a)


def test_hashin_shtrikman_bounds():
    for kr in (0.05, 0.5, 2.0, 10.0, 170.0):
        assert analytic.hashin_shtrikman(0.0, kr) == pytest.approx((1.0, 1.0))
        assert analytic.hashin_shtrikman(1.0, kr) == pytest.approx((kr, kr))
        for f in (0.1, 0.5, 0.9):
            lo, hi = analytic.hashin_shtrikman(f, kr)
            wiener_lo = 1 / ((1 - f) + f / kr)
            wiener_hi = (1 - f) + f * kr
            assert wiener_lo <= lo <= hi <= wiener_hi
    # lower bound = Maxwell-Garnett when the inclusions conduct better
    assert analytic.hashin_shtrikman(0.3, 10.0)[0] == pytest.approx(
        analytic.maxwell_garnett(0.3, 10.0), rel=1e-14)
    assert analytic.hashin_shtrikman(0.3, 0.1)[1] == pytest.approx(
        analytic.maxwell_garnett(0.3, 0.1), rel=1e-14)
    lo, hi = analytic.hashin_shtrikman(0.3, math.inf)
    assert lo == pytest.approx(1.6 / 0.7) and hi == math.inf
    with pytest.raises(ValueError, match="f"):
        analytic.hashin_shtrikman(1.2, 10.0)


def test_laminate():
    L = [1e-3, 3e-3]
    k = [1.0, 3.0]
    # series: 4e-3 / (1e-3/1 + 3e-3/3) = 2 ; parallel: (1e-3 + 9e-3)/4e-3 = 2.5
    assert analytic.laminate(L, k) == pytest.approx(2.0)
    assert analytic.laminate(L, k, direction="parallel") == pytest.approx(2.5)
    # two interfaces per period with R = 1e-3 m^2K/W each: 4e-3 / (2e-3 + 2e-3) = 1
    assert analytic.laminate(L, k, 1e-3) == pytest.approx(1.0)
    assert analytic.laminate(L, k, [1.5e-3, 0.5e-3]) == pytest.approx(1.0)
    assert analytic.laminate(L, k, 1e-3, direction="parallel") == pytest.approx(2.5)
    assert analytic.laminate(L, k, math.inf) == 0.0
    # single layer with its periodic interface
    assert analytic.laminate([2e-3], [4.0], 1e-4) == pytest.approx(2e-3 / (5e-4 + 1e-4))
    with pytest.raises(ValueError, match="conductivities"):
        analytic.laminate(L, [1.0, -3.0])
    with pytest.raises(ValueError, match="thicknesses_m"):
        analytic.laminate([0.0, 1e-3], k)
    with pytest.raises(ValueError, match="resistances"):
        analytic.laminate(L, k, [1e-3])
    with pytest.raises(ValueError, match="resistances"):
        analytic.laminate(L, k, -1.0)
    with pytest.raises(ValueError, match="direction"):
        analytic.laminate(L, k, direction="diagonal")
