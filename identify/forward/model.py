"""Forward models of the identification: per formulation, RVE replicas and a reduced basis.

A :class:`Parametrisation` says which interface parameters a formulation's conductivity
depends on and what contact model carries them:

- ``"area"`` (paper-compatible): ``contact="area"``; per filler ``R_<f>_silicone`` and the
  per-area contact resistance ``Rff_<f>_<f>``; per pair of fillers ``Rff_<A>_<B>``. Its
  contact values belong to the voxel they are identified at (the paper's 0.1 um).
- ``"gap"`` (physical): ``contact="gap"``; per filler ``R_<f>_silicone`` only: a contact is
  two particle-matrix interfaces and the true matrix film between the spheres (Eq. 6).

A :class:`ForwardModel` packs the replicas of one formulation (the size distributions of the
settings' material system),
fits a :class:`itr_surrogate.reduced_basis.ReducedBasis` on the first replica over the prior
box of its parameters, and measures the RVE-to-RVE scatter by full solves of every replica
at the centre of the box. Its prediction is the first replica's reduced basis scaled by the
ratio of the replica mean to the first replica at the centre
(:attr:`ForwardModel.replica_factor`). Filler and matrix conductivities stay at the nominal
values of the material system (:attr:`ForwardSettings.system`; the paper's by default), as in
the paper's screening; the identification marginalises them afterwards.
"""

from __future__ import annotations

import math
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field, fields, replace

import numpy as np

from itr_fv import Materials
from itr_fv.discrete.problem import DiscreteProblem
from itr_fv.materials import default_system
from itr_fv.materials.material_system import MaterialSystem
from itr_fv.materials.parameters import parameter_name
from itr_fv.rve import FillerSpec, build_rve
from itr_fv.rve.spec import RVESpec
from itr_fv.solvers.choice import Solver, as_solver, default_solver
from itr_surrogate.engine import SolveEngine
from itr_surrogate.reduced_basis import ReducedBasis
from itr_surrogate.requests import RVEData, SolveRequest, SolveResult, solve_row
from itr_surrogate.worker import cached_problem

from .fidelity import CHEAP_REPLICAS, Correction, FaithfulRVE, direction_scatter
from .shipped import ShippedCorrections, ShippedFactor

__all__ = ["Parametrisation", "PARAMETRISATIONS", "ForwardSettings", "ForwardModel",
           "full_solve", "filler_specs"]
#: The engine of models built without one: serial, in this process, no store.
_SERIAL = SolveEngine()
#: Held by the thread whose model does work in this process (see ForwardModel.build).
_LOCAL_WORK = threading.Lock()
_HOLDER = threading.local()


@contextmanager
def _local_work() -> Iterator[None]:
    """Hold :data:`_LOCAL_WORK` (numba's default threading layer, the problem cache and
    the progress bars take one caller at a time)."""
    with _LOCAL_WORK:
        _HOLDER.held = True
        try:
            yield
        finally:
            _HOLDER.held = False


@contextmanager
def _waiting_for_solves() -> Iterator[None]:
    """Let other models' local work run while this thread waits for the engine."""
    if not getattr(_HOLDER, "held", False):
        yield
        return
    _HOLDER.held = False
    _LOCAL_WORK.release()
    try:
        yield
    finally:
        _LOCAL_WORK.acquire()
        _HOLDER.held = True


@dataclass(frozen=True)
class Parametrisation:
    """Which interface parameters a formulation depends on, and under which contact model."""

    name: str
    contact: str
    description: str

    def parameters(self, fillers: list[str] | tuple[str, ...], *, matrix: str) -> list[str]:
        """Flat names of the identified parameters of a formulation holding ``fillers`` in
        ``matrix``."""
        fl = sorted(fillers)
        out = [parameter_name("R", f, matrix) for f in fl]
        if self.contact == "area":
            out += [parameter_name("Rff", a, b) for i, a in enumerate(fl) for b in fl[i:]]
        return out


