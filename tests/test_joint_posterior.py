"""The joint posterior over resistances and inputs (issue 59): tabulated forward models,
the parameter space and its priors, the vectorised likelihood, the seeded sampler."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from refusals import refuses

from itr_identify.inference.formulations import fractions_of
from itr_identify.inference.joint import (
    JointLikelihood,
    JointSpace,
    Tabulated,
    sample,
)
from itr_identify.inference.measurements import Measurements
from itr_identify.inference.nuisance import FilmPrior, InputPrior
from itr_identify.inference.priors import ModelFormPrior, ResistancePrior

FORMS = ("Al2O3-55", "Al2O3-60", "Al2O3-65", "AlN-55", "AlN-60", "AlN-62",
         "Al2O3-29-AlN-29", "Al2O3-31-AlN-31")
SCATTER = {"Al2O3": 0.01, "AlN": 0.01, "Al2O3-AlN": 0.01}


class _Box:
    def __init__(self, names, lo, hi):
        self.names, self.lo, self.hi = list(names), [lo] * len(names), [hi] * len(names)


class StandIn:
    """What the joint posterior reads of a ForwardModel: k falls smoothly with every
    resistance of the formulation (a two-filler one: both), a shipped-like shared sd."""

    def __init__(self, form: str):
        self.fractions = fractions_of(form)
        self.phi = sum(self.fractions.values())
        self.parameters = [f"R_{f}_silicone" for f in sorted(self.fractions)]
        self.rb = SimpleNamespace(box_=_Box(self.parameters, 5e-10, 2e-6))
        self.fixed = {}
        self.model_sd, self.rve_scatter, self.packing_dof = 0.004, 0.01, (0.003, 8)
        self.shared_system = "-".join(sorted(self.fractions))

    def predict(self, cols):
        s = sum(np.log1p(np.asarray(cols[p], float) / 1.5e-8) for p in self.parameters)
        k = np.atleast_1d(4.5 * self.phi ** 1.5 / (1 + 0.6 * s / len(self.parameters)))
        return k, 1e-3 * k

    def shared_sd(self, cols):
        return np.full(max(np.asarray(v).size for v in cols.values()), 0.006)


ELASTICITY = {"Al2O3": 0.12, "AlN": 0.02}
INPUTS = {"k_silicone": InputPrior("k_silicone", 0.18, 0.10),
          "k_Al2O3": InputPrior("k_Al2O3", 30.0, 0.15),
          "k_AlN": InputPrior("k_AlN", 200.0, 0.25), "film_nm": FilmPrior()}


def _tables():
    return {f: Tabulated.of(f, StandIn(f), {**{x: ELASTICITY[x] for x in fractions_of(f)},
                                            "film_nm": -0.008}) for f in FORMS}


def _space(tables, **kw):
    return JointSpace.build(tables, matrix="silicone", resistance=ResistancePrior(),
                            inputs=kw.pop("inputs", INPUTS),
                            model_form=kw.pop("model_form", ModelFormPrior()), **kw)


def _simulate(lik: JointLikelihood, values: dict[str, float], seed: int,
              rel_sd: float = 0.015) -> Measurements:
    """Four replicates per formulation about the likelihood's k at ``values`` (the other
    parameters at their prior's centre)."""
    space = lik.space
    theta = np.array([[values.get(n, 0.0 if k != "uniform" else (a + b) / 2)
                       for n, k, a, b in zip(space.names, space.kinds, space.a, space.b)]])
    cols = space.columns(theta)
    rng = np.random.default_rng(seed)
    return Measurements({f: lik.conductivities(cols, f)[0][0]
                         * (1 + rel_sd * rng.standard_normal(4)) for f in FORMS}, "sim")


