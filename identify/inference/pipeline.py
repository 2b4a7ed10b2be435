"""Identification of one measurement table under one parametrisation, stage by stage.

:func:`identify` packs the RVEs and fits the reduced bases of the single-filler formulations
over the whole prior box and calibrates them; then, as the paper's hierarchy, the two-filler
formulations hold the single-filler parameters at a central point of their posterior
(:meth:`~itr_identify.inference.calibrate.Posterior.central`, not the best grid point, which
can lie far out on a ridge the single-filler data leave) and their reduced bases vary only
their own contact parameter (none under the gap parametrisation). The earlier stages'
uncertainty enters a two-filler formulation's likelihood as the relative spread of its k_iso
over :data:`CARRIED_DRAWS` posterior draws (full solves). Each group of models is calibrated
once, its replicas are solved at the best values (the *anchor*: the replica factor and the
RVE scatter there, see :meth:`itr_identify.forward.model.ForwardModel.anchor_at`) and it is
calibrated again; the last of these calibrations (over every model) is the result, and the
paper's screening runs on the same models. Formulation names give the composition
(:func:`itr_identify.inference.formulations.fractions_of`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from itr_fv.io import counted
from itr_surrogate.engine import SolveEngine

from ..forward.model import PARAMETRISATIONS, ForwardModel, ForwardSettings, Parametrisation
from .alone import fit_alone
from .calibrate import Posterior, calibrate
from .formulations import fractions_of
from .free_inputs_fit import fit_with_inputs_free
from .joint import JointPosterior
from .joint_fit import (
    alone_agreement,
    as_posterior,
    floor_sensitivity,
    joint_fit_record,
    joint_note,
    likelihood_of,
    run_joint,
)
from .joint_fit import inputs_record as inputs_record_of
from .measurements import Measurements
from .misfit import misfit_note, with_model_form
from .nuisance import (
    DEFAULT_FILM,
    FilmPrior,
    InputPrior,
    default_priors,
    elasticities,
    marginalise,
)
from .priors import DEFAULT_MODEL_FORM, DEFAULT_RESISTANCE, ModelFormPrior, ResistancePrior
from .screen import ScreenResult, hierarchical_screen

__all__ = [
    "CARRIED_DRAWS",
    "Identification",
    "default_inputs",
    "film_is_zero",
    "identify",
    "marginalised_inputs",
]

#: Draws of the earlier stages' posterior whose spread a later stage's likelihood carries.
CARRIED_DRAWS = 6


@dataclass
class Identification:
    """Forward models, posterior and screening of one parametrisation."""

    parametrisation: str
    settings: ForwardSettings
    models: dict[str, ForwardModel]
    posterior: Posterior
    screening: list[ScreenResult]
    seconds: dict[str, float] = field(default_factory=dict)
    measurements: Measurements | None = None
    fidelity_rounds: list[dict] = field(default_factory=list)
    fit: dict = field(default_factory=dict)
    inputs: dict = field(default_factory=dict)
    alone: list[dict] = field(default_factory=list)
    nominal: Posterior | None = None
    joint: JointPosterior | None = None
    priors: dict = field(default_factory=dict)
    model_form: ModelFormPrior = DEFAULT_MODEL_FORM

    def likelihood(self, *, model_form: ModelFormPrior | None = None, effect=None):
        """The joint posterior's likelihood (:func:`~.joint_fit.likelihood_of` of the
        models, measurements, priors and elasticities of this identification); with
        ``model_form`` in place of its own, and a candidate ``effect``'s terms
        (:mod:`.effect_terms`)."""
        from .joint_fit import likelihood_of

        return likelihood_of(self.models, self.measurements, self.priors,
                             self.inputs.get("elasticity", {}),
                             resistance=self.resistance_prior,
                             model_form=self.model_form if model_form is None else model_form,
                             effect=effect)

    def leave_one_out(self, *, seed: int = 0) -> list[dict]:
        """Each formulation predicted from the others (the joint posterior without the
        model-form term, reweighted: :func:`~.joint_fit.leave_one_out_joint`)."""
        from .joint_fit import leave_one_out_joint, run_joint
        from .priors import ModelFormPrior

        jp, lik = run_joint(self.models, self.measurements, self.priors,
                            self.inputs.get("elasticity", {}),
                            resistance=self.resistance_prior,
                            model_form=ModelFormPrior(on=False), seed=seed,
                            marginals=False)
        return leave_one_out_joint(jp, lik, seed=seed)

    @property
    def quoted(self) -> dict[str, float]:
        """The values quoted and validated by full solves, m^2 K/W: the joint posterior's
        points (medians of ln R) where it ran, else the calibration's at the nominal inputs."""
        return dict(self.posterior.best if self.joint is not None else self.at_nominal.best)

    @property
    def resistance_prior(self):
        """The joint posterior's resistance prior (its range is the posterior's)."""
        from .priors import ResistancePrior

        return ResistancePrior(*self.posterior.prior)

    @property
    def n_parameters(self) -> int:
        return len(self.posterior.names)

    @property
    def at_nominal(self) -> Posterior:
        """The calibration at the nominal inputs (the models as built): where the models are
        checked against full solves and the measurements (validation, residuals, the fit's
        test). :attr:`posterior` is the marginal one where inputs were marginalised; its
        best values are the marginal's, which the nominal models need not reproduce."""
        return self.posterior if self.nominal is None else self.nominal

    def residuals(self, *, model_form: bool = False) -> dict[str, tuple[float, float, float]]:
        """Per formulation at the best values: (measured mean, model k_iso, likelihood
        variance), W/(m K) and (W/(m K))^2; the variance without the model-form term
        (the fit's test) unless ``model_form``."""
        from .calibrate import residuals

        post = self.at_nominal
        return residuals(self.models, self.measurements, post.best,
                         post.model_form_sd if model_form else 0.0)

    def held(self) -> dict[str, dict]:
        """Per two-filler formulation: the single-filler parameters it is held at
        (``held_at``, m^2 K/W: the earlier posterior's central point) and the relative
        spread of its k_iso over that posterior (``carried_scatter``)."""
        return {f: {"held_at": dict(m.fixed), "carried_scatter": m.carried_scatter}
                for f, m in self.models.items() if m.fixed}

    def chi_square(self) -> float:
        """Sum over formulations of (measured - model)^2 / variance at the best values,
        the variance without the model-form term (the fit's test)."""
        return float(sum((m - k) ** 2 / v for m, k, v in self.residuals().values()))

    def bic(self) -> float:
        """Bayesian information criterion: -2 ln L_best + P ln(n formulations), the
        likelihood without the model-form term (parametrisations compared on the same
        stated errors)."""
        ll = self.fit.get("log_likelihood_best", self.posterior.log_likelihood_best())
        return -2 * ll + self.n_parameters * math.log(len(self.models))



