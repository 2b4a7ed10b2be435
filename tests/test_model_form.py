"""The model-form term of the discrepancy workflow (issue 25): a Gaussian-process discrepancy
in the filler fraction, checked against independent implementations (SciPy's multivariate
normal, scikit-learn's Gaussian-process regressor) and on tables from an analytic model
(Hasselman-Johnson spheres with an interface resistance), where the truth is known."""

import math

import numpy as np
import pytest
from scipy import stats
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel

from itr_fv.analytic import hasselman_johnson
from itr_identify.discrepancy import gp_discrepancy as mf
from itr_identify.discrepancy.fit import Group
from itr_identify.discrepancy.settings import DiscrepancySettings
from itr_identify.discrepancy.tables import ForwardTables

K_M, K_P, RADIUS = 0.18, 30.0, 2e-6
SETTINGS = DiscrepancySettings(faithful=None)
FRACTIONS = (0.45, 0.50, 0.55, 0.60, 0.65)
TRUE_R = 2e-8
SCATTER = 0.01


def k_model(phi, r):
    return K_M * hasselman_johnson(phi, K_P / K_M, r * K_M / RADIUS)


def tables(fractions=FRACTIONS):
    grid = SETTINGS.r_grid_m2K_per_W
    names = [f"X-{round(100 * p)}" for p in fractions]
    base = {n: np.array([k_model(p, r) for r in grid]) for n, p in zip(names, fractions)}
    return ForwardTables(SETTINGS, [], base, {}, {n: 1.0 for n in names},
                         {n: SCATTER for n in names})


def groups(misfit=lambda phi: 0.0, *, rel_se=0.012, seed=0, fractions=FRACTIONS):
    rng = np.random.default_rng(seed)
    out = []
    for p in fractions:
        k = k_model(p, TRUE_R) * math.exp(misfit(p)) * (1 + rel_se * rng.standard_normal())
        out.append(Group(f"X-{round(100 * p)}", "X", p, None, k, rel_se * k, 4))
    return out


def test_the_evidence_is_the_multivariate_normal_density():
    t, g = tables(), groups(seed=1)
    d = mf._data(t, g)
    amps, lengths = np.array([0.05]), np.array([6.0])
    ev = mf._log_evidence(d, amps, lengths)
    for j in (0, 40, 100):
        cov = (np.diag(d.rel_var) + SCATTER ** 2 * np.eye(len(g))
               + 0.05 ** 2 * np.exp(-0.5 * ((d.phi[:, None] - d.phi[None, :]) / 6.0) ** 2))
        ref = stats.multivariate_normal(np.zeros(len(g)), cov).logpdf(d.y - d.ln_model[:, j])
        assert ev[0, 0, 0, j] == pytest.approx(ref, rel=1e-10)


def test_the_conditional_is_a_gaussian_process_regression():
    t, g = tables(), groups(lambda p: 0.1 * (p - 0.5) / 0.1, seed=2)
    d = mf._data(t, g)
    idx = np.arange(len(g) - 1)                     # the last formulation predicted
    s, length, j = 0.08, 7.0, 60
    w, var = mf._conditional(d, idx, d.phi[-1], s, length)
    noise = d.rel_var[idx] + SCATTER ** 2
    gpr = GaussianProcessRegressor(ConstantKernel(s ** 2, "fixed") * RBF(length, "fixed"),
                                   alpha=noise, optimizer=None, normalize_y=False)
    gpr.fit(d.phi[idx, None], d.y[idx] - d.ln_model[idx, j])
    mean, sd = gpr.predict(d.phi[-1:, None], return_std=True)
    assert w @ (d.y[idx] - d.ln_model[idx, j]) == pytest.approx(mean[0], rel=1e-8)
    assert var == pytest.approx(sd[0] ** 2, rel=1e-8)


def test_without_a_misfit_the_term_stays_small_and_the_resistance_is_recovered():
    t, g = tables(), groups(seed=3)
    fit = mf.fit_model_form(t, g)
    r, lo, hi = fit.resistances["R_X_silicone"]
    assert lo <= TRUE_R <= hi
    assert lo <= r <= hi                             # the reported value in its interval
    assert fit.amplitude[0] < 0.03                   # below the noise level of the data
    assert fit.amplitude[1] <= fit.amplitude[0] <= fit.amplitude[2]


