"""The plan of the shipped faithful corrections: which solves make them, as engine campaigns.

A corrections file (``examples/corrections.toml``) names per filler system

- **the table**: its Table 2 formulations solved at one box and one voxel (the table box,
  ``box_um``, and ``voxel_um``), ``packings`` packings each, at every resistance of the
  system's design (a ``values`` grid, or ``points`` listed one by one). One task is one
  packing with all its resistances: one packing and voxelisation, the solves warm-started
  from each other;
- **the studies** that take the table to a converged box without voxel bias, each a shared
  term of the system (one value for all its formulations):

  * ``[system.boxes]``: one formulation at several boxes (the table's voxel), many
    packings per box: the step from the table box to the converged one;
  * ``[system.order]``: one formulation at several voxels of the same particles (the
    table voxel's fine-tail cut): the voxel bias of the table voxel and its order (where
    a system states none, its middle formulation at the table box and voxel and two finer
    voxels, 2 packings);
  * ``[system.tail]``: one formulation at the table box with the size distribution's tails
    cut at other number quantiles: what the tail cut leaves out.

  A system without a box study takes its table box as converged (the powders' rule,
  :func:`itr_fv.rve.from_powders.faithful_box`) with the rule's uncertainty; one without a
  tail study adds none for the tail. Where a system states no ``box_um`` or ``voxel_um``,
  those of its powders are used.

Each becomes one campaign of the campaign engine per box, voxel or quantile
(:mod:`itr_surrogate.campaign`), and one more campaign per system holds the cheap RVE whose
reduced basis the correction multiplies (:func:`~itr_identify.forward.fidelity.
cheap_rve_for`, its replicas). Each campaign runs (and resumes) in its own folder named by
the campaign; :mod:`itr_identify.forward.shipped` assembles the factors from their rows.
A study may name campaigns that ran before (``name``: the stem of their names, e.g. issue
47's AlN box study) so that what is measured is not solved again.

:meth:`CorrectionPlan.estimate` says per campaign the solves and the hours they take on this
machine's cores (``itr corrections build --plan``).

The file::

    name = "corrections-v2"
    packings = 3                # table packings per formulation
    seed = 9101                 # packing seed of the table's first packing
    solver = "mg"               # any solver choice (itr_fv.solvers.choice)
    tol = 1e-6                  # relative residual of every faithful solve

    [[system]]
    name = "AlN"
    box_um = 64.0
    voxel_um = 0.25
    formulations = ["AlN-55", "AlN-58", "AlN-60", "AlN-62"]   # Table 2 names
    values = { R_AlN_silicone = [5e-9, 1.5e-8, 5e-8, 2e-7] }  # or points = [{...}, ...]

    [system.boxes]
    formulation = "AlN-60"
    boxes_um = [64.0, 80.0, 96.0]
    packings = 6
    seed = 201
    values = { R_AlN_silicone = [3e-8] }
    name = "box47-AlN"          # optional: the stem of campaigns that ran before

    [system.order]
    formulation = "AlN-60"
    box_um = 32.0
    voxels_um = [0.25, 0.2, 0.16]
    packings = 3
    seed = 401
    values = { R_AlN_silicone = [5e-9, 3e-8, 2e-7] }

    [system.tail]
    formulation = "AlN-60"
    box_um = 80.0
    quantiles = [1e-3, 1e-5]    # the table's cut: the RVE's tail_quantile (1e-4)
    packings = 3
    seed = 201
    values = { R_AlN_silicone = [3e-8] }
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from itr_fv.checks import unknown_key
from itr_fv.io import read_toml
from itr_fv.materials import default_system
from itr_fv.materials.material_system import MaterialSystem
from itr_fv.rve.from_powders import faithful_box, voxel_for
from itr_fv.rve.spec import RVESpec
from itr_fv.solvers.choice import Solver, as_solver
from itr_surrogate.campaign import Campaign

from .fidelity import CHEAP_REPLICAS, CHEAP_TOL, cheap_rve_for

__all__ = ["CorrectionPlan", "CorrectionSystem", "Study", "STUDY_KINDS"]

_TOP = {"name", "packings", "seed", "solver", "tol", "system"}
_SYSTEM = {"name", "formulations", "box_um", "voxel_um"}
_STUDY_KEYS = {"boxes": {"formulation", "boxes_um", "packings", "seed", "values", "points",
                         "name"},
               "order": {"formulation", "box_um", "voxels_um", "packings", "seed", "values",
                         "points", "name"},
               "tail": {"formulation", "box_um", "quantiles", "packings", "seed", "values",
                        "points", "name"}}
#: The studies a system may have, in the order they run.
STUDY_KINDS = ("boxes", "order", "tail")


def _design(entry: dict[str, Any], where: str) -> dict[str, Any]:
    """A campaign design from ``values`` (a grid) or ``points`` (sets one by one)."""
    if ("values" in entry) == ("points" in entry):
        raise ValueError(f"{where}: give either values (a grid) or points (sets one by one)")
    if "values" in entry:
        return {"kind": "grid", "values": {str(k): [float(x) for x in v]
                                           for k, v in entry["values"].items()}}
    return {"kind": "points", "points": [{str(k): float(x) for k, x in p.items()}
                                         for p in entry["points"]]}


def _whole(value: Any, least: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < least:
        raise ValueError(f"{what}: expected a whole number >= {least}, got {value!r}")
    return value


def _lengths(value: Any, what: str) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a list of numbers, got {value!r}") from None
    if not out or any(not v > 0 for v in out):
        raise ValueError(f"{what}: expected a non-empty list of numbers > 0, got {value!r}")
    return out


@dataclass(frozen=True)
class Study:
    """One study of a system (``kind`` one of :data:`STUDY_KINDS`): its formulation, the
    boxes (um; one unless ``boxes``), voxels (um; one unless ``order``), tail quantiles
    (``tail`` only), packings, first seed, campaign design and the stem of its campaigns'
    names."""

    kind: str
    formulation: str
    boxes_um: tuple[float, ...]
    voxels_um: tuple[float, ...]
    quantiles: tuple[float, ...]
    packings: int
    seed: int
    design: dict[str, Any]
    stem: str

    @classmethod
    def from_dict(cls, kind: str, data: dict[str, Any], *, system: str, plan: str,
                  box_um: float, voxel_um: float) -> Study:
        where = f"{kind}"
        unknown = unknown_key(data, _STUDY_KEYS[kind])
        if unknown:
            raise ValueError(f"{where}: {unknown}")
        need = {"boxes": "boxes_um", "order": "voxels_um", "tail": "quantiles"}[kind]
        for key in ("formulation", need):
            if key not in data:
                raise ValueError(f"{where}: missing key {key!r}")
        boxes = (_lengths(data["boxes_um"], f"{where}.boxes_um") if kind == "boxes"
                 else (float(data.get("box_um", box_um)),))
        voxels = (_lengths(data["voxels_um"], f"{where}.voxels_um") if kind == "order"
                  else (voxel_um,))
        if kind == "order" and (len(voxels) < 3 or voxels[0] != voxel_um
                                or list(voxels) != sorted(voxels, reverse=True)):
            raise ValueError(f"{where}.voxels_um: expected at least three edges, coarsest "
                             f"first and the first the table's {voxel_um:g} um, got "
                             f"{list(voxels)}")
        if kind == "boxes" and len(boxes) < 2:
            raise ValueError(f"{where}.boxes_um: expected at least two boxes, got "
                             f"{list(boxes)}")
        quantiles = (_lengths(data["quantiles"], f"{where}.quantiles") if kind == "tail"
                     else ())
        if any(q >= 0.5 for q in quantiles):
            raise ValueError(f"{where}.quantiles: expected number quantiles < 0.5, got "
                             f"{list(quantiles)}")
        return cls(kind, str(data["formulation"]), boxes, voxels, quantiles,
                   _whole(data.get("packings", 3), 2, f"{where}.packings"),
                   _whole(data.get("seed", 1), 1, f"{where}.seed"),
                   _design(data, where) if ("values" in data or "points" in data) else {},
                   str(data.get("name", f"{plan}-{system}-{kind}")))

    def campaign_names(self) -> list[str]:
        """The names of the study's campaigns, in the order they run."""
        if self.kind == "boxes":
            return [f"{self.stem}-{b:g}" for b in self.boxes_um]
        if self.kind == "order":
            return [f"{self.stem}-{v:g}" for v in self.voxels_um]
        return [f"{self.stem}-q{q:g}" for q in self.quantiles]


