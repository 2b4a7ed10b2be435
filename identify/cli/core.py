"""The common core of the ``itr`` command line: its error, argument parser and number
types, flag names, the output folder, and the flags and readers that several commands share.
The command modules (:mod:`~itr_identify.cli.demo`, :mod:`~itr_identify.cli.campaign`,
:mod:`~itr_identify.cli.surrogate`, :mod:`~itr_identify.cli.reproduce`,
:mod:`~itr_identify.cli.identify`, :mod:`~itr_identify.cli.discrepancy`) import this
module; :mod:`~itr_identify.cli.dispatch` registers them and runs ``main``.

Every failure is one line on standard error, ``itr: error: ...`` naming the flag where a
flag is at fault, with exit status 2 for bad input (usage, values, output folder) and 1 for a
failure while running (packing, solver, memory, disk). No traceback is shown unless the
environment sets ``ITR_DEBUG=1``. An output folder that the command created is removed
again when the run fails; files are written atomically and ``manifest.json`` last.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import shutil
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from itr_fv.solvers.choice import Solver

__all__ = ["CLIError", "Parser", "number", "FLAG_NAMES", "flagged", "output_folder", "planned",
           "refuse_unfit",
           "identification_plan",
           "engine_arguments", "engine_options", "solver_arguments", "solver_option",
           "open_campaign", "rve_arguments", "forward_settings", "read_table",
           "identification_arguments", "reproduce_settings", "system_arguments",
           "system_option"]

#: Library argument names as the command line spells them, for error messages.
FLAG_NAMES = {"box_um": "--box-um", "voxel_um": "--voxel-um", "volume_fraction": "--fraction",
              "seed": "--seed", "tol": "--tol", "path": "--out"}


class CLIError(Exception):
    """A failure to report as one line; ``status`` 2 for bad input, 1 for a runtime failure."""

    def __init__(self, message: str, status: int = 1) -> None:
        super().__init__(message)
        self.status = status


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage block), exit status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise CLIError(message, 2)


def number(kind: Callable[[str], float], lo: float | None = None, hi: float | None = None,
            lo_open: bool = True, hi_open: bool = True, unit: str = "") -> Callable[[str], float]:
    """argparse type: a finite number in an interval (open or closed at each end)."""
    def parse(text: str) -> float:
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a {'whole ' if kind is int else ''}number: "
                                             f"{text!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
        bad_lo = lo is not None and (v <= lo if lo_open else v < lo)
        bad_hi = hi is not None and (v >= hi if hi_open else v > hi)
        if bad_lo or bad_hi:
            left = "(" if lo_open else "["
            right = ")" if hi_open else "]"
            span = f"{left}{'-inf' if lo is None else f'{lo:g}'}, " \
                   f"{'inf' if hi is None else f'{hi:g}'}{right}"
            raise argparse.ArgumentTypeError(f"expected a value in {span}{unit}, got {text}")
        return v
    return parse


def flagged(message: str) -> str:
    """Translate a library message 'voxel_um: ...' into the flag's spelling '--voxel-um: ...'."""
    head, sep, rest = message.partition(":")
    name = head.strip().split("[")[0].split(" ")[0]
    if sep and name in FLAG_NAMES:
        return f"{FLAG_NAMES[name]}{head.strip()[len(name):]}:{rest}"
    return message