def test_a_table_reproduces_its_model_between_grid_points():
    for f in ("AlN-60", "Al2O3-29-AlN-29"):
        model, tab = StandIn(f), _tables()[f]
        rng = np.random.default_rng(0)
        x = rng.uniform(-9.2, -5.8, (200, len(model.parameters)))
        k, rel_err, shared = tab.evaluate(x)
        want, err = model.predict({p: 10 ** x[:, i] for i, p in enumerate(model.parameters)})
        np.testing.assert_allclose(k, want, rtol=2e-4 if len(model.parameters) == 2 else 1e-5)
        np.testing.assert_allclose(rel_err, err / want, rtol=1e-6)
        np.testing.assert_allclose(shared, 0.006, rtol=1e-12)


def test_the_space_holds_every_input_the_shared_terms_and_the_model_form():
    tables = _tables()
    space = _space(tables)
    assert space.names[:2] == ("log10 R_AlN_silicone", "log10 R_Al2O3_silicone") or \
        set(space.names[:2]) == {"log10 R_AlN_silicone", "log10 R_Al2O3_silicone"}
    for name in ("ln k_silicone", "ln k_Al2O3", "ln k_AlN", "film_nm", "offset_Al2O3",
                 "offset_AlN", "offset_Al2O3-AlN", "slope_Al2O3", "slope_Al2O3-AlN"):
        assert name in space.names
    assert space.held == {"tau_offset": 0.05, "tau_slope": 0.03}
    rng = np.random.default_rng(1)
    draws = space.draw(rng, 20000)
    lo, hi = ResistancePrior().log10_bounds
    r = draws[:, space.names.index("log10 R_AlN_silicone")]
    assert lo <= r.min() and r.max() <= hi
    km = draws[:, space.names.index("ln k_silicone")]
    assert km.std() == pytest.approx(0.10, rel=0.03)
    assert np.all(np.isfinite(space.log_prior(draws)))
    # a point of the unit cube maps onto the prior (nested sampling's transform)
    u = rng.uniform(size=(20000, space.dim))
    v = space.from_unit(u)
    assert v[:, space.names.index("ln k_AlN")].std() == pytest.approx(0.25, rel=0.03)
    with refuses(ValueError, "hold"):
        _space(tables, hold={"k_silicone": 0.2})
    off = _space(tables, model_form=ModelFormPrior(on=False))
    assert not any(n.startswith("slope_") for n in off.names)
    assert "offset_AlN" in off.names   # the shipped correction's shared term stays


def test_a_two_filler_prediction_moves_with_the_matrix_conductivity_alone():
    """Issue 59, point 1: every formulation, the hybrids too, is evaluated at every input
    value: k_silicone +10 % alone changes a hybrid's k (exactly: lam k_model(lam R), the
    filler terms to first order)."""
    tables = _tables()
    space = _space(tables)
    lik = JointLikelihood(tables, Measurements({f: np.ones(4) for f in FORMS}, "x"), space,
                          scatter=SCATTER)
    theta = np.zeros((2, space.dim))
    for i, n in enumerate(space.names):
        if n.startswith("log10"):
            theta[:, i] = math.log10(2e-8)
    theta[1, space.names.index("ln k_silicone")] = math.log(1.1)
    cols = space.columns(theta)
    k, _ = lik.conductivities(cols, "Al2O3-29-AlN-29")
    assert k[1] != k[0]
    model = StandIn("Al2O3-29-AlN-29")
    base = model.predict({p: np.array([2e-8 * 1.1]) for p in model.parameters})[0][0]
    filler = (1 / 1.1) ** ELASTICITY["Al2O3"] * (1 / 1.1) ** ELASTICITY["AlN"]
    assert k[1] == pytest.approx(1.1 * filler * base, rel=3e-4)


def _simulated_likelihood(r_al2o3: float, *, seed: int) -> JointLikelihood:
    """The likelihood of a table simulated at R_Al2O3 ``r_al2o3`` (m^2 K/W), R_AlN 3e-8 and
    a 1 nm film."""
    tables = _tables()
    space = _space(tables)
    blank = JointLikelihood(tables, Measurements({f: np.ones(4) for f in FORMS}, "x"), space,
                            scatter=SCATTER)
    truth = {"log10 R_Al2O3_silicone": math.log10(r_al2o3),
             "log10 R_AlN_silicone": math.log10(3e-8), "film_nm": 1.0}
    return JointLikelihood(tables, _simulate(blank, truth, seed=seed), space, scatter=SCATTER)


