"""``itr solve VOLUME``: the conductivity tensor of a segmented volume (micro-CT, FIB-SEM)
with interface resistances (the job: :func:`itr_identify.workflows.image_solve.
run_image_solve`; reading, labelling and checks in :mod:`itr_fv.rve`)."""

from __future__ import annotations

import argparse

from itr_fv.solvers.choice import default_solver

from .core import (
    CLIError,
    number,
    output_folder,
    refuse_unfit,
    solver_arguments,
    solver_option,
    system_arguments,
    system_option,
)

__all__ = ["add_parser"]

#: Library argument names as this command spells them.
_FLAGS = {"volume": "VOLUME", "voxel_um": "--voxel-um", "particles": "--particles",
          "phases": "--phase", "resistance": "--resistance", "resistances": "--resistances",
          "split": "--split", "split_distance_voxels": "--split-distance"}


def _flagged(exc: ValueError) -> CLIError:
    """A library refusal ``name: ...`` as a one-line CLIError naming the flag (status 2)."""
    msg = str(exc)
    head, sep, rest = msg.partition(":")
    return CLIError(f"{_FLAGS[head]}:{rest}" if sep and head in _FLAGS else msg, 2)


def _phase_table(args: argparse.Namespace, system, labels):
    from itr_fv.rve.phase_table import PhaseTable, label_values

    if args.phase and args.phases:
        raise CLIError("--phase: give the table by --phase items or by --phases FILE, not "
                       "both", 2)
    if not args.phase and not args.phases:
        present = ", ".join(str(int(v)) for v in label_values(labels)[0][:12])
        raise CLIError(f"--phase: give the phase of each label (--phase 0=matrix --phase "
                       f"1={system.filler_names[0]}, or --phases FILE; labels in the volume: "
                       f"{present})", 2)
    table = (PhaseTable.parse(args.phase, system.matrix) if args.phase
             else PhaseTable.read(args.phases, system.matrix))
    table.check_phases(system.phases, where=f"the material system {system.name!r}")
    return table


def _resistances(args: argparse.Namespace, system, phases) -> tuple[dict, dict]:
    """{pair: value} and the record of the sources (command line over identified.json over
    the system file)."""
    from itr_fv.io import sha256
    from itr_fv.materials.resistance_sources import (
        PRECEDENCE,
        merge_resistances,
        pair_of,
        parse_resistance,
        resistances_from_identified,
        resistances_from_system,
    )

    names, matrix = phases.phases, system.matrix
    given = dict(parse_resistance(t, names, matrix) for t in args.resistance)
    sources = [("command line", given)]
    record: dict = {"precedence": list(PRECEDENCE)}
    if args.resistances:
        values, par, skipped = resistances_from_identified(
            args.resistances, parametrisation=args.parametrisation)
        sources.append(("identified", {pair_of(n, matrix, argument="resistances"): v
                                       for n, v in values.items()}))
        record["identified"] = {"path": args.resistances, "sha256": sha256(args.resistances),
                                "parametrisation": par, "values": values,
                                "not_used": skipped}
    sources.append(("system file", {pair_of(n, matrix, argument="system"): v
                                    for n, v in resistances_from_system(system).items()}))
    merged = merge_resistances(sources)
    record["pairs"] = {"-".join(p): r for p, r in merged.items()}
    return {p: r["value"] for p, r in merged.items()}, record


def _job(args: argparse.Namespace, system, volume, solver):
    from itr_fv.rve.from_image import image_materials, microstructure_from_image
    from itr_fv.rve.volume_files import read_labels

    from ..workflows.image_solve import ImageJob

    phases = _phase_table(args, system, volume.labels)
    resistance, record = _resistances(args, system, phases)
    particles, how = None, {"method": "connected components per filler phase (face "
                                      "connectivity, periodic)"}
    if args.particles:
        particles = read_labels(args.particles, array=args.particles_array,
                                argument="particles")[0]
        how = {"method": "given", "path": args.particles}
    elif args.split:
        how = {"method": "watershed split of each filler phase",
               "split_distance_voxels": args.split_distance}
    ms = microstructure_from_image(volume, phases, particles=particles, split=args.split,
                                   split_distance_voxels=args.split_distance)
    mat = image_materials(ms, system.conductivities(phases.fillers), resistance)
    return ImageJob(volume, phases, ms, mat, record, how, solver, args.tol, system.to_dict())