@dataclass(frozen=True)
class CorrectionSystem:
    """One filler system: its table box and voxel (um), Table 2 formulations, the campaign
    design of its resistances (m^2 K/W) and its studies by kind."""

    name: str
    box_um: float
    voxel_um: float
    formulations: tuple[str, ...]
    design: dict[str, Any]
    studies: dict[str, Study] = field(default_factory=dict)

    @property
    def parameters(self) -> list[str]:
        """The resistances the design varies (flat names, sorted)."""
        if self.design["kind"] == "grid":
            return sorted(self.design["values"])
        return sorted(self.design["points"][0])


def _system(i: int, s: dict[str, Any], plan: str,
            material: MaterialSystem) -> CorrectionSystem:
    """One checked ``[[system]]``. Where it states no voxel or box, those of the material
    system's powders (:mod:`itr_fv.rve.from_powders`: the cheap voxel; the smallest box whose
    size cut removes at most 1.5 % of any of its fillers' volume); where it states no order
    study, one is made (:func:`_default_order`)."""
    unknown = unknown_key(s, _SYSTEM | {"values", "points"} | set(STUDY_KINDS))
    if unknown:
        raise ValueError(f"system {i}: {unknown}")
    missing = sorted({"name", "formulations"} - set(s))
    if missing:
        raise ValueError(f"system {i}: missing key {missing[0]!r}")
    name = str(s["name"])
    try:
        fillers = [material.filler(f) for f in name.split("-")]
        voxel = float(s.get("voxel_um", voxel_for(f.psd for f in fillers)))
        box = float(s["box_um"]) if "box_um" in s else max(
            faithful_box(f.psd, voxel) for f in fillers)
        forms = tuple(str(f) for f in s["formulations"])
        design = _design(s, "design")
        given = {k: s[k] for k in STUDY_KINDS if k in s}
        given.setdefault("order", _default_order(forms, box, voxel, design))
        studies = {k: Study.from_dict(k, given[k], system=name, plan=plan, box_um=box,
                                      voxel_um=voxel)
                   for k in STUDY_KINDS if k in given}
    except ValueError as exc:
        raise ValueError(f"system {name!r}: {exc}") from None
    return CorrectionSystem(name, box, voxel, forms, design, studies)