def identify(measurements: Measurements, parametrisation: str = "gap", *,
             settings: ForwardSettings | None = None, grid_points: int = 121, seed: int = 0,
             reuse: Mapping[str, ForwardModel] | None = None, progress: bool = False,
             echo: Callable[[str], None] = print,
             engine: SolveEngine | None = None,
             inputs: Mapping[str, InputPrior | FilmPrior] | None = None,
             resistance: ResistancePrior = DEFAULT_RESISTANCE,
             model_form: ModelFormPrior = DEFAULT_MODEL_FORM,
             joint: bool = True, floor_check: bool = True) -> Identification:
    """Calibrate and screen the interface parameters of one parametrisation.

    Parameters
    ----------
    measurements : Measurements
        One entry per formulation (two replicates at least); names give the composition.
    parametrisation : {"gap", "area"}
        See :mod:`itr_identify.forward.model`.
    settings : ForwardSettings, optional
        RVE and surrogate settings (default ``ForwardSettings()``).
    grid_points : int
        Posterior grid points per parameter.
    seed : int
        Seed of the posterior sampling.
    reuse : mapping of formulation to ForwardModel, optional
        Built single-filler models of an earlier call with the same settings and
        parametrisation (they do not depend on the measurements); the others are built.
    progress : bool
        Progress bars (reduced-basis full solves).
    echo : callable
        Where one-line progress messages go.
    engine : SolveEngine, optional
        Where every full solve runs and is kept (:mod:`itr_surrogate.engine`; default:
        this process, nothing kept).
    inputs : mapping of name to InputPrior or FilmPrior, optional
        The inputs to marginalise (:mod:`itr_identify.inference.nuisance`; default
        :func:`default_inputs`: the conductivities of the matrix and every filler, and the
        film where the settings state none; ``{}`` or a zero sd holds an input at its
        nominal value; a film prior is dropped under the per-area contact model, which has
        no film).
    resistance, model_form : ResistancePrior, ModelFormPrior
        The joint posterior's priors (:mod:`itr_identify.inference.priors`).
    joint : bool
        The posterior over the resistances and every uncertain input sampled at once
        (:mod:`itr_identify.inference.joint`; under the gap parametrisation the two-filler
        formulations' reduced bases then vary both resistances); False: the earlier
        quadrature over the inputs (:func:`~itr_identify.inference.nuisance.marginalise`)
        with a point-estimated model-form error.
    floor_check : bool
        With ``joint``: how the point and interval move when the resistance prior's floor
        moves a decade (one more, shorter run; :func:`~.joint_fit.floor_sensitivity`).
    """
    par, settings = _checked_arguments(parametrisation, settings, resistance)
    system = settings.system
    comps = {f: fractions_of(f, system) for f in measurements.formulations}
    priors = marginalised_inputs(
        default_inputs(sorted({system.matrix, *(x for f in comps.values() for x in f)}),
                       settings)
        if inputs is None else inputs, contact=par.contact, settings=settings)
    # every grid calibration (at the nominal inputs, alone, per input node) over the one
    # resistance prior that the joint posterior also has
    run = _Run(parametrisation, par, settings, measurements, comps,
               cal={"grid_points": grid_points, "seed": seed,
                    "prior": (resistance.low, resistance.high)},
               faithful=settings.faithful if par.name == "gap" else None, progress=progress,
               echo=echo, engine=engine)
    models, post, seconds = _single_filler_stage(run, reuse)
    post, more = _two_filler_stage(run, models, post,
                                   vary_both=joint and par.contact == "gap")
    seconds.update(more)
    if joint:
        return _joint_identification(run, models, post, priors, seconds,
                                     resistance=resistance, model_form=model_form,
                                     floor_check=floor_check)
    return _quadrature_identification(run, models, post, priors, seconds)