@contextlib.contextmanager
def output_folder(path: str, job: str, *, folders: Sequence[str] = (),
                  workload=None) -> Iterator[Path]:
    """Check the ``--out`` folder for ``itr <job>`` (:func:`itr_fv.run_folder.check`: new,
    empty or an earlier run of the same command; anything else refused in one line, nothing
    touched), then refuse a ``workload`` that cannot fit (:func:`refuse_unfit`), then claim
    the folder (:func:`itr_fv.run_folder.begin_run`) and print the workload's plan; remove
    the folder again if the run fails and we made it, unless it keeps finished work in one
    of its owned ``folders``.

    Raises
    ------
    CLIError
        (status 2) if ``path`` is a file, lies under a file, holds anything that is not an
        earlier ``itr <job>`` run's, or cannot be written; or the workload cannot fit.
    """
    from itr_fv.io import counted
    from itr_fv.run_folder import FolderRefused, begin_run, check, release

    out = Path(path)
    try:
        check(out, f"itr {job}")
    except FolderRefused as exc:
        raise CLIError(str(exc), 2) from None
    if workload is not None:
        refuse_unfit(workload)
    created = not out.exists()
    try:
        earlier = begin_run(out, job, folders=folders)
    except FolderRefused as exc:
        raise CLIError(str(exc), 2) from None
    except OSError as exc:
        if created:
            shutil.rmtree(out, ignore_errors=True)
        raise CLIError(f"--out: cannot write to {path!r} ({exc.strerror or exc})", 2) from None
    if earlier is not None:
        kept = sum(1 for f in folders for _ in (out / f).rglob("*.parquet"))
        print(f"--out: {path!r} holds an earlier 'itr {job}' run: the files its manifest "
              f"lists are replaced" + (f", {counted(kept, 'finished solve')} kept"
                                       if folders else ""), file=sys.stderr)
    if workload is not None:
        print(workload.summary())
        print(workload.alternatives())
    try:
        yield out
    except BaseException:
        release(out)
        # a folder this run made goes again, unless it keeps finished work
        if created and not any((out / f).is_dir() and any((out / f).iterdir())
                               for f in folders):
            shutil.rmtree(out, ignore_errors=True)
        raise
    release(out)


# ------------------------------------------------------------------- shared by several commands
def refuse_unfit(workload) -> None:
    """Refuse (status 2, one line) a :class:`~itr_surrogate.workload.Workload` that cannot
    fit in memory: before any packing, solving or writing."""
    from itr_surrogate.workload import WorkloadRefused

    try:
        workload.check()
    except WorkloadRefused as exc:
        raise CLIError(str(exc), 2) from None


def planned(workload) -> None:
    """:func:`refuse_unfit`, else print the workload's plan (one line)."""
    refuse_unfit(workload)
    print(workload.summary())


def identification_plan(args: argparse.Namespace, settings, formulations, *,
                        validation: bool):
    """The :class:`~itr_surrogate.workload.Workload` of ``itr identify`` and ``itr
    reproduce``: identifying ``formulations`` with ``settings`` (a ReproduceSettings)."""
    from ..forward.work_estimate import identification_workload
    from ..inference.formulations import fractions_of

    system = settings.forward.system
    return identification_workload(
        settings.forward, {f: fractions_of(f, system) for f in formulations},
        settings.parametrisations, validation=validation, workers=args.workers,
        scheduler=args.scheduler)


def open_campaign(folder: str):
    """The :class:`~itr_surrogate.store.CampaignStore` of a campaign folder (``DIR`` of
    ``itr campaign status|export`` and ``itr surrogate fit``); a CLIError (status 2) when
    the folder holds no campaign or a broken one."""
    from itr_surrogate.campaign import CampaignError
    from itr_surrogate.store import CampaignStore

    store = CampaignStore(folder)
    if not store.campaign_file.exists():
        raise CLIError(f"DIR: {folder!r} holds no campaign (no campaign.json)", 2)
    try:
        store.campaign()
    except CampaignError as exc:
        raise CLIError(f"DIR: {folder!r}: {exc}", 2) from None
    return store


