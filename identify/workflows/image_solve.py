"""The ``itr solve VOLUME`` job: the conductivity tensor of a segmented volume with interface
resistances, its plan before any work, and its output folder.

The volume, the phase table and the particles are read and checked in :mod:`itr_fv.rve`
(:mod:`~itr_fv.rve.volume_files`, :mod:`~itr_fv.rve.phase_table`,
:mod:`~itr_fv.rve.from_image`), the resistances gathered in
:mod:`itr_fv.materials.resistance_sources`; this module plans the solve, runs it through
:func:`itr_fv.homogenize` and writes ``result.json``, ``image.vti``, ``slice.png`` and
``manifest.json`` (last).
"""

from __future__ import annotations

import json
import math
import os
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from itr_fv import Materials, Microstructure
from itr_fv.rve.phase_table import PhaseTable
from itr_fv.rve.volume_files import LabelVolume
from itr_fv.solvers.choice import Solver, load_case_seconds
from itr_fv.solvers.resources import (
    HEADROOM,
    InsufficientMemoryError,
    available_memory,
    check_device_memory,
    estimate_peak_memory,
)
from itr_surrogate.worker import PROBLEM_BYTES_PER_VOXEL
from itr_surrogate.workload import PROCESS_BASE_BYTES, SOLVE_OVERHEAD_S, WorkloadRefused

__all__ = ["ImagePlan", "ImageJob", "run_image_solve", "image_summary"]


def _gb(b: float) -> str:
    return f"{b / 1e9:.1f} GB" if b >= 1e8 else f"{b / 1e6:.0f} MB"


@dataclass(frozen=True)
class ImagePlan:
    """The one solve of an image: its peak memory and time before any work (the
    interface of :class:`itr_surrogate.workload.Workload` that the output folder asks).

    Attributes
    ----------
    shape : (n1, n2, n3)
        The image's voxels per axis.
    voxel_um : float
        Voxel edge, um.
    solver : Solver
        The resolved solver.
    """

    shape: tuple[int, int, int]
    voxel_um: float
    solver: Solver

    @property
    def voxels(self) -> int:
        return math.prod(self.shape)

    def peak_bytes(self) -> int:
        """The process (:data:`~itr_surrogate.workload.PROCESS_BASE_BYTES`), the solve with
        its fields and the discrete problem, bytes."""
        backend = self.solver.entry.backend
        return int(PROCESS_BASE_BYTES + PROBLEM_BYTES_PER_VOXEL * self.voxels
                   + estimate_peak_memory(self.shape, backend, store_fields=True))

    def seconds(self, solver: Solver | None = None) -> float:
        """Wall time of the three load cases (cost model: an order of magnitude), s."""
        entry = (solver or self.solver).for_grid(self.voxels).entry
        return SOLVE_OVERHEAD_S + 3 * load_case_seconds(entry, self.voxels)

    def refusal(self, available: int | None = None) -> str | None:
        """One line when the solve cannot fit (host memory, or the device's), else None."""
        grid = "x".join(str(n) for n in self.shape)
        try:
            check_device_memory(self.shape, self.solver.backend(voxels=self.voxels))
        except InsufficientMemoryError as exc:
            return str(exc).replace("; pass check_memory=False to try anyway", "")
        avail = available_memory() if available is None else int(available)
        need = self.peak_bytes()
        if avail is None or need <= HEADROOM * avail:
            return None
        fit = int(self.voxels * (HEADROOM * avail - PROCESS_BASE_BYTES) / need)
        return (f"memory: the solve of the {grid} image (solver {self.solver}) needs "
                f"~{_gb(need)} but {_gb(avail)} is available; about {max(fit, 0):.3g} voxels "
                f"(~{max(fit, 1) ** (1 / 3):.0f}^3) fit: crop or downsample the volume")

    def check(self) -> None:
        """Refuse what cannot fit (:class:`~itr_surrogate.workload.WorkloadRefused`)."""
        why = self.refusal()
        if why:
            raise WorkloadRefused(why)

    def summary(self) -> str:
        grid = "x".join(str(n) for n in self.shape)
        avail = available_memory()
        mem = f"peak ~{_gb(self.peak_bytes())}" + (f" of {_gb(avail)} available"
                                                   if avail is not None else "")
        return (f"plan: one solve (3 load cases) of the {grid} image ({self.voxels / 1e6:.3g} M "
                f"voxels of {self.voxel_um:g} um), solver {self.solver}; {mem} in this "
                f"process; about {max(self.seconds(), 1):.0f} s on {os.cpu_count() or 1} "
                "cores (an order of magnitude)")

    def alternatives(self) -> str:
        other = self.solver.on_other_device()
        where = ("on the CPU (--device cpu)" if self.solver.device == "cuda"
                 else "on a CUDA device (--device cuda)")
        return f"  {where}: about {max(self.seconds(other), 1):.0f} s"


