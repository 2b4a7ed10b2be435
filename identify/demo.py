"""The ``itr demo`` job: one random Al2O3/silicone RVE, its k_eff, a .vti file and a figure.

Defaults come from the package's own studies, not from convenience:

- voxel 0.16 um: the largest voxel within 2 % of the converged k_eff on dense 60 % Al2O3
  RVEs at the paper's resistances (``validation/results/resolution.md``: +1.45 % and
  +1.75 % on two packings; 0.4 um reads +16 %, 0.32 um +12 %);
- the FFT solver: the same discrete system as the FV reference to solver tolerance
  (``validation/results/crossval.md``) and 4-7x faster on these grids
  (``validation/results/bench_solvers.md``);
- a 16 um box (100^3 voxels), largest diameter 0.45 box (the packer's pair search needs
  below 0.5; the default box/3 would cut 21 % of the Al2O3 volume, this cuts 4.7 %): the
  scatter between packings of this size is printed with the result (``DEMO_SCATTER``).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

__all__ = ["DemoSettings", "run_demo", "PAPER_K", "PAPER_R", "VOXEL_BIAS", "DEMO_SCATTER"]

# The paper's identified resistances (Table 5), m^2 K/W, and its conductivities, W/(m K).
PAPER_K = {"silicone": 0.18, "Al2O3": 30.0, "AlN": 200.0}
PAPER_R = {("Al2O3", "silicone"): 2.2e-8, ("AlN", "silicone"): 3.0e-8,
           ("Al2O3", "Al2O3"): 2.0e-7, ("AlN", "AlN"): 1.0e-7, ("Al2O3", "AlN"): 3.0e-7}

#: Measured discretisation bias of k_iso against the extrapolated value, per voxel (um):
#: (smallest, largest) over two packings, %, dense 60 % Al2O3 at the paper's resistances
#: (validation/results/resolution.md).
VOXEL_BIAS = {0.4: (15.62, 16.62), 0.32: (10.87, 12.14), 0.25: (6.87, 6.89),
              0.2: (3.37, 3.76), 0.16: (1.45, 1.75), 0.125: (0.38, 0.57),
              0.1: (-0.13, 0.07), 0.08: (-0.14, 0.06)}

#: RVE-to-RVE scatter of k_iso at the demo's default settings (16 um box, 0.16 um voxel,
#: 55 % Al2O3): relative standard deviation and full range over seeds 1-4, %, of k_iso
#: and of the single diagonal components. Measured with ``itr demo --seed N``: k_iso =
#: 1.3127, 1.3099, 1.3213, 1.3174 W/(m K); k_xx, k_yy, k_zz from 1.275 to 1.346.
DEMO_SCATTER = {"seeds": 4, "std_percent": 0.4, "range_percent": 0.9,
                "component_std_percent": 1.6, "component_range_percent": 5.4}


@dataclass(frozen=True)
class DemoSettings:
    """Settings of one demo run (lengths in micrometres)."""

    box_um: float = 16.0
    voxel_um: float = 0.16
    fraction: float = 0.55
    seed: int = 1
    solver: str = "fft"
    tol: float = 1e-8

    @property
    def n(self) -> int:
        return int(round(self.box_um / self.voxel_um))


def bias_note(voxel_um: float) -> str:
    """What the resolution study says of this voxel size (one line)."""
    known = sorted(VOXEL_BIAS)
    if voxel_um < known[0]:
        return (f"voxel {voxel_um:g} um is finer than the resolution study's finest "
                f"({known[0]:g} um, bias within 0.2 %)")
    # nearest studied voxel at or above this one bounds the bias from above
    above = min((v for v in known if v >= voxel_um - 1e-12), default=None)
    if above is None:
        return (f"voxel {voxel_um:g} um is coarser than anything the resolution study measured "
                f"(0.4 um already reads +16 %): expect k_eff well above the converged value")
    lo, hi = VOXEL_BIAS[above]
    span = f"{lo:+.1f} %" if abs(hi - lo) < 0.05 else f"{lo:+.1f} to {hi:+.1f} %"
    if abs(above - voxel_um) < 1e-9:
        where = f"voxel {voxel_um:g} um: discretisation bias {span}"
    else:
        where = (f"voxel {voxel_um:g} um: discretisation bias at most that of {above:g} um, "
                 f"the next coarser voxel studied ({span})")
    return (f"{where} against the converged k_eff (validation/results/resolution.md, "
            "60 % Al2O3, paper resistances)")


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


def run_demo(settings: DemoSettings, out: Path, echo=print) -> list[Path]:
    """Generate, solve and write the demo; returns the files written (manifest last).

    ``out`` must exist and be writable; earlier demo files in it are replaced.
    """
    from itr_fv import Materials, homogenize
    from itr_fv.io import begin_run, write_manifest, write_text
    from itr_fv.rve import FillerSpec, generate_rve

    begin_run(out)
    t0 = time.perf_counter()
    ms = generate_rve([FillerSpec("Al2O3", mu=1.02, sigma=0.35,
                                  volume_fraction=settings.fraction)],
                      box_um=settings.box_um, voxel_um=settings.voxel_um, seed=settings.seed,
                      matrix="silicone", max_diameter_box_ratio=0.45)
    echo(f"RVE: {settings.n}^3 voxels of {settings.voxel_um:g} um ({settings.box_um:g} um box), "
         f"{ms.n_particles} Al2O3 particles, {ms.volume_fractions()['Al2O3']:.3f} by volume, "
         f"seed {settings.seed} ({time.perf_counter() - t0:.1f} s)")
    # the gap contact model: a contact is the two particle-matrix resistances and the
    # silicone film between the spheres, so only the particle-matrix value is needed
    mat = Materials(PAPER_K, {("Al2O3", "silicone"): PAPER_R[("Al2O3", "silicone")]},
                    matrix="silicone", contact="gap")
    if settings.solver == "fft":
        import itr_fft
        solve = itr_fft.homogenize
    else:
        solve = homogenize
    res = solve(ms, mat, tol=settings.tol)
    echo(res.summary())
    k_iso = float(np.trace(res.k_eff) / 3.0)
    echo(f"k_iso = {k_iso:.4f} W/(m K), solver {res.solver}")
    echo(f"  {bias_note(settings.voxel_um)}")
    echo(f"  {scatter_note(settings)}")
    vti = res.to_vtk(out / "demo.vti", load_cases=[0], vectors=False)
    png = res.render_png(out / "demo.png")
    summary = {"k_eff_W_per_mK": res.k_eff.tolist(), "k_iso_W_per_mK": k_iso,
               "iterations": res.iterations, "volume_fractions": ms.volume_fractions(),
               "solver": res.solver, "contact_model": res.info.get("contact"),
               "settings": asdict(settings),
               "discretisation_note": bias_note(settings.voxel_um),
               "scatter_note": scatter_note(settings),
               "rve_scatter_percent": DEMO_SCATTER}
    js = write_text(out / "demo.json", json.dumps(summary, indent=2) + "\n")
    files = [vti, png, js]
    manifest = write_manifest(out, files, {"job": "demo", **asdict(settings)})
    echo(f"wrote {vti}, {png}, {js}, {manifest}")
    return files + [manifest]
