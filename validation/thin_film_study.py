"""How the voxel grid represents a thin matrix film: periodic laminates whose film normal
is along (1,0,0), (1,1,0) or (1,1,1) (diagnostic behind the gap model's BCC/FCC error).

A matrix slab of true thickness t (in voxels h) between particle-phase slabs (k_p/k_m = 1e4,
no interface resistance), voxelized by centres, 64^3. The normal conductivity n.K.n is
compared with the exact laminate value for the true thickness and for the voxelized one.
Writes ``validation/results/thin_film.md``.

Usage::

    python validation/thin_film_study.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
N = 64
K_M, K_P = 1.0, 1e4
NORMALS = {"(1,0,0)": np.array([1.0, 0, 0]), "(1,1,0)": np.array([1.0, 1, 0]) / np.sqrt(2),
           "(1,1,1)": np.ones(3) / np.sqrt(3)}


def laminate_normal(f: float) -> float:
    return 1.0 / (f / K_M + (1.0 - f) / K_P)


def main() -> None:
    from itr_fv import Materials, Microstructure, homogenize

    h = 1e-6 / N
    x = (np.arange(N) + 0.5) * h
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    mat = Materials({"m": K_M, "P": K_P}, {("P", "m"): 0.0}, "m")
    lines = ["# Thin matrix films on the voxel grid", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "| film normal | t / h | layers spacing / h | voxel film / true film | n.K.n / exact "
             "(true t) | n.K.n / exact (voxel t) |", "|---|---|---|---|---|---|"]
    for label, n in NORMALS.items():
        u = X * n[0] + Y * n[1] + Z * n[2]
        period = 1e-6 * float(np.max(np.abs(n)))  # the slabs repeat along n every L max|n_i|
        for tr in (1.0, 1.25, 1.5, 2.0, 3.0):
            slab = np.abs(np.mod(u, period) - period / 2) < tr * h / 2
            mid = np.where(slab, 0, 1).astype(np.int32)
            ms = Microstructure.from_labels(mid, mid.copy(), voxel_m=h, names=("m", "P"))
            res = homogenize(ms, mat, solver="fft", tol=1e-10, store_fields=False,
                             check_memory=False)
            kn = float(n @ res.k_eff @ n)
            f_true = tr * h / period
            f_vox = float(slab.mean())
            lines.append(f"| {label} | {tr:g} | {float(np.max(np.abs(n))):.3f} | "
                         f"{f_vox / f_true:.3f} | {kn / laminate_normal(f_true):.3f} | "
                         f"{kn / laminate_normal(f_vox):.3f} |")
            print(lines[-1], flush=True)
    lines += ["", "A resolved film conducts exactly as a film of its voxelized thickness (last "
              "column 1.000): the error is in the thickness. Voxel layers along a diagonal "
              "normal are spaced h max|n_i| (0.707 h for (1,1,0), 0.577 h for (1,1,1)) and a "
              "film is represented by a whole number of them: its conductance is off by up to "
              "1.8x (too thin) or 0.5x (too thick). Over a wedge whose thickness varies, 1/t is "
              "convex, so on average the films of 1-3 voxels just outside the gap model's neck "
              "conduct too much (Jensen), most where the layers are thinnest: BCC and FCC "
              "contacts."]
    out = ROOT / "validation" / "results" / "thin_film.md"
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    sys.exit(main())
