"""The gap contact model against the multipole reference: arrays of nearly touching spheres.

SC, BCC and FCC arrays of spheres of radius a = 1.5 um whose nearest neighbours are
separated by a matrix film of 1.5, 10 or 20 nm, particle-matrix resistance R_b = 2e-8 or
5e-8 m^2 K/W, k_p = 30 or 200 W/(m K) in k_m = 0.18 W/(m K). Reference:
``itr_fv.analytic.sphere_array`` (the spheres with interface resistance R_b in the matrix:
the film is the matrix between them). Cells from ``itr_fv.gallery.touching_array``.
Solvers: itr_fft and the FV reference itr_fv at tol 1e-8, ``contact="gap"``, h = a/8,
a/12, a/16; the error is that of itr_fft, ``FV-FFT`` the largest relative difference of the
two solvers' diagonals. Writes ``validation/results/gap_model.md``.

Usage::

    python validation/gap_model_study.py [--per 8,12,16]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

A = 1.5e-6
K_M = 0.18
FINDINGS = """## Findings

- At h = a/16 every case is within 2 % of the reference (largest 1.63 %, SC), with both
  solvers (they agree to the solver tolerance). At a/12 the SC (up to 2.46 %) and FCC (up to
  2.98 %) arrays with 1.5 nm films are not; BCC is (0.97 %). At a/8 the CI-size bound of 4 %
  holds for SC and FCC, BCC reaches 4.16 % (1.5 nm, k_p 200, R_b 2e-8).
- The error converges at first order with a voxelization jitter (the refinement table): it is
  the first-order error of the staircase interface model (``convergence.md``: median order
  0.96 on the sphere arrays without contacts), not of the contact treatment. Measured on the
  a/12 cases (1.5 nm films): widening the segment zone from 3 to 6 voxels changes SC from
  -2.10 to -2.18 % and FCC from -2.98 to -2.65 %; averaging the film conductance over 4 x 4
  or 8 x 8 points of each contact face (the contact core is narrower than a voxel) changes
  SC by 0.05 % and FCC not at all. Meeting 2 % at a/12 needs a higher-order interface
  treatment of the whole sphere surface, not a change at the contacts."""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per", default="8,12,16", help="voxels per radius")
    ap.add_argument("--out", default=str(ROOT / "validation" / "results" / "gap_model.md"))
    args = ap.parse_args()
    import itr_fft
    import itr_fv
    from itr_fv import Materials, analytic
    from itr_fv.gallery import touching_array

    rows = []
    for per in [int(p) for p in args.per.split(",")]:
        for lat in ("sc", "bcc", "fcc"):
            for film in (1.5e-9, 10e-9, 20e-9):
                for kp in (30.0, 200.0):
                    for rb in (2e-8, 5e-8):
                        ms, f = touching_array(lat, A, film, per)
                        mat = Materials({"silicone": K_M, "Al2O3": kp},
                                        {("Al2O3", "silicone"): rb}, matrix="silicone",
                                        contact="gap")
                        ref = analytic.sphere_array(lat, f, kp / K_M, rb * K_M / A) * K_M
                        t = time.perf_counter()
                        res = itr_fft.homogenize(ms, mat, tol=1e-8, store_fields=False)
                        fv = itr_fv.homogenize(ms, mat, tol=1e-8, store_fields=False)
                        k = float(np.trace(res.k_eff) / 3)
                        diff = float(np.max(np.abs(np.diag(res.k_eff) - np.diag(fv.k_eff))
                                            / np.diag(fv.k_eff)))
                        rows.append((per, lat, film * 1e9, kp, rb, ms.shape[0], f, k, ref,
                                     100 * (k / ref - 1), diff, time.perf_counter() - t))
                        print(*rows[-1], flush=True)
    lines = ["# Gap contact model vs the multipole reference (issue 9, acceptance 1)", "",
             __doc__.split("\n\n")[1].replace("\n", " "), "",
             "| h | lattice | film (nm) | k_p | R_b | n | f | k_iso | reference | error (%) "
             "| FV-FFT |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for per, lat, film, kp, rb, n, f, k, ref, err, diff, _ in rows:
        lines.append(f"| a/{per} | {lat} | {film:g} | {kp:g} | {rb:.0e} | {n} | {f:.4f} | "
                     f"{k:.5f} | {ref:.5f} | {err:+.2f} | {diff:.1e} |")
    lines += ["", "Largest |error| per lattice and resolution:", ""]
    for per in sorted({r[0] for r in rows}):
        for lat in ("sc", "bcc", "fcc"):
            errs = [abs(r[9]) for r in rows if r[0] == per and r[1] == lat]
            lines.append(f"- a/{per}, {lat}: {max(errs):.2f} %")
    lines.append(f"\nLargest FV-FFT difference over all cases: {max(r[10] for r in rows):.1e}")
    lines += ["", "## Refinement of one case (SC, 1.5 nm film, k_p 30, R_b 2e-8, itr_fft)", "",
              "| h | n | error (%) |", "|---|---|---|"]
    for per in (8, 10, 12, 14, 16, 20, 24, 32):
        ms, f = touching_array("sc", A, 1.5e-9, per)
        mat = Materials({"silicone": K_M, "Al2O3": 30.0}, {("Al2O3", "silicone"): 2e-8},
                        matrix="silicone", contact="gap")
        ref = analytic.sphere_array("sc", f, 30.0 / K_M, 2e-8 * K_M / A) * K_M
        k = float(np.trace(itr_fft.homogenize(ms, mat, tol=1e-8, store_fields=False).k_eff) / 3)
        lines.append(f"| a/{per} | {ms.shape[0]} | {100 * (k / ref - 1):+.2f} |")
    lines += ["", FINDINGS]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