@dataclass(frozen=True, eq=False)
class _Run:
    """What every stage of :func:`identify` reads: its arguments, the formulations'
    compositions, the grid calibrations' keywords (``cal``: grid points, seed, prior), the
    faithful level of runtime corrections (None under the area parametrisation) and the
    correction rounds so far (``rounds``, which :func:`_corrected` appends to)."""

    parametrisation: str
    par: Parametrisation
    settings: ForwardSettings
    measurements: Measurements
    comps: dict[str, dict[str, float]]
    cal: dict[str, Any]
    faithful: Any
    progress: bool
    echo: Callable[[str], None]
    engine: SolveEngine | None
    rounds: list[dict] = field(default_factory=list)

    @property
    def singles(self) -> list[str]:
        """The single-filler formulations, in measurement order."""
        return [f for f in self.comps if len(self.comps[f]) == 1]

    @property
    def multis(self) -> list[str]:
        """The formulations of two fillers or more, in measurement order."""
        return [f for f in self.comps if len(self.comps[f]) > 1]

    def build(self, fixed_of: Mapping[str, dict[str, float]]) -> dict[str, ForwardModel]:
        """The models of ``fixed_of`` (formulation -> parameters held), built
        (:func:`_build_all`)."""
        return _build_all(fixed_of, self.comps, self.par, self.settings, self.progress,
                          self.echo, self.engine)

    def corrected(self, models: dict[str, ForwardModel], names: list[str],
                  post: Posterior) -> Posterior:
        """:func:`_corrected` of the models ``names`` that carry no shipped correction."""
        return _corrected(models, _runtime(models, names, self.echo), self.measurements,
                          post, self.faithful, self.cal, self.rounds, self.echo)


def _checked_arguments(parametrisation: str, settings: ForwardSettings | None,
                       resistance: ResistancePrior
                       ) -> tuple[Parametrisation, ForwardSettings]:
    """The parametrisation named and the settings (default ``ForwardSettings()``);
    ValueError for an unknown parametrisation or a resistance prior beyond the settings'
    reduced-basis box."""
    if parametrisation not in PARAMETRISATIONS:
        raise ValueError(f"parametrisation: expected one of {sorted(PARAMETRISATIONS)}, got "
                         f"{parametrisation!r}")
    settings = settings or ForwardSettings()
    lo, hi = settings.prior_m2K_per_W
    if not (lo <= resistance.low and resistance.high <= hi):
        raise ValueError(f"resistance: the prior {resistance.low:g} - {resistance.high:g} "
                         f"m^2 K/W reaches beyond the reduced bases' box {lo:g} - {hi:g} "
                         "(settings.prior_m2K_per_W)")
    return PARAMETRISATIONS[parametrisation], settings