@pytest.mark.slow
def test_the_sampler_recovers_the_truth_and_is_seeded():
    lik = _simulated_likelihood(2.2e-8, seed=3)
    post = sample(lik, seed=7)
    assert post.converged and 0.05 < post.acceptance < 0.6
    for r, t in (("R_Al2O3_silicone", 2.2e-8), ("R_AlN_silicone", 3e-8)):
        lo, hi = post.interval(r)
        assert lo < t < hi and lo < post.point(r) < hi
        assert post.half_width_factor(r) < 3
    again = sample(lik, seed=7)
    np.testing.assert_array_equal(post.samples, again.samples)
    assert sample(lik, seed=8, steps=200, burn=100).samples.shape == (post.walkers * 200,
                                                                      lik.space.dim)


@pytest.mark.slow       # a chain four times the default: minutes on 2 cores
def test_conditional_quantiles_agree_with_a_long_chains_and_are_steadier():
    """The Rao-Blackwell quantiles of log10 R (the mixture of conditional CDFs) agree with
    the quantiles counted from a chain four times the default, and two seeds of them differ
    less than two seeds of the counted ones at the low end (where the likelihood is flat)."""
    from itr_identify.inference import joint

    lik = _simulated_likelihood(4e-9, seed=5)
    name = "log10 R_Al2O3_silicone"
    a, b = (sample(lik, seed=s) for s in (1, 2))
    long = sample(lik, seed=3, steps=4 * a.steps, burn=a.burn)
    q = [0.05, 0.5, 0.95]
    ref = joint.weighted_quantile(long.column(name), q, long.weights)
    rb = [joint.marginal_of(lik, p, name, seed=s).quantile(q) for p, s in ((a, 1), (b, 2))]
    for r in rb:
        np.testing.assert_allclose(r, ref, atol=0.03)        # log10: 7 % in R
    np.testing.assert_allclose(a.quantile(name, q), a.marginals[name].quantile(q))
    counted = [joint.weighted_quantile(p.column(name), [0.05], p.weights)[0] for p in (a, b)]
    assert abs(rb[0][0] - rb[1][0]) <= abs(counted[0] - counted[1]) + 0.005


def test_the_log_prior_is_each_parameters_density_summed_in_order():
    """The vectorised log prior equals the densities written out parameter by parameter
    (uniform, normal, half-normal; -inf outside a support), summed in the parameters' order:
    the same number to the last bit, so a seeded chain does not move."""
    space = JointSpace(("u", "n", "h", "v"), ("uniform", "normal", "halfnormal", "uniform"),
                       (-9.0, 0.3, 0.0, -0.7), (-5.0, 0.05, 0.2, 0.0), {}, {}, "silicone")
    rng = np.random.default_rng(4)
    theta = np.column_stack([rng.uniform(-10, -4, 500), rng.normal(0.3, 0.1, 500),
                             rng.normal(0.1, 0.2, 500), rng.uniform(-1, 0.2, 500)])

    def by_hand(x):
        out = 0.0
        out += -math.log(4.0) if -9 <= x[0] <= -5 else -math.inf
        out += -0.5 * ((x[1] - 0.3) / 0.05) ** 2 - math.log(0.05 * math.sqrt(2 * math.pi))
        out += (-0.5 * (x[2] / 0.2) ** 2 + math.log(math.sqrt(2 / math.pi) / 0.2)
                if x[2] >= 0 else -math.inf)
        out += -math.log(0.7) if -0.7 <= x[3] <= 0 else -math.inf
        return out

    got = space.log_prior(theta)
    want = np.array([by_hand(x) for x in theta])
    assert np.isinf(want).sum() > 100 and np.isfinite(want).sum() > 50
    np.testing.assert_array_equal(got, want)


