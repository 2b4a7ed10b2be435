"""The discrepancy workflow's candidate effects as terms of the identification's own joint
model (issue 60; :mod:`itr_identify.inference.effect_terms`).

Eight effects, each with its parameters' physical range and the range's source:

========== =========== ===================================================================
key        kind        parameter (prior: uniform over the physical range)
========== =========== ===================================================================
matrix     matrix      ``ln k_<matrix>``: ln(1/2) - ln 2 instead of the stated sd
filler     ratio       ``ln filler_conductivity_factor``: ln 0.05 - 0
porosity   porosity    ``void_fraction``: 0 - 0.10 of the composite
fraction   ratio       ``filler_fraction_factor``: 0.8 - 1
spots      ratio       ``G_contact_W_per_K``: 0 - 3e-5 W/K per contact
tester     tester      ``R_contact_m2K_per_W``: 0 - 1e-4 m^2 K/W
batch      batch       ``batch_fraction_sd``: 0 - 0.01 (volume fraction)
film       thinning    ``film_end_fraction``: 0.60 - 0.80 (the film ``film_nm`` of the
                       model, stated at 55 vol%, reaches zero there)
========== =========== ===================================================================

A ratio effect's table is solved here: per formulation, the first replica of its forward
model (the identification's cheap RVE, the same particles) at :data:`RATIO_LOG10_R` and the
parameter's grid, the effect built with the library's hooks
(:mod:`itr_identify.discrepancy.effects`), over the base model at the same resistance. A
two-filler formulation is solved along the diagonal (both resistances equal): the ratio is
read at the fraction-weighted geometric mean of its two.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from itr_surrogate.engine import SolveEngine
from itr_surrogate.requests import RVEData, SolveRequest

from ..forward.model import ForwardModel
from ..inference.effect_terms import EffectParameter, JointEffect, RatioTable
from .effects import ContactSpots, FillerConductivity, FillerFraction

__all__ = [
    "JOINT_EFFECTS",
    "RATIO_GRIDS",
    "RATIO_LOG10_R",
    "joint_effects",
    "n_ratio_solves",
    "ratio_tables",
]

#: log10 R (m^2 K/W) at which a ratio table is solved: the resistance prior's 1e-9 - 1e-6
#: widened by the matrix conductivity's scaling (a factor 2 either way).
RATIO_LOG10_R = (-9.4, -8.5, -7.6, -6.7, -5.6)
#: The parameter grid of each ratio effect (the nominal value last or first).
RATIO_GRIDS = {"filler": tuple(math.log(v) for v in (0.05, 0.1, 0.2, 0.4, 0.7, 1.0)),
               "fraction": (0.8, 0.85, 0.9, 0.95, 1.0),
               "spots": (0.0, 1e-6, 3e-6, 1e-5, 3e-5)}
#: The library effects the joint model carries, in the report's order.
JOINT_EFFECTS = ("matrix", "filler", "porosity", "fraction", "spots", "tester", "batch",
                 "film")


def _parameters(key: str, matrix: str) -> tuple[EffectParameter, ...]:
    """The effect's parameters with their physical ranges and sources."""
    table = {
        "matrix": (f"ln k_{matrix}", math.log(0.5), math.log(2.0), 0.0,
                   ("unfilled silicones conduct 0.15 - 0.25 W/(m K) (handbooks), with "
                   "additives and coupling agents up to about 0.35: half to twice the "
                   "stated value covers them")),
        "filler": ("ln filler_conductivity_factor", math.log(0.05), 0.0, 0.0,
                   ("powders conduct below their bulk crystals: oxygen in AlN (70 - 285 "
                   "W/(m K)), impurities and grain boundaries in alumina (18 - 35 W/(m K)); "
                   "down to a twentieth of the stated value")),
        "porosity": ("void_fraction", 0.0, 0.10, 0.0,
                     ("air entrapped in mixed, undegassed silicone composites: 0 - 10 vol% "
                     "(typically 1 - 5 vol%)")),
        "fraction": ("filler_fraction_factor", 0.8, 1.0, 1.0,
                     ("filler lost in mixing and transfer, or the coupling agent counted as "
                     "filler: up to a fifth of the stated fraction")),
        "spots": ("G_contact_W_per_K", 0.0, 3e-5, 0.0,
                  ("a neck of radius a in a solid of conductivity k conducts about 2 a k: "
                  "0.1 - 0.5 um necks in alumina give 6e-6 - 3e-5 W/K")),
        "tester": ("R_contact_m2K_per_W", 0.0, 1e-4, 0.0,
                   ("bar-sample contacts of steady-state testers (ASTM D5470): 1e-6 - 1e-5 "
                   "m^2 K/W with paste, up to about 1e-4 dry")),
        "batch": ("batch_fraction_sd", 0.0, 0.01, 0.0,
                  ("a weighed mix misses its filler fraction by well under 1 vol% (1 vol% "
                  "at 60 vol% is 1.5 % of the filler's weight)")),
        "film": ("film_end_fraction", 0.60, 0.80, 0.80,
                 ("the film is squeezed out where the powder's random packing jams: above "
                 "0.60 (the table packs at 0.65) and below 0.80 (beyond the densest random "
                 "packing of lognormal spheres of this width, about 0.70 - 0.75)")),
    }
    name, lo, hi, nominal, source = table[key]
    return (EffectParameter(name, lo, hi, nominal, source),)


