"""``itr discrepancy``: the discrepancy workflow (:mod:`itr_identify.discrepancy`) on a
measurement table, with its report: discrepancy.md, .json, .png and manifest.json."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

from itr_fv.io import write_text
from itr_fv.run_folder import begin_run, write_manifest

from ..discrepancy.best_point import corrector
from ..discrepancy.decision import Discrepancy, find_discrepancy
from ..discrepancy.effects import default_effects
from ..discrepancy.observables import auxiliary_groups
from ..discrepancy.settings import DiscrepancySettings
from ..discrepancy.tables import build_tables, n_solves, shipped_corrections
from ..inference.formulations import fractions_of
from ..inference.measurements import Measurements
from ..reporting.discrepancy_report import gap_figure, report_lines
from .reproduce import drop_fields, open_engine

__all__ = ["run_discrepancy"]


def run_discrepancy(meas: Measurements, settings: DiscrepancySettings, out: Path, *,
                    effects: list | None = None, progress: bool = True,
                    echo: Callable[[str], None] = print, workers: int | None = None,
                    scheduler: str | None = None, store: str | Path | None = None,
                    keep_fields: bool = False) -> Discrepancy:
    """The workflow on ``meas`` (``effects``: the candidates, default the whole library)
    with its report in ``out``: discrepancy.md, .json, .png, manifest.json. The forward
    tables' full solves run on the solve engine (in this process, on ``workers`` local
    processes or on the Dask ``scheduler``) and are kept in ``out/solves`` or ``store``: a
    re-run (another table, or after a kill) on the same store redoes none that finished;
    ``keep_fields`` as :func:`~itr_identify.workflows.reproduce.drop_fields`."""
    from tqdm.auto import tqdm

    comps = {f: fractions_of(f, settings.system) for f in meas.formulations}
    auxiliary_groups(meas, comps)          # an auxiliary column without its noise: refused now
    out = Path(out)
    begin_run(out, "discrepancy", folders=("solves",))
    singles = {f: c for f, c in comps.items() if len(c) == 1}
    effects = default_effects(settings.system) if effects is None else list(effects)
    with open_engine(out, workers=workers, scheduler=scheduler, store=store,
                     echo=echo) as engine, \
            tqdm(total=n_solves(len(singles), settings, effects,
                                shipped=len(shipped_corrections(singles, settings))),
                 desc="forward solves",
                 unit="solve", disable=not progress) as bar:
        tables = build_tables(singles, settings=settings, effects=effects,
                              tick=lambda: bar.update(), engine=engine)
        correct = corrector(engine) if settings.correct_at_best else None
        d = find_discrepancy(meas, settings=settings, tables=tables, correct=correct)
        drop_fields(engine, keep_fields, echo)
    echo(f"engine: {engine.summary()}")
    files = [write_text(out / "discrepancy.json", json.dumps(d.to_dict(), indent=2) + "\n")]
    files.append(gap_figure(d, out / "discrepancy.png"))
    lines = [f"# Discrepancy between model and measurements: {meas.source}", ""]
    lines += report_lines(d, settings)
    lines += ["", "Figure: `discrepancy.png` (relative error per group, before and after)."]
    files.append(write_text(out / "discrepancy.md", "\n".join(lines) + "\n"))
    files.append(write_manifest(out, files, {"measurements": meas.source,
                                             "forward": settings.forward.to_dict(),
                                             "faithful": (settings.faithful.to_dict()
                                                          if settings.faithful else None),
                                             "densities_g_per_cm3": d.densities},
                                job="discrepancy"))
    echo(f"discrepancy: {d.verdict}; wrote {out / 'discrepancy.md'}")
    return d
