"""``itr corrections build|show``: make the shipped faithful corrections, or show them.

``build`` runs a corrections file's campaigns (:mod:`itr_identify.forward.correction_plan`)
on the campaign engine, each in its own sub-folder of ``--out`` named by the campaign (run
it again after a kill: finished tasks are kept; ``--solved-in DIR`` counts another
machine's finished tasks, e.g. a GPU's, as done), and writes ``--out/corrections.json``
(:func:`itr_identify.forward.corrections_table.assemble`); copy that over
``identify/data/corrections.json`` to ship it. ``--plan`` prints the campaigns, what is done
and the hours left, and solves nothing. ``show`` prints a corrections file's table.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from .core import (
    CLIError,
    Parser,
    number,
    output_folder,
    solver_arguments,
    solver_option,
    system_arguments,
    system_option,
)

__all__ = ["add_parser"]


def _solved_elsewhere(dirs: list[str] | None, name: str) -> set[str]:
    """Task ids of campaign ``name`` finished in the run folders ``dirs`` (another machine's
    stores of the same campaign, e.g. a GPU's): ``DIR/<name>/parts``."""
    from itr_surrogate.store import CampaignStore

    done: set[str] = set()
    for d in dirs or ():
        folder = Path(d) / name
        if (folder / "campaign.json").is_file():
            done |= CampaignStore(folder).done_tasks()
    return done


def _tasks_left(camp, folder: Path, solved_in: list[str] | None) -> int:
    """Tasks of ``camp`` neither in its store ``folder`` nor solved elsewhere."""
    from itr_surrogate.store import CampaignStore

    done = _solved_elsewhere(solved_in, camp.name)
    if (folder / "campaign.json").is_file():
        done |= CampaignStore(folder).done_tasks()
    return sum(t.task_id not in done for t in camp.tasks())


def _plan_table(campaigns, args) -> list[str]:
    """The plan's lines: per campaign its grid, tasks done (here, elsewhere) and to run,
    the solves left and their hours on this machine's cores; the total."""
    from itr_surrogate.runner import local_workers
    from itr_surrogate.store import CampaignStore
    from itr_surrogate.workload import Workload, campaign_workload

    lines = [f"{'campaign':<40}{'grid':>8}{'tasks':>7}{'done':>6}{'left':>6}{'solves':>8}"
             f"{'hours':>8}"]
    total = 0.0
    for folder, camp in campaigns:
        tasks = camp.tasks()
        here = (CampaignStore(Path(args.out) / folder).done_tasks() if args.out and
                (Path(args.out) / folder / "campaign.json").is_file() else set())
        done = here | _solved_elsewhere(args.solved_in, camp.name)
        left = [t for t in tasks if t.task_id not in done]
        grid = campaign_workload(camp, label=folder).grids[0]
        g = dataclasses.replace(grid, rves=len(left),
                                solves=sum(len(t.set_indices) for t in left))
        hours = Workload((g,), camp.solver, local_workers(args.workers)).seconds() / 3600
        total += hours
        lines.append(f"{folder:<40}{grid.n:>7}^3{len(tasks):>7}{len(tasks) - len(left):>6}"
                     f"{len(left):>6}{g.solves:>8}{hours:>8.2f}")
    lines.append(f"{'total':<40}{'':>8}{'':>7}{'':>6}{'':>6}{'':>8}{total:>8.2f}")
    return lines


def _build(args: argparse.Namespace) -> int:
    from itr_fv.io import write_text
    from itr_fv.run_folder import write_manifest
    from itr_surrogate.campaign import CampaignError
    from itr_surrogate.runner import local_workers, run_campaign
    from itr_surrogate.workload import Workload, campaign_workload

    from ..forward.correction_plan import CorrectionPlan
    from ..forward.corrections_table import assemble

    try:
        plan = CorrectionPlan.from_toml(args.file, system_option(args))
        systems = tuple(args.systems.split(",")) if args.systems else None
        if systems:
            for s in systems:
                plan.system(s)
    except ValueError as exc:
        raise CLIError(str(exc), 2) from None
    solver = solver_option(args, plan.solver)
    campaigns = list(plan.campaigns(systems=systems, solver=solver, threads=args.threads))
    if args.plan:
        print(f"plan {plan.name}: {len(campaigns)} campaigns, solver {solver}, "
              f"{local_workers(args.workers) or 1} worker(s) on this machine's cores; hours "
              "of what is left (an order of magnitude)")
        print("\n".join(_plan_table(campaigns, args)))
        return 0
    if not args.out:
        raise CLIError("--out: give the run folder (or --plan to see the work)", 2)
    left = [(f, c) for f, c in campaigns if _tasks_left(c, Path(args.out) / f, args.solved_in)]
    if not left:   # every task is solved: assemble only (the first campaign's plan line)
        left = campaigns[:1]
    work = Workload(tuple(campaign_workload(camp, label=folder).grids[0]
                          for folder, camp in left),
                    solver, local_workers(args.workers), args.scheduler)
    failed = 0
    with output_folder(args.out, "corrections build",
                       folders=[folder for folder, _ in campaigns], workload=work) as out:
        for folder, camp in campaigns:
            try:
                summary = run_campaign(camp, out / folder, workers=args.workers,
                                       scheduler=args.scheduler,
                                       progress=not args.no_progress,
                                       skip=_solved_elsewhere(args.solved_in, camp.name))
            except CampaignError as exc:
                raise CLIError(str(exc), 2) from None
            failed += summary.tasks_failed
        data = assemble(plan, [out, *(Path(d) for d in args.solved_in or ())],
                        provenance={"solver": solver.key})
        path = write_text(out / "corrections.json", json.dumps(data, indent=1) + "\n")
        write_manifest(out, [path], {"plan": args.file, "systems": list(systems or []),
                                     "solver": solver.key}, job="corrections build")
    print(f"wrote {path} ({len(data['points'])} points, systems: "
          f"{', '.join(data['systems']) or 'none fitted yet'})")
    return 1 if failed else 0


def _show(args: argparse.Namespace) -> int:
    from ..forward.shipped import ShippedCorrections

    try:
        table = ShippedCorrections.load(args.file, argument="file")
    except ValueError as exc:
        raise CLIError(str(exc), 2) from None
    prov = table.provenance
    print(f"corrections {prov.get('plan')} ({prov.get('date')}, commit "
          f"{str(prov.get('commit'))[:10]}; contacts: {prov.get('contacts', 'earlier')}; "
          f"table boxes {prov.get('boxes_um')} um at {prov.get('voxels_um')} um, packing "
          f"seeds {prov.get('seeds')})")
    solver = prov.get("solver")
    for name, where in (solver.items() if isinstance(solver, dict) else [("all", solver)]):
        print(f"  solved ({name}): {where}")
    print(f"{'formulation':<22}{'resistances (m^2 K/W)':<34}{'c':>8}{'packing sd':>12}"
          f"{'shared sd':>11}")
    for p in table.data["points"]:
        vals = ", ".join(f"{k.split('_')[1]} {v:.1e}" for k, v in p["values"].items())
        print(f"{p['formulation']:<22}{vals:<34}{p['c']:>8.4f}{100 * p['packing_sd']:>11.2f}%"
              f"{100 * p.get('shared_sd', 0.0):>10.2f}%")
    for name, s in table.systems.items():
        lo, hi = s["fraction_range"]
        line = f"fit {name}: fractions {lo:.3f}-{hi:.3f}, rms {100 * s['fit_rms']:.2f} %"
        if "shared" in s:
            sh = s["shared"]
            line += (f"; box {sh['box']['table_box_um']:g} -> {sh['box']['converged_um']:g} um "
                     f"x{sh['box']['factor']:.4f} (sd {100 * sh['box']['sd']:.2f} %), tail sd "
                     f"{100 * sh['tail']['sd']:.2f} %, voxel bias " + ", ".join(
                         f"{100 * q['bias']:+.2f} % (order {q['order']:.2f})"
                         for q in sh["voxel"]["points"]))
        print(line)
    return 0


def add_parser(sub) -> None:
    """Register ``corrections build|show`` on the ``itr`` subparsers ``sub``."""
    cor = sub.add_parser("corrections", help="the shipped faithful corrections",
                         description="Build the faithful corrections of a corrections file "
                         "on the campaign engine, or show a corrections table.")
    actions = cor.add_subparsers(dest="action", required=True, parser_class=Parser)
    build = actions.add_parser("build", help="run (or resume) a corrections file")
    build.add_argument("file", help="corrections file (TOML), e.g. examples/corrections.toml")
    build.add_argument("--out", default=None, help="run folder (new, or this plan's)")
    build.add_argument("--plan", action="store_true",
                       help="print the campaigns, what is done and the hours left; solve "
                            "nothing")
    build.add_argument("--solved-in", action="append", default=None, metavar="DIR",
                       help="a run folder of the same plan on another machine (e.g. a GPU's "
                            "stores): its finished tasks are not solved again and its rows "
                            "join the table (repeatable)")
    build.add_argument("--systems", default=None,
                       help="comma-separated systems of the file (default: all)")
    build.add_argument("--workers", type=number(int, 0, 64, lo_open=False, hi_open=False),
                       default=None,
                       help="workers of the local Dask cluster (0: this process)")
    build.add_argument("--threads", type=number(int, 1, 64, hi_open=False), default=1,
                       help="solver threads per worker of the faithful solves")
    build.add_argument("--scheduler", default=None,
                       help="address of a running Dask scheduler, e.g. tcp://host:8786")
    solver_arguments(build)
    system_arguments(build)
    build.add_argument("--no-progress", action="store_true", help="no progress bar")
    build.set_defaults(func=_build)
    show = actions.add_parser("show", help="print a corrections table")
    show.add_argument("file", nargs="?", default=None,
                      help="corrections.json (default: the one shipped in the package)")
    show.set_defaults(func=_show)
