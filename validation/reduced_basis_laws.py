"""The certified reduced basis under both interface laws (issue 28, acceptance 4).

One dense RVE (60 vol% Al2O3, Table 1's size distribution, 12 um box at 0.25 um = 48^3,
seed 5, gap contacts) and the parameter box k_Al2O3 in [20, 40] W/(m K), R_Al2O3_silicone in
[1e-8, 5e-5] m^2 K/W. For each law (``itr_fv.discrete.interface_law``: staircase, segment) the
reduced basis is fitted (tol 1e-4, at most 30 full solves, itr_fft at tol 1e-10) and
compared with 30 held-out full solves (a Latin hypercube, log-uniform in R, seed 11; itr_fft,
tol 1e-11, energy estimate): its error estimate must bound the true error of every diagonal
entry. Writes ``validation/results/reduced_basis_laws.md``.

Usage::

    python validation/reduced_basis_laws.py
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from itr_fv import Materials, homogenize  # noqa: E402
from itr_fv.discrete.problem import DiscreteProblem  # noqa: E402
from itr_fv.rve import FillerSpec, RVESpec, generate_rve  # noqa: E402
from itr_surrogate.face_decomposition import ParameterBox  # noqa: E402
from itr_surrogate.reduced_basis import ReducedBasis  # noqa: E402

OUT = ROOT / "validation" / "results" / "reduced_basis_laws.md"
BOUNDS = {"k_Al2O3": (20.0, 40.0), "R_Al2O3_silicone": (1e-8, 5e-5)}
HELD_OUT = 30


def main() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        ms = generate_rve(RVESpec(12.0, 0.25, max_diameter_box_ratio=1 / 3),
                          FillerSpec("Al2O3", mu=1.02, sigma=0.35, volume_fraction=0.60), 5,
                          matrix="silicone")
    mat = Materials({"silicone": 0.18, "Al2O3": 30.0}, {("Al2O3", "silicone"): 1e-7},
                    "silicone", contact="gap")
    box = ParameterBox(BOUNDS, mat)
    held = box.sample(HELD_OUT, seed=11)[2 ** box.size:]  # the Latin hypercube, no corners
    lines = ["# The reduced basis under both interface laws (issue 28)", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "| law | RVE | full solves (fit) | fit (s) | max rel. error held out | "
             "entries bounded by the estimate | median estimate / error | "
             "interpolation error |",
             "|---|---|---|---|---|---|---|---|"]
    for law in ("staircase", "segment"):
        problem = DiscreteProblem(ms, contact="gap", interface=law)
        t0 = time.perf_counter()
        rb = ReducedBasis(problem, mat, BOUNDS, tol=1e-4, max_solves=30, solver="fft",
                          solver_tol=1e-10).fit()
        fit_s = time.perf_counter() - t0
        sets = {n: held[:, i] for i, n in enumerate(box.names)}
        pred = np.diagonal(rb.predict(sets), axis1=1, axis2=2)
        est = rb.error_estimate(sets)
        truth = np.array([np.diag(homogenize(
            problem, box.materials(mat, x), solver="fft", tol=1e-11,
            store_fields=False).k_eff_energy)
            for x in held])
        err = np.abs(pred - truth)
        bounded = err <= est
        lines.append(f"| {law} | {ms.shape[0]}^3, {ms.n_particles} particles | {rb.n_solves_} | "
                     f"{fit_s:.0f} | {float((err / truth).max()):.1e} | "
                     f"{int(bounded.sum())} of {bounded.size} ({100 * bounded.mean():.0f} %) | "
                     f"{float(np.median(est / np.maximum(err, 1e-300))):.3g} | "
                     f"{rb.interpolation_error_:.1e} |")
        print(lines[-1], flush=True)
    OUT.write_text("\n".join(lines) + "\n")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
