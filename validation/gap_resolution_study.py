"""Voxel-size study of the gap contact model on a dense random packing (issue 9, acceptance 2
and 3).

One packing of 60 vol% Al2O3 (lognormal mu = 1.02, sigma = 0.35, 16 um box, seed 1,
diameters cut at 0.45 box) is re-voxelized at 0.25 ... 0.08 um and solved with itr_fft
(tol 1e-8) under the gap model (R_b = 2.2e-8 m^2 K/W, the paper's Al2O3-silicone value, no
contact parameter), the gap model with a contact spot of G_c = 2e-6 W/K per touching pair
(closest gap <= 5 nm), and, beside them, the per-area model with the paper's R_ff = 2e-7.
For the spots the total spot conductance the grid carries is reported per voxel size.
Writes ``validation/results/gap_resolution.md``.

Usage::

    python validation/gap_resolution_study.py [--voxels 0.25,0.2,0.16,0.125,0.1,0.08]
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BOX_UM = 16.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voxels", default="0.25,0.2,0.16,0.125,0.1,0.08")
    ap.add_argument("--out", default=str(ROOT / "validation" / "results" / "gap_resolution.md"))
    args = ap.parse_args()
    import itr_fft
    from itr_fv import Materials, Microstructure
    from itr_fv.checks import VoxelContactWarning
    from itr_fv.problem import DiscreteProblem
    from itr_fv.rve import FillerSpec, generate_rve

    warnings.simplefilter("ignore", VoxelContactWarning)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        ms0 = generate_rve([FillerSpec("Al2O3", mu=1.02, sigma=0.35, volume_fraction=0.60)],
                           box_um=BOX_UM, voxel_um=0.4, seed=1, matrix="silicone",
                           max_diameter_box_ratio=0.45)
    t = ms0.particles
    models = {
        "gap": Materials({"silicone": 0.18, "Al2O3": 30.0}, {("Al2O3", "silicone"): 2.2e-8},
                         "silicone", contact="gap"),
        "gap+spots": Materials({"silicone": 0.18, "Al2O3": 30.0},
                               {("Al2O3", "silicone"): 2.2e-8}, "silicone", contact="gap",
                               contact_conductance={("Al2O3", "Al2O3"): 2e-6}),
        "area": Materials({"silicone": 0.18, "Al2O3": 30.0},
                          {("Al2O3", "silicone"): 2.2e-8, ("Al2O3", "Al2O3"): 2e-7},
                          "silicone", contact="area"),
    }
    rows = []
    for name, mat in models.items():
        for h in [float(v) for v in args.voxels.split(",")]:
            n = int(round(BOX_UM / h))
            ms = Microstructure.from_spheres(t.centers_m, t.radii_m, t.material,
                                             box_m=BOX_UM * 1e-6, shape=n, matrix="silicone")
            problem = DiscreteProblem(ms, contact=mat.contact)
            res = itr_fft.homogenize(problem, mat, tol=1e-8, store_fields=False)
            k = float(np.trace(res.k_eff) / 3)
            spots = problem.geometry.total_spot_conductance(mat)
            rows.append((name, h, n, k, problem.geometry.filled_voxels,
                         problem.geometry.n_contact_faces, res.iterations, res.wall_time, spots))
            print(*rows[-1], flush=True)
    lines = ["# Gap contact model: voxel-size study on a dense random packing", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "| model | voxel (um) | n | k_iso (W/mK) | change vs previous (%) | filled voxels "
             "| contact faces | total spot conductance (W/K) | iterations | wall (s) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for i, (name, h, n, k, filled, faces, its, wall, spots) in enumerate(rows):
        prev = rows[i - 1] if i and rows[i - 1][0] == name else None
        change = f"{100 * (k / prev[3] - 1):+.2f}" if prev else ""
        lines.append(f"| {name} | {h:g} | {n} | {k:.4f} | {change} | {filled} | {faces} | "
                     f"{spots:.4g} | {'/'.join(map(str, its))} | {wall:.1f} |")
    for name in models:
        ks = [r[3] for r in rows if r[0] == name]
        lines.append("")
        lines.append(f"- {name}: k_iso from {ks[0]:.4f} to {ks[-1]:.4f} "
                     f"({100 * (ks[-1] / ks[0] - 1):+.2f} % over the range), last step "
                     f"{100 * (ks[-1] / ks[-2] - 1):+.2f} %.")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    sys.exit(main())