@pytest.mark.slow
def test_a_misfit_steepening_with_the_fraction_is_covered_only_with_the_term():
    # the measurements steepen above the model towards the packing limit (as Table 3 does):
    # +0 % at 45 vol%, +17 % at 65 vol%, on top of replicate noise
    fractions = (0.45, 0.50, 0.53, 0.55, 0.58, 0.60, 0.62, 0.65)
    misfit = lambda p: 0.4 * (p - 0.45) ** 2 / 0.2 ** 2 * 0.4        # noqa: E731
    covered = {"base": [], "term": []}
    for seed in range(3):
        t, g = tables(fractions), groups(misfit, seed=seed, fractions=fractions)
        base = mf.leave_one_out(t, g, with_term=False)
        term = mf.leave_one_out(t, g)
        covered["base"].append(base.coverage)
        covered["term"].append(term.coverage)
        assert np.all(term.low < term.high)
    assert np.mean(covered["term"]) >= 0.75
    assert np.mean(covered["term"]) > np.mean(covered["base"]) + 0.2


def test_a_misfit_beyond_the_bounded_prior_is_flagged():
    # a factor 3 across the fractions is more than the term may carry (25 % of k): the
    # amplitude piles at the prior's upper end and the fit says so; a small one does not
    big = mf.fit_model_form(tables(), groups(lambda p: math.log(3.0) * (p - 0.45) / 0.2,
                                             seed=4))
    assert big.amplitude[0] == pytest.approx(mf.AMPLITUDE_RANGE[1])
    assert big.at_prior_edge and big.to_dict()["at_prior_edge"]
    small = mf.fit_model_form(tables(), groups(lambda p: 0.05 * (p - 0.45) / 0.2, seed=4))
    assert not small.at_prior_edge


def test_the_fraction_slope_is_the_derivative_of_the_model():
    from itr_identify.discrepancy.fit import _fraction_slopes

    fractions = (0.45, 0.50, 0.55, 0.60, 0.65)
    r = np.array([1e-8, 3e-8, 1e-7])
    where = {f"X-{round(100 * p)}": ("X", p) for p in fractions}
    k = {f: np.array([k_model(p, x) for x in r]) for f, (_, p) in where.items()}
    slopes = _fraction_slopes(where, k)
    for f, (_, p) in where.items():
        if p in (0.45, 0.65):
            continue                     # a quadratic's end points: skip
        h = 1e-4
        exact = (np.log([k_model(p + h, x) for x in r])
                 - np.log([k_model(p - h, x) for x in r])) / (2 * h)
        np.testing.assert_allclose(slopes[f], exact, rtol=0.08)


def test_a_batch_fraction_error_widens_the_model_where_k_is_steep():
    from itr_identify.discrepancy.effects import BatchFraction
    from itr_identify.discrepancy.fit import fit_model

    # each formulation's batch off nominal by +-1.5 vol% (alternating): k scatters about
    # the model by more than the replicates allow, and more at the steep end
    fractions = (0.45, 0.50, 0.55, 0.60, 0.65)
    t = tables(fractions)
    rng = np.random.default_rng(5)
    g = []
    for i, p in enumerate(fractions):
        k = k_model(p + (0.015 if i % 2 else -0.015), TRUE_R) * (1 + 0.005 * rng.standard_normal())
        g.append(Group(f"X-{round(100 * p)}", "X", p, None, k, 0.005 * k, 4))
    base = fit_model(t, g, None)
    batch = fit_model(t, g, BatchFraction())
    lo, hi = batch.interval
    assert lo <= batch.parameters["batch_fraction_sd"] <= hi
    assert lo <= 0.015 <= hi
    assert batch.log_likelihood > base.log_likelihood + 3
    assert batch.chi_square < base.chi_square / 3
    # the mean is the base model's: a variance effect does not move it
    assert BatchFraction().formulation_sd(np.array([2.0, 4.0]), 0.01).tolist() == [0.02, 0.04]