class _Known:
    """A posterior known in closed form: independent normal likelihoods (centres ``m``, sds
    ``s``) of two log10 resistances with uniform priors over -9 to -6 (one inside, one
    whose likelihood peaks below the floor, so its posterior fills the range's low end) and
    of one input with a normal prior (sd 0.1)."""

    m = np.array([-7.5, -9.2, 0.05])
    s = np.array([0.3, 0.8, 0.05])

    def __init__(self):
        self.space = JointSpace(("u1", "u2", "n"), ("uniform", "uniform", "normal"),
                                (-9.0, -9.0, 0.0), (-6.0, -6.0, 0.1), {}, {}, "silicone")

    def log_posterior(self, theta):
        ll = -0.5 * ((theta - self.m) / self.s) ** 2 - np.log(self.s * math.sqrt(2 * math.pi))
        return self.space.log_prior(theta) + ll.sum(axis=1)

    def ln_z(self) -> float:
        """The evidence: per uniform parameter the likelihood's mass inside the range over
        the range's width; the normal one's, the convolution of two normals at its centre."""
        from scipy import stats

        out = 0.0
        for m, s in zip(self.m[:2], self.s[:2]):
            out += math.log((stats.norm.cdf(-6, m, s) - stats.norm.cdf(-9, m, s)) / 3.0)
        return out + stats.norm.logpdf(self.m[2], 0.0, math.hypot(0.1, self.s[2]))

    def exact(self, n: int, seed: int) -> np.ndarray:
        """``n`` independent draws of the posterior (truncated normals; the input's product
        of two normals)."""
        from scipy import stats

        rng = np.random.default_rng(seed)
        cols = [stats.truncnorm.rvs((-9 - m) / s, (-6 - m) / s, loc=m, scale=s, size=n,
                                    random_state=rng) for m, s in zip(self.m[:2], self.s[:2])]
        v = 1 / (1 / 0.1 ** 2 + 1 / self.s[2] ** 2)
        cols.append(rng.normal(v * self.m[2] / self.s[2] ** 2, math.sqrt(v), n))
        return np.column_stack(cols)


