"""The posterior predictive of formulations: what an identification says about a sample not
measured (``itr predict``, ``itr design``).

An identification's joint posterior (:mod:`.joint`) is a set of draws over the resistances,
the uncertain inputs, the shared correction terms and the model form. A formulation that was
not measured is predicted by evaluating its own forward model, tabulated as the measured ones
are (:class:`~.joint.Tabulated`), at every draw:

- the resistances, conductivities and film of the draw, as for a measured formulation;
- its filler system's shared correction offset and model-form slope where the system was
  identified (the draw's own ``offset_<system>``, ``slope_<system>``; the slope's ``z`` from the
  identified system's mean filler fraction); for a filler system that was not measured, both
  drawn from their standard normal priors, scaled by the draw's model-form sds;
- then the noise of a measured mean of ``replicates`` samples: the pooled relative replicate sd
  of the identification's table over sqrt(``replicates``), the RVE scatter of its system (the
  identified system's pooled one, else the model's own), the model level's own sd, the
  surrogate's error bound and the pooled packing sd, each drawn once per draw;
- and the formulation's own misfit: where the identification's fit fails its chi-square test
  (Table 3's does: chi-square 77 on 9 degrees of freedom with the model form), the measured
  formulations scatter about the model by more than every term above allows, and a new
  formulation will too. :func:`formulation_sd` estimates that scatter from the
  identification's own residuals (the relative sd ``s`` that brings their chi-square to its
  degrees of freedom, the measured formulations less the resistances; 0 where the fit
  passes), and the prediction adds ``(s k)^2`` to its variance.

The equal-tailed interval of those values is the predictive interval of the measured mean.

:class:`PredictiveRecord` is what an identification writes for this (``identified.json``'s
``"predictive"`` block beside ``posterior_<parametrisation>.parquet``, the draws); it is read
back by :func:`read_record`.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .effect_terms import JointEffect
from .joint import FRACTION_UNIT, JointLikelihood, JointSpace, Tabulated, system_means

__all__ = ["PredictiveRecord", "Prediction", "record_of", "write_record", "read_record",
           "predict", "model_draws", "measured_draws", "with_draws", "formulation_sd",
           "RECORD_DRAWS",
           "DEFAULT_REPLICATES", "DEFAULT_LEVEL"]

#: Equal-weight draws of the joint posterior kept for prediction (by weight, counted).
RECORD_DRAWS = 20000
#: Samples per formulation whose measured mean a prediction is of, by default (Table 3's).
DEFAULT_REPLICATES = 4
#: The predictive interval's level by default.
DEFAULT_LEVEL = 0.9
#: The record's format (read back only by this version or a later one).
RECORD_FORMAT = 1


@dataclass(frozen=True, eq=False)
class PredictiveRecord:
    """What the prediction of an unmeasured formulation needs of an identification (frozen).

    Attributes
    ----------
    parametrisation : str
        ``gap`` or ``area``.
    space : dict
        The joint space: ``names``, ``kinds``, ``a``, ``b``, ``held``, ``matrix``.
    group_means : dict
        Per identified filler system (fillers joined by '-') its formulations' mean total
        filler fraction (the model-form slope's centre).
    scatter : dict
        Per identified filler system its pooled relative RVE scatter.
    replicate_sd : float
        Relative sd of one sample about its formulation's mean, pooled over the table.
    quoted : dict
        The resistances quoted (posterior medians of ln R), m^2 K/W.
    settings : dict
        The forward settings the models were built with (``ForwardSettings.to_dict``) and
        ``fidelity``, the level's name.
    draws : ndarray
        (S, D) equal-weight draws over ``space["names"]``.
    effect : str or None
        The effect fitted inside the identification (:mod:`.effect_terms`), if any.
    measured : tuple of str
        The formulations the identification was fitted on.
    formulation_sd : float
        Relative sd of a formulation's own misfit (:func:`formulation_sd`).
    """

    parametrisation: str
    space: dict
    group_means: dict
    scatter: dict
    replicate_sd: float
    quoted: dict
    settings: dict
    draws: np.ndarray
    effect: str | None = None
    measured: tuple[str, ...] = ()
    formulation_sd: float = 0.0

    @property
    def resistances(self) -> list[str]:
        """The flat names of the resistances the identification sampled."""
        return _resistances(self.space["names"])

    def to_dict(self, draws_file: str, draws_sha256: str) -> dict[str, Any]:
        """The JSON block (the draws in ``draws_file``)."""
        return {"format": RECORD_FORMAT, "parametrisation": self.parametrisation,
                "space": self.space, "group_means": self.group_means,
                "scatter": self.scatter, "replicate_sd": self.replicate_sd,
                "formulation_sd": self.formulation_sd,
                "quoted": self.quoted, "settings": self.settings, "effect": self.effect,
                "measured": list(self.measured), "draws_file": draws_file,
                "draws_sha256": draws_sha256, "draws": int(self.draws.shape[0])}


def _resistances(names) -> list[str]:
    return [n[len("log10 "):] for n in names if n.startswith("log10 ")]


def _replicate_sd(measurements) -> float:
    """Relative sd of one sample about its formulation's mean, pooled (dof-weighted)."""
    ss, dof = 0.0, 0
    for f in measurements.formulations:
        v = np.asarray(measurements.values[f], dtype=float)
        if v.size > 1:
            ss += float(((v / v.mean() - 1) ** 2).sum())
            dof += v.size - 1
    return math.sqrt(ss / dof) if dof else 0.0


def record_of(ident, *, draws: int = RECORD_DRAWS, joint=None,
              likelihood: JointLikelihood | None = None) -> PredictiveRecord:
    """The :class:`PredictiveRecord` of an identification with a joint posterior
    (:class:`~.pipeline.Identification`), or of another joint posterior on its models
    (``joint`` and its ``likelihood``: the identification with an effect, whose key the
    record then carries and whose resistances are quoted at the draws' medians of ln R);
    ValueError without one."""
    jp = joint if joint is not None else ident.joint
    if jp is None:
        raise ValueError("ident: the prediction needs the joint posterior (identify with "
                         "joint=True)")
    lik = likelihood if likelihood is not None else ident.likelihood()
    sp = lik.space
    rows = jp.counted_rows(draws, seed=jp.seed + 3)
    samples = np.asarray(jp.samples[rows], dtype=float)
    effect = sp.effect.key if sp.effect is not None else None
    quoted = dict(ident.quoted) if joint is None else {
        r: float(10 ** np.median(samples[:, sp.names.index(f"log10 {r}")]))
        for r in _resistances(sp.names)}
    from ..forward.fidelity import fidelity_name

    settings = {**ident.settings.to_dict(), "fidelity": fidelity_name(ident.settings.faithful)}
    if sp.effect is not None:
        settings["effect_reference_fraction"] = sp.effect.reference_fraction
    return PredictiveRecord(
        ident.parametrisation,
        {"names": list(sp.names), "kinds": list(sp.kinds), "a": list(sp.a), "b": list(sp.b),
         "held": dict(sp.held), "matrix": sp.matrix},
        system_means(lik.tables),
        {g: float(s) for g, s in lik.scatter.items()},
        _replicate_sd(ident.measurements), quoted, settings, samples, effect,
        tuple(ident.measurements.formulations),
        formulation_sd(lik, samples[:: max(1, samples.shape[0] // MISFIT_DRAWS)],
                       fitted=len(_resistances(sp.names))))


#: Posterior draws over which :func:`formulation_sd` averages the model's k and variance.
MISFIT_DRAWS = 2000


def formulation_sd(likelihood: JointLikelihood, theta: np.ndarray, *, fitted: int) -> float:
    """The relative sd ``s`` of the measured formulations' own misfit (module notes): with
    each formulation's model k and variance averaged over the draws ``theta`` (the measured
    mean's standard error, RVE scatter, level, error bound, packing and the model form as
    the likelihood has them), the ``s`` at which ``sum (m - k)^2 / (v + (s k)^2)`` equals
    the formulations less ``fitted`` (at least one); 0 where it is already below."""
    k, v = likelihood.predictive(theta)
    mean = np.array([likelihood.data[f][0] for f in likelihood.order])
    kbar, vbar = k.mean(axis=1), v.mean(axis=1)
    r2 = (mean - kbar) ** 2
    dof = max(len(mean) - fitted, 1)
    chi2 = lambda x: float(np.sum(r2 / (vbar + (x * kbar) ** 2)))  # noqa: E731
    if chi2(0.0) <= dof:
        return 0.0
    lo, hi = 0.0, 1.0
    for _ in range(60):                       # chi2 falls monotonically in s
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if chi2(mid) > dof else (lo, mid)
    return 0.5 * (lo + hi)


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def write_record(record: PredictiveRecord, folder: str | Path) -> tuple[dict, Path]:
    """Write the draws to ``folder/posterior_<parametrisation>.parquet`` (atomically);
    returns the JSON block and the file's path."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from itr_fv.io import atomic_path

    suffix = f"_{record.effect}" if record.effect else ""
    path = Path(folder) / f"posterior_{record.parametrisation}{suffix}.parquet"
    table = pa.table({n: record.draws[:, i] for i, n in enumerate(record.space["names"])})
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)
    return record.to_dict(path.name, _sha256(path)), path


def read_record(path: str | Path, parametrisation: str | None = None, *,
                effect: bool = True) -> PredictiveRecord:
    """The record of ``identified.json`` at ``path``: with ``effect``, the identification
    with the effect the discrepancy workflow named (or was asked for) where the file holds
    one; else the parametrisation its headline quotes (or ``parametrisation``). ValueError
    naming ``identified`` for a file that is not one, holds no record (written before ``itr
    predict``) or whose draws are missing or changed."""
    import pyarrow.parquet as pq

    path = Path(path)
    block = _block(_identified(path), parametrisation, effect=effect, path=path)
    draws_path = path.parent / block["draws_file"]
    if not draws_path.is_file():
        raise ValueError(f"identified: the posterior draws {draws_path} are missing (keep "
                         "them beside identified.json)")
    if _sha256(draws_path) != block["draws_sha256"]:
        raise ValueError(f"identified: {draws_path} is not the file identified.json was "
                         "written with (its sha256 differs)")
    table = pq.read_table(draws_path)
    names = block["space"]["names"]
    draws = np.column_stack([table.column(n).to_numpy() for n in names])
    return PredictiveRecord(block["parametrisation"], block["space"], block["group_means"],
                            block["scatter"], float(block["replicate_sd"]), block["quoted"],
                            block["settings"], draws, block.get("effect"),
                            tuple(block.get("measured", ())),
                            float(block.get("formulation_sd", 0.0)))


def _identified(path: Path) -> dict:
    from itr_fv.materials.resistance_sources import read_identified

    return read_identified(path, argument="identified")


def _block(data: dict, parametrisation: str | None, *, effect: bool, path: Path) -> dict:
    """The record's JSON block (module notes)."""
    with_effect = (data.get("discrepancy") or {}).get("predictive")
    if effect and with_effect is not None and parametrisation in (None, "gap"):
        return with_effect
    par = parametrisation or _quoted_parametrisation(data)
    entry = data.get(par)
    block = entry.get("predictive") if isinstance(entry, dict) else None
    if block is None:
        have = [p for p in ("gap", "area") if isinstance(data.get(p), dict)
                and "predictive" in data[p]]
        raise ValueError(f"identified: {path} holds no posterior record for the {par} "
                         "parametrisation" + (f" (it has {', '.join(have)})" if have else
                                              "; identify again with this version"))
    return block


def _quoted_parametrisation(data: Mapping) -> str:
    """The parametrisation the headline quotes (else the only one there)."""
    head = data.get("headline") or {}
    quote = head.get("quote") if isinstance(head, dict) else None
    if quote in ("gap", "area"):
        return quote
    have = [p for p in ("gap", "area") if isinstance(data.get(p), dict)]
    if len(have) == 1:
        return have[0]
    return "gap"


@dataclass(frozen=True)
class Prediction:
    """One formulation's predicted measured mean (frozen).

    Attributes
    ----------
    formulation : str
    median : float
        W/(m K).
    interval : (float, float)
        The equal-tailed ``level`` predictive interval, W/(m K).
    level : float
    model_median : float
        The model's k alone (no measurement noise), median over the draws, W/(m K).
    replicates : int
        Samples whose mean is predicted.
    system_identified : bool
        Whether its filler system was measured in the identification.
    draws : ndarray
        The predictive draws of the measured mean, W/(m K).
    """

    formulation: str
    median: float
    interval: tuple[float, float]
    level: float
    model_median: float
    replicates: int
    system_identified: bool
    draws: np.ndarray

    def probability_above(self, target: float) -> float:
        """The predictive probability that the measured mean reaches ``target``."""
        return float(np.mean(self.draws >= target))

    def to_dict(self) -> dict[str, Any]:
        return {"formulation": self.formulation, "median": self.median,
                "interval": list(self.interval), "level": self.level,
                "model_median": self.model_median, "replicates": self.replicates,
                "system_identified": self.system_identified, "unit": "W/(m K)"}


def _space_for(record: PredictiveRecord, tables: Mapping[str, Tabulated],
               effect: JointEffect | None = None) -> tuple[JointSpace, list[str]]:
    """The record's space with the groups of ``tables`` (``z`` about the identified means)
    and, for a filler system not identified, its offset and slope added; returns it and the
    names added (drawn from their priors)."""
    sp = record.space
    names, kinds = list(sp["names"]), list(sp["kinds"])
    a, b = list(sp["a"]), list(sp["b"])
    form = "tau_offset" in names or "tau_offset" in sp["held"]
    groups, added = {}, []
    for f, t in tables.items():
        g, total = t.group, sum(t.fractions.values())
        centre = record.group_means.get(g, total)
        groups[f] = (g, (total - centre) / FRACTION_UNIT)
        # the shared correction's offset wherever the model carries one, the slope with
        # the model form
        wanted = ([f"offset_{g}"] if form or t.system else []) + (
            [f"slope_{g}"] if form else [])
        for n in wanted:
            if n not in names and n not in sp["held"] and n not in added:
                added.append(n)
    for n in added:
        names.append(n)
        kinds.append("normal")
        a.append(0.0)
        b.append(1.0)
    space = JointSpace(tuple(names), tuple(kinds), tuple(a), tuple(b), dict(sp["held"]),
                       groups, sp["matrix"], effect)
    return space, added


def _checked(record: PredictiveRecord, tables: Mapping[str, Tabulated], replicates: int,
             level: float | None) -> None:
    if isinstance(replicates, bool) or not isinstance(replicates, int) or replicates < 1:
        raise ValueError(f"replicates: expected a whole number >= 1, got {replicates!r}")
    if level is not None and not 0 < level < 1:
        raise ValueError(f"level: expected a value in (0, 1), got {level!r}")
    for f, t in tables.items():
        missing = [p for p in t.parameters if p not in record.resistances]
        if missing:
            raise ValueError(f"formulations: {f} needs {', '.join(missing)}, which the "
                             "identification did not identify (measure a formulation of "
                             "that filler)")


def model_draws(record: PredictiveRecord, tables: Mapping[str, Tabulated], *, seed: int = 0,
                effect: JointEffect | None = None, matrix_conductivity: float | None = None
                ) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Each formulation's model k at every draw of ``record`` and its variance without the
    measurement's (module notes): (order, k (F, S), variance (F, S)), W/(m K) and
    (W/(m K))^2; the same draw in every column, so that formulations can be compared or
    interpolated draw by draw. A record of an identification with an effect needs the
    effect's terms for ``tables`` (``effect``, with their ratio tables where it has them)
    and the matrix's nominal conductivity, W/(m K)."""
    _checked(record, tables, 1, None)
    if (record.effect is None) != (effect is None) or (
            effect is not None and effect.key != record.effect):
        raise ValueError(f"effect: the record's identification carries "
                         f"{record.effect or 'no effect'}; got "
                         f"{effect.key if effect is not None else 'none'}")
    space, added = _space_for(record, tables, effect)
    rng = np.random.default_rng(seed)
    n = record.draws.shape[0]
    theta = np.column_stack([record.draws, rng.standard_normal((n, len(added)))]) \
        if added else record.draws
    lik = JointLikelihood.predictor(tables, space, scatter=_scatter(record, tables),
                                    matrix_conductivity=matrix_conductivity)
    k, v = lik.predictive_of_model(space.columns(theta))
    return list(lik.order), k, v


def measured_draws(record: PredictiveRecord, k: np.ndarray, v: np.ndarray, *,
                   replicates: int, rng: np.random.Generator) -> np.ndarray:
    """Draws of a measured mean of ``replicates`` samples about the model's ``k`` (any
    shape) with the model variance ``v``: the record's pooled replicate sd and its
    formulation misfit (:func:`formulation_sd`) added."""
    se2 = (record.replicate_sd * k) ** 2 / replicates + (record.formulation_sd * k) ** 2
    return k + np.sqrt(v + se2) * rng.standard_normal(k.shape)


def predict(record: PredictiveRecord, tables: Mapping[str, Tabulated], *,
            replicates: int = DEFAULT_REPLICATES, level: float = DEFAULT_LEVEL,
            seed: int = 0, effect: JointEffect | None = None,
            matrix_conductivity: float | None = None) -> dict[str, Prediction]:
    """Each formulation of ``tables`` (its forward model tabulated, :class:`~.joint.Tabulated`)
    predicted at every draw of ``record`` (module notes).

    Parameters
    ----------
    record : PredictiveRecord
    tables : mapping of formulation to Tabulated
        Built with the record's settings; their resistances must be among the record's.
    replicates : int
        Samples per measured mean predicted (>= 1).
    level : float
        Interval level in (0, 1).
    seed : int
        Seed of the prior draws of unidentified systems' terms and of the noise.
    effect, matrix_conductivity : JointEffect, float
        A record with an effect: its terms for ``tables`` and the matrix's nominal
        conductivity, W/(m K) (:func:`model_draws`).

    Returns
    -------
    dict of formulation to Prediction
    """
    _checked(record, tables, replicates, level)
    order, k, v = model_draws(record, tables, seed=seed, effect=effect,
                              matrix_conductivity=matrix_conductivity)
    y = measured_draws(record, k, v, replicates=replicates,
                       rng=np.random.default_rng(seed + 1))
    a = (1 - level) / 2
    out = {}
    for i, f in enumerate(order):
        lo, med, hi = np.quantile(y[i], [a, 0.5, 1 - a])
        out[f] = Prediction(f, float(med), (float(lo), float(hi)), level,
                            float(np.median(k[i])), replicates,
                            tables[f].group in record.group_means, y[i])
    return out


def _scatter(record: PredictiveRecord, tables: Mapping[str, Tabulated]) -> dict[str, float]:
    """Per filler system of ``tables`` its RVE scatter: the identified system's pooled one,
    else the root mean square of its tables' own."""
    out = dict(record.scatter)
    by: dict[str, list[float]] = {}
    for t in tables.values():
        if t.group not in out:
            by.setdefault(t.group, []).append(t.rve_scatter)
    out.update({g: math.sqrt(float(np.mean(np.square(v)))) for g, v in by.items()})
    return out


def with_draws(record: PredictiveRecord, draws: np.ndarray) -> PredictiveRecord:
    """A copy of ``record`` over other draws (a subset, for tests and studies)."""
    return replace(record, draws=np.asarray(draws, dtype=float))
