"""A high-throughput campaign: formulations x RVE replicas x parameter sets.

A :class:`Campaign` is read from a TOML file (:meth:`Campaign.from_toml`) or built from the
same structure in Python (:meth:`Campaign.from_dict`). Everything is checked before any work
starts; an error names the key. The file::

    name = "tiny"                  # optional label
    box_um = 6.0                   # RVE box edge, um
    voxel_um = 0.25                # voxel edge, um (box / voxel a whole number)
    replicas = 2                   # RVEs per formulation (seeds seed, seed + 1, ...)
    seed = 1
    contact = "gap"                # "gap" (default) or "area" (the paper's per-area R_ff)
    solver = "fft"                 # one of (itr_fv.solvers.choice):
                                   #  "fft" (default) numba FFT-PCG on the CPU;
                                   #  "mg"  the same, multigrid-preconditioned (high
                                   #        contrast, resistive interfaces);
                                   #  "gpu" array-API PCG on a CUDA device: a local
                                   #        cluster gets one worker per GPU; an external
                                   #        one needs 'dask worker ADDR --resources GPU=1';
                                   #  "fv"  the pyamg finite-volume reference (slower);
                                   #  "auto" gpu where a CUDA device is seen, else fft;
                                   #  or a registered backend name, e.g. "scipy_fft"
    tol = 1e-6                     # relative residual of every solve
    block_size = 8                 # parameter sets per task (one RVE geometry per task)
    max_diameter_box_ratio = 0.45  # largest particle diameter / box
    min_gap_um = 0.0               # thinnest matrix film the packer keeps, um
    film_um = 0.002                # optional: the film touching particles meet at, um
                                   # (default min_gap_um; the same packing at any film)
    tail_quantile = 1e-4           # optional: number quantile cut off each far size tail
    cut_voxel_um = 0.2             # optional: pack with this voxel's fine-tail cut (the
                                   # same particles as a campaign at 0.2 um, re-voxelized)
    threads_per_worker = 1         # solver threads in each worker
    matrix = "silicone"

    [base]                         # values every parameter set starts from (flat names);
    k_Al2O3 = 30.0                 # default: the paper's k and Table 5 filler-matrix R
    R_Al2O3_silicone = 2.2e-8

    [[formulation]]                # a Table 2 name alone takes the shipped fractions
    name = "Al2O3-60"

    [[formulation]]
    name = "Al2O3-40"
    fractions = { Al2O3 = 0.40 }   # volume fractions; size distributions from Table 1
    psd = { Al2O3 = [1.02, 0.35] } # optional: mu, sigma of ln(D / 1 um)

    [design]
    kind = "grid"                  # "table4", "grid", "points" or "space_filling"
    values = { R_Al2O3_silicone = [1e-8, 1e-7] }       # grid
    # points = [{ R_Al2O3_silicone = 1e-8 }, { R_Al2O3_silicone = 5e-8 }]  # points
    # n = 20, seed = 0, bounds = { R_Al2O3_silicone = [1e-8, 5e-5] }  # space_filling

Parameter names are the package's flat names (:mod:`itr_fv.materials.parameters`). A task is one RVE
(formulation, replica) with one block of consecutive parameter sets: the runner builds the
RVE and its discrete problem once per task and warm-starts every solve from the nearest
solved set (:mod:`itr_surrogate.runner`).
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from itr_fv import Materials
from itr_fv.checks import unknown_key
from itr_fv.io import read_toml
from itr_fv.materials import default_system, is_default_system, paper_data
from itr_fv.materials.formulation_names import (
    UnknownFormulationError,
    formulation_name,
    fractions_of,
)
from itr_fv.materials.material_system import MaterialSystem
from itr_fv.materials.parameters import parameter_name
from itr_fv.rve import FillerSpec, packing_limit
from itr_fv.rve.spec import RVESpec
from itr_fv.solvers.choice import Solver, as_solver, default_solver

from . import design as designs

__all__ = ["Campaign", "Formulation", "Task", "CampaignError", "PAPER_BASE", "nearest_solved"]

#: The paper's conductivities (W/(m K)) and Table 5 filler-matrix resistances (m^2 K/W).
PAPER_BASE = paper_data.paper_parameters()

_TOP_KEYS = {"name", "box_um", "voxel_um", "replicas", "seed", "contact", "solver", "tol",
             "block_size", "max_diameter_box_ratio", "min_gap_um", "film_um", "cut_voxel_um",
             "tail_quantile",
             "threads_per_worker", "matrix", "base", "formulation", "design"}
_DESIGN_KEYS = {"table4": {"kind"}, "grid": {"kind", "values"}, "points": {"kind", "points"},
                "space_filling": {"kind", "n", "seed", "bounds"}}
#: The file's keys that make its :class:`~itr_fv.rve.spec.RVESpec`.
_RVE_KEYS = ("box_um", "voxel_um", "seed", "max_diameter_box_ratio", "min_gap_um",
             "cut_voxel_um", "film_um", "tail_quantile")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9.+-]*$")


class CampaignError(ValueError):
    """A campaign file or object that cannot run; the message names the key."""


@dataclass(frozen=True)
class Formulation:
    """One composition: filler volume fractions and their size distributions (Table 1)."""

    name: str
    fractions: dict[str, float]
    psd: dict[str, tuple[float, float]]

    def specs(self) -> list[FillerSpec]:
        return [FillerSpec(f, mu=self.psd[f][0], sigma=self.psd[f][1], volume_fraction=v)
                for f, v in self.fractions.items()]


@dataclass(frozen=True)
class Task:
    """One RVE (formulation, replica) and a block of parameter-set indices."""

    task_id: str
    formulation: str
    replica: int
    seed: int
    block: int
    set_indices: tuple[int, ...]


@dataclass(frozen=True)
class Campaign:
    """A checked campaign (see the module docstring for the keys and their meaning)."""

    formulations: tuple[Formulation, ...]
    design: dict[str, Any]
    rve: RVESpec
    name: str = "campaign"
    replicas: int = 1
    contact: str = "gap"
    solver: Solver = field(default_factory=default_solver)
    tol: float = 1e-6
    block_size: int = 8
    threads_per_worker: int = 1
    matrix: str = field(default_factory=lambda: default_system().matrix)
    base: dict[str, float] = field(default_factory=dict)

    # the RVE's fields, read through (the specification holds and checks them)
    box_um = property(lambda self: self.rve.box_um, doc="RVE edge, um.")
    voxel_um = property(lambda self: self.rve.voxel_um, doc="Voxel edge, um.")
    seed = property(lambda self: self.rve.seed, doc="Packing seed of replica 0.")
    max_diameter_box_ratio = property(lambda self: self.rve.max_diameter_box_ratio,
                                      doc="Largest particle diameter / box edge.")
    min_gap_um = property(lambda self: self.rve.min_gap_um,
                          doc="Thinnest matrix film between two particles, um.")

    def __post_init__(self) -> None:
        """The solver as a :class:`~itr_fv.solvers.choice.Solver` (a name of a file is
        resolved here, once; CampaignError naming ``solver``)."""
        try:
            object.__setattr__(self, "solver", as_solver(self.solver))
        except ValueError as err:
            raise CampaignError(str(err)) from None

    # ------------------------------------------------------------------ reading
    @classmethod
    def from_toml(cls, path: str | Path, system: MaterialSystem | None = None) -> "Campaign":
        """Read and check a campaign file (CampaignError naming the file and key); its
        formulations, matrix, size distributions and base conductivities are those of
        ``system`` (default: the package's, the paper's) where the file does not state
        them."""
        p = Path(path)
        try:
            data = read_toml(p, "campaign file")
        except ValueError as exc:
            raise CampaignError(str(exc)) from None
        try:
            return cls.from_dict(data, system)
        except CampaignError as exc:
            raise CampaignError(f"{p}: {exc}") from None

    @classmethod
    def from_dict(cls, data: dict[str, Any],
                  system: MaterialSystem | None = None) -> "Campaign":
        """Build and check a campaign from the structure of the TOML file, in ``system``
        (default: the package's)."""
        system = system or default_system()
        if not isinstance(data, dict):
            raise CampaignError("expected a table of campaign keys")
        unknown = unknown_key(data, _TOP_KEYS)
        if unknown:
            raise CampaignError(unknown)
        for key in ("box_um", "voxel_um", "formulation", "design"):
            if key not in data:
                raise CampaignError(f"missing key {key!r}")
        scalars = {k: v for k, v in data.items()
                   if k not in ("formulation", "design", "base", *_RVE_KEYS)}
        try:
            rve = RVESpec(**{k: data[k] for k in _RVE_KEYS if k in data})
        except ValueError as exc:
            raise CampaignError(str(exc)) from None
        scalars.setdefault("matrix", system.matrix)
        # a campaign in another matrix (a stored one, read back by a worker) is complete
        # in itself: nothing of the default system is added to its base
        defaults = system_base(system) if scalars["matrix"] == system.matrix else {}
        camp = cls(formulations=tuple(_formulation(f, i, system)
                                      for i, f in enumerate(_list(data["formulation"]))),
                   design=_design(data["design"]), rve=rve,
                   base={**defaults, **_base(data.get("base", {}))}, **scalars)
        camp.check()
        return camp

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able form; ``from_dict(to_dict())`` gives the same campaign."""
        d = asdict(self)
        d["solver"] = self.solver.key
        del d["rve"]
        d.update({k: getattr(self.rve, k) for k in _RVE_KEYS})
        for optional in ("cut_voxel_um", "film_um"):
            if d[optional] is None:  # unset: the forms (and fingerprints) of earlier runs
                del d[optional]
        if d["tail_quantile"] == RVESpec.tail_quantile:  # the default: as earlier runs wrote
            del d["tail_quantile"]
        d["formulation"] = [{"name": f.name, "fractions": f.fractions,
                             "psd": {k: list(v) for k, v in f.psd.items()}}
                            for f in self.formulations]
        del d["formulations"]
        return d

    def fingerprint(self) -> str:
        """SHA-256 of the canonical JSON form: two runs are the same campaign iff equal."""
        text = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()

    # ----------------------------------------------------------------- checking
    def check(self) -> None:
        """Every value and every parameter set, before any work (CampaignError)."""
        if not isinstance(self.rve, RVESpec):
            raise CampaignError(f"rve: expected an RVESpec, got {type(self.rve).__name__}")
        for key in ("replicas", "block_size", "threads_per_worker"):
            _whole(getattr(self, key), key, 1)
        if self.contact not in ("gap", "area"):
            raise CampaignError(f"contact: expected 'gap' or 'area', got {self.contact!r}")
        if not (isinstance(self.tol, (int, float)) and 1e-12 <= self.tol < 1):
            raise CampaignError(f"tol: expected a relative residual in [1e-12, 1), got "
                                f"{self.tol!r}")
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise CampaignError(f"name: letters, digits and . + - only, got {self.name!r}")
        if not self.formulations:
            raise CampaignError("formulation: give at least one [[formulation]]")
        try:
            Materials.from_parameters(self.base, self.matrix, contact=self.contact)
        except ValueError as exc:
            raise CampaignError(f"base: {exc}") from None
        names = [f.name for f in self.formulations]
        if len(set(names)) != len(names):
            raise CampaignError(f"formulation: a name appears twice in {names}")
        for f in self.formulations:
            self._check_formulation(f)

    def _check_formulation(self, f: Formulation) -> None:
        where = f"formulation {f.name!r}"
        try:
            specs = f.specs()
        except ValueError as exc:
            raise CampaignError(f"{where}: {exc}") from None
        limit, _ = packing_limit(specs)
        total = sum(f.fractions.values())
        if total >= limit:
            raise CampaignError(f"{where}: total volume fraction {total:.3f} is beyond what "
                                f"can be packed (estimate {limit:.3f} for these sizes)")
        sets = self.parameter_sets(f)
        if not sets:
            raise CampaignError(f"design: no parameter set for {where}")
        for i, s in enumerate(sets):
            try:
                mat = self.materials(s)
            except ValueError as exc:
                raise CampaignError(f"design: parameter set {i} of {where}: {exc}") from None
            missing = [p for p in (self.matrix, *f.fractions) if p not in mat.conductivity]
            if missing:
                raise CampaignError(f"base: {where} needs k_{missing[0]}")
            for filler in f.fractions:
                try:
                    mat.resistance_between(filler, self.matrix)
                except ValueError:
                    name = "R_" + "_".join(sorted((filler, self.matrix)))
                    raise CampaignError(f"base: {where} needs {name}") from None

    # ------------------------------------------------------------------ content
    @property
    def shape(self) -> tuple[int, int, int]:
        return self.rve.shape

    def formulation(self, name: str) -> Formulation:
        for f in self.formulations:
            if f.name == name:
                return f
        raise CampaignError(f"formulation: no formulation {name!r} in this campaign")

    def parameter_sets(self, f: Formulation) -> list[dict[str, float]]:
        """The design's parameter sets for formulation ``f`` (only the varied names)."""
        kind = self.design["kind"]
        try:
            if kind == "table4":
                return designs.table4(list(f.fractions), contact=self.contact,
                                      matrix=self.matrix)
            if kind == "grid":
                return designs.grid(self.design["values"])
            if kind == "points":
                return designs.points(self.design["points"])
            return designs.space_filling(self.design["bounds"], self.design["n"],
                                         self.design.get("seed", 0))
        except ValueError as exc:
            raise CampaignError(f"design: {exc}") from None

    def materials(self, parameter_set: dict[str, float]) -> Materials:
        """Materials of one parameter set: the base values with the set's replaced."""
        return Materials.from_parameters({**self.base, **parameter_set}, self.matrix,
                                         contact=self.contact)

    def tasks(self) -> list[Task]:
        """Every task of the campaign, in a fixed order."""
        out = []
        for f in self.formulations:
            n_sets = len(self.parameter_sets(f))
            blocks = [tuple(range(i, min(i + self.block_size, n_sets)))
                      for i in range(0, n_sets, self.block_size)]
            for r in range(self.replicas):
                for b, idx in enumerate(blocks):
                    out.append(Task(f"{f.name}__r{r}__b{b:04d}", f.name, r, self.seed + r, b,
                                    idx))
        return out

    def n_solves(self) -> int:
        return sum(len(t.set_indices) for t in self.tasks())


# ---------------------------------------------------------------------- helpers
def _list(value: Any) -> list:
    if isinstance(value, dict):
        return [value]
    if not isinstance(value, list):
        raise CampaignError("formulation: expected [[formulation]] tables")
    return value


def _whole(value: Any, key: str, low: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise CampaignError(f"{key}: expected a whole number >= {low}, got {value!r}")


def _base(table: Any) -> dict[str, float]:
    if not isinstance(table, dict):
        raise CampaignError("base: expected a table {parameter name: value}")
    out = {}
    for name, value in table.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise CampaignError(f"base: {name} must be a number, got {value!r}")
        out[name] = float(value)
    return out


def system_base(system: MaterialSystem) -> dict[str, float]:
    """A campaign's base values in ``system``: its conductivities and known resistances;
    the paper's system also the paper's Table 5 resistances (:data:`PAPER_BASE`)."""
    if is_default_system(system):
        return dict(PAPER_BASE)
    out = {parameter_name("k", p): v for p, v in system.conductivities().items()}
    return {**out, **dict(system.resistances)}


def _formulation(entry: Any, i: int, system: MaterialSystem) -> Formulation:
    if not isinstance(entry, dict):
        raise CampaignError(f"formulation {i}: expected a table")
    unknown = unknown_key(entry, ("name", "fractions", "psd"))
    if unknown:
        raise CampaignError(f"formulation {i}: {unknown}")
    name = entry.get("name")
    if not isinstance(name, str) or not _NAME.match(name):
        raise CampaignError(f"formulation {i}: name must be letters, digits and . + -, got "
                            f"{name!r}")
    if "fractions" in entry:
        fractions = entry["fractions"]
    else:
        try:  # a name of the system in any letter case; a near miss gets a "did you mean"
            name = formulation_name(name, system=system)
            fractions = fractions_of(name, system)
        except UnknownFormulationError as exc:
            hint = f"; did you mean {exc.suggestion!r}?" if exc.suggestion else ""
            named = ", ".join(system.named_formulations())
            raise CampaignError(f"formulation {name!r}: no fractions given and not a "
                                f"formulation of the system {system.name!r}{hint} "
                                f"({named or 'name fillers by composition, e.g. '}"
                                f"{'' if named else system.filler_names[0] + '-50'})") from None
    if not isinstance(fractions, dict) or not fractions:
        raise CampaignError(f"formulation {name!r}: fractions must be a table {{filler: "
                            "volume fraction}")
    for filler, v in fractions.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < 1:
            raise CampaignError(f"formulation {name!r}: fractions.{filler} must lie in (0, 1), "
                                f"got {v!r}")
    sizes = {f.name: f.psd.to_number() for f in system.fillers}
    psd = {f: (sizes[f].mu, sizes[f].sigma) if f in sizes else None for f in fractions}
    for filler, pair in entry.get("psd", {}).items():
        if filler not in fractions or not isinstance(pair, list) or len(pair) != 2:
            raise CampaignError(f"formulation {name!r}: psd.{filler} must be [mu, sigma] of a "
                                "filler of this formulation")
        psd[filler] = (float(pair[0]), float(pair[1]))
    missing = [f for f, p in psd.items() if p is None]
    if missing:
        raise CampaignError(f"formulation {name!r}: no size distribution for {missing[0]!r} "
                            f"(the system {system.name!r} has {sorted(sizes)}; give "
                            f"psd.{missing[0]} = [mu, sigma])")
    return Formulation(name, {f: float(v) for f, v in fractions.items()},
                       {f: (float(p[0]), float(p[1])) for f, p in psd.items()})


def _design(entry: Any) -> dict[str, Any]:
    if not isinstance(entry, dict) or entry.get("kind") not in _DESIGN_KEYS:
        kind = entry.get("kind") if isinstance(entry, dict) else entry
        raise CampaignError(f"design.kind: expected one of {sorted(_DESIGN_KEYS)}, got {kind!r}")
    kind = entry["kind"]
    unknown = unknown_key(entry, _DESIGN_KEYS[kind], detail=f" for kind {kind!r}")
    if unknown:
        raise CampaignError(f"design: {unknown}")
    needed = sorted(_DESIGN_KEYS[kind] - {"kind", "seed"} - set(entry))
    if needed:
        raise CampaignError(f"design: kind {kind!r} needs {needed[0]!r}")
    return dict(entry)


def nearest_solved(target: dict[str, float], solved: list[dict[str, float]]) -> int | None:
    """Index of the solved parameter set nearest to ``target`` (log scale for resistances
    and conductances of contacts, relative scale for conductivities); None if none."""
    if not solved:
        return None
    names = sorted(target)

    def coords(p: dict[str, float]) -> np.ndarray:  # every parameter is > 0: log scale
        return np.array([math.log10(max(p[n], 1e-300)) for n in names])

    t = coords(target)
    dist = [float(np.sum((coords(s) - t) ** 2)) for s in solved]
    return int(np.argmin(dist))