def rve_arguments(p: argparse.ArgumentParser, *, box: str, voxel: str) -> None:
    """--box-um, --voxel-um, --replicas, --seed (read by :func:`forward_settings`); ``box``
    and ``voxel`` are the defaults as the help shows them."""
    p.add_argument("--box-um", type=number(float, 0, None, unit=" um"), default=None,
                   help=f"RVE edge, um (default {box})")
    p.add_argument("--voxel-um", type=number(float, 0, None, unit=" um"), default=None,
                   help=f"voxel edge, um (default {voxel})")
    p.add_argument("--replicas", type=number(int, 1, 20, hi_open=False), default=None,
                   help="RVE replicas per formulation, 2-20 (default 3)")
    p.add_argument("--seed", type=number(int, 0, None, lo_open=False), default=None,
                   help="packing seed of the first replica (default 1)")
    p.add_argument("--film-nm", type=number(float, 0, 100, lo_open=False, unit=" nm"),
                   default=None, help="silicone film at which touching particles meet, nm, "
                   "the same for every particle size, held in the intervals (default: "
                   "the models at 0, in contact through the two interface resistances "
                   "alone, and the film marginalised over 0-5 nm); the packing does not "
                   "change with it")
    p.add_argument("--psd-basis", choices=["number", "volume"], default=None,
                   help="weighting of Table 1's lognormals (default number: the paper's "
                   "reading; volume: a laser-diffraction analyser's default)")


def forward_settings(fw, args: argparse.Namespace):
    """``fw`` (a ForwardSettings) with the command line's --box-um, --voxel-um, --replicas,
    --seed, --film-nm, --psd-basis, --solver and --device; a bad value is a CLIError naming
    the flag."""
    film = getattr(args, "film_nm", None)
    solver = solver_option(args, fw.solver) if hasattr(args, "solver") else None
    changes = {k: v for k, v in (("box_um", args.box_um), ("voxel_um", args.voxel_um),
                                 ("replicas", args.replicas), ("seed", args.seed),
                                 ("film_um", None if film is None else film / 1000),
                                 ("psd_basis", getattr(args, "psd_basis", None)),
                                 ("solver", solver))
               if v is not None}
    try:
        return fw.with_(**changes)
    except ValueError as exc:
        msg = str(exc)
        # (the box/voxel rule's message stays as itr_fv.rve.spec words it: the same line
        # from every command and from campaign files)
        for name, flag in (("box_um", "--box-um"), ("voxel_um", "--voxel-um"),
                           ("replicas", "--replicas")):
            if msg.startswith(name + ":"):
                msg = flag + msg[len(name):]
                break
        raise CLIError(msg, 2) from None


def read_table(path: str | None, reader: Callable, system=None):
    """``reader(path)`` with formulations named by composition in ``system`` (a
    MaterialSystem; default the package's); a bad file is a CLIError (status 2) naming
    MEASUREMENTS."""
    try:
        return reader(path, system=system)
    except ValueError as exc:
        msg = str(exc)
        raise CLIError("MEASUREMENTS: " + (msg[len("path: "):] if msg.startswith("path: ")
                                           else msg), 2) from None


def solver_arguments(p: argparse.ArgumentParser, *, default: str | None = None) -> None:
    """--solver NAME and --device cpu|cuda|auto: what solves and where (read by
    :func:`solver_option`). ``default`` None: the solver is taken from elsewhere (a
    campaign file) unless given."""
    from itr_fv.solvers.choice import DEFAULT_DEVICE, DEVICES, SOLVERS

    names = ", ".join(f"{n} ({c.summary})" for n, c in SOLVERS.items())
    p.add_argument("--solver", default=default, metavar="NAME",
                   help=f"the full solver: {names}, auto (gpu on a CUDA device, else fft), "
                   "or a registered backend name"
                   + (f" (default {default})" if default else " (default: the file's)"))
    p.add_argument("--device", choices=DEVICES, default=None,
                   help="where to solve: cpu, cuda (refused at once without a CUDA device) "
                   "or auto (a CUDA device where one is seen) (default: the solver's, "
                   f"{DEFAULT_DEVICE} but for gpu); fft on cuda is the gpu solver")


def solver_option(args: argparse.Namespace, solver: Solver | None = None) -> Solver:
    """The resolved solver of --solver (else ``solver``) and --device; a CLIError
    (status 2) naming the flag when they do not go together or no CUDA device is seen.
    With --scheduler the device is the workers' business: ``cuda`` is not checked here
    (the engine refuses before submitting when no worker declares a GPU)."""
    from itr_fv.solvers.choice import resolve_solver

    name = getattr(args, "solver", None) or solver
    device = getattr(args, "device", None)
    try:
        return resolve_solver(name, device, solver_argument="--solver",
                              device_argument="--device",
                              local=not getattr(args, "scheduler", None))
    except ValueError as exc:
        raise CLIError(str(exc), 2) from None


