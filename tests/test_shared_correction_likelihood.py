"""The shipped correction's system-wide term in the likelihood (issue 58): one term shared
by every formulation of a system, integrated out once per system; and the pooled packing
variance's degrees of freedom in the Student t."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from itr_identify.inference.calibrate import Stage, _stage_loglike, log_likelihood
from itr_identify.inference.measurements import Measurements


class _Model:
    """A forward model stand-in: k = a / (1 + b log10(R / 1e-8)), a shared term ``u``."""

    def __init__(self, a: float, b: float, u: float, system: str | None) -> None:
        self.a, self.b, self.u, self.shared_system = a, b, u, system
        self.model_sd, self.packing_dof, self.parameters = 0.0, None, ["R"]

    def predict(self, columns):
        x = np.log10(np.asarray(columns["R"], float) / 1e-8)
        k = self.a / (1 + self.b * x)
        return k, np.zeros_like(k)

    def shared_sd(self, columns):
        return np.full(np.asarray(columns["R"]).size, self.u)


def _measurements(means: dict[str, float], se: float, n: int, seed: int) -> Measurements:
    """Replicates with exactly the given mean and standard error."""
    rng = np.random.default_rng(seed)
    out = {}
    for f, m in means.items():
        z = rng.standard_normal(n)
        z = (z - z.mean()) / z.std(ddof=1)
        out[f] = m + se * math.sqrt(n) * z
    return Measurements(out, "test")


@pytest.mark.parametrize("u", [0.005, 0.03, 0.08])
def test_the_shared_term_integrates_to_the_joint_gaussian_in_the_gaussian_limit(u):
    """With many replicates the Student t is a Gaussian, and integrating one shared relative
    shift out gives the multivariate normal with covariance ``D + (u k)(u k)^T``, also where
    the data pin the shift down to a fraction of its prior (u = 8 %, four formulations)."""
    models = {f: _Model(a, 0.1, u, "S") for f, a in
              (("A", 1.5), ("B", 1.8), ("C", 2.1), ("D", 2.4))}
    means = {"A": 1.55, "B": 1.83, "C": 2.20, "D": 2.41}
    meas = _measurements(means, se=0.02, n=400000, seed=1)
    stage = Stage(("S",), tuple(models), ("R",), ())
    R = np.array([5e-9, 1e-8, 3e-8])
    got = _stage_loglike(models, stage, meas, {"R": R}, scatter=0.0)
    for i, r in enumerate(R):
        k = np.array([models[f].predict({"R": np.array([r])})[0][0] for f in models])
        se = np.array([meas.standard_error(f) for f in models])
        cov = np.diag(se ** 2) + np.outer(u * k, u * k)
        want = stats.multivariate_normal(k, cov).logpdf([meas.mean(f) for f in models])
        assert got[i] == pytest.approx(want, rel=5e-5, abs=3e-4)  # t against normal


def test_formulations_of_no_shipped_system_stay_independent():
    models = {"A": _Model(1.5, 0.1, 0.05, None), "B": _Model(1.8, 0.1, 0.05, None)}
    meas = _measurements({"A": 1.52, "B": 1.86}, se=0.03, n=5, seed=2)
    stage = Stage(("S",), ("A", "B"), ("R",), ())
    R = np.array([1e-8, 2e-8])
    got = _stage_loglike(models, stage, meas, {"R": R}, scatter=0.01)
    want = 0.0
    for f, m in models.items():
        k, _ = m.predict({"R": R})
        v = meas.standard_error(f) ** 2 + (0.01 * k) ** 2
        want = want + log_likelihood(meas.mean(f) - k, v, meas.standard_error(f) ** 2, 5)
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_a_shared_term_weighs_a_common_offset_less_than_independent_terms_would():
    """Four formulations all 3 % above the model: a shared term of 3 % explains the common
    offset, so the data are likelier than with the same 3 % independent per formulation
    (which must explain four offsets at once)."""
    means = {"A": 1.5 * 1.03, "B": 1.8 * 1.03, "C": 2.1 * 1.03, "D": 2.4 * 1.03}
    meas = _measurements(means, se=0.01, n=2000, seed=4)
    stage = Stage(("S",), tuple(means), ("R",), ())
    R = np.array([1e-8])
    shared = {f: _Model(a, 0.1, 0.03, "S") for f, a in zip(means, (1.5, 1.8, 2.1, 2.4))}
    indep = {f: _Model(a, 0.1, 0.0, None) for f, a in zip(means, (1.5, 1.8, 2.1, 2.4))}
    for m in indep.values():
        m.model_sd = 0.03
    assert _stage_loglike(shared, stage, meas, {"R": R}, 0.0)[0] > \
        _stage_loglike(indep, stage, meas, {"R": R}, 0.0)[0] + 3


def test_an_estimated_variance_part_lowers_the_degrees_of_freedom():
    """Welch-Satterthwaite with a second estimated part: nu = v^2 / (v_m^2 / (n - 1) +
    v_p^2 / dof); fewer degrees of freedom give heavier tails (lower density far out)."""
    r, v, vm, n = np.array([0.0, 0.2]), 0.01, 0.004, 4
    plain = log_likelihood(r, v, vm, n)
    with_pack = log_likelihood(r, v, vm, n, estimated=(np.array(0.005), 8))
    nu = v ** 2 / (vm ** 2 / (n - 1) + 0.005 ** 2 / 8)
    want = stats.t(nu, scale=math.sqrt(v)).logpdf(r)
    np.testing.assert_allclose(with_pack, want, rtol=1e-10)
    assert with_pack[1] > plain[1]   # heavier tail: a residual of 2 sd is likelier