def _single_filler_stage(run: _Run, reuse: Mapping[str, ForwardModel] | None
                         ) -> tuple[dict[str, ForwardModel], Posterior | None,
                                    dict[str, float]]:
    """The single-filler models (those of ``reuse`` built with the same settings and
    parametrisation and holding nothing, the others built), calibrated with their replicas
    anchored at the best point, then corrected on faithful RVEs where the level asks;
    returns the models, the posterior (None without a single-filler formulation) and the
    seconds of each step."""
    par, singles, echo = run.par, run.singles, run.echo
    t0 = time.perf_counter()
    models: dict[str, ForwardModel] = {}
    todo = {}
    for f in singles:
        old = (reuse or {}).get(f)
        if (old is not None and old.settings == run.settings and old.parametrisation == par
                and not old.fixed):
            models[f] = old
        else:
            todo[f] = {}
    if todo:
        echo(f"  {par.name}: single-filler models ({len(todo)}: RVEs, reduced bases, "
             "RVE scatter)")
    models.update(run.build(todo))
    models = {f: models[f] for f in singles}
    seconds = {"single-filler models": time.perf_counter() - t0}
    t = time.perf_counter()
    if singles:
        echo(f"  {par.name}: calibration of {counted(len(singles), 'single-filler formulation')}"
             ", replicas solved at the best point")
    post = _anchored(models, singles, run.measurements, run.cal) if singles else None
    seconds["single-filler calibration and anchors"] = time.perf_counter() - t
    if post is not None and run.faithful is not None:
        t = time.perf_counter()
        echo(f"  {par.name}: faithful corrections of the single-filler models "
             f"({run.faithful.name})")
        post = run.corrected(models, singles, post)
        seconds["single-filler faithful corrections"] = time.perf_counter() - t
    return models, post, seconds


def _two_filler_stage(run: _Run, models: dict[str, ForwardModel], post: Posterior | None, *,
                      vary_both: bool) -> tuple[Posterior, dict[str, float]]:
    """The two-filler models added to ``models``: held at the single-filler posterior's
    central point, or (``vary_both``) varying every resistance; each held one carries the
    spread of its k_iso over that posterior. Every model is then calibrated (the new ones'
    replicas anchored at the best point) and the new ones corrected on faithful RVEs where
    the level asks; returns the posterior and the seconds of each step."""
    par, multis, echo = run.par, run.multis, run.echo
    t = time.perf_counter()
    fixed_of = ({f: {} for f in multis} if vary_both   # the hybrids move with both resistances
                else _held_at(run, post))
    if multis:
        echo(f"  {par.name}: two-filler models ({len(multis)}), held at the single-filler "
             "posterior's central point")
    models.update(run.build(fixed_of))
    if multis:
        echo(f"  {par.name}: two-filler spread over the single-filler posterior, anchors and "
             "final calibration")
    for f in multis:
        if fixed_of[f]:
            models[f].carried_scatter = _carried_scatter(models[f], post, run.cal["seed"])
    if any(models[f].rb is not None for f in multis):
        post = _anchored(models, multis, run.measurements, run.cal)
    elif multis or post is None:
        post = calibrate(models, run.measurements, **run.cal)
    seconds = {"two-filler models, anchors and final calibration": time.perf_counter() - t}
    if multis and run.faithful is not None:
        t = time.perf_counter()
        echo(f"  {par.name}: faithful corrections of the two-filler models "
             f"({run.faithful.name})")
        post = run.corrected(models, multis, post)
        seconds["two-filler faithful corrections"] = time.perf_counter() - t
    return post, seconds


def _held_at(run: _Run, post: Posterior | None) -> dict[str, dict[str, float]]:
    """Per two-filler formulation, its single-filler parameters at the central point of the
    single-filler posterior ``post`` (m^2 K/W; none without one)."""
    central = post.central() if post is not None else {}
    matrix = run.settings.system.matrix
    return {f: {p: central[p] for p in run.par.parameters(list(run.comps[f]), matrix=matrix)
                if p in central}
            for f in run.multis}