def _library(key: str, system) -> object:
    from .effects import by_key
    return by_key([key], system)[0]


def n_ratio_solves(n_formulations: int, keys: Sequence[str]) -> int:
    """Full solves :func:`ratio_tables` makes for ``n_formulations`` and effects ``keys``."""
    cols = 1 + sum(len(RATIO_GRIDS[k]) - 1 for k in set(keys) | ({"fraction"} if "batch"
                                                                 in keys else set())
                   if k in RATIO_GRIDS)
    return n_formulations * len(RATIO_LOG10_R) * cols


def ratio_tables(models: Mapping[str, ForwardModel], keys: Sequence[str], *,
                 engine: SolveEngine | None = None, seed: int = 0,
                 tick: Callable[[], None] | None = None
                 ) -> dict[str, dict[str, RatioTable]]:
    """Per ratio effect of ``keys`` (and the fraction's where ``batch`` is asked) and
    formulation its :class:`RatioTable` from full solves of the first replica (module
    notes); ``seed`` orders the particles a fraction loss removes."""
    need = [k for k in RATIO_GRIDS if k in keys or (k == "fraction" and "batch" in keys)]
    out: dict[str, dict[str, RatioTable]] = {k: {} for k in need}
    if not need:
        return out
    engine = engine or SolveEngine()
    fillers = {"filler": FillerConductivity(), "fraction": FillerFraction(),
               "spots": ContactSpots()}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for f, m in models.items():
            if not m.microstructures:
                raise ValueError(f"models: {f!r} has no packed replica")
            ms0 = m.microstructures[0]
            s = m.settings
            columns = [("base", None, ms0, lambda mat: mat)]
            for k in need:
                e = fillers[k]
                for x in RATIO_GRIDS[k][:-1] if k != "spots" else RATIO_GRIDS[k][1:]:
                    v = math.exp(x) if k == "filler" else x
                    ms = e.microstructure(ms0, v, seed=seed)
                    columns.append((k, x, ms, lambda mat, e=e, v=v: e.materials(mat, v)))
            reqs = [SolveRequest.for_materials(
                RVEData.of(ms), how(m.materials({p: 10.0 ** lr for p in m.parameters})),
                s.solver_tol, solver=s.solver, purpose="effect ratio", formulation=f,
                effect=k, effect_value=x)
                for k, x, ms, how in columns for lr in RATIO_LOG10_R]
            res = engine.solve(reqs, tick=tick)
            nr = len(RATIO_LOG10_R)
            kk = np.array([r.k_diagonal.mean() for r in res]).reshape(len(columns), nr)
            base = kk[0]
            for k in need:
                grid = RATIO_GRIDS[k]
                nominal = 0.0 if k == "spots" else grid[-1]
                tab = np.zeros((nr, len(grid)))
                for j, x in enumerate(grid):
                    if x != nominal:
                        i = next(i for i, c in enumerate(columns) if c[0] == k and c[1] == x)
                        tab[:, j] = np.log(kk[i] / base)
                out[k][f] = RatioTable(np.array(RATIO_LOG10_R), np.array(grid), tab)
    return out


def joint_effects(keys: Sequence[str], *, matrix: str,
                  ratios: Mapping[str, Mapping[str, RatioTable]] | None = None,
                  system=None, reference_fraction: float = 0.55) -> list[JointEffect]:
    """The :class:`JointEffect` of each key of ``keys`` (:data:`JOINT_EFFECTS`), a ratio
    effect's with its tables (:func:`ratio_tables`); ValueError naming an unknown key."""
    unknown = [k for k in keys if k not in JOINT_EFFECTS]
    if unknown:
        raise ValueError(f"effects: unknown effect {unknown[0]!r} (known: "
                         f"{', '.join(JOINT_EFFECTS)})")
    ratios = ratios or {}
    kinds = {"matrix": "matrix", "filler": "ratio", "porosity": "porosity",
             "fraction": "ratio", "spots": "ratio", "tester": "tester", "batch": "batch",
             "film": "thinning"}
    roles = {"fraction": "filler_factor", "porosity": "voids"}
    out = []
    for k in keys:
        lib = _library(k, system)
        table_of = "fraction" if k == "batch" else k
        out.append(JointEffect(
            k, lib.name if k != "film" else "silicone film between particles thinning "
            "with the fraction", kinds[k], _parameters(k, matrix), lib.signature,
            lib.separate_by, dict(ratios.get(table_of, {})) if k in (
                "filler", "fraction", "spots", "batch") else {},
            reference_fraction=reference_fraction, composition_role=roles.get(k)))
    return out


