"""``itr reproduce`` and ``itr identify``: the paper's pipeline on the shipped data.

:func:`run_reproduce`: the shipped Table 3 -> RVEs of every formulation (Table 1 size
distributions, Table 2 fractions) -> full solves of the reduced bases and the RVE scatter
(the campaign, kept in ``full_solves.parquet``) -> calibration and the paper's screening
under both parametrisations -> validation with full solves (3 RVEs x 3 directions) and
leave-one-formulation-out -> ``report.md``, ``identified.json``, figures, ``.vti`` fields
and ``manifest.json`` (written last). Only package data is read.

:func:`run_identify`: the same identification for a user's measurement table, without the
validation solves; writes ``identified.json``, ``report.md`` and a posterior figure.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

from itr_fv.io import atomic_path, counted, write_text
from itr_fv.materials.material_system import MaterialSystem
from itr_fv.run_folder import begin_run, write_manifest
from itr_surrogate.engine import SolveEngine

from ..forward.fidelity import (
    CHEAP_REPLICAS,
    CHEAP_RVE,
    CHEAP_TOL,
    cheap_rve_for,
    faithful_for,
    fidelity_name,
)
from ..forward.model import ForwardSettings
from ..inference.formulations import fractions_of
from ..inference.joint_fit import mark_predictive
from ..inference.measurements import Measurements, read_measurements
from ..inference.pipeline import Identification, identify
from ..inference.validate import leave_one_out as calibrated_leave_one_out
from ..inference.validate import validate
from ..reporting import figures, report
from ..reporting.headline import headline, headline_lines, headline_markdown
from ..reporting.level import runs_record

__all__ = ["ReproduceSettings", "run_reproduce", "run_identify", "write_solves",
           "drop_fields"]


#: The fidelity level of ``itr reproduce`` and ``itr identify`` by default: ``shipped`` (the
#: corrections shipped with the package: converged boxes at the cost of ``quick``);
#: ``standard`` took 48 min (validation/results/reproduce_fidelity.md), beyond what the
#: README's first command and CI can spend.
DEFAULT_FIDELITY = "shipped"


@dataclass(frozen=True)
class ReproduceSettings:
    """Settings of ``itr reproduce`` and ``itr identify``: reduced bases on 12 um RVEs at
    0.25 um, corrected (gap parametrisation) on the faithful RVEs of the fidelity level
    (:meth:`at_fidelity`, :mod:`itr_identify.forward.fidelity`)."""

    forward: ForwardSettings = field(default_factory=lambda: ForwardSettings(
        CHEAP_RVE, replicas=CHEAP_REPLICAS, solver_tol=CHEAP_TOL,
        faithful=faithful_for(DEFAULT_FIDELITY)))
    parametrisations: tuple[str, ...] = ("area", "gap")
    grid_points: int = 121
    seed: int = 0
    leave_one_out: bool = True
    #: (phase, relative sd) of the conductivities marginalised, beside the defaults of
    #: the material system's (:meth:`~itr_fv.materials.material_system.MaterialSystem.
    #: conductivity_sds`; 0 holds one at nominal)
    conductivity_sd: tuple[tuple[str, float], ...] = ()
    #: Run the discrepancy verdict (the library's effects on the gap identification's own
    #: model, :mod:`itr_identify.workflows.effects`).
    discrepancy: bool = False
    #: An effect fitted jointly with the resistances beside the base model (one of
    #: :data:`~itr_identify.discrepancy.joint_effects.JOINT_EFFECTS`; None: the named one).
    effect: str | None = None

    def __post_init__(self) -> None:
        from ..discrepancy.joint_effects import JOINT_EFFECTS

        if self.effect is not None and self.effect not in JOINT_EFFECTS:
            raise ValueError(f"effect: expected one of {', '.join(JOINT_EFFECTS)}, got "
                             f"{self.effect!r}")
        if (self.discrepancy or self.effect) and "gap" not in self.parametrisations:
            raise ValueError("parametrisations: the discrepancy verdict and an effect are "
                             "fitted on the gap identification; include 'gap'")

    def input_priors(self, phases) -> dict:
        """The inputs marginalised: the defaults of
        :func:`~itr_identify.inference.pipeline.default_inputs` (every phase of ``phases``,
        the film where none is stated), with :attr:`conductivity_sd` where given."""
        from ..inference.nuisance import InputPrior
        from ..inference.pipeline import default_inputs

        given = dict(self.conductivity_sd)
        return {n: (InputPrior(n, p.nominal, given.get(p.phase, p.rel_sd))
                    if isinstance(p, InputPrior) else p)
                for n, p in default_inputs(sorted(phases), self.forward).items()}

    @classmethod
    def at_fidelity(cls, level: str, system: MaterialSystem | None = None
                    ) -> "ReproduceSettings":
        """Default settings at fidelity ``level`` (``quick``, ``shipped``, ``standard``,
        ``paper``) for ``system`` (default: the package's): its cheap RVE and faithful RVEs
        from its powders (:func:`~itr_identify.forward.fidelity.cheap_rve_for`,
        :func:`~itr_identify.forward.fidelity.faithful_for`; the paper's system: 12 um at
        0.25 um and the levels' measured boxes)."""
        forward = cls().forward
        if system is not None:
            forward = forward.with_(system=system, rve=cheap_rve_for(system))
        return cls(forward=forward.with_(faithful=faithful_for(level, forward.system)))

    @property
    def fidelity(self) -> str:
        return fidelity_name(self.forward.faithful)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["forward"] = self.forward.to_dict()
        d["parametrisations"] = list(self.parametrisations)
        d["fidelity"] = self.fidelity
        return d


def _bar(total: int, desc: str, progress: bool, unit: str = "solve"):
    from tqdm.auto import tqdm
    return tqdm(total=total, desc=desc, unit=unit, disable=not progress)


def write_solves(idents: Sequence[Identification], path: Path) -> Path:
    """Every full solve of the run as one Parquet table (atomic): the solve store's rows
    (:func:`itr_surrogate.requests.solve_row`: key, RVE, parameters, the raw tensor of that
    RVE, iterations, labels) with the parametrisation that asked for them and, for the
    solves of the cheap RVEs, their value at the fidelity level: ``level`` (``runtime``,
    ``shipped`` or ``none``: :meth:`~itr_identify.forward.model.ForwardModel.level_at` at
    the row's parameters), ``level_factor`` and ``k_iso_at_level`` (W/(m K)). A faithful
    RVE's own solve (``level`` ``faithful RVE``) has no factor: it is a level itself."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows = []
    for ident in idents:
        cheap = (ident.settings.box_um, ident.settings.voxel_um)
        for m in ident.models.values():
            for row in m.solves:
                extra: dict[str, object] = {"parametrisation": ident.parametrisation}
                if not all(math.isclose(row[k], v, rel_tol=1e-9)
                           for k, v in zip(("box_um", "voxel_um"), cheap)):
                    extra.update(level="faithful RVE", level_factor=math.nan,
                                 k_iso_at_level=math.nan)
                else:
                    values = {p: row.get(p, m.fixed.get(p)) for p in m.parameters}
                    level = m.level_at(values)
                    extra.update(level=level["source"], level_factor=level["factor"],
                                 k_iso_at_level=row["k_iso"] * level["factor"])
                rows.append({**extra, **row})
    names = sorted({k for r in rows for k in r})
    table = pa.table({k: [r.get(k) for r in rows] for k in names})
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)
    return Path(path)


def _temperature_field(ident: Identification, formulation: str, out: Path) -> list[Path]:
    """Full solve with fields of the first replica at the best values (three load cases:
    the .vti holds the whole tensor), its .vti, a render and a temperature figure, whose k
    is said raw and at the fidelity level (on this process's cached problem of that RVE: its
    geometry is not built again)."""
    from itr_fv import homogenize
    from itr_surrogate.requests import RVEData
    from itr_surrogate.worker import cached_problem

    m = ident.models[formulation]
    best = {p: ident.quoted[p] for p in m.parameters}
    mat = m.materials(best)
    problem = cached_problem(RVEData.of(m.microstructures[0]), mat.contact)[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        backend = ident.settings.solver.backend(voxels=math.prod(problem.shape))
        res = homogenize(problem, mat, solver=backend,
                         tol=ident.settings.solver_tol)
    level = m.level_at(best)
    name = fidelity_name(ident.settings.faithful)
    stem = f"temperature_{formulation}_{ident.parametrisation}"
    vti = res.to_vtk(out / f"{stem}.vti", load_cases=[0], vectors=False)
    flux = res.render_png(out / f"flux_{formulation}_{ident.parametrisation}.png",
                          k_text="k_11 = " + figures.level_caption(float(res.k_eff[0, 0]),
                                                                   level, name))
    temp = figures.temperature_figure(res, out / f"{stem}.png", level=level, level_name=name)
    return [Path(vti), Path(flux), Path(temp)]


def open_engine(out: Path, *, workers: int | None = None, scheduler: str | None = None,
                store: str | Path | None = None,
                echo: Callable[[str], None] = print) -> SolveEngine:
    """The solve engine of a run writing to ``out``: every full solve is kept in
    ``out/solves``, or in ``store`` (a folder several runs share: a solve is keyed by its
    RVE, parameters, solver and tolerance, never by the measurements), so a re-run of a
    killed command, or another run on the same store, redoes none that finished; run in
    this process, on ``workers`` local processes or on the Dask ``scheduler``."""
    return SolveEngine(Path(store) if store is not None else Path(out) / "solves",
                       workers=workers, scheduler=scheduler, echo=echo)


def _identify_all(meas: Measurements, settings: ReproduceSettings, progress: bool,
                  echo: Callable[[str], None], engine: SolveEngine, *,
                  validation: bool = False, leave_one_out: bool = False) -> dict[str, dict]:
    """Every parametrisation of ``settings`` identified, side by side in processes of their
    own where the machine allows (:mod:`.side_processes`), else one after the other; with
    ``validation``, each one's full-solve validation at its quoted values, with
    ``leave_one_out``, each joint identification's leave-one-formulation-out too. Returns
    per parametrisation :func:`_identify_one`'s dict."""
    from .side_processes import identify_side_by_side, side_by_side_possible, tie_to

    pars = list(settings.parametrisations)
    kwargs = {"meas": meas, "settings": settings, "validation": validation,
              "leave_one_out": leave_one_out}
    if not side_by_side_possible(len(pars), distributed=engine.distributed):
        return {par: _identify_one(par, progress=progress, echo=echo, engine=engine, **kwargs)
                for par in pars}
    echo(f"{' and '.join(pars)}: identified side by side, one process each "
         "(solves on one thread each)")
    outs = identify_side_by_side(_identify_in_side_process, pars, echo=echo,
                                 store=engine.store.folder if engine.store else None,
                                 **kwargs)
    for out in outs.values():
        tie_to(out["ident"].models, engine)
        engine.absorb(out.pop("engine_counts"))
    return outs


def _identify_in_side_process(par: str, *, store: Path | None, echo: Callable[[str], None],
                              **kwargs) -> dict:
    """:func:`_identify_one` in a side process: its own engine on the run's store, the
    models untied from it for the trip back (:func:`.side_processes.tie_to`)."""
    engine = SolveEngine(store, echo=echo)
    out = _identify_one(par, progress=False, echo=echo, engine=engine, **kwargs)
    for m in out["ident"].models.values():
        m.engine = None
    out["engine_counts"] = engine.counts()
    return out


def _identify_one(par: str, *, meas: Measurements, settings: ReproduceSettings,
                  progress: bool, echo: Callable[[str], None], engine: SolveEngine,
                  validation: bool, leave_one_out: bool) -> dict:
    """One parametrisation identified; with ``validation`` its full-solve validation, with
    ``leave_one_out`` its leave-one-formulation-out. Returns ``{"ident", "validation",
    "lofo"}`` (None where not run) and ``seconds`` per stage."""
    t = time.perf_counter()
    echo(f"{par}: RVEs, reduced bases and RVE scatter of "
         f"{counted(len(meas.formulations), 'formulation')}")
    system = settings.forward.system
    phases = {system.matrix, *(f for name in meas.formulations
                               for f in fractions_of(name, system))}
    ident = identify(meas, par, settings=settings.forward, grid_points=settings.grid_points,
                     seed=settings.seed, progress=progress, echo=echo, engine=engine,
                     inputs=settings.input_priors(phases))
    post = ident.posterior
    best = ", ".join(f"{n} {v:.2e} (90 % {post.interval(n)[0]:.2e} - "
                     f"{post.interval(n)[1]:.2e})" for n, v in post.best.items())
    echo(f"{par}: identified {best} (m^2 K/W)")
    out = {"ident": ident, "validation": None, "lofo": None,
           "seconds": {"identification": time.perf_counter() - t}}
    if validation:
        t = time.perf_counter()
        n = len(ident.models) * settings.forward.replicas
        echo(f"{par}: validation: full solves of {settings.forward.replicas} RVEs x 3 "
             "directions per formulation at the identified values")
        with _bar(n, f"{par} validation solves", progress) as bar:
            out["validation"] = validate(ident.models, ident.quoted, meas,
                                         tick=lambda: bar.update(1))
        if ident.joint is not None:
            mark_predictive(out["validation"], ident)
        out["seconds"]["validation"] = time.perf_counter() - t
    if leave_one_out:
        t = time.perf_counter()
        echo(f"{par}: leave one formulation out: each held out, the rest "
             + ("the joint posterior without the model form, reweighted"
                if ident.joint is not None else "calibrated") + ", the held-out one predicted")
        with _bar(len(ident.models), f"{par} leave-one-out", progress and ident.joint is None,
                  unit="formulation") as bar:
            out["lofo"] = (ident.leave_one_out(seed=settings.seed) if ident.joint is not None
                           else calibrated_leave_one_out(
                               ident.models, meas, grid_points=settings.grid_points,
                               seed=settings.seed, prior=ident.posterior.prior,
                               tick=lambda: bar.update(1)))
        out["seconds"]["leave-one-formulation-out"] = time.perf_counter() - t
    return out


def run_reproduce(settings: ReproduceSettings, out: Path, *, progress: bool = True,
                  echo: Callable[[str], None] = print, workers: int | None = None,
                  scheduler: str | None = None, store: str | Path | None = None,
                  keep_fields: bool = False) -> list[Path]:
    """The whole pipeline on the shipped data; returns the files written (manifest last).

    Every full solve runs on the solve engine (:func:`open_engine`: in this process, on
    ``workers`` local processes or on the Dask ``scheduler``) and is kept in ``out/solves``
    (or ``store``); the reduced bases' snapshot fields stay there only while the run lasts,
    unless ``keep_fields`` (:func:`drop_fields`).
    """
    begin_run(out, "reproduce", folders=("solves",))
    with open_engine(out, workers=workers, scheduler=scheduler, store=store,
                     echo=echo) as engine:
        files = _reproduce(settings, Path(out), progress, echo, engine, keep_fields)
    return files


def drop_fields(engine: SolveEngine, keep_fields: bool,
                echo: Callable[[str], None] = print) -> str:
    """At the end of a finished run: remove the snapshot fields from the engine's store
    unless ``keep_fields`` (a later run on the same store then solves those snapshots
    again); returns what the store holds now, for the report and the last line."""
    store = engine.store
    if store is None:
        return "no store"
    if keep_fields:
        n, size = store.field_count()
        return f"{n} snapshot fields kept ({size / 1e6:.0f} MB, --keep-fields)"
    n, size = store.drop_fields()
    if n:
        echo(f"store: {n} snapshot fields removed ({size / 1e6:.0f} MB; --keep-fields keeps "
             "them)")
    return "snapshot fields removed at the end of the run (--keep-fields keeps them)"


def _reproduce(settings: ReproduceSettings, out: Path, progress: bool,
               echo: Callable[[str], None], engine: SolveEngine,
               keep_fields: bool) -> list[Path]:
    t0 = time.perf_counter()
    meas = read_measurements()
    outs = _identify_all(meas, settings, progress, echo, engine, validation=True,
                         leave_one_out=settings.leave_one_out)
    idents = {p: o["ident"] for p, o in outs.items()}
    validation = {p: o["validation"] for p, o in outs.items()}
    lofo = {p: o["lofo"] for p, o in outs.items() if o["lofo"] is not None}
    stages = {s: [o["seconds"].get(s, 0.0) for o in outs.values()]
              for s in ("validation", "leave-one-formulation-out")}
    t_ident = time.perf_counter() - t0
    t = time.perf_counter()
    extra = _effects(idents, settings, out, engine, progress, echo)
    t_effects = time.perf_counter() - t
    echo("figures and fields")
    files, psd_fits = _figures(idents, validation, out)
    files += extra[2]
    fields = drop_fields(engine, keep_fields, echo)
    files.append(write_solves(list(idents.values()), out / "full_solves.parquet"))
    head = headline(idents, discrepancy=extra[0].get("headline"))
    data = {"headline": head}
    data.update({p: {**report.identified_dict(i), "validation": validation[p],
                     "leave_one_out": lofo.get(p, [])} for p, i in idents.items()})
    files += _predictive_records(idents, data, settings, out)
    data["selection"] = report.selection(idents)
    data["surrogate_check"] = figures.surrogate_check(validation, idents)
    data["psd_fit"] = psd_fits
    if extra[0]:
        data["discrepancy"] = extra[0]
    files.append(write_text(out / "identified.json", json.dumps(data, indent=2) + "\n"))
    wall = time.perf_counter() - t0
    from .side_processes import side_by_side_possible

    side = side_by_side_possible(len(outs), distributed=engine.distributed)
    timing = {("identification, validation full solves and leave-one-formulation-out, "
               "the parametrisations side by side" if side else
               "identification, validation full solves and leave-one-formulation-out"):
              t_ident,
              **{f"of which {s} (the longest parametrisation's)" if side else
                 f"of which {s}": max(v) for s, v in stages.items()},
              "discrepancy verdict and effect": t_effects,
              "total (before the report)": wall}
    files.append(write_text(out / "report.md", _reproduce_markdown(
        head, idents, meas, validation, lofo, psd_fits, timing, settings,
        data["surrogate_check"]) + ("\n" + "\n".join(extra[1]) + "\n" if extra[1] else "")))
    files.append(write_manifest(out, files, {**settings.to_dict(), "fidelity_ran": runs_record(
        idents), "wall_s": round(wall, 1), "engine": engine.summary(), "store_fields": fields},
        job="reproduce"))
    echo(f"engine: {engine.summary()}")
    for line in headline_lines(head):
        echo(line)
    echo(f"reproduce: done in {wall:.0f} s; wrote {len(files)} files to {out}")
    return files


def _figures(idents: dict[str, Identification], validation: dict, out: Path
             ) -> tuple[list[Path], dict]:
    """The figures and the temperature field; returns their paths and the PSD fits."""
    first = next(iter(idents.values()))
    files = []
    psd_png, fits = figures.psd_figure(first, out / "fig2_psd.png")
    files.append(psd_png)
    files.append(figures.rve_figure(first, ["Al2O3-60", "AlN-60", "Al2O3-30-AlN-30"],
                                    out / "fig4_rves.png"))
    files.append(figures.parity_figure(validation, idents, out / "fig6_parity.png"))
    files.append(figures.screening_figure(idents, out / "fig8_screening.png"))
    for par, ident in idents.items():
        files.append(figures.posterior_figure(ident, out / f"posterior_{par}.png"))
    if "gap" in idents and idents["gap"].alone:
        files.append(figures.alone_figure(idents["gap"], out / "fig_alone.png"))
    target = "Al2O3-60" if "Al2O3-60" in first.models else next(iter(first.models))
    files += _temperature_field(idents.get("gap", first), target, out)
    return files, fits


def _reproduce_markdown(head, idents, meas, validation, lofo, psd_fits, timing,
                        settings, surrogate) -> str:
    from itr_fv.materials import paper_data

    table1 = paper_data.psd_lognormal()
    lines = ["# The paper's pipeline, reproduced (`itr reproduce`)", "",
             "Interfacial thermal resistances of Al2O3/AlN-silicone composites identified "
             "from the shipped measurements (the paper's Table 3) with certified "
             "reduced-basis surrogates of full voxel solves, validated with the full solver.",
             ""]
    lines += headline_markdown(head)
    lines += [""] + report.joint_lines(idents)
    lines += ["", "## Settings", ""]
    lines += report.settings_lines(idents, {"wall time (s)": ", ".join(
        f"{k} {v:.0f}" for k, v in timing.items())})
    lines += ["", "## Table 1: size distributions (packed RVEs against the paper)", "",
              "| filler | paper mu | paper sigma | packed particles | fitted mu | fitted sigma "
              "| drawn range (um) |", "|---|---|---|---|---|---|---|"]
    for f, fit in psd_fits.items():
        lines.append(f"| {f} | {table1[f][0]} | {table1[f][1]} | {fit['particles']} | "
                     f"{fit['mu']:.2f} | {fit['sigma']:.2f} | {fit['d_min_um']:.2f} - "
                     f"{fit['d_max_um']:.2f} |")
    lines += ["", "The fit is a truncated-lognormal maximum likelihood on the packed diameters "
              "(truncation at the drawn extremes); the box cut (largest diameter "
              f"{settings.forward.max_diameter_box_ratio:g} x box) removes the coarse tail.",
              "", "## Table 3: measurements (shipped)", ""]
    lines += report.table3_lines(meas)
    lines += ["", "## Table 5: identified resistances (m^2 K/W)", ""]
    lines += report.table5_lines(idents)
    lines += ["", "### Against the paper's Table 5", ""] + report.difference_lines(idents)
    lines += ["", "Screening: the paper's Eq. 4 on its grid (Fig. 8 analogue: "
              "`fig8_screening.png`). Calibration: posterior with replicate variance, RVE "
              "scatter and surrogate error (`posterior_*.png`).", "",
              "## Which parametrisation the data support", ""]
    lines += report.selection_lines(idents)
    lines += ["", "Residuals at the best values (reduced basis of replica 1):", ""]
    lines += report.residual_lines(idents)
    lines += [""] + report.alone_lines(idents)
    lines += ["", "## Identifiability", ""]
    lines += report.identifiability_lines(idents)
    lines += ["", "## Table 6: validation with the full solver", ""]
    lines += report.table6_lines(validation)
    lines += ["", "Fig. 6 (`fig6_parity.png`), left: the surrogate against the full solver, "
              "both raw (the cheap RVE's own k):", ""] + report.surrogate_lines(surrogate)
    if lofo:
        lines += ["", "## Leave one formulation out", ""]
        lines += report.lofo_lines(lofo)
    lines += ["", "## Files", "",
              "`identified.json` (every value above), `full_solves.parquet` (every full solve "
              "of the run: the raw tensor of its RVE, and for the cheap RVEs `level`, "
              "`level_factor` and `k_iso_at_level`), `fig2_psd.png`, `fig4_rves.png`, "
              "`fig6_parity.png`, `fig8_screening.png`, `posterior_*.png`, "
              "`temperature_*.vti/.png` (temperature on a mid-plane), `flux_*.png` (pyvista "
              "render of the heat flux), "
              "`manifest.json` (sizes and SHA-256, settings, versions)."]
    return "\n".join(lines) + "\n"


def run_identify(meas: Measurements, settings: ReproduceSettings, out: Path, *,
                 progress: bool = True, echo: Callable[[str], None] = print,
                 workers: int | None = None, scheduler: str | None = None,
                 store: str | Path | None = None, keep_fields: bool = False) -> list[Path]:
    """Identification of a user's measurement table; returns the files written. Full
    solves as in :func:`run_reproduce` (kept in ``out/solves``; the snapshot fields only
    with ``keep_fields``)."""
    out = Path(out)
    begin_run(out, "identify", folders=("solves",))
    with open_engine(out, workers=workers, scheduler=scheduler, store=store,
                     echo=echo) as engine:
        t0 = time.perf_counter()
        idents = {p: o["ident"] for p, o in
                  _identify_all(meas, settings, progress, echo, engine).items()}
        extra = _effects(idents, settings, out, engine, progress, echo)
        drop_fields(engine, keep_fields, echo)
        echo(f"engine: {engine.summary()}")
    return _identify_report(meas, settings, out, idents, t0, echo, extra)


def _effects(idents, settings: ReproduceSettings, out: Path, engine: SolveEngine,
             progress: bool, echo: Callable[[str], None]) -> tuple[dict, list[str], list[Path]]:
    """The discrepancy verdict and the effect the settings ask for (nothing where they ask
    for neither)."""
    if not (settings.discrepancy or settings.effect):
        return {}, [], []
    from .effects import run_effects

    return run_effects(idents["gap"], out, engine=engine, verdict=settings.discrepancy,
                       effect=settings.effect, progress=progress, echo=echo)


def _identify_report(meas: Measurements, settings: ReproduceSettings, out: Path,
                     idents: dict[str, Identification], t0: float,
                     echo: Callable[[str], None],
                     extra: tuple[dict, list[str], list[Path]] = ({}, [], [])) -> list[Path]:
    head = headline(idents, discrepancy=extra[0].get("headline"))
    data = {"headline": head}
    data.update({p: report.identified_dict(i) for p, i in idents.items()})
    records = _predictive_records(idents, data, settings, out)
    if extra[0]:
        data["discrepancy"] = extra[0]
    if len(idents) > 1:
        data["selection"] = report.selection(idents)
    files = [write_text(out / "identified.json", json.dumps(data, indent=2) + "\n"), *records]
    for par, ident in idents.items():
        files.append(figures.posterior_figure(ident, out / f"posterior_{par}.png"))
    lines = [f"# Identified interface resistances: {meas.source}", ""]
    lines += headline_markdown(head) + [""] + report.joint_lines(idents)
    lines += ["", "## Settings", ""]
    lines += report.settings_lines(idents, {"wall time (s)": f"{time.perf_counter() - t0:.0f}"})
    lines += ["", "## Measurements", ""] + report.table3_lines(meas)
    lines += ["", "## Identified (m^2 K/W)", ""] + report.table5_lines(idents)
    lines += ["", "## Fit", ""] + report.selection_lines(idents)
    lines += [""] + report.residual_lines(idents)
    lines += ["", "## Identifiability", ""] + report.identifiability_lines(idents)
    if extra[1]:
        lines += [""] + extra[1]
        files += extra[2]
    files.append(write_text(out / "report.md", "\n".join(lines) + "\n"))
    files.append(write_manifest(out, files, {"measurements": meas.source,
                                             **settings.to_dict(),
                                             "fidelity_ran": runs_record(idents)},
                                job="identify"))
    for line in headline_lines(head):
        echo(line)
    echo(f"identify: done in {time.perf_counter() - t0:.0f} s; wrote {_written(out, files)}")
    return files


def _predictive_records(idents: dict[str, Identification], data: dict,
                        settings: ReproduceSettings, out: Path) -> list[Path]:
    """Each joint identification's posterior record for ``itr predict`` and ``itr design``
    (:mod:`itr_identify.inference.predictive`): its draws written beside identified.json,
    the record under ``data[parametrisation]["predictive"]``; returns the draws' files."""
    from ..inference.predictive import record_of, write_record

    files = []
    for par, ident in idents.items():
        if ident.joint is None:
            continue
        block, path = write_record(record_of(ident), out)
        data[par]["predictive"] = block
        files.append(path)
    return files


def _written(out: Path, files: list[Path]) -> str:
    """The files of a run as its last line names them: the folder, the report first, the
    figures together ("itr-identify/: report.md, identified.json, figures posterior_area.png
    and posterior_gap.png, manifest.json")."""
    names = [Path(f).name for f in files]
    figs = [n for n in names if n.endswith(".png")]
    parts = [n for n in ("report.md",) if n in names]
    parts += [n for n in names if n not in figs and n not in ("report.md", "manifest.json")]
    if figs:
        parts.append(f"figure {figs[0]}" if len(figs) == 1 else
                     f"figures {', '.join(figs[:-1])} and {figs[-1]}")
    parts += [n for n in ("manifest.json",) if n in names]
    return f"{out}{'' if str(out).endswith('/') else '/'}: " + ", ".join(parts)