def _joint_identification(run: _Run, models: dict[str, ForwardModel], post: Posterior,
                          priors: Mapping[str, InputPrior | FilmPrior],
                          seconds: dict[str, float], *, resistance: ResistancePrior,
                          model_form: ModelFormPrior, floor_check: bool) -> Identification:
    """The identification whose posterior is the joint one over the resistances, the
    uncertain inputs ``priors``, the shared correction terms and the model form
    (:func:`~.joint_fit.run_joint`); ``post``, the grid calibration at the nominal inputs,
    is kept as its nominal one. Then the formulations alone and the paper's screening."""
    par, echo, seed = run.par, run.echo, run.cal["seed"]
    measurements = run.measurements
    film = any(isinstance(p, FilmPrior) for p in priors.values())
    t = time.perf_counter()
    echo(f"  {par.name}: the joint posterior (resistances, "
         + ", ".join(sorted(priors)) + (", " if priors else "")
         + "the shared correction terms and the model form; emcee"
         + ("; one full solve per filler" + (" and one at a film" if film else "")
            + " and formulation for the inputs' elasticities)" if priors else ")"))
    nominal = post
    elastic = elasticities(models, post.best, film=film) if priors else {}
    jp, _ = run_joint(models, measurements, priors, elastic, resistance=resistance,
                      model_form=model_form, seed=seed, progress=run.progress)
    post = as_posterior(jp, resistance=resistance, stages=nominal.stages)
    free = fit_with_inputs_free(
        likelihood_of(models, measurements, priors, elastic, resistance=resistance,
                      model_form=ModelFormPrior(on=False)), seed=seed)
    fit = joint_fit_record(models, measurements, post, jp, model_form, free)
    if floor_check:
        fit["floor_sensitivity"] = floor_sensitivity(
            jp, models, measurements, priors, elastic, resistance=resistance,
            model_form=model_form, seed=seed)
    inputs_record = {**inputs_record_of(jp, nominal, priors, seed=seed),
                     "elasticity": elastic, "sampler": jp.summary()["sampler"]}
    echo(f"  {par.name}: {joint_note(jp)}; {misfit_note(fit)}")
    seconds["joint posterior"] = time.perf_counter() - t
    alone = fit_alone(models, measurements, **run.cal)
    fit["alone_agreement"] = alone_agreement(alone)
    screening, seconds["screening"] = _screened(run, models)
    return Identification(run.parametrisation, run.settings, models, post, screening, seconds,
                          measurements, run.rounds, fit, inputs_record, alone, nominal, jp,
                          dict(priors), model_form)


def _quadrature_identification(run: _Run, models: dict[str, ForwardModel], post: Posterior,
                               priors: Mapping[str, InputPrior | FilmPrior],
                               seconds: dict[str, float]) -> Identification:
    """The identification of the earlier scheme: the grid calibration ``post`` with a
    point-estimated model-form error (:func:`~.misfit.with_model_form`), the inputs
    ``priors`` integrated out by quadrature (:func:`~.nuisance.marginalise`), then the
    formulations alone and the paper's screening."""
    par, echo, measurements = run.par, run.echo, run.measurements
    post, fit = with_model_form(models, measurements, post, **run.cal)
    echo(f"  {par.name}: {misfit_note(fit)}")
    inputs_record: dict = {}
    nominal = post
    if priors:
        film = any(isinstance(p, FilmPrior) for p in priors.values())
        t = time.perf_counter()
        echo(f"  {par.name}: inputs marginalised ({', '.join(sorted(priors))}; one full "
             "solve per filler" + (" and one at a film" if film else "")
             + " and formulation for its elasticity)")
        elastic = elasticities(models, post.best, film=film)
        post, record = marginalise(models, measurements, post, priors, elasticity=elastic,
                                   **run.cal)
        inputs_record = {**record.to_dict(), "elasticity": elastic}
        seconds["conductivities marginalised"] = time.perf_counter() - t
    alone = fit_alone(models, measurements, **run.cal)
    screening, seconds["screening"] = _screened(run, models)
    return Identification(run.parametrisation, run.settings, models, post, screening, seconds,
                          measurements, run.rounds, fit, inputs_record, alone,
                          None if post is nominal else nominal)