PARAMETRISATIONS = {
    "area": Parametrisation("area", "area", "paper-compatible: filler-matrix R and per-area "
                            "contact resistance Rff per filler pair (contact='area')"),
    "gap": Parametrisation("gap", "gap", "physical: filler-matrix R per filler; a contact is "
                           "two interfaces and the true matrix film (contact='gap')"),
}


@dataclass(frozen=True)
class ForwardSettings:
    """RVE and surrogate settings shared by every formulation.

    Attributes
    ----------
    rve : RVESpec
        Box, voxel (the paper: 40 and 0.1 um), size cuts, matrix film and the packing seed
        of the first replica (:class:`itr_fv.rve.spec.RVESpec`, checked there).
    replicas : int
        RVE replicas per formulation (seeds ``rve.seed + 0, 1, ...``); the reduced basis is
        fitted on the first, all enter the RVE scatter and the validation.
    prior_m2K_per_W : (float, float)
        Range of every resistance in the reduced bases' box and the grid calibration's
        log-uniform prior, m^2 K/W: the joint posterior's resistance prior (1e-9 to 1e-6,
        :mod:`itr_identify.inference.priors`) widened by a factor 2 each side, so that a
        resistance scaled by the matrix conductivity stays inside it.
    rb_tol : float
        Relative bound gap at which the reduced basis stops adding full solves.
    rb_max_solves : int
        Full solves per reduced basis at most.
    solver_tol : float
        Relative residual of every full solve.
    solver : Solver or str
        The solver of every full solve (a name is resolved once, here:
        :func:`itr_fv.solvers.choice.as_solver`; ``"fft"`` by default, ``"gpu"`` on a CUDA
        device, ``"mg"``, ...).
    psd_basis : {"number", "volume"}
        Weighting of Table 1's lognormal (mu, sigma): ``"number"`` (default; the paper's
        Table 1 reads as number-weighted, E[D] = exp(mu + sigma^2 / 2) matches its mean
        diameters) or ``"volume"`` (a laser-diffraction analyser's default; its number
        median is smaller by exp(3 sigma^2): 2.84x for AlN, 1.44x for Al2O3). A stated
        input of the identification, reported with the identified values.
    faithful : FaithfulRVE, optional
        Where the gap parametrisation's models are corrected by full solves on faithful
        RVEs (:mod:`itr_identify.forward.fidelity`); None: no correction, the results hold
        at :attr:`rve`'s fidelity only.
    system : MaterialSystem
        The matrix and fillers: nominal conductivities, size distributions, known
        resistances (:mod:`itr_fv.materials.system_file`; default: the paper's).
    """

    rve: RVESpec = RVESpec(box_um=16.0, voxel_um=0.25)
    replicas: int = 3
    prior_m2K_per_W: tuple[float, float] = (5e-10, 2e-6)
    rb_tol: float = 2e-3
    rb_max_solves: int = 30
    solver_tol: float = 1e-8
    solver: Solver = field(default_factory=default_solver)
    psd_basis: str = "number"
    faithful: FaithfulRVE | None = None
    system: MaterialSystem = field(default_factory=default_system)

    def __post_init__(self) -> None:
        if not isinstance(self.system, MaterialSystem):
            raise ValueError(f"system: expected a MaterialSystem, got "
                             f"{type(self.system).__name__}")
        if self.faithful is not None and not isinstance(self.faithful, FaithfulRVE):
            raise ValueError(f"faithful: expected a FaithfulRVE or None, got "
                             f"{type(self.faithful).__name__}")
        if self.psd_basis not in ("number", "volume"):
            raise ValueError(f"psd_basis: expected 'number' or 'volume', got "
                             f"{self.psd_basis!r}")
        if not isinstance(self.rve, RVESpec):
            raise ValueError(f"rve: expected an RVESpec, got {type(self.rve).__name__}")
        object.__setattr__(self, "solver", as_solver(self.solver))
        if not isinstance(self.replicas, int) or self.replicas < 2:
            raise ValueError(f"replicas: expected a whole number >= 2 (the RVE scatter needs "
                             f"two), got {self.replicas!r}")
        lo, hi = self.prior_m2K_per_W
        if not (0 < lo < hi < math.inf):
            raise ValueError(f"prior_m2K_per_W: expected 0 < lo < hi in m^2 K/W, got "
                             f"{self.prior_m2K_per_W!r}")

    # the RVE's fields, read through (the specification holds them)
    box_um = property(lambda self: self.rve.box_um, doc="RVE edge, um.")
    voxel_um = property(lambda self: self.rve.voxel_um, doc="Voxel edge, um.")
    seed = property(lambda self: self.rve.seed, doc="Packing seed of the first replica.")
    max_diameter_box_ratio = property(lambda self: self.rve.max_diameter_box_ratio,
                                      doc="Largest particle diameter / box edge.")
    n = property(lambda self: self.rve.n, doc="Voxels per box edge.")

    def to_dict(self) -> dict:
        """Flat JSON-able form: the RVE's fields next to the others."""
        d = {f.name: getattr(self, f.name) for f in fields(self)
             if f.name not in ("rve", "system", "faithful")}
        d["system"] = self.system.to_dict()
        d["solver"] = self.solver.key
        d["prior_m2K_per_W"] = list(self.prior_m2K_per_W)
        d["faithful"] = self.faithful.to_dict() if self.faithful is not None else None
        return {**self.rve.to_dict(), **d}

    def with_(self, **changes) -> "ForwardSettings":
        """A copy with ``changes``; the RVE's fields (``box_um``, ``seed``, ...) go to
        :attr:`rve` and are checked there."""
        rve_names = set(RVESpec.field_names())
        rve_changes = {k: changes.pop(k) for k in list(changes) if k in rve_names}
        if rve_changes:
            changes["rve"] = self.rve.with_(**rve_changes)
        return replace(self, **changes)


