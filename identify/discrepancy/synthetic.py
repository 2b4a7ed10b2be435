"""Measurements made with the full solver, a hidden effect switched on and replicate noise
added: the truth of the discrepancy workflow's recovery tests and studies."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence

import numpy as np

from ..forward.model import PARAMETRISATIONS, ForwardModel, ForwardSettings, full_solve
from ..inference.formulations import fractions_of
from ..inference.measurements import Measurements, read_measurements
from .effects import Effect
from .settings import DiscrepancySettings
from .steepening import Repacker

__all__ = ["synthetic_measurements", "paper_noise"]


def paper_noise(filler: str) -> float:
    """Root-mean-square replicate standard deviation of Table 3's single-filler
    formulations of ``filler``, W/(m K)."""
    t3 = read_measurements()
    var = [t3.variance(f) for f in t3.formulations if list(fractions_of(f)) == [filler]]
    if not var:
        raise ValueError(f"filler: Table 3 has no single-filler formulation of {filler!r}")
    return float(math.sqrt(np.mean(var)))


def synthetic_measurements(formulations: Sequence[str], resistances: dict[str, float], *,
                           effect: Effect | None = None, value: float | None = None,
                           settings: ForwardSettings | None = None, rves: int = 2,
                           rve_seed: int = 500, replicates: int = 4,
                           noise_sd: float | None = None,
                           thickness_mm: Sequence[float] | None = None,
                           modify: Callable | None = None,
                           extra: Sequence[tuple[Effect, float]] = (),
                           seed: int = 0) -> Measurements:
    """Measurements made with the full solver: every formulation solved on ``rves`` RVEs
    (packing seeds from ``rve_seed``, none of the forward models' own) with ``effect`` at
    ``value`` switched on, averaged, read through the effect's tester model at each
    thickness, plus Gaussian replicate noise of relative standard deviation
    ``relative_sd``.

    Parameters
    ----------
    formulations : names (``<filler>-<vol%>`` or Table 2)
    resistances : dict
        ``R_<f>_silicone`` values, m^2 K/W.
    effect, value : the hidden effect and its parameter (None: noise only).
    modify : callable, optional
        ``modify(microstructure, seed) -> microstructure``: a change outside the library
        (e.g. a particle shape) applied to every RVE.
    extra : sequence of (Effect, value)
        Further material or geometry effects switched on together with ``effect`` (a
        combination the library holds only one at a time).
    thickness_mm : sequence of float, optional
        Replicates cycle through these thicknesses (then the table has a thickness).
    seed : int
        Seed of the noise.
    """
    if (effect is None) != (value is None):
        raise ValueError("value: give an effect and its value together")
    s = settings or DiscrepancySettings().forward
    rng = np.random.default_rng(seed)
    if noise_sd is not None and not noise_sd >= 0:
        raise ValueError(f"noise_sd: expected >= 0 W/(m K), got {noise_sd!r}")
    values, thick = {}, {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for f in formulations:
            comp = fractions_of(f, s.system)
            model = ForwardModel(f, comp, PARAMETRISATIONS["gap"], s.with_(seed=rve_seed))
            mat = model.materials({p: resistances[p] for p in model.parameters})
            ks = []
            for r in range(rves):
                ms = model.pack(r)
                pack = Repacker.of(model, r)
                if modify is not None:
                    ms = modify(ms, rve_seed + r)
                m = mat
                for e, v in ([(effect, value)] if effect is not None else []) + list(extra):
                    ms = e.rebuild(pack, ms, v, seed=rve_seed + r)
                    m = e.materials_in(ms, m, v)
                ks.append(full_solve(ms, m, s.solver_tol, solver=s.solver).mean())
            k = float(np.mean(ks))
            t = (np.resize(np.asarray(thickness_mm, dtype=float), replicates) * 1e-3
                 if thickness_mm is not None else None)
            k_app = (effect.apparent(np.full(replicates, k), t, value)
                     if effect is not None and t is not None else np.full(replicates, k))
            sd = paper_noise(next(iter(comp))) if noise_sd is None else noise_sd
            values[f] = k_app + sd * rng.standard_normal(replicates)
            if t is not None:
                thick[f] = t
    what = ", ".join(f"{e.name} = {v:g}" for e, v in
                     ([(effect, value)] if effect is not None else []) + list(extra))
    what = what or "noise only"
    return Measurements(values, f"synthetic ({what})", thick or None)