def _screened(run: _Run, models: Mapping[str, ForwardModel]
              ) -> tuple[list[ScreenResult], float]:
    """The paper's screening of ``models`` (:func:`~.screen.hierarchical_screen`) and its
    seconds."""
    t = time.perf_counter()
    run.echo(f"  {run.par.name}: the paper's screening (Eq. 4 on its grid)")
    screening = hierarchical_screen(models, run.measurements)
    return screening, time.perf_counter() - t


def film_is_zero(settings: ForwardSettings) -> bool:
    """Whether the settings' RVEs have touching particles at film 0 (none stated)."""
    rve = settings.rve
    film = rve.min_gap_um if rve.film_um is None else rve.film_um
    return film == 0


def marginalised_inputs(inputs: Mapping[str, InputPrior | FilmPrior], *, contact: str,
                        settings: ForwardSettings) -> dict[str, InputPrior | FilmPrior]:
    """The inputs of ``inputs`` that are integrated out under the contact model ``contact``:
    conductivities with a non-zero sd, and a film under the gap model only (the per-area
    contact resistance holds no film). A film prior with models built at another film than
    0 is a ValueError naming ``inputs``."""
    out = {n: p for n, p in inputs.items()
           if (contact == "gap" if isinstance(p, FilmPrior) else p.rel_sd > 0)}
    if any(isinstance(p, FilmPrior) for p in out.values()) and not film_is_zero(settings):
        raise ValueError("inputs: a film prior needs forward models built at film 0 (the "
                         "settings state a film; hold it instead)")
    return out


def default_inputs(phases, settings: ForwardSettings) -> dict[str, InputPrior | FilmPrior]:
    """The inputs :func:`identify` marginalises by default: every phase's conductivity
    (:func:`~itr_identify.inference.nuisance.default_priors` of the settings' material
    system) and, where the settings state no film, the film
    (:data:`~itr_identify.inference.nuisance.DEFAULT_FILM`)."""
    out: dict[str, InputPrior | FilmPrior] = dict(default_priors(phases, settings.system))
    if settings.rve.film_um is None and settings.rve.min_gap_um == 0:
        out[DEFAULT_FILM.name] = DEFAULT_FILM
    return out


def _runtime(models: dict[str, ForwardModel], names: list[str], echo: Callable) -> list[str]:
    """Those of ``names`` whose models carry no shipped correction (they are corrected at
    runtime); says why for each that the level asked a shipped correction for."""
    out = []
    for f in names:
        m = models[f]
        if m.shipped is None:
            out.append(f)
            if m.shipped_note:
                echo(f"  {f}: {m.shipped_note}; corrected at runtime instead")
        else:
            echo(f"  {f}: shipped correction x{m.fidelity_factor:.3f} ({m.shipped.system})")
    return out


def _anchored(models: dict[str, ForwardModel], names: list[str], measurements: Measurements,
              cal: Mapping[str, Any]) -> Posterior:
    """Calibrate ``models`` (:func:`calibrate` with ``cal``: grid points, seed, prior),
    solve every replica of ``names`` at the best values (:meth:`ForwardModel.anchor_at`:
    the replica factor and RVE scatter there, not at the box centre) and calibrate again;
    returns the second posterior."""
    post = calibrate(models, measurements, **cal)
    for f in names:
        models[f].anchor_at(post.best)
    return calibrate(models, measurements, **cal)


def _moves(before: Posterior, after: Posterior, names: list[str]) -> dict[str, float]:
    """Per parameter: how far the best point moved, in units of its 90 % interval's width
    (log10)."""
    out = {}
    for p in names:
        lo, hi = after.interval(p)
        width = max(math.log10(hi / lo), 1e-12)
        out[p] = abs(math.log10(after.best[p] / before.best[p])) / width
    return out