def filler_specs(settings: ForwardSettings, fractions: Mapping[str, float]) -> list[FillerSpec]:
    """The fillers of a formulation (filler -> volume fraction) as the RVE generator takes
    them: the size distributions of ``settings.system``. ``settings.psd_basis`` ``"volume"``
    reads a number-basis statement as volume-weighted (the basis question of the paper's
    Table 1); a statement in the volume basis is taken as stated."""
    return [FillerSpec.of(f, settings.system.filler(f).psd, v,
                          number_read_as=settings.psd_basis) for f, v in fractions.items()]


def shipped_factor(settings: ForwardSettings, parametrisation: Parametrisation,
                   fractions: Mapping[str, float]) -> tuple[ShippedFactor | None, str]:
    """The shipped correction of a formulation where ``settings`` ask for it (a faithful RVE
    with ``shipped``, the gap parametrisation) and it holds (the cheap RVE the corrections
    were computed for, number-weighted sizes, a studied system and fraction); else None and
    the reason (empty where the settings do not ask)."""
    fa = settings.faithful
    if fa is None or not fa.shipped or parametrisation.contact != "gap":
        return None, ""
    if settings.replicas != CHEAP_REPLICAS:
        return None, (f"the corrections correct the cheap RVE's {CHEAP_REPLICAS} replicas, "
                      f"not {settings.replicas}")
    if settings.psd_basis != "number":
        return None, ("the corrections hold for the system's size distributions as stated "
                      "(the paper's Table 1: number-weighted), not re-read as "
                      "volume-weighted")
    table = ShippedCorrections.load(fa.corrections, argument="--corrections")
    why = table.why_not_for(settings.system, settings.rve)
    if why:
        return None, why
    factor = table.for_fractions(fractions)
    return (factor, "") if factor is not None else (None, table.why_not(fractions))


def full_solve(ms, materials: Materials, tol: float, *, engine: SolveEngine | None = None,
               solver: Solver | None = None, **labels) -> np.ndarray:
    """Diagonal of k_eff (3,), W/(m K), of ``ms`` (a packed Microstructure, or its
    :class:`~itr_fv.discrete.problem.DiscreteProblem`) by a full solve on the solve engine
    (:mod:`itr_surrogate.engine`; default: this process, no store). The engine keeps one
    discrete problem per RVE, so many solves of one RVE build its geometry once; the
    per-area contact model's VoxelContactWarning is silenced there (that parametrisation is
    tied to its voxel on purpose; the report says so). ``solver``: the resolved
    :class:`~itr_fv.solvers.choice.Solver` (None: the default); ``labels`` go with the
    stored row."""
    if isinstance(ms, DiscreteProblem):
        ms = ms.microstructure
    request = SolveRequest.for_materials(RVEData.of(ms), materials, tol, solver=solver,
                                         **labels)
    return (engine or _SERIAL).solve_one(request).k_diagonal


