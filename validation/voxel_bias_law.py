"""The voxel-bias law of the gap model, fitted (issue 24, part 1).

``validation/results/resolution.csv`` holds k_iso of two dense 60 % Al2O3 packings (16 um
box) re-voxelized from 0.25 to 0.0625 um under the gap model. This script first checks that
today's code still gives those numbers (the two coarsest voxels of both packings are solved
again), then fits ``k(h) = k_0 (1 - c h^p)`` (h in um) with one order ``p`` shared by the
packings and their own ``k_0`` and ``c`` (least squares in k, every voxel), and gives ``p`` with its
standard error and the relative bias ``-c h^p`` at the voxels the package uses, with the
spread of that bias over the two packings. Writes ``validation/results/voxel_bias_law.md``
and ``voxel_bias_law.json`` (the law a faithful forward model can correct with).

Usage::

    python validation/voxel_bias_law.py [--no-check]
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "validation" / "results"
VOXELS = (0.25, 0.2, 0.16, 0.125, 0.1)


def read_rows() -> dict[int, list[tuple[float, float]]]:
    rows: dict[int, list[tuple[float, float]]] = {}
    with open(RESULTS / "resolution.csv", newline="") as fh:
        for r in csv.DictReader(fh):
            if r["model"] == "gap":
                rows.setdefault(int(r["seed"]), []).append((float(r["voxel_um"]),
                                                            float(r["k_iso"])))
    return {s: sorted(v) for s, v in rows.items()}


def check(rows: dict[int, list[tuple[float, float]]]) -> list[tuple[int, float, float, float]]:
    """Re-solve the two coarsest voxels of every packing with today's code."""
    sys.path.insert(0, str(ROOT / "validation"))
    from resolution_study import solve

    out = []
    for seed, pts in rows.items():
        for h, k in sorted(pts, reverse=True)[:2]:
            now = float(solve("gap", seed, h)["k_iso"])
            out.append((seed, h, k, now))
            print(f"seed {seed}, {h:g} um: csv {k:.6f}, today {now:.6f}", flush=True)
    return out


def fit(rows: dict[int, list[tuple[float, float]]]) -> dict:
    seeds = sorted(rows)

    def residuals(x: np.ndarray) -> np.ndarray:
        p = x[0]
        res = []
        for i, s in enumerate(seeds):
            k0, c = x[1 + 2 * i], x[2 + 2 * i]
            h, k = np.array(rows[s]).T
            res.append(k - k0 * (1 - c * h ** p))
        return np.concatenate(res)

    x0 = [1.0] + [v for s in seeds for v in (max(k for _, k in rows[s]), 0.1)]
    sol = least_squares(residuals, x0)
    dof = sol.fun.size - sol.x.size
    s2 = float(sol.fun @ sol.fun) / dof
    cov = np.linalg.inv(sol.jac.T @ sol.jac) * s2
    p, p_se = float(sol.x[0]), float(np.sqrt(cov[0, 0]))
    per_seed = {s: {"k0": float(sol.x[1 + 2 * i]), "c": float(sol.x[2 + 2 * i])}
                for i, s in enumerate(seeds)}
    bias = {h: [-v["c"] * h ** p for v in per_seed.values()] for h in VOXELS}
    return {"p": p, "p_standard_error": p_se, "rms_residual_W_per_mK": float(np.sqrt(s2)),
            "per_seed": per_seed,
            "relative_bias": {f"{h:g}": {"mean": float(np.mean(b)),
                                         "spread": float(np.ptp(b))} for h, b in bias.items()}}


def write(law: dict, checked: list) -> None:
    lines = ["# Voxel-bias law of the gap model", "",
             " ".join(__doc__.split("\n\n")[1].split()), ""]
    if checked:
        lines += ["## Today's code against resolution.csv", "",
                  "| packing | voxel (um) | k_iso csv | k_iso today | difference |",
                  "|---|---|---|---|---|"]
        lines += [f"| seed {s} | {h:g} | {k:.6f} | {now:.6f} | {100 * (now / k - 1):+.3f} % |"
                  for s, h, k, now in checked]
        lines.append("")
    lines += ["## Fit", "",
              f"- order p = {law['p']:.3f} +- {law['p_standard_error']:.3f} (standard error; "
              f"rms residual {1000 * law['rms_residual_W_per_mK']:.2f} mW/(m K))"]
    lines += [f"- packing seed {s}: k_0 = {v['k0']:.4f} W/(m K), c = {v['c']:.4f}"
              for s, v in law["per_seed"].items()]
    lines += ["", "| voxel (um) | relative bias -c h^p (mean of the packings) | spread over "
              "the packings |", "|---|---|---|"]
    lines += [f"| {h} | {100 * b['mean']:+.2f} % | {100 * b['spread']:.2f} % |"
              for h, b in law["relative_bias"].items()]
    (RESULTS / "voxel_bias_law.md").write_text("\n".join(lines) + "\n")
    (RESULTS / "voxel_bias_law.json").write_text(json.dumps(law, indent=2) + "\n")
    print(f"wrote {RESULTS / 'voxel_bias_law.md'}", flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-check", action="store_true")
    args = ap.parse_args()
    rows = read_rows()
    checked = [] if args.no_check else check(rows)
    write(fit(rows), checked)
    return 0


if __name__ == "__main__":
    sys.exit(main())