def test_the_open_map_inverts_and_its_jacobian_is_the_derivative():
    box = _Known()
    theta = box.exact(200, seed=1)
    y = box.space.to_open(theta)
    back, log_jac = box.space.from_open(y)
    np.testing.assert_allclose(back, theta, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(y[:, 2], theta[:, 2])     # a normal one is left as it is
    h = 1e-6          # central differences of each uniform coordinate's map
    d = [(box.space.from_open(y + h * e)[0][:, i] - box.space.from_open(y - h * e)[0][:, i])
         / (2 * h) for i, e in ((0, np.eye(3)[0]), (1, np.eye(3)[1]))]
    np.testing.assert_allclose(log_jac, np.log(d[0]) + np.log(d[1]), rtol=0, atol=1e-6)
    np.testing.assert_array_equal(box.space.log_jacobian(y), log_jac)
    assert box.space.inside(theta).all()
    outside = theta.copy()
    outside[0, 0] = box.space.a[0]            # on the end of its uniform prior: not inside
    assert not box.space.inside(outside)[0] and box.space.inside(outside)[1:].all()


def test_importance_draws_give_the_exact_evidence_and_quantiles():
    """From a chain of the exact posterior, the importance draws' ln Z is the closed form's
    (within 3 of its standard errors and 0.01), and the weighted quantiles of the
    floor-bound parameter are the truncated normal's."""
    from scipy import stats

    from itr_identify.inference.joint import refine, weighted_quantile

    box = _Known()
    x, w, ess, ln_z, se, _ = refine(box, box.exact(20000, seed=2), seed=3, draws=200_000)
    assert ess > 0.3 * 200_000
    assert abs(ln_z - box.ln_z()) < max(3 * se, 1e-3) and abs(ln_z - box.ln_z()) < 0.01
    q = [0.05, 0.5, 0.95]
    want = stats.truncnorm.ppf(q, (-9 + 9.2) / 0.8, (-6 + 9.2) / 0.8, loc=-9.2, scale=0.8)
    np.testing.assert_allclose(weighted_quantile(x[:, 1], q, w), want, atol=0.01)


def test_the_chain_stops_where_its_importance_draws_are_worth_the_target():
    """Where a t fitted to a chain of 20 autocorrelation times is a good proposal, the
    importance draws are the posterior and the chain stops short of its own rule (50
    autocorrelation times and the target's worth); the quantiles are the closed form's."""
    from scipy import stats

    from itr_identify.inference.joint import (
        CHAIN_TAUS,
        PROPOSAL_TAUS,
        TARGET_DRAWS,
        weighted_quantile,
    )

    box = _Known()
    post = sample(box, seed=4, marginals=False)
    tau = max(post.autocorr.values())
    assert post.converged and post.source == "importance"
    assert post.effective_draws >= TARGET_DRAWS
    # the chain's own rule: 50 autocorrelation times and walkers x steps / tau >= target
    assert PROPOSAL_TAUS * tau <= post.steps < max(CHAIN_TAUS * tau,
                                                   TARGET_DRAWS * tau / post.walkers)
    q = [0.05, 0.5, 0.95]
    for i, (m, s) in enumerate(zip(box.m[:2], box.s[:2])):
        want = stats.truncnorm.ppf(q, (-9 - m) / s, (-6 - m) / s, loc=m, scale=s)
        np.testing.assert_allclose(weighted_quantile(post.samples[:, i], q, post.weights),
                                   want, atol=0.02)
    assert abs(post.log_evidence - box.ln_z()) < 0.01


def test_the_compiled_table_interpolation_is_numpys_to_the_last_bit():
    """The likelihood's compiled (bi)linear interpolation gives NumPy's gathers' numbers
    bit for bit, points outside the axes clipped to the edges."""
    from itr_identify.inference._table_kernels import linear_1d, linear_2d

    rng = np.random.default_rng(9)
    values1 = rng.normal(size=(3, 4, 41))
    values2 = rng.normal(size=(3, 4, 17, 23))
    ax1 = np.linspace(-9.0, -6.0, 41)
    ax2 = (np.linspace(-9.0, -6.0, 17), np.linspace(-10.0, -5.0, 23))
    x = rng.uniform(-9.5, -5.5, (4, 300))
    y = rng.uniform(-10.5, -4.5, (4, 300))
    rows = np.arange(4)[:, None]

    def place(v, ax):
        t = np.clip((v - ax[0]) / (ax[1] - ax[0]), 0.0, ax.size - 1 - 1e-9)
        i = t.astype(int)
        return i, t - i

    i, w = place(x, ax1)
    want1 = values1[:, rows, i] * (1 - w) + values1[:, rows, i + 1] * w
    got1 = linear_1d(values1, x, ax1[0], ax1[1] - ax1[0], ax1.size - 1 - 1e-9)
    np.testing.assert_array_equal(got1, want1)
    (i, a), (j, b) = place(x, ax2[0]), place(y, ax2[1])
    want2 = ((1 - a) * (1 - b) * values2[:, rows, i, j] + a * (1 - b) * values2[:, rows, i + 1, j]
             + (1 - a) * b * values2[:, rows, i, j + 1] + a * b * values2[:, rows, i + 1, j + 1])
    lo = np.array([ax2[0][0], ax2[1][0]])
    step = np.array([ax2[0][1] - ax2[0][0], ax2[1][1] - ax2[1][0]])
    last = np.array([16 - 1e-9, 22 - 1e-9])
    np.testing.assert_array_equal(linear_2d(values2, x, y, lo, step, last), want2)
