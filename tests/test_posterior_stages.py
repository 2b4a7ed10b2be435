"""The calibration's per-stage results (:class:`StageResult`): typed, frozen, and the same
JSON-ready dict as before through ``to_dict()``.

Stand-in forward models (a closed-form k_iso, no solves) keep this fast and reach both
kinds of stage: single-filler systems that identify their own parameter and a two-filler
system (gap parametrisation) that has nothing new to identify.
"""

import dataclasses
import json
from types import SimpleNamespace

import numpy as np
import pytest

from itr_identify.inference.calibrate import Posterior, StageResult, calibrate
from itr_identify.inference.formulations import fractions_of
from itr_identify.inference.measurements import Measurements

TRUE = {"R_Al2O3_silicone": 3e-8, "R_AlN_silicone": 1e-7}


class _StubModel:
    """What :func:`calibrate` reads of a ForwardModel; k_iso (W/(m K)) falls linearly in
    log10 of each interface resistance."""

    def __init__(self, formulation: str):
        self.fractions = fractions_of(formulation)
        self.parameters = tuple(f"R_{f}_silicone" for f in sorted(self.fractions))
        self.rve_scatter = 0.01
        self.carried_scatter = 0.0
        self.model_sd = 0.0          # earlier stages' spread and faithful correction
        self.settings = SimpleNamespace(prior_m2K_per_W=(1e-9, 1e-5))

    def predict(self, columns):
        k = 2.0
        for p in self.parameters:
            k = k - 0.3 * (np.log10(np.asarray(columns[p], dtype=float)) + 7.0)
        k = np.atleast_1d(k)
        return k, np.full(k.shape, 1e-3)


@pytest.fixture(scope="module")
def posterior() -> Posterior:
    forms = ("Al2O3-60", "AlN-60", "Al2O3-30-AlN-30")
    models = {f: _StubModel(f) for f in forms}
    noise = np.array([-0.02, 0.01, 0.02, -0.01])
    meas = Measurements({f: models[f].predict({p: np.array([TRUE[p]]) for p in TRUE})[0][0]
                         + noise for f in forms}, "stub")
    return calibrate(models, meas, grid_points=31, n_samples=500)


def test_stages_are_typed_frozen_results(posterior):
    assert len(posterior.stages) == 3
    assert all(isinstance(s, StageResult) for s in posterior.stages)
    first, _, hybrid = posterior.stages
    with pytest.raises(dataclasses.FrozenInstanceError):
        first.log_likelihood_best = 0.0
    assert first.parameters == ("R_Al2O3_silicone",)
    assert hybrid.parameters == () and hybrid.axes_log10 is None and hybrid.density is None
    assert posterior.log_likelihood_best() == pytest.approx(
        sum(s.log_likelihood_best for s in posterior.stages))


def test_stage_attributes_match_their_dict_form(posterior):
    for s in posterior.stages:
        d = s.to_dict()
        assert d["parameters"] == list(s.parameters)
        assert d["system"] == list(s.system)
        assert d["log_likelihood_best"] == s.log_likelihood_best
        assert d["rve_scatter"] == s.rve_scatter
        assert d["identifiability"] == s.identifiability
        json.dumps(d)                                        # JSON-ready as it is
    first = posterior.stages[0].to_dict()
    assert list(first) == ["system", "formulations", "parameters", "carried", "rve_scatter",
                           "axes_log10", "density", "log_likelihood_best", "identifiability"]
    assert first["density"] == posterior.stages[0].density.tolist()
    assert sum(first["density"]) == pytest.approx(1.0)
    hybrid = posterior.stages[2].to_dict()
    assert list(hybrid) == ["system", "formulations", "parameters", "carried", "rve_scatter",
                            "log_likelihood_best", "identifiability"]
    assert hybrid["carried"] == ["R_Al2O3_silicone", "R_AlN_silicone"]
    assert posterior.to_dict()["identifiability"] == [s.identifiability
                                                      for s in posterior.stages]
