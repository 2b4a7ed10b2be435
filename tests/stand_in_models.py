"""A closed-form stand-in forward model for the calibration's tests (issue 47's model-form
and marginalisation tests): what the calibration reads of a ForwardModel, no solves."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from itr_fv.materials import default_system
from itr_identify.inference.formulations import fractions_of

#: Four single-filler formulations of each filler: two stages of one parameter each.
FORMS = ("Al2O3-55", "Al2O3-58", "Al2O3-60", "Al2O3-65", "AlN-55", "AlN-58", "AlN-60", "AlN-62")


class StandInModel:
    """k_iso (W/(m K)) rises with the filler fraction and falls linearly in log10 of the
    interface resistance."""

    def __init__(self, formulation: str):
        self.fractions = fractions_of(formulation)
        self.parameters = tuple(f"R_{f}_silicone" for f in sorted(self.fractions))
        self.phi = sum(self.fractions.values())
        self.rve_scatter = 0.01
        self.carried_scatter = 0.0
        self.model_sd = 0.0
        self.settings = SimpleNamespace(prior_m2K_per_W=(1e-9, 1e-5), system=default_system())

    def predict(self, columns):
        k = 4.0 * self.phi
        for p in self.parameters:
            k = k - 0.4 * (np.log10(np.asarray(columns[p], dtype=float)) + 7.0)
        k = np.atleast_1d(k)
        return k, np.zeros(k.shape)