def engine_arguments(p: argparse.ArgumentParser) -> None:
    """--workers N and --scheduler ADDRESS: where the full solves run; --store DIR: where
    they are kept (read by :func:`engine_options`); --solver and --device: what solves
    (:func:`solver_arguments`)."""
    from itr_fv.solvers.choice import default_solver

    solver_arguments(p, default=default_solver())
    p.add_argument("--workers", type=number(int, 1, 64, hi_open=False), default=None,
                   help="run the full solves on a local Dask cluster of N processes "
                   "(default: in this process, the fastest on 2 cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the full solves on a running Dask scheduler "
                   "(tcp://host:port)")
    p.add_argument("--store", default=None, metavar="DIR",
                   help="keep and reuse the full solves in DIR (default OUT/solves); runs "
                   "that share a DIR share their solves, which do not depend on the "
                   "measurements")
    p.add_argument("--keep-fields", action="store_true",
                   help="keep the temperature fields of the reduced bases' full solves in "
                   "the store when the run ends (2.65 MB each at 48^3, about 320 MB for "
                   "itr reproduce), so that a later run on the same store solves none of "
                   "them again; by default they are kept only while the run lasts (a "
                   "killed run still resumes from them)")


def engine_options(args: argparse.Namespace) -> dict:
    """``workers``, ``scheduler``, ``store`` and ``keep_fields`` of the solve engine from
    the command line."""
    store = getattr(args, "store", None)
    if store is not None and Path(store).exists() and not Path(store).is_dir():
        raise CLIError(f"--store: {store!r} is a file, not a folder", 2)
    return {"workers": args.workers, "scheduler": args.scheduler, "store": store,
            "keep_fields": args.keep_fields}