def _run(args: argparse.Namespace) -> int:
    from itr_fv.materials import default_system
    from itr_fv.rve.volume_files import read_volume

    from ..workflows.image_solve import ImagePlan, run_image_solve

    system = system_option(args) or default_system()
    solver = solver_option(args)
    if args.particles and args.split:
        raise CLIError("--split: the particles are given (--particles); a split is for "
                       "particles found in the phases", 2)
    try:
        volume = read_volume(args.volume, voxel_um=args.voxel_um, array=args.array)
        plan = ImagePlan(volume.shape, volume.voxel_um, solver)
        refuse_unfit(plan)
        job = _job(args, system, volume, solver)
    except ValueError as exc:
        raise _flagged(exc) from None
    if args.plan:
        print(plan.summary())
        print(plan.alternatives())
        return 0
    with output_folder(args.out, "solve", workload=plan) as out:
        run_image_solve(job, out, progress=not args.no_progress)
    return 0


def add_parser(sub) -> None:
    """Register ``solve`` on the ``itr`` subparsers ``sub``."""
    p = sub.add_parser("solve", help="conductivity tensor of your segmented volume",
                       description="The effective conductivity tensor of a segmented volume "
                       "(TIFF stack, .npy, .npz, .vti, .vtk, .raw + header) with interface "
                       "resistances: result.json, image.vti, slice.png, manifest.json "
                       "(docs/images.md).")
    p.add_argument("volume", metavar="VOLUME", help="label image, one integer label per phase")
    p.add_argument("--voxel-um", type=number(float, 0, None, unit=" um"), default=None,
                   help="voxel edge, um (default: the file's; refused where they disagree)")
    p.add_argument("--array", default=None, metavar="NAME",
                   help="the label array of an .npz or VTK file that holds several")
    p.add_argument("--phase", action="append", default=[], metavar="LABEL=PHASE",
                   help="phase of a label value, a phase of the system or 'matrix'; repeat "
                   "per label (e.g. --phase 0=matrix --phase 1=Al2O3)")
    p.add_argument("--phases", default=None, metavar="FILE",
                   help="the phase table as a TOML file: [phases] 0 = \"matrix\" ...")
    p.add_argument("--particles", default=None, metavar="FILE",
                   help="one label per particle (0 on the matrix), same shape (default: "
                   "connected components of each filler phase)")
    p.add_argument("--particles-array", default=None, metavar="NAME",
                   help="the array of --particles in an .npz or VTK file that holds several")
    p.add_argument("--split", choices=["watershed"], default=None,
                   help="split touching particles of one phase by a watershed of the "
                   "distance map (needs scikit-image)")
    p.add_argument("--split-distance", type=number(int, 1, None, lo_open=False), default=5,
                   metavar="VOXELS", help="least distance between two particle centres of "
                   "the watershed split, voxels (default 5)")
    p.add_argument("--resistance", action="append", default=[], metavar="PAIR=VALUE",
                   help="interface resistance, m^2 K/W: Al2O3-matrix=1e-8 (filler-matrix), "
                   "Al2O3-Al2O3=5e-8 (contacts between particles); repeat per pair; over "
                   "--resistances and the system file")
    p.add_argument("--resistances", default=None, metavar="FILE",
                   help="identified.json of itr identify/reproduce: its quoted best values "
                   "(over the system file's)")
    p.add_argument("--parametrisation", choices=["area", "gap"], default=None,
                   help="the parametrisation of --resistances to read (default: the one its "
                   "headline quotes)")
    system_arguments(p)
    solver_arguments(p, default=default_solver())
    p.add_argument("--tol", type=number(float, 1e-12, 1, lo_open=False), default=1e-8,
                   help="relative residual, in [1e-12, 1) (default 1e-8)")
    p.add_argument("--out", default="itr-solve", help="output folder (default itr-solve)")
    p.add_argument("--plan", action="store_true",
                   help="check the inputs, print the plan (memory, time) and stop, before "
                   "any solving")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar (the load cases by decades of their residual)")
    p.set_defaults(func=_run)
