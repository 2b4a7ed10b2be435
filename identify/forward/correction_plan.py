"""The plan of the shipped faithful corrections: which solves make them, as engine campaigns.

A corrections file (``examples/corrections.toml``) names per filler system a converged box,
its Table 2 formulations and a grid of the gap parametrisation's resistances. For each
system and each of the two voxel edges it becomes one campaign of the campaign engine
(:mod:`itr_surrogate.campaign`: the faithful packings ``seed, seed + 1, ...`` at that box),
and one more campaign holds the cheap RVE whose reduced basis the correction multiplies
(:data:`~itr_identify.forward.fidelity.CHEAP_RVE`, its replicas). Each campaign runs (and
resumes) in its own folder under the run's folder; :mod:`itr_identify.forward.shipped`
assembles the factors from their stores.

The file::

    name = "corrections-v1"
    voxels_um = [0.25, 0.2]     # coarse and fine voxel of the same packing, um
    packings = 2                # faithful packings per formulation
    seed = 9001                 # packing seed of the first faithful packing
    solver = "mg"               # any solver choice (itr_fv.solvers.choice; default its default)
    tol = 1e-7                  # relative residual of the faithful solves

    [[system]]
    name = "AlN"
    box_um = 64.0
    formulations = ["AlN-55", "AlN-62"]           # Table 2 names
    values = { R_AlN_silicone = [1e-8, 5e-8] }    # grid, m^2 K/W

    [[system]]                  # a system solved at one voxel takes its voxel bias from
    name = "Al2O3-AlN"          # systems solved at two (their mean at its resistances)
    box_um = 64.0
    voxels_um = [0.25]
    bias_from = ["Al2O3", "AlN"]
    ...
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from itr_fv.checks import unknown_key
from itr_fv.io import read_toml
from itr_fv.materials import default_system
from itr_fv.materials.material_system import MaterialSystem
from itr_fv.rve.from_powders import FAITHFUL_VOXEL_RATIO, faithful_box, voxel_for
from itr_fv.rve.spec import RVESpec
from itr_fv.solvers.choice import check_solver
from itr_surrogate.campaign import Campaign

from .fidelity import CHEAP_REPLICAS, CHEAP_TOL, cheap_rve_for

__all__ = ["CorrectionPlan", "CorrectionSystem"]

_TOP = {"name", "voxels_um", "packings", "seed", "solver", "tol", "system"}
_SYSTEM = {"name", "formulations", "values"}
_SYSTEM_OPTIONAL = {"voxels_um", "bias_from", "box_um"}


@dataclass(frozen=True)
class CorrectionSystem:
    """One filler system: its box (um), Table 2 formulations and resistance grid
    (flat names to values in m^2 K/W); ``voxels_um`` its own voxel edges (None: the
    plan's two); with one voxel, ``bias_from`` names the systems whose voxel bias at that
    voxel it takes (the mean of theirs at its resistances)."""

    name: str
    box_um: float
    formulations: tuple[str, ...]
    values: dict[str, tuple[float, ...]]
    voxels_um: tuple[float, ...] | None = None
    bias_from: tuple[str, ...] = ()


@dataclass(frozen=True)
class CorrectionPlan:
    """A checked corrections file (see the module docstring)."""

    name: str
    voxels_um: tuple[float, float]
    packings: int
    seed: int
    solver: str
    tol: float
    systems: tuple[CorrectionSystem, ...]
    material: MaterialSystem = field(default_factory=default_system)

    @classmethod
    def from_toml(cls, path: str | Path,
                  material: MaterialSystem | None = None) -> "CorrectionPlan":
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
                  material: MaterialSystem | None = None) -> "CorrectionPlan":
        """A checked plan; where it states no voxels or a system no box, those of the
        material system's powders (:mod:`itr_fv.rve.from_powders`: the cheap voxel and
        0.8 of it; the smallest box whose size cut removes at most 1.5 % of any of the
        system's fillers' volume)."""
        material = material or default_system()
        unknown = unknown_key(data, _TOP)
        if unknown:
            raise ValueError(unknown)
        h = voxel_for(f.psd for f in material.fillers)
        voxels = tuple(float(v) for v in data.get(
            "voxels_um", (h, round(FAITHFUL_VOXEL_RATIO * h, 12))))
        if len(voxels) != 2 or not 0 < voxels[1] < voxels[0]:
            raise ValueError(f"voxels_um: expected [coarse, fine] edges in um with coarse > "
                             f"fine > 0, got {data.get('voxels_um')!r}")
        packings = data.get("packings", 2)
        if isinstance(packings, bool) or not isinstance(packings, int) or packings < 2:
            raise ValueError(f"packings: expected a whole number >= 2 (their scatter is part "
                             f"of the correction's uncertainty), got {packings!r}")
        systems = []
        for i, s in enumerate(data.get("system", [])):
            unknown = unknown_key(s, _SYSTEM | _SYSTEM_OPTIONAL)
            if unknown:
                raise ValueError(f"system {i}: {unknown}")
            missing = sorted(_SYSTEM - set(s))
            if missing:
                raise ValueError(f"system {i}: missing key {missing[0]!r}")
            own = tuple(float(v) for v in s.get("voxels_um", ())) or None
            bias_from = tuple(str(b) for b in s.get("bias_from", ()))
            if own is not None and len(own) == 1 and not bias_from:
                raise ValueError(f"system {i}: one voxel ({own[0]:g} um) needs bias_from, the "
                                 "systems whose voxel bias it takes")
            if own is not None and len(own) == 2 and not 0 < own[1] < own[0]:
                raise ValueError(f"system {i}: voxels_um: expected [coarse, fine], got "
                                 f"{list(own)}")
            try:
                box = float(s["box_um"]) if "box_um" in s else max(
                    faithful_box(material.filler(f).psd, voxels[0])
                    for f in str(s["name"]).split("-"))
            except ValueError as exc:
                raise ValueError(f"system {i}: {exc}") from None
            systems.append(CorrectionSystem(
                str(s["name"]), box, tuple(str(f) for f in s["formulations"]),
                {str(k): tuple(float(x) for x in v) for k, v in s["values"].items()},
                own, bias_from))
        if not systems:
            raise ValueError("system: give at least one [[system]]")
        plan = cls(str(data.get("name", "corrections")), voxels, packings,
                   int(data.get("seed", 9001)), check_solver(data.get("solver")),
                   float(data.get("tol", 1e-7)), tuple(systems), material)
        check_solver(plan.solver)
        for s in plan.systems:   # every campaign checks its own keys before any work
            try:
                for voxel in plan.voxels_of(s.name):
                    plan.faithful_campaign(s.name, voxel)
                plan.cheap_campaign(s.name)
                for b in s.bias_from:
                    if len(plan.voxels_of(b)) != 2 or s.voxels_um[0] != plan.voxels_of(b)[0]:
                        raise ValueError(f"bias_from: {b!r} has no voxel pair whose coarse "
                                         f"voxel is {s.voxels_um[0]:g} um")
            except ValueError as exc:   # a CampaignError too
                raise ValueError(f"system {s.name!r}: {exc}") from None
        return plan

    def voxels_of(self, system: str) -> tuple[float, ...]:
        """A system's voxel edges, um: (coarse, fine), or its one voxel."""
        s = self.system(system)
        return s.voxels_um if s.voxels_um is not None else self.voxels_um

    def system(self, name: str) -> CorrectionSystem:
        for s in self.systems:
            if s.name == name:
                return s
        raise ValueError(f"system: no system {name!r} in {self.name!r} (have "
                         f"{', '.join(s.name for s in self.systems)})")

    def _campaign(self, s: CorrectionSystem, name: str, rve: RVESpec, replicas: int,
                  tol: float, solver: str | None, threads: int = 1) -> Campaign:
        n_sets = 1
        for v in s.values.values():
            n_sets *= len(v)
        data = {"name": name, "replicas": replicas, "contact": "gap",
                "solver": solver or self.solver, "tol": tol, "block_size": n_sets,
                "threads_per_worker": threads,
                **{k: v for k, v in rve.to_dict().items() if k != "tail_quantile"},
                "formulation": [{"name": f} for f in s.formulations],
                "design": {"kind": "grid", "values": {k: list(v) for k, v in s.values.items()}}}
        return Campaign.from_dict(data, self.material)

    def faithful_campaign(self, system: str, voxel_um: float, *, solver: str | None = None,
                          threads: int = 1) -> Campaign:
        """The campaign of one system's faithful packings at one voxel edge, um (``solver``:
        the plan's by default; ``threads``: solver threads per worker). Both voxels hold
        the same particles: the fine voxel's fine-tail cut (``cut_voxel_um``)."""
        s = self.system(system)
        voxels = self.voxels_of(system)
        if voxel_um not in voxels:
            raise ValueError(f"voxel_um: system {system!r} is solved at {list(voxels)} um, "
                             f"not {voxel_um!r}")
        fine = voxels[-1]
        # the coarse voxel solves the fine campaign's particles (its fine-tail cut)
        rve = self.cheap_rve.with_(box_um=s.box_um, voxel_um=voxel_um, seed=self.seed,
                                   cut_voxel_um=None if voxel_um == fine else fine)
        return self._campaign(s, f"{self.name}-{s.name}-{voxel_um:g}um", rve, self.packings,
                              self.tol, solver, threads)

    def cheap_campaign(self, system: str, *, solver: str | None = None) -> Campaign:
        """The campaign of one system's cheap RVEs (the replicas the reduced basis of
        ``itr reproduce`` is fitted on), at the same design."""
        s = self.system(system)
        return self._campaign(s, f"{self.name}-{s.name}-cheap", self.cheap_rve,
                              CHEAP_REPLICAS, CHEAP_TOL, check_solver(solver))

    @property
    def cheap_rve(self) -> RVESpec:
        """The cheap RVE the corrections correct: the material system's
        (:func:`~itr_identify.forward.fidelity.cheap_rve_for`; the paper's: 12 um at
        0.25 um)."""
        return cheap_rve_for(self.material)

    def folders(self, system: str) -> dict[str, str]:
        """Sub-folder of each of a system's campaigns: ``coarse`` and ``fine`` (or ``only``
        for a one-voxel system), ``cheap``."""
        voxels = self.voxels_of(system)
        keys = ("coarse", "fine") if len(voxels) == 2 else ("only",)
        return {**{k: f"{system}-{v:g}um" for k, v in zip(keys, voxels)},
                "cheap": f"{system}-cheap"}

    def campaigns(self, *, systems: tuple[str, ...] | None = None, solver: str | None = None,
                  threads: int = 1) -> list[tuple[str, Campaign]]:
        """Every (sub-folder, campaign) of the plan's ``systems`` (default: all), cheap
        ones first (seconds), then the faithful ones system by system, coarse voxel before
        fine."""
        names = [s.name for s in self.systems] if systems is None else [
            self.system(n).name for n in systems]
        out = [(self.folders(n)["cheap"], self.cheap_campaign(n)) for n in names]
        for n in names:
            for voxel in self.voxels_of(n):
                out.append((f"{n}-{voxel:g}um", self.faithful_campaign(
                    n, voxel, solver=solver, threads=threads)))
        return out