@dataclass(frozen=True)
class ImageJob:
    """Everything an image solve runs on, checked.

    Attributes
    ----------
    volume : LabelVolume
    phases : PhaseTable
    microstructure : Microstructure
    materials : Materials
        Conductivities, resistances, ``contact="area"``.
    resistances : dict
        Per pair ``"A-B"``: value, source and overridden values (the record of
        :func:`itr_fv.materials.resistance_sources.merge_resistances`), plus ``sources``.
    particles : dict
        How the particles were labelled (``method``, its parameter or file).
    solver : Solver
    tol : float
    system : dict
        The material system (``MaterialSystem.to_dict``).
    """

    volume: LabelVolume
    phases: PhaseTable
    microstructure: Microstructure
    materials: Materials
    resistances: dict
    particles: dict
    solver: Solver
    tol: float = 1e-8
    system: dict = field(default_factory=dict)


def _sizes(ms: Microstructure) -> dict:
    from itr_fv.rve.from_image import particle_sizes_um

    out = {}
    for phase, d in particle_sizes_um(ms).items():
        out[phase] = {"count": int(d.size), "mean_um": float(d.mean()),
                      "sd_um": float(d.std(ddof=1)) if d.size > 1 else 0.0,
                      "min_um": float(d.min()), "max_um": float(d.max())}
    return out


def image_summary(job: ImageJob) -> dict:
    """Phase fractions, particle statistics and percolation of the job's microstructure."""
    from itr_fv.discrete.percolation import spanning_clusters

    ms = job.microstructure
    perc = spanning_clusters(ms)
    axes = job.volume.axes
    spans = [a for a, s in zip(axes, perc["spans"]) if s]
    note = (f"a filler cluster spans the box along {', '.join(spans)}" if spans else
            "no filler cluster spans the box along any axis")
    return {"phase_fractions": ms.volume_fractions(), "particles": ms.n_particles,
            "particle_sizes": _sizes(ms),
            "percolation": {**perc, "axes": list(axes), "note": note + " (clusters joined "
                            "through faces, contacts included; the image as a sample, its "
                            "periodic wrap cut)"}}


def _tensor_lines(res, axes: tuple[str, ...]) -> list[str]:
    lines = ["k_eff (W/(m K)), columns = load cases:"]
    for i, row in enumerate(res.k_eff):
        lines.append("  " + "  ".join(f"{v:12.6g}" for v in row) + f"   ({axes[i]})")
    for d, it, r in zip(res.directions, res.iterations, res.residuals):
        lines.append(f"  load e{d + 1} (1 K/m along {axes[d]}): {it} iterations, residual "
                     f"{r:.1e}")
    return lines


def _summary_lines(summary: dict) -> list[str]:
    lines = ["phase fractions: " + ", ".join(f"{p} {v:.4f}" for p, v in
                                            summary["phase_fractions"].items())]
    lines.append(f"particles: {summary['particles']}")
    for p, s in summary["particle_sizes"].items():
        lines.append(f"  {p}: {s['count']}, equivalent diameter mean {s['mean_um']:.3g} um, "
                     f"sd {s['sd_um']:.3g}, min {s['min_um']:.3g}, max {s['max_um']:.3g}")
    lines.append(f"percolation: {summary['percolation']['note']}")
    return lines


