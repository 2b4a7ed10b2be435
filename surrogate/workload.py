"""What a command will compute, and whether it can: one estimate before any work.

Every command that packs or solves (``itr demo``, ``identify``, ``reproduce``,
``discrepancy``, ``campaign run``, ``corrections build``) first describes its work as a
:class:`Workload`: per RVE size (:class:`Grid`) the RVEs it packs, their expected particles,
the full solves and whether they keep fields. From that alone, before anything is packed,

- **memory**: one solve's peak on the largest grid (the solver's measured bytes per voxel,
  :func:`itr_fv.solvers.resources.estimate_peak_memory`, plus the discrete problem the
  process keeps, :data:`~itr_surrogate.worker.PROBLEM_BYTES_PER_VOXEL`), against what this
  machine has available now (a Dask worker's limit: that plus the worker's own base,
  :func:`~itr_surrogate.cluster.worker_memory_limit`); :meth:`Workload.check` refuses in one
  line what cannot fit and says what would (the finest voxel, the largest box);
- **time**: packing (:data:`PACK_SECONDS_PER_PARTICLE`) plus solves (the solver's measured
  seconds per voxel and load case, :attr:`itr_fv.solvers.choice.SolverChoice.seconds_per_voxel`,
  and :data:`SOLVE_OVERHEAD_S` per solve), on this machine's cores or the workers: an
  order of magnitude, said as such.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace

from itr_fv.io import counted
from itr_fv.rve import FillerSpec
from itr_fv.rve.generate import size_cut
from itr_fv.rve.spec import RVESpec
from itr_fv.solvers.choice import Solver, load_case_seconds
from itr_fv.solvers.resources import HEADROOM, available_memory, estimate_peak_memory

from .cluster import worker_memory_limit
from .worker import PROBLEM_BYTES_PER_VOXEL, PROBLEM_CACHE_BYTES

__all__ = ["Grid", "Workload", "WorkloadRefused", "expected_particles", "campaign_workload",
           "PACK_SECONDS_PER_PARTICLE", "SOLVE_OVERHEAD_S", "PROCESS_BASE_BYTES"]

#: Packing wall time per particle, s (serial packer; validation/results/bench_rve.md: 0.5 ms
#: per particle at 55-60 vol%, 1.5 ms at 65 vol%, on the 2-core reference machine).
PACK_SECONDS_PER_PARTICLE = 1.0e-3
#: Fixed cost of one full solve beyond its CG (set-up, gauge, tensor, the store's row), s.
SOLVE_OVERHEAD_S = 0.3
#: Resident bytes of a command's process before its first RVE: Python, NumPy, SciPy, numba
#: and the package (measured 0.22-0.36 GB; validation/results/memory.md's baselines).
PROCESS_BASE_BYTES = 4 * 10**8


class WorkloadRefused(ValueError):
    """Work that cannot fit in memory: one line with the estimate and what would fit."""


def expected_particles(rve: RVESpec, fillers: Sequence[FillerSpec]) -> int:
    """Particles a packing of ``fillers`` in ``rve`` draws, by expectation: per filler its
    volume fraction of the box over the mean volume of its size distribution within the
    RVE's size cuts (:func:`itr_fv.rve.generate.size_cut`).

    Raises
    ------
    ValueError
        A voxel too coarse for the fillers' small particles (the packer's own refusal).
    """
    total = 0.0
    for f in fillers:
        cut = size_cut(f, rve.box_um, rve.voxel_um, tail_quantile=rve.tail_quantile,
                       min_diameter_voxels=rve.min_diameter_voxels,
                       max_diameter_box_ratio=rve.max_diameter_box_ratio)
        mean_v = math.pi / 6 * f.psd.truncated_moment_um(3.0, cut.d_lo_um, cut.d_hi_um)
        total += f.volume_fraction * rve.box_um ** 3 / mean_v
    return int(math.ceil(total))


@dataclass(frozen=True)
class Grid:
    """Full solves on RVEs of one size.

    Attributes
    ----------
    label : str
        What they are, for the plan's line (e.g. ``"cheap RVEs"``).
    box_um, voxel_um : float
        Box and voxel edge, um.
    rves : int
        RVEs packed on this grid.
    solves : int
        Full solves (three load cases each), at most.
    particles : int
        Expected particles of one RVE (the largest formulation's).
    fields : bool
        Whether the solves keep their fields (reduced-basis snapshots, a .vti).
    kept_fields : int
        Solves whose fields the run holds in memory until it ends (reduced-basis
        snapshots: three load cases of float64 per voxel each).
    """

    label: str
    box_um: float
    voxel_um: float
    rves: int
    solves: int
    particles: int = 0
    fields: bool = False
    kept_fields: int = 0

    @property
    def n(self) -> int:
        """Voxels per edge."""
        return int(round(self.box_um / self.voxel_um))

    @property
    def voxels(self) -> int:
        return self.n ** 3

    def solve_bytes(self, solver: Solver) -> int:
        """Peak bytes of one solve on this grid in a process that holds its problem."""
        backend = solver.entry.backend
        est = estimate_peak_memory((self.n,) * 3, backend, store_fields=self.fields)
        return int(est + PROBLEM_BYTES_PER_VOXEL * self.voxels)

    def held_bytes(self) -> tuple[int, int]:
        """(the discrete problems of its RVEs, the fields it keeps), bytes: what a run holds
        beside the solve in flight (the problems up to the process's cache budget)."""
        return (PROBLEM_BYTES_PER_VOXEL * self.voxels * self.rves,
                3 * 8 * self.voxels * self.kept_fields)

    def seconds(self, solver: Solver) -> float:
        """Serial wall time of its packings and solves, s (an order of magnitude): each
        solve three load cases of the cost model (:func:`~itr_fv.solvers.choice.
        load_case_seconds`) of the solver this grid goes to (:meth:`~itr_fv.solvers.choice.
        Solver.for_grid`: a GPU's small grids to the CPU), as the solves themselves choose."""
        entry = solver.for_grid(self.voxels).entry
        return (self.rves * self.particles * PACK_SECONDS_PER_PARTICLE
                + self.solves * (SOLVE_OVERHEAD_S + 3 * load_case_seconds(entry, self.voxels)))


def _gb(b: float) -> str:
    return f"{b / 1e9:.1f} GB" if b >= 1e8 else f"{b / 1e6:.0f} MB"


def _duration(s: float) -> str:
    if s < 90:
        return f"{max(s, 1):.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.1f} h"


@dataclass(frozen=True)
class Workload:
    """The work of one command: its grids, the solver and where the solves run.

    Attributes
    ----------
    grids : tuple of Grid
    solver : Solver
        The resolved solver (:func:`itr_fv.solvers.choice.resolve_solver`).
    workers : int, optional
        Local Dask worker processes (None: serially in this process).
    scheduler : str, optional
        An external Dask scheduler: its workers' memory is theirs, checked when they
        are reached (:func:`itr_surrogate.cluster.ready_workers`), not here.
    """

    grids: tuple[Grid, ...]
    solver: Solver
    workers: int | None = None
    scheduler: str | None = None
    #: Processes of this machine that share the grids' solves side by side, each holding
    #: its own caches and fields (1: this process alone).
    processes: int = 1

    def __post_init__(self) -> None:
        if not self.grids:
            raise ValueError("grids: a workload needs at least one grid")
        if not isinstance(self.solver, Solver):
            raise ValueError(f"solver: expected a Solver (itr_fv.solvers.choice.resolve_solver), "
                             f"got {self.solver!r}")
        if isinstance(self.processes, bool) or not isinstance(self.processes, int) \
                or self.processes < 1:
            raise ValueError(f"processes: expected a whole number >= 1, got "
                             f"{self.processes!r}")

    @property
    def largest(self) -> Grid:
        return max(self.grids, key=lambda g: (g.solve_bytes(self.solver), g.voxels))

    def peak_bytes(self) -> int:
        """Peak of the command's process, bytes: the interpreter and libraries
        (:data:`PROCESS_BASE_BYTES`), the solve on the largest grid, the discrete problems it
        caches (at most :data:`~itr_surrogate.worker.PROBLEM_CACHE_BYTES`) and the fields it
        keeps; on Dask workers, one worker's limit
        (:func:`~itr_surrogate.cluster.worker_memory_limit`)."""
        return self._peak(self.grids)

    def _peak(self, grids: Sequence[Grid]) -> int:
        task = max(g.solve_bytes(self.solver) for g in grids)
        if self.workers or self.scheduler:
            return worker_memory_limit(task)
        problems = sum(g.held_bytes()[0] for g in grids)
        fields = sum(g.held_bytes()[1] for g in grids)
        each = PROCESS_BASE_BYTES + task + min(problems, PROBLEM_CACHE_BYTES) + fields
        # side by side: every process as large as one alone would be (a bound), and this
        # one waiting beside them
        return int(self.processes * each
                   + (PROCESS_BASE_BYTES if self.processes > 1 else 0))

    def _fit(self, g: Grid, budget: float) -> int:
        """The most voxels per edge grid ``g`` may have, its box kept, for a run of it alone
        to stay within ``budget`` bytes; 0 if not even 8 fit."""
        def peak(n: int) -> int:
            return self._peak([replace(g, voxel_um=g.box_um / n)])

        lo, hi = 0, g.n
        while hi - lo > 1:                       # peak(lo) fits (or lo = 0), peak(hi) not
            mid = (lo + hi) // 2
            if peak(max(mid, 8)) <= budget:
                lo = max(mid, 8)
            else:
                hi = mid
        return lo if lo >= 8 else 0

    def seconds(self) -> float:
        """Wall time on this machine's cores (local workers share them), s."""
        serial = sum(g.seconds(self.solver) for g in self.grids)
        parallel = max(1, min(self.workers or 1, os.cpu_count() or 1))
        return serial / parallel

    def refusal(self, available: int | None = None) -> str | None:
        """The one-line refusal when the largest grid cannot fit in ``available`` bytes
        (default: what this machine has now), else None."""
        if self.scheduler:
            return None
        avail = available_memory() if available is None else int(available)
        need = self.peak_bytes()
        if avail is None or need <= HEADROOM * avail:
            return None
        g = self.largest
        budget = HEADROOM * avail
        fit = self._fit(g, budget)
        where = "a Dask worker" if self.workers else "the run"
        hint = (f"at most ~{fit}^3 voxels fit: a voxel of at least {g.box_um / fit:.3g}"
                f" um for the {g.box_um:g} um box, or a box of at most "
                f"{fit * g.voxel_um:.3g} um at {g.voxel_um:g} um" if fit else
                "no grid of 8^3 voxels or more fits")
        also = [h for h in self.grids if h is not g and self._peak([h]) > budget]
        if also:
            hint += "; too large as well: " + ", ".join(f"{h.n}^3 ({h.label})" for h in also)
        return (f"memory: {where} on {g.n}^3 voxels ({g.label}: {g.box_um:g} um box at "
                f"{g.voxel_um:g} um, solver {self.solver}) needs ~{_gb(need)} but "
                f"{_gb(avail)} is available; {hint}")

    def check(self, available: int | None = None) -> None:
        """Refuse what cannot fit (:meth:`refusal`), before any work.

        Raises
        ------
        WorkloadRefused
            One line: the estimate, what is available and what would fit.
        """
        why = self.refusal(available)
        if why:
            raise WorkloadRefused(why)

    def summary(self) -> str:
        """The plan in one line: grids, solves, peak memory against what is available,
        and the time on this machine."""
        parts = [f"{counted(g.rves, 'RVE')} of {g.n}^3 ({g.label}, {g.box_um:g} um at "
                 f"{g.voxel_um:g} um, ~{g.particles} particles), about "
                 f"{counted(g.solves, 'solve')}" for g in self.grids]
        avail = available_memory()
        where = (f"each worker of scheduler {self.scheduler}" if self.scheduler else
                 f"{counted(self.workers, 'local worker')}" if self.workers else
                 f"this process and {self.processes} side processes" if self.processes > 1
                 else "this process")
        mem = f"peak ~{_gb(self.peak_bytes())} in {where}"
        if avail is not None and not self.scheduler:
            mem += f" of {_gb(avail)} available"
        cores = os.cpu_count() or 1
        goes_to = {g.n: self.solver.for_grid(g.voxels).key for g in self.grids}
        routed = {n: to for n, to in sorted(goes_to.items()) if to != self.solver.key}
        solver = self.solver.key + (f", its {', '.join(f'{n}^3' for n in routed)} solves on the "
                                f"CPU ({', '.join(sorted(set(routed.values())))}: sooner "
                                "there by the cost model)" if routed else "")
        time = ("time: on the scheduler's workers" if self.scheduler else
                f"about {_duration(self.seconds())} on {counted(cores, 'core')} (solver "
                f"{solver}; an order of magnitude)")
        return "plan: " + "; ".join(parts) + f"; {mem}; {time}"

    def alternatives(self) -> str:
        """One line: what a CUDA device or a Dask scheduler would change (the same grids on
        the ``gpu`` solver's measured speed; the solves spread over a cluster's workers)."""
        on_gpu = self.solver.device == "cuda"
        other = replace(self, solver=self.solver.on_other_device(), workers=None,
                        scheduler=None)
        where = (f"on the CPU (--device cpu, solver {other.solver})" if on_gpu
                 else "on a CUDA device (--device cuda)")
        serial = sum(g.seconds(self.solver) for g in self.grids)
        return (f"  {where}: about {_duration(other.seconds())} (peak "
                f"~{_gb(other.peak_bytes())}); with --scheduler ADDRESS the solves spread "
                f"over its workers: about {_duration(serial / 8)} on 8 workers")


def campaign_workload(campaign, *, workers: int | None = None,
                      scheduler: str | None = None, label: str | None = None) -> Workload:
    """The work of a :class:`~itr_surrogate.campaign.Campaign`: one packing per task (a task
    packs its RVE and solves a block of parameter sets on it, warm-starting from the block's
    fields); ``workers`` local Dask workers (None or 0: in this process)."""
    particles = max(expected_particles(campaign.rve, f.specs()) for f in campaign.formulations)
    grid = Grid(label or f"campaign {campaign.name}", campaign.rve.box_um,
                campaign.rve.voxel_um, rves=len(campaign.tasks()), solves=campaign.n_solves(),
                particles=particles, fields=True)
    return Workload((grid,), campaign.solver, workers or None, scheduler)