def _corrected(models: dict[str, ForwardModel], names: list[str], measurements: Measurements,
               post: Posterior, faithful, cal: Mapping[str, Any], rounds: list[dict],
               echo: Callable[[str], None]) -> Posterior:
    """Correct the models ``names`` on faithful RVEs at the best point and calibrate again,
    until the best value of every parameter they identify moves less than
    ``faithful.move_tolerance`` of its 90 % interval (at most ``faithful.max_rounds``
    corrections); each round is appended to ``rounds``. A model whose own parameters have
    stopped moving is not corrected again (the stages are independent: another filler's
    corrections do not move them)."""
    todo = list(names)
    if not todo:
        return post
    for r in range(1, faithful.max_rounds + 1):
        t = time.perf_counter()
        own = sorted({p for f in todo for p in models[f].parameters})
        for f in todo:
            models[f].correct_at(post.best, faithful)
        new = calibrate(models, measurements, **cal)
        moves = _moves(post, new, own)
        rounds.append({"round": r, "formulations": list(todo),
                       "at": {p: post.best[p] for p in own},
                       "best": {p: new.best[p] for p in own},
                       "factors": {f: models[f].fidelity_factor for f in todo},
                       "relative_sd": {f: models[f].correction.relative_sd for f in todo},
                       "moves": moves, "seconds": time.perf_counter() - t})
        echo(f"  faithful correction {r} ({', '.join(todo)}): factors "
             + ", ".join(f"{models[f].fidelity_factor:.3f}" for f in todo) + "; best "
             + ", ".join(f"{p} {new.best[p]:.2e}" for p in own) + "; moved "
             + ", ".join(f"{m:.2f}" for m in moves.values()) + " of the 90 % interval")
        post = new
        todo = [f for f in todo
                if any(moves[p] >= faithful.move_tolerance for p in models[f].parameters)]
        if not todo:
            rounds[-1]["converged"] = True
            break
    else:
        rounds[-1]["converged"] = False
        echo(f"  faithful correction: the best point still moved after "
             f"{faithful.max_rounds} rounds (see identified.json)")
    return post


def _carried_scatter(model: ForwardModel, posterior: Posterior, seed: int) -> float:
    """Relative spread of a later-stage model's k_iso over :data:`CARRIED_DRAWS` draws of
    the earlier stages' posterior (full solves of the first replica, own parameters at
    the centre of their box)."""
    rng = np.random.default_rng(seed)
    rows = posterior.samples[rng.choice(posterior.samples.shape[0], CARRIED_DRAWS,
                                        replace=False)]
    ks = []
    for row in rows:
        values = {p: 10 ** row[posterior.names.index(p)] for p in model.fixed}
        values.update(model.centre)
        ks.append(model.solve_first(values, purpose="earlier-stage spread").mean())
    return float(np.std(ks, ddof=1) / np.mean(ks))


def _build_all(fixed_of: Mapping[str, dict[str, float]], comps: Mapping[str, dict[str, float]],
               par, settings: ForwardSettings, progress: bool, echo: Callable[[str], None],
               engine: SolveEngine | None) -> dict[str, ForwardModel]:
    """Build the models of the formulations ``fixed_of`` (name -> parameters held fixed).

    On a distributed engine the formulations are independent and are built from one thread
    each, so that their full solves share the workers (each model's own steps stay in
    order; :meth:`ForwardModel.build` runs the local work one model at a time); otherwise
    one after another. The lines on ``echo`` come in formulation order either way."""
    def build(f: str) -> ForwardModel:
        m = ForwardModel(f, comps[f], par, settings, fixed=dict(fixed_of[f]), engine=engine)
        return m.build(progress=progress)

    from tqdm.auto import tqdm

    names = list(fixed_of)
    bar = tqdm(total=len(names), desc=f"{par.name} models", unit="formulation",
               disable=not progress or not names)
    with bar:
        if engine is not None and engine.distributed and len(names) > 1:
            with ThreadPoolExecutor(max_workers=len(names)) as pool:
                built = {}
                for f, m in zip(names, pool.map(build, names)):
                    built[f] = m
                    bar.update(1)
            for f in names:
                echo(_describe(built[f]))
            return built
        built = {}
        for f in names:
            built[f] = build(f)
            bar.update(1)
            echo(_describe(built[f]))
        return built


def _describe(m: ForwardModel) -> str:
    """One line on a built model: particles, reduced basis, RVE scatter, seconds."""
    rb = (f"reduced basis {m.rb.n_solves_} full solves (gap {m.rb.training_gap_:.1e})"
          if m.rb is not None else "no parameter of its own")
    return (f"  {m.parametrisation.name}: {m.formulation}: "
            f"{m.microstructures[0].n_particles} particles, {rb}, RVE scatter "
            f"{100 * m.rve_scatter:.1f} %, {m.build_seconds:.0f} s")