def identification_arguments(p: argparse.ArgumentParser) -> None:
    """The flags that ``itr reproduce`` and ``itr identify`` share (read by
    :func:`reproduce_settings`)."""
    p.add_argument("--parametrisation", choices=["area", "gap", "both"], default="both",
                   help="area (the paper's per-area contact resistance), gap (physical "
                   "contacts) or both (default)")
    rve_arguments(p, box="the system's powders': 12 for the paper's",
                  voxel="the system's powders': 0.25 for the paper's")
    p.add_argument("--fidelity", choices=["shipped", "quick", "standard", "paper"],
                   default=None,
                   help="how the gap parametrisation's models are corrected: shipped "
                   "(default; the corrections shipped with the package, converged boxes, "
                   "`itr corrections show`; a formulation they do not hold is corrected as "
                   "at standard), quick (none: the 12 um RVE's level), standard (runtime "
                   "full solves on 24 um boxes at 0.2 and 0.25 um; 48 min for reproduce on 2 "
                   "cores), paper (40 um boxes at 0.1 and 0.125 um; hours)")
    p.add_argument("--conductivity-sd", action="append", default=[], metavar="PHASE=SD",
                   help="relative standard deviation of a phase's conductivity, "
                   "marginalised in the intervals (defaults: the material system's; the "
                   "paper's silicone 0.10, Al2O3 0.15, AlN 0.25; e.g. silicone=0.02 for a "
                   "measured matrix, 0 to hold it at its nominal value); repeat per phase")
    p.add_argument("--discrepancy", action="store_true",
                   help="run the discrepancy verdict on the gap identification's own model: "
                   "the library's eight effects as terms of its joint posterior, base and "
                   "candidates without the model-form term (ratio solves on its first "
                   "replicas; report section Discrepancy)")
    p.add_argument("--effect", default=None, metavar="NAME",
                   help="fit this effect's parameters jointly with the resistances, beside "
                   "the base model (matrix, filler, porosity, fraction, spots, tester, batch, "
                   "film; default: the one the verdict names)")
    engine_arguments(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def conductivity_sds(args: argparse.Namespace, system) -> dict[str, float]:
    """``--conductivity-sd PHASE=SD`` as {phase: sd} for the phases of ``system``; a bad
    one is a CLIError naming the flag."""
    out = {}
    for item in getattr(args, "conductivity_sd", []) or []:
        phase, _, value = item.partition("=")
        if phase not in system.phases:
            raise CLIError(f"--conductivity-sd: unknown phase {phase!r} (known: "
                           f"{', '.join(sorted(system.phases))})", 2)
        try:
            sd = float(value)
        except ValueError:
            sd = math.nan
        if not 0 <= sd <= 1:
            raise CLIError(f"--conductivity-sd: expected PHASE=SD with a relative sd in "
                           f"[0, 1], got {item!r}", 2)
        out[phase] = sd
    return out


def reproduce_settings(args: argparse.Namespace):
    """The ReproduceSettings of ``itr reproduce`` and ``itr identify`` from their flags."""
    from ..discrepancy.joint_effects import JOINT_EFFECTS
    from ..workflows.reproduce import DEFAULT_FIDELITY, ReproduceSettings

    base = ReproduceSettings.at_fidelity(args.fidelity or DEFAULT_FIDELITY,
                                         system_option(args))
    fw = forward_settings(base.forward, args)
    corrections = getattr(args, "corrections", None)
    if corrections is not None:
        fw = fw.with_(faithful=_with_corrections(fw, corrections))
    pars = ("area", "gap") if args.parametrisation == "both" else (args.parametrisation,)
    sds = conductivity_sds(args, fw.system)
    effect = getattr(args, "effect", None)
    if effect is not None and effect not in JOINT_EFFECTS:
        raise CLIError(f"--effect: unknown effect {effect!r} (known: "
                       f"{', '.join(JOINT_EFFECTS)})", 2)
    if (effect or getattr(args, "discrepancy", False)) and "gap" not in pars:
        raise CLIError("--effect, --discrepancy: fitted on the gap identification; use "
                       "--parametrisation gap or both", 2)
    return ReproduceSettings(forward=fw, parametrisations=pars,
                             leave_one_out=not getattr(args, "no_leave_one_out", False),
                             conductivity_sd=tuple(sorted(sds.items())),
                             discrepancy=bool(getattr(args, "discrepancy", False)),
                             effect=effect)


def _with_corrections(fw, path: str):
    """The settings' fidelity level reading the corrections file ``path``; a CLIError
    (status 2) naming --corrections for a level without tabled corrections or a file that
    is none, or that holds for another system or cheap RVE."""
    from dataclasses import replace

    from ..forward.shipped import ShippedCorrections

    fa = fw.faithful
    if fa is None or not fa.shipped:
        raise CLIError("--corrections: a corrections file is used at --fidelity shipped "
                       "(the default), not at this level", 2)
    try:
        why = ShippedCorrections.load(path, argument="--corrections").why_not_for(
            fw.system, fw.rve)
    except ValueError as exc:
        raise CLIError(str(exc), 2) from None
    if why:
        raise CLIError(f"--corrections: {path}: {why}", 2)
    return replace(fa, corrections=str(path))


def system_arguments(p: argparse.ArgumentParser) -> None:
    """--system FILE: the material system (read by :func:`system_option`)."""
    p.add_argument("--system", default=None, metavar="FILE",
                   help="material-system file (TOML: the matrix and fillers, their "
                   "conductivities, densities and size distributions; examples/*/system.toml; "
                   "`itr materials` lists the phases it may name without a value) "
                   "(default: the paper's system, examples/paper/system.toml)")


def system_option(args: argparse.Namespace):
    """The MaterialSystem of --system (None where not given); a bad file is a CLIError
    (status 2) in one line naming the flag, the file and the key."""
    path = getattr(args, "system", None)
    if path is None:
        return None
    from itr_fv.materials.system_file import read_system

    try:
        return read_system(path)
    except ValueError as exc:
        raise CLIError(f"--system: {exc}", 2) from None