@dataclass
class ForwardModel:
    """RVE replicas, reduced basis and RVE scatter of one formulation.

    Build with :meth:`build`; :meth:`predict` gives the isotropic conductivity
    ``trace(k_eff) / 3`` (W/(m K)) of the first replica and the reduced basis's error bound.
    """

    formulation: str
    fractions: dict[str, float]
    parametrisation: Parametrisation
    settings: ForwardSettings
    microstructures: list = field(default_factory=list)
    rb: ReducedBasis | None = None
    centre: dict[str, float] = field(default_factory=dict)
    replica_k: np.ndarray | None = None     # (replicas, 3) full solves at the centre
    anchor: dict[str, float] = field(default_factory=dict)
    anchor_k: np.ndarray | None = None      # (replicas, 3) full solves at ``anchor``
    solves: list[dict] = field(default_factory=list)   # the engine's rows (solve_row)
    seeds: list[int] = field(default_factory=list)
    fixed: dict[str, float] = field(default_factory=dict)
    carried_scatter: float = 0.0
    correction: Correction | None = None
    corrections: list[Correction] = field(default_factory=list)  # every round, in order
    faithful_rves: list = field(default_factory=list)   # (RVEData, seed) per faithful packing
    shipped: ShippedFactor | None = None    # the shipped correction, where it holds
    shipped_note: str = ""                  # why there is none, where the level asks for it
    build_seconds: float = 0.0
    engine: SolveEngine | None = field(default=None, repr=False, compare=False)

    @property
    def parameters(self) -> list[str]:
        """The varied parameters (those of the parametrisation not in :attr:`fixed`)."""
        return [p for p in self.parametrisation.parameters(list(self.fractions),
                                                           matrix=self.settings.system.matrix)
                if p not in self.fixed]

    def materials(self, values: Mapping[str, float]) -> Materials:
        """The system's nominal conductivities and known resistances plus ``values`` (flat
        names) under this contact model."""
        system = self.settings.system
        matrix = system.matrix
        k = system.conductivities(self.fractions)
        base = Materials(k, {(f, matrix): 1e-8 for f in self.fractions}, matrix=matrix,
                         contact=self.parametrisation.contact)
        known = {n: v for n, v in system.resistances
                 if set(n.split("_")[1:]) <= set(k)}
        params = {**known, **self.fixed, **dict(values)}
        if self.parametrisation.contact == "area":
            fl = sorted(self.fractions)
            for i, a in enumerate(fl):
                for b in fl[i:]:
                    params.setdefault(parameter_name("Rff", a, b), 1e-7)
        return base.with_parameters(params)

    def pack(self, replica: int, *, progress: bool = False):
        """The RVE of one replica (:func:`itr_fv.rve.build_rve`: packing seed
        ``settings.seed + replica``, redrawn with ``+ 100``, ``+ 200``, ... where a packing
        fails; the seed used is kept in :attr:`seeds`). The box cut of the coarse tail is
        in the report, not a warning; ``progress``: the packing's bar (shown after a
        second)."""
        ms, seed = build_rve(self.settings.rve, filler_specs(self.settings, self.fractions),
                             replica, matrix=self.settings.system.matrix,
                             warn_box_cut=False, progress=progress)
        self.seeds.append(seed)
        return ms

    def build(self, *, bounds: Mapping[str, tuple[float, float]] | None = None,
              progress: bool = False) -> "ForwardModel":
        """Pack the replicas, fit the reduced basis over ``bounds`` (default: the prior box
        of every parameter) and solve every replica at the box centre; returns self.

        Models may be built from several threads at once (on a distributed engine): the
        work done in this process (packing, the reduced basis's own algebra) runs one
        model at a time, and only the waits for the engine's full solves overlap."""
        with _local_work():
            return self._build(bounds, progress)

    def _build(self, bounds: Mapping[str, tuple[float, float]] | None,
               progress: bool) -> "ForwardModel":
        t0 = time.perf_counter()
        s = self.settings
        if bounds is None:
            bounds = {p: tuple(s.prior_m2K_per_W) for p in self.parameters}
        self.microstructures = [self.pack(r, progress=progress) for r in range(s.replicas)]
        self.centre = {p: math.sqrt(lo * hi) for p, (lo, hi) in bounds.items()}
        mat = self.materials(self.centre)
        if bounds:
            # the reduced basis works on this process's problem of replica 0, the one the
            # engine's serial solves use too (one geometry)
            problem = cached_problem(RVEData.of(self.microstructures[0]), mat.contact)[0]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # VoxelContactWarning: the area model
                self.rb = ReducedBasis(problem, mat, bounds, tol=s.rb_tol,
                                       max_solves=s.rb_max_solves, solver_tol=s.solver_tol,
                                       solver=s.solver, seed=s.seed, progress=progress)
                self.rb.fit(full_solve=lambda _problem, m: self._solve_recorded(
                    [self._request(0, m, purpose="reduced basis", fields=True)])[0])
        ks = self._solve_all(self.centre, purpose="RVE scatter")
        self.replica_k = ks
        self.shipped, self.shipped_note = shipped_factor(self.settings, self.parametrisation,
                                                         self.fractions)
        self.build_seconds = time.perf_counter() - t0
        return self

    @property
    def rve_scatter(self) -> float:
        """Relative standard deviation of one RVE's k_iso, estimated from the diagonal
        entries of every replica at the anchor (:meth:`anchor_at`; the box centre before):
        ``sd(k_dd over replicas and directions) / mean / sqrt(3)``. With few replicas the
        spread of k_iso alone is a poor estimate (two replicas of 24^3 gave 0.02 % where six
        gave 0.75 %); the direction-based one has three times the samples and matched six
        replicas (0.7 to 1.4 % for 0.75 to 1.1 %) in ``tests/test_identify.py``'s
        settings."""
        return direction_scatter(self.anchor_k if self.anchor_k is not None
                                 else self.replica_k)

    def _n_rows(self, columns: Mapping[str, np.ndarray]) -> int:
        return max((np.asarray(v).size for v in columns.values()), default=1)

    def clipped(self, columns: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``columns`` restricted to this model's parameters and clipped into its reduced
        basis's box (a later stage's box is narrowed to the earlier posterior)."""
        box = self.rb.box_
        out = {}
        for p in self.parameters:
            i = box.names.index(p)
            out[p] = np.clip(np.asarray(columns[p], dtype=np.float64), box.lo[i], box.hi[i])
        return out

    def outside_fraction(self, columns: Mapping[str, np.ndarray]) -> float:
        """Fraction of the rows of ``columns`` outside the reduced basis's box."""
        if self.rb is None:
            return 0.0
        box = self.rb.box_
        out = np.zeros(np.asarray(columns[self.parameters[0]]).size, dtype=bool)
        for p in self.parameters:
            i = box.names.index(p)
            v = np.asarray(columns[p])
            out |= (v < box.lo[i] * (1 - 1e-9)) | (v > box.hi[i] * (1 + 1e-9))
        return float(out.mean())

    def predict(self, columns: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(k_iso, error bound), each (n,), W/(m K), for ``{name: values}`` columns: the
        first replica's reduced basis times :attr:`replica_factor`
        (clipped into the reduced basis's box: see :meth:`outside_fraction`). Without
        varied parameters, the full solve of the first replica at :attr:`fixed`."""
        k, err = self._predict_raw(columns)
        c = self._factor_of(columns, k.size)
        return k * c, err * c

    def first_replica_k(self, values: Mapping[str, float]) -> tuple[float, float, float]:
        """k_iso of the first replica's reduced basis at ``values`` (m^2 K/W) and its
        certified lower and upper bounds, W/(m K): raw (without the replica factor and the
        fidelity level's factor), the numbers a full solve of that replica checks."""
        if self.rb is None:
            raise ValueError("values: this model holds its parameters fixed; it has no "
                             "reduced basis")
        cols = self.clipped({p: np.array([values[p]]) for p in self.parameters})
        lower, upper = self.rb.bounds_of(cols)
        return (float(np.trace(self.rb.predict(cols)[0]) / 3.0), float(lower[0].mean()),
                float(upper[0].mean()))

    def _predict_raw(self, columns: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`predict` without the faithful correction."""
        if self.rb is None:
            n = self._n_rows(columns)
            return np.full(n, float(self.replica_k.mean())), np.zeros(n)
        cols = self.clipped(columns)
        lower, upper = self.rb.bounds_of(cols)
        k = np.trace(self.rb.predict(cols), axis1=1, axis2=2) / 3.0
        return k * self.replica_factor, (upper - lower).mean(axis=1) * self.replica_factor

    def _factor_of(self, columns: Mapping[str, np.ndarray], n: int) -> np.ndarray:
        """The faithful correction's factor for each row of ``columns``: the last
        correction's; with one varied parameter and two corrections at different values,
        the line through the last two in log10 of the parameter (extrapolated at most one
        span beyond them), so that the corrected model is exact at both and repeated
        corrections converge as a secant method."""
        if self.correction is None:
            if self.shipped is not None:
                return self.shipped.factor(columns, n)[0]
            return np.ones(n)
        last = self.correction
        if len(self.parameters) == 1 and len(self.corrections) >= 2:
            p = self.parameters[0]
            prev = self.corrections[-2]
            xa, xb = math.log10(prev.at[p]), math.log10(last.at[p])
            if abs(xb - xa) > 1e-9:
                lo, hi = min(xa, xb), max(xa, xb)
                span = hi - lo
                x = np.clip(np.log10(np.broadcast_to(np.asarray(columns[p], float), (n,))),
                            lo - span, hi + span)
                slope = (last.factor - prev.factor) / (xb - xa)
                return last.factor + slope * (x - xb)
        return np.full(n, last.factor)

    def level_at(self, values: Mapping[str, float]) -> dict[str, object]:
        """How this model's level is set at ``values`` (flat names, m^2 K/W): ``source``
        (``"runtime"``: corrected by faithful solves of this run; ``"shipped"``: the
        corrections shipped with the package; ``"none"``), the ``factor`` on the cheap
        RVE's k and its ``relative_sd`` there, and where it comes from (the shipped
        system, or the runtime correction's box, voxels, packing seeds and rounds)."""
        cols = {p: np.array([float(values[p])]) for p in self.parameters}
        factor = float(self._factor_of(cols, 1)[0])
        if self.correction is not None:
            c = self.correction
            return {"source": "runtime", "factor": factor, "relative_sd": c.relative_sd,
                    "box_um": c.box_um, "voxels_um": [c.coarse_voxel_um, c.voxel_um],
                    "seeds": list(c.seeds), "rounds": len(self.corrections)}
        if self.shipped is not None:
            u = float(self.shipped.factor(cols, 1)[1][0])
            return {"source": "shipped", "factor": factor, "relative_sd": u,
                    "system": self.shipped.system}
        return {"source": "none", "factor": 1.0, "relative_sd": 0.0,
                **({"why": self.shipped_note} if self.shipped_note else {})}

    @property
    def fidelity_factor(self) -> float:
        """The last faithful correction's factor (:class:`~itr_identify.forward.fidelity.
        Correction`), at the point it was computed at; the shipped correction's at the
        anchor; 1 without either."""
        if self.correction is None and self.shipped is not None:
            return self._shipped_at_anchor()[0]
        return self.correction.factor if self.correction is not None else 1.0

    def _shipped_at_anchor(self) -> tuple[float, float]:
        """The shipped correction's factor and relative uncertainty at the anchor (the box
        centre before it)."""
        at = self.anchor or self.centre
        c, u = self.shipped.factor({p: np.array([v]) for p, v in at.items()}, 1)
        return float(c[0]), float(u[0])

    @property
    def model_sd(self) -> float:
        """Relative standard uncertainty of the model's level beyond its own RVE scatter:
        the earlier stages' spread and the faithful correction's own uncertainty, in
        quadrature (a shipped correction's system-wide term is :meth:`shared_sd`)."""
        u = self.correction.relative_sd if self.correction is not None else 0.0
        if self.correction is None and self.shipped is not None:
            u = self._shipped_at_anchor()[1]
        return math.hypot(self.carried_scatter, u)

    @property
    def shared_system(self) -> str | None:
        """The system whose shared correction term this model's level carries (the shipped
        correction's system where it is in use), else None."""
        return self.shipped.system if self.correction is None and self.shipped else None

    def shared_sd(self, columns: Mapping[str, np.ndarray]) -> np.ndarray:
        """The shipped correction's system-wide relative sd per row of ``columns`` (the box
        step, the voxel bias and the tail cut: one term for every formulation of the
        system), (n,); zeros where the level is not the shipped one."""
        n = self._n_rows(columns)
        if self.shared_system is None:
            return np.zeros(n)
        return self.shipped.shared_sd(columns, n)

    @property
    def packing_dof(self) -> tuple[float, int] | None:
        """(relative sd, degrees of freedom) of the shipped correction's packing term at the
        anchor (a pooled estimate: its dof enter the likelihood's Student t), or None."""
        if self.shared_system is None:
            return None
        at = self.anchor or self.centre
        p = self.shipped.parts({q: np.array([v]) for q, v in at.items()}, 1)
        return float(p["packing"][0]), int(p["packing_dof"])

    def correct_at(self, values: Mapping[str, float], faithful: FaithfulRVE, *,
                   k_model: float | None = None,
                   tick: Callable[[], None] | None = None) -> Correction:
        """Correct the model's level at ``values`` by full solves on faithful packings
        (packed once, re-voxelized at the coarse voxel; every solve on the engine and in
        :attr:`solves`); returns the correction, also kept in :attr:`correction` and
        :attr:`corrections`.

        ``k_model`` is the cheap model's k_iso at ``values``, W/(m K) (default: the reduced
        basis's prediction without the correction; a model without a reduced basis, such
        as a table of full solves, gives it); ``tick`` is called after every solve."""
        values = {p: float(values[p]) for p in self.parameters}
        fillers = list(self.fractions)
        with _local_work():
            if not self.faithful_rves:
                spec = faithful.spec_for(fillers, self.settings.rve)
                for j in range(faithful.packings):
                    ms, seed = build_rve(spec, filler_specs(self.settings, self.fractions),
                                         j, matrix=self.settings.system.matrix,
                                         warn_box_cut=False)
                    self.faithful_rves.append((RVEData.of(ms), seed))
            mat = self.materials(values)
            if k_model is None:
                k_model = float(self._predict_raw({p: np.array([v])
                                                   for p, v in values.items()})[0][0])
        coarse = faithful.coarse_shape(fillers)
        requests = []
        for j, (rve, _) in enumerate(self.faithful_rves):
            for grid, label in ((rve, "fine"), (replace(rve, shape=coarse), "coarse")):
                requests.append(SolveRequest.for_materials(
                    grid, mat, self.settings.solver_tol, solver=self.settings.solver,
                    purpose=f"faithful {label}",
                    formulation=self.formulation, replica=faithful.seed + j))
        with _local_work():
            results = self._solve_recorded(requests, tick=tick)
        k = np.array([res.k_diagonal for res in results])
        corr = Correction(values, faithful.box_for(fillers), faithful.voxel_um,
                          faithful.coarse_voxel_um, [s for _, s in self.faithful_rves],
                          k_model, k[0::2], k[1::2])
        self.correction = corr
        self.corrections.append(corr)
        return corr

    @property
    def replica_factor(self) -> float:
        """Mean k_iso of all replicas over that of the first, at the anchor (the box centre
        until :meth:`anchor_at`): scales the first replica's reduced basis to the replica
        mean. The ratio depends on the parameters (for Al2O3-55 at 12 um it was 0.978 at
        the centre of the prior box and 0.970 at R = 2.2e-8), hence the anchor."""
        k = self.anchor_k if self.anchor_k is not None else self.replica_k
        return float(k.mean() / k[0].mean())

    def anchor_at(self, values: Mapping[str, float]) -> "ForwardModel":
        """Solve every replica at ``values`` (typically a first calibration's best values)
        and take :attr:`replica_factor` and :attr:`rve_scatter` from there; returns self.
        Without varied parameters (the replica mean is the prediction) nothing is done."""
        if self.rb is None:
            return self
        values = {p: float(values[p]) for p in self.parameters}
        self.anchor_k = self.solve_replicas(values, purpose="anchor")
        self.anchor = values
        return self

    def solve_replicas(self, values: Mapping[str, float],
                       tick: Callable[[], None] | None = None, *,
                       purpose: str = "validation",
                       inputs: Mapping[str, float] | None = None,
                       film_m: float | None = None) -> np.ndarray:
        """Full solves (replicas, 3) of every replica at ``values``, W/(m K); the anchor's
        solves are reused when ``values`` is the anchor; ``inputs``: phase conductivities
        other than the system's nominal ones (``k_<phase>``, W/(m K)); ``film_m``: touching
        particles at this film, m (default the RVE's own)."""
        values = {p: float(values[p]) for p in self.parameters}
        if inputs or film_m is not None:
            return self._solve_all({**values, **{k: float(v) for k, v in (inputs or {}).items()}},
                                   purpose=purpose, tick=tick, film_m=film_m)
        if self.anchor_k is not None and values == self.anchor:
            if tick is not None:
                for _ in self.microstructures:
                    tick()
            return self.anchor_k.copy()
        return self._solve_all(values, purpose=purpose, tick=tick)

    @property
    def _engine(self) -> SolveEngine:
        return self.engine if self.engine is not None else _SERIAL

    def _request(self, replica: int, mat: Materials, *, purpose: str,
                 fields: bool = False, tol: float | None = None,
                 film_m: float | None = None) -> SolveRequest:
        ms = self.microstructures[replica]
        return SolveRequest.for_materials(
            RVEData.of(ms if film_m is None else ms.with_film(film_m)), mat,
            self.settings.solver_tol if tol is None else tol,
            solver=self.settings.solver, fields=fields, purpose=purpose,
            formulation=self.formulation, replica=replica)

    def _solve_all(self, values: Mapping[str, float], *, purpose: str,
                   tick: Callable[[], None] | None = None,
                   film_m: float | None = None) -> np.ndarray:
        """Full solves (replicas, 3) of every replica at ``values`` on the engine (the
        replicas in parallel where it has workers), recorded in :attr:`solves`."""
        mat = self.materials(values)
        requests = [self._request(r, mat, purpose=purpose, film_m=film_m)
                    for r in range(len(self.microstructures))]
        results = self._solve_recorded(requests, tick=tick)
        return np.array([res.k_diagonal for res in results])

    def _solve_recorded(self, requests: list[SolveRequest], *,
                        tick: Callable[[], None] | None = None) -> list[SolveResult]:
        """``requests`` on the engine, each recorded in :attr:`solves` (the store's row)."""
        with _waiting_for_solves():
            results = self._engine.solve(requests, tick=tick)
        self.solves.extend(solve_row(q, res) for q, res in zip(requests, results))
        return results

    def solve_first(self, values: Mapping[str, float], *, purpose: str,
                    tol: float | None = None, film_m: float | None = None) -> np.ndarray:
        """Full solve (3,) of the first replica at ``values`` (with :attr:`fixed`), recorded
        in :attr:`solves`; ``tol``: the solver's relative residual (default the settings');
        ``film_m``: touching particles at this film, m (default the RVE's own)."""
        request = self._request(0, self.materials(values), purpose=purpose, tol=tol,
                                film_m=film_m)
        return self._solve_recorded([request])[0].k_diagonal
