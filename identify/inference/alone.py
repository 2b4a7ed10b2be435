"""Each formulation fitted alone: do the formulations agree on their resistance?

Every single-filler formulation of a parametrisation with one parameter per filler (gap:
``R_<filler>_silicone``) is calibrated on its own replicates
(:func:`~itr_identify.inference.calibrate.calibrate` with that one model): its best value,
90 % interval and flag. Formulations that share a filler should agree within their
intervals where the model holds; a trend with the fraction is a model-form error that the
joint fit spreads over all of them (``itr_identify.inference.misfit``).
"""

from __future__ import annotations

from collections.abc import Mapping

from ..forward.model import ForwardModel
from .calibrate import calibrate
from .measurements import Measurements

__all__ = ["fit_alone"]


def _only(measurements: Measurements, name: str) -> Measurements:
    return Measurements({name: measurements.values[name]}, f"{measurements.source}: {name}")


def fit_alone(models: Mapping[str, ForwardModel], measurements: Measurements, *,
              grid_points: int = 121, seed: int = 0,
              prior: tuple[float, float] | None = None) -> list[dict]:
    """Per single-filler formulation with one parameter: ``formulation``, ``parameter``,
    ``fraction`` (filler volume fraction), ``best``, ``interval_90`` (m^2 K/W) and
    ``determination``; formulations with more parameters than one are left out (one
    measured mean cannot determine two); ``prior``: the resistance prior's range, m^2 K/W
    (default: the models' box; :func:`~.calibrate.calibrate`)."""
    rows = []
    for name, m in models.items():
        if len(m.fractions) != 1 or len(m.parameters) != 1:
            continue
        (p,) = m.parameters
        post = calibrate({name: m}, _only(measurements, name), grid_points=grid_points,
                         seed=seed, prior=prior)
        rows.append({"formulation": name, "parameter": p,
                     "fraction": float(sum(m.fractions.values())), "best": post.best[p],
                     "interval_90": list(post.interval(p)),
                     "determination": post.determination(p)})
    return rows