def _default_order(formulations: tuple[str, ...], box_um: float, voxel_um: float,
                   design: dict[str, Any]) -> dict[str, Any]:
    """The order study of a system that states none: its middle formulation at the table
    box, the table voxel and two finer ones of the same box (``n``, ``1.25 n`` and ``1.5 n``
    voxels per edge), 2 packings, the table's design."""
    n = round(box_um / voxel_um)
    voxels = [voxel_um] + [box_um / m for m in (round(1.25 * n), round(1.5 * n))]
    return {"formulation": formulations[len(formulations) // 2], "box_um": box_um,
            "voxels_um": voxels, "packings": 2, "seed": 401,
            **({"values": design["values"]} if design["kind"] == "grid"
               else {"points": design["points"]})}


@dataclass(frozen=True)
class CorrectionPlan:
    """A checked corrections file (see the module docstring)."""

    name: str
    packings: int
    seed: int
    solver: Solver
    tol: float
    systems: tuple[CorrectionSystem, ...]
    material: MaterialSystem = field(default_factory=default_system)

    @classmethod
    def from_toml(cls, path: str | Path,
                  material: MaterialSystem | None = None) -> CorrectionPlan:
        """Read and check a corrections file (ValueError naming the file and key) for the
        material system ``material`` (default: the package's)."""
        p = Path(path)
        data = read_toml(p, "corrections file")
        try:
            return cls.from_dict(data, material)
        except ValueError as exc:
            raise ValueError(f"{p}: {exc}") from None

    @classmethod
    def from_dict(cls, data: dict[str, Any],
                  material: MaterialSystem | None = None) -> CorrectionPlan:
        """A checked plan: every campaign it makes is built (and so checked) here."""
        material = material or default_system()
        unknown = unknown_key(data, _TOP)
        if unknown:
            raise ValueError(unknown)
        name = str(data.get("name", "corrections"))
        packings = _whole(data.get("packings", 3), 2, "packings")
        systems = tuple(_system(i, s, name, material)
                        for i, s in enumerate(data.get("system", [])))
        if not systems:
            raise ValueError("system: give at least one [[system]]")
        tol = data.get("tol", 1e-6)
        if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 < tol < 1:
            raise ValueError(f"tol: expected a relative residual in (0, 1), got {tol!r}")
        plan = cls(name, packings, _whole(data.get("seed", 9101), 1, "seed"),
                   as_solver(data.get("solver")), float(tol), systems, material)
        for s in plan.systems:   # every campaign checks its own keys before any work
            try:
                plan.campaigns(systems=(s.name,))
            except ValueError as exc:   # a CampaignError too
                raise ValueError(f"system {s.name!r}: {exc}") from None
        return plan

    def system(self, name: str) -> CorrectionSystem:
        for s in self.systems:
            if s.name == name:
                return s
        raise ValueError(f"system: no system {name!r} in {self.name!r} (have "
                         f"{', '.join(s.name for s in self.systems)})")

    def _campaign(self, name: str, rve: RVESpec, *, formulations: tuple[str, ...],
                  design: dict[str, Any], replicas: int, tol: float, solver: Solver | None,
                  threads: int = 1) -> Campaign:
        n_sets = (math.prod(len(v) for v in design["values"].values())
                  if design["kind"] == "grid" else len(design["points"]))
        data = {"name": name, "replicas": replicas, "contact": "gap",
                "solver": solver or self.solver, "tol": tol, "block_size": n_sets,
                "threads_per_worker": threads, **rve.to_dict(),
                "formulation": [{"name": f} for f in formulations], "design": design}
        return Campaign.from_dict(data, self.material)

    @property
    def cheap_rve(self) -> RVESpec:
        """The cheap RVE the corrections correct: the material system's
        (:func:`~itr_identify.forward.fidelity.cheap_rve_for`; the paper's: 12 um at
        0.25 um)."""
        return cheap_rve_for(self.material)

    def table_campaign(self, system: str, *, solver: Solver | None = None,
                       threads: int = 1) -> Campaign:
        """The campaign of a system's table: its formulations at the table box and voxel,
        :attr:`packings` packings (seeds ``seed, seed + 1, ...``), every resistance."""
        s = self.system(system)
        rve = self.cheap_rve.with_(box_um=s.box_um, voxel_um=s.voxel_um, seed=self.seed)
        return self._campaign(f"{self.name}-{s.name}-table", rve, formulations=s.formulations,
                              design=s.design, replicas=self.packings, tol=self.tol,
                              solver=solver, threads=threads)

    def cheap_campaign(self, system: str, *, solver: Solver | None = None) -> Campaign:
        """The campaign of one system's cheap RVEs (the replicas the reduced basis of
        ``itr reproduce`` is fitted on), at the table's design."""
        s = self.system(system)
        return self._campaign(f"{self.name}-{s.name}-cheap", self.cheap_rve,
                              formulations=s.formulations, design=s.design,
                              replicas=CHEAP_REPLICAS, tol=CHEAP_TOL,
                              solver=as_solver(solver))

    def study_campaigns(self, system: str, kind: str, *, solver: Solver | None = None,
                        threads: int = 1) -> list[Campaign]:
        """The campaigns of one study of a system, one per box, voxel or quantile."""
        s = self.system(system)
        st = s.studies[kind]
        design = st.design or s.design
        base = self.cheap_rve.with_(box_um=s.box_um, voxel_um=s.voxel_um, seed=st.seed)
        if kind == "boxes":
            rves = [base.with_(box_um=b) for b in st.boxes_um]
        elif kind == "order":   # the same particles at every voxel: the table voxel's cut
            rves = [base.with_(box_um=st.boxes_um[0], voxel_um=v,
                               cut_voxel_um=None if v == s.voxel_um else s.voxel_um)
                    for v in st.voxels_um]
        else:
            rves = [base.with_(box_um=st.boxes_um[0], tail_quantile=q) for q in st.quantiles]
        return [self._campaign(n, rve, formulations=(st.formulation,), design=design,
                               replicas=st.packings, tol=self.tol, solver=solver,
                               threads=threads)
                for n, rve in zip(st.campaign_names(), rves)]

    def campaigns(self, *, systems: tuple[str, ...] | None = None, solver: Solver | None = None,
                  threads: int = 1) -> list[tuple[str, Campaign]]:
        """Every (sub-folder, campaign) of the plan's ``systems`` (default: all): the cheap
        ones first (minutes), then system by system its studies and its table. A
        campaign's folder is its name."""
        names = [s.name for s in self.systems] if systems is None else [
            self.system(n).name for n in systems]
        out = [self.cheap_campaign(n) for n in names]
        for n in names:
            for kind in STUDY_KINDS:
                if kind in self.system(n).studies:
                    out += self.study_campaigns(n, kind, solver=solver, threads=threads)
            out.append(self.table_campaign(n, solver=solver, threads=threads))
        return [(c.name, c) for c in out]
