"""The ``itr demo`` job: one random RVE of a material system's first filler (the paper's:
Al2O3 in silicone), its k_eff, a .vti file and a figure.

Defaults come from the package's own studies, not from convenience:

- the gap contact model (the package default): contacts are the two particle-matrix
  resistances and the silicone film between the spheres, so the paper's Al2O3-silicone
  resistance (Table 5) is the only interface value, and k_eff converges under refinement;
- voxel 0.16 um: reads 1.40 % and 1.47 % below the extrapolated k_eff on two dense 60 %
  Al2O3 packings (``validation/results/resolution.md``; first-order convergence, the same
  bias on both packings); 0.125 um reads -1.0 %, 0.0625 um -0.5 %;
- the FFT solver: the same discrete system as the FV reference to solver tolerance
  (``validation/results/crossval.md``) and 4-7x faster on these grids
  (``validation/results/bench_solvers.md``);
- a 16 um box (100^3 voxels), largest diameter 0.45 box (the packer's pair search needs
  below 0.5; the default box/3 would cut 21 % of the Al2O3 volume, this cuts 4.7 %): the
  scatter between packings of this size is printed with the result (``DEMO_SCATTER``).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from itr_fv.materials import default_system, is_default_system, paper_data
from itr_fv.materials.material_system import MaterialSystem
from itr_fv.materials.parameters import parameter_name
from itr_fv.rve.spec import RVESpec
from itr_fv.solvers.choice import Solver, as_solver, default_solver

__all__ = ["DemoSettings", "run_demo", "demo_workload", "PAPER_R", "VOXEL_BIAS", "DEMO_SCATTER"]

# The paper's identified resistances (Table 5), m^2 K/W, and its conductivities, W/(m K).
PAPER_R = paper_data.paper_resistances()
#: The filler-matrix resistance of a system that states none, m^2 K/W (the order of the
#: paper's identified values).
TYPICAL_R = 1e-8
#: The demo's largest grid, voxels per edge.
MAX_DEMO_VOXELS = 512

#: Measured discretisation bias of k_iso against the Richardson-extrapolated value, per
#: voxel (um): (smallest, largest) over two packings, %, dense 60 % Al2O3 under the gap model
#: at the paper's Al2O3-silicone resistance (validation/results/resolution.md).
VOXEL_BIAS = {0.25: (-2.50, -2.46), 0.2: (-1.92, -1.86), 0.16: (-1.47, -1.40),
              0.125: (-1.04, -1.03), 0.1: (-0.78, -0.77), 0.08: (-0.61, -0.60),
              0.0625: (-0.48, -0.47)}

#: RVE-to-RVE scatter of k_iso at the demo's default settings (16 um box, 0.16 um voxel,
#: 55 % Al2O3, gap model): relative standard deviation and full range over seeds 1-4, %, of
#: k_iso and of the single diagonal components. Measured (itr_fft, tol 1e-8): k_iso = 1.3459,
#: 1.3400, 1.3567, 1.3467 W/(m K) for seeds 1-4; k_xx, k_yy, k_zz from 1.313 to 1.380.
DEMO_SCATTER = {"seeds": 4, "std_percent": 0.5, "range_percent": 1.2,
                "component_std_percent": 1.5, "component_range_percent": 5.0}


@dataclass(frozen=True)
class DemoSettings:
    """Settings of one demo run.

    Attributes
    ----------
    rve : RVESpec
        Box (default 16 um), voxel (0.16 um), packing seed (1), checked there.
    fraction : float
        Volume fraction of the system's first filler.
    solver : str
        A resolved solver choice of :mod:`itr_fv.solvers.choice` (``"fft"``, ``"gpu"``, ...).
    tol : float
        Relative residual of the solve.
    system : MaterialSystem
        The matrix and filler (default: the paper's, Al2O3 in silicone).
    """

    rve: RVESpec = RVESpec(box_um=16.0, voxel_um=0.16)
    fraction: float = 0.55
    solver: Solver = field(default_factory=default_solver)
    tol: float = 1e-8
    system: MaterialSystem = field(default_factory=default_system)

    @property
    def filler(self) -> str:
        """The filler of the demo: the system's first."""
        return self.system.filler_names[0]

    def resistance(self) -> tuple[float, str]:
        """The filler-matrix resistance the demo solves at, m^2 K/W, and where it is from:
        the paper's Table 5 for its system, a value the system states, else
        :data:`TYPICAL_R`."""
        pair = (self.filler, self.system.matrix)
        name = parameter_name("R", *pair)
        if is_default_system(self.system) and pair in PAPER_R:
            return PAPER_R[pair], "the paper's Table 5"
        known = dict(self.system.resistances)
        if name in known:
            return known[name], "the system file"
        return TYPICAL_R, "a typical value (the system states none)"

    def __post_init__(self) -> None:
        if self.rve.n > MAX_DEMO_VOXELS:
            raise ValueError(f"box_um/voxel_um: {self.rve.n}^3 voxels is beyond the demo's "
                             f"{MAX_DEMO_VOXELS}^3 limit")
        object.__setattr__(self, "solver", as_solver(self.solver))

    box_um = property(lambda self: self.rve.box_um, doc="RVE edge, um.")
    voxel_um = property(lambda self: self.rve.voxel_um, doc="Voxel edge, um.")
    seed = property(lambda self: self.rve.seed, doc="Packing seed.")
    n = property(lambda self: self.rve.n, doc="Voxels per box edge.")

    def to_dict(self) -> dict:
        """Flat JSON-able form: the RVE's fields next to the others."""
        d = asdict(self)
        del d["rve"]
        d["system"] = self.system.to_dict()
        d["solver"] = self.solver.key
        return {**self.rve.to_dict(), **d}


def bias_note(voxel_um: float) -> str:
    """What the resolution study says of this voxel size (one line)."""
    known = sorted(VOXEL_BIAS)
    if voxel_um < known[0]:
        return (f"voxel {voxel_um:g} um is finer than the resolution study's finest "
                f"({known[0]:g} um, bias {VOXEL_BIAS[known[0]][0]:+.1f} %)")
    # nearest studied voxel at or above this one bounds the bias from above
    above = min((v for v in known if v >= voxel_um - 1e-12), default=None)
    if above is None:
        return (f"voxel {voxel_um:g} um is coarser than anything the resolution study measured "
                f"({known[-1]:g} um already reads {VOXEL_BIAS[known[-1]][0]:+.1f} %): expect "
                "k_eff further below the converged value")
    lo, hi = VOXEL_BIAS[above]
    span = f"{lo:+.1f} %" if abs(hi - lo) < 0.05 else f"{lo:+.1f} to {hi:+.1f} %"
    if abs(above - voxel_um) < 1e-9:
        where = f"voxel {voxel_um:g} um: discretisation bias {span}"
    else:
        where = (f"voxel {voxel_um:g} um: discretisation bias at most that of {above:g} um, "
                 f"the next coarser voxel studied ({span})")
    return (f"{where} against the converged k_eff (validation/results/resolution.md, "
            "60 % Al2O3, gap model, paper resistance)")


def scatter_note(settings: "DemoSettings") -> str:
    """The RVE-to-RVE scatter measured at the default box and voxel (one line)."""
    default = DemoSettings()
    at = "" if (settings.box_um, settings.voxel_um) == (default.box_um, default.voxel_um) else (
        f" (measured at the default {default.box_um:g} um box and {default.voxel_um:g} um voxel;"
        " smaller boxes scatter more)")
    sc = DEMO_SCATTER
    return (f"RVE-to-RVE scatter over {sc['seeds']} seeds: k_iso {sc['std_percent']:.1f} % (std), "
            f"{sc['range_percent']:.1f} % (range); single diagonal components "
            f"{sc['component_std_percent']:.1f} % (std), {sc['component_range_percent']:.1f} % "
            f"(range){at}")


def _filler(settings: DemoSettings):
    from itr_fv.rve import FillerSpec
    return FillerSpec.of(settings.filler, settings.system.filler(settings.filler).psd,
                         settings.fraction)


def demo_workload(settings: DemoSettings):
    """The demo's work (:class:`itr_surrogate.workload.Workload`): one RVE, one solve that
    keeps its fields."""
    from itr_surrogate.workload import Grid, Workload, expected_particles

    rve = settings.rve
    return Workload((Grid("demo RVE", rve.box_um, rve.voxel_um, rves=1, solves=1,
                          particles=expected_particles(rve, [_filler(settings)]),
                          fields=True),), settings.solver)


def run_demo(settings: DemoSettings, out: Path, echo=print) -> list[Path]:
    """Generate, solve and write the demo; returns the files written (manifest last).

    ``out`` must exist and be writable; earlier demo files in it are replaced.
    """
    from itr_fv import Materials, homogenize
    from itr_fv.io import write_text
    from itr_fv.run_folder import begin_run, write_manifest
    from itr_fv.rve import build_rve

    begin_run(out, "demo")
    t0 = time.perf_counter()
    system, filler = settings.system, settings.filler
    matrix = system.matrix
    ms, _ = build_rve(settings.rve, [_filler(settings)], 0, matrix=matrix)
    echo(f"RVE: {settings.n}^3 voxels of {settings.voxel_um:g} um ({settings.box_um:g} um box), "
         f"{ms.n_particles} {filler} particles, {ms.volume_fractions()[filler]:.3f} by volume, "
         f"seed {settings.seed} ({time.perf_counter() - t0:.1f} s)")
    # the gap contact model: a contact is the two particle-matrix resistances and the
    # matrix film between the spheres, so only the particle-matrix value is needed
    r, r_source = settings.resistance()
    echo(f"system {system.name}: {system.describe()}; R_{filler}_{matrix} {r:g} m^2 K/W "
         f"({r_source})")
    mat = Materials(system.conductivities([filler]), {(filler, matrix): r}, matrix=matrix,
                    contact="gap")
    backend = settings.solver.backend(voxels=math.prod(ms.shape))
    res = homogenize(ms, mat, solver=backend, tol=settings.tol)
    echo(res.summary())
    k_iso = float(np.trace(res.k_eff) / 3.0)
    echo(f"k_iso = {k_iso:.4f} W/(m K), solver {res.solver}")
    measured_for = ("" if is_default_system(system) else
                    "measured for the paper's Al2O3 in silicone, not this system: ")
    echo(f"  {measured_for}{bias_note(settings.voxel_um)}")
    echo(f"  {measured_for}{scatter_note(settings)}")
    vti = res.to_vtk(out / "demo.vti", load_cases=[0], vectors=False)
    png = res.render_png(out / "demo.png")
    summary = {"k_eff_W_per_mK": res.k_eff.tolist(), "k_iso_W_per_mK": k_iso,
               "iterations": res.iterations, "volume_fractions": ms.volume_fractions(),
               "solver": res.solver, "contact_model": res.info.get("contact"),
               "settings": settings.to_dict(),
               "discretisation_note": bias_note(settings.voxel_um),
               "scatter_note": scatter_note(settings),
               "rve_scatter_percent": DEMO_SCATTER}
    js = write_text(out / "demo.json", json.dumps(summary, indent=2) + "\n")
    files = [vti, png, js]
    manifest = write_manifest(out, files, settings.to_dict(), job="demo")
    echo(f"wrote {vti}, {png}, {js}, {manifest}")
    return files + [manifest]