def residual_bar(tol: float, *, cases: int = 3, progress: bool = True):
    """A progress bar of a solve's load cases by decades of their relative residual (down
    to ``tol``; tqdm's ETA) and the solver callback that moves it; returns (bar, callback)."""
    from tqdm.auto import tqdm

    decades = max(1, math.ceil(-math.log10(tol) - 1e-9))
    bar = tqdm(total=cases * decades, desc=f"solve ({cases} load cases)", unit="decade",
               disable=not progress)
    reached: dict[int, int] = {}

    def callback(direction: int, iteration: int, residual: float) -> None:
        d = min(decades, max(0, int(math.floor(-math.log10(max(residual, 1e-300))))))
        if d > reached.get(direction, 0):
            bar.update(d - reached.get(direction, 0))
            reached[direction] = d

    return bar, callback


def run_image_solve(job: ImageJob, out: Path, echo: Callable[[str], None] = print, *,
                    progress: bool = True) -> list[Path]:
    """Solve the job's image and write its folder; returns the files (manifest last);
    ``progress``: a bar of the load cases' residual decades.

    ``out`` must be claimed for ``itr solve`` (or free: it is claimed here).
    """
    from itr_fv import __version__, homogenize
    from itr_fv.io import write_text
    from itr_fv.output.slice_png import slice_png
    from itr_fv.run_folder import begin_run, write_manifest

    begin_run(out, "solve")
    t0 = time.perf_counter()
    ms = job.microstructure
    summary = image_summary(job)
    backend = job.solver.backend(voxels=math.prod(ms.shape))
    bar, callback = residual_bar(job.tol, progress=progress)
    with bar, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = homogenize(ms, job.materials, solver=backend, tol=job.tol, callback=callback)
    notes = _notes(caught, ms)
    for line in _tensor_lines(res, job.volume.axes) + _summary_lines(summary):
        echo(line)
    vti = res.to_vtk(out / "image.vti", vectors=True)
    png = slice_png(res, out / "slice.png", load_case=0)
    record = {
        "k_eff_W_per_mK": res.k_eff.tolist(),
        "load_cases": [{"direction": job.volume.axes[d], "load": f"e{d + 1}, 1 K/m",
                        "iterations": it, "relative_residual": r}
                       for d, it, r in zip(res.directions, res.iterations, res.residuals)],
        "symmetry_error": res.symmetry_error, **summary,
        "input": job.volume.describe(), "phase_table": job.phases.to_dict(),
        "particle_labels": job.particles, "resistances_m2K_per_W": job.resistances,
        "contact_model": "area (per-area resistance at faces between two particles)",
        "conductivities_W_per_mK": job.materials.conductivity, "system": job.system,
        "solver": {"key": job.solver.key, "backend": res.solver, "device": job.solver.device,
                   "ran_on": job.solver.for_grid(math.prod(ms.shape)).device,
                   "tol": job.tol},
        "notes": notes, "wall_time_s": time.perf_counter() - t0,
        "package_version": __version__}
    js = write_text(out / "result.json", json.dumps(record, indent=2, default=_plain) + "\n")
    files = [js, vti, png]
    manifest = write_manifest(out, files, {"volume": job.volume.path, "tol": job.tol,
                                           "solver": job.solver.key}, job="solve")
    echo(f"wrote {js}, {vti}, {png}, {manifest}")
    return files + [manifest]


def _notes(caught: list, ms: Microstructure) -> list[str]:
    """The solve's warnings, said once each (and on standard error): the per-area contact
    resistance in the words of an image solve, every other as it came."""
    from itr_fv.checks import VoxelContactWarning

    notes = []
    for w in caught:
        if issubclass(w.category, VoxelContactWarning):
            text = (f"contact: the per-area contact resistance acts on the voxel faces between "
                    f"touching particles; their area, and so the value to give, belongs to "
                    f"the voxel size ({ms.voxel_m * 1e6:.4g} um here)")
            warnings.warn(text, UserWarning, stacklevel=3)
        else:
            text = str(w.message)
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        if text not in notes:
            notes.append(text)
    return notes


def _plain(value: object) -> object:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON: {type(value).__name__}")
