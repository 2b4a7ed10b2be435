"""Converged boxes for AlN and the hybrid (issue 39, item 1): boxes of 56, 64 and 80 um at two
voxels, the voxel bias extrapolated away.

For AlN-60 and the hybrid Al2O3-30-AlN-30 (Table 1 size distributions, largest diameter
0.45 x box, gap contact model, two packings per box, the same packings at both voxels) this
solves k_iso at R = 3e-8 m^2 K/W for every filler (the order of the values a faithful
identification finds) with the particle-deflated multigrid (``solver = "mg"``). Every
(box, voxel) is one campaign run on the campaign engine (``itr_surrogate.runner``: resumable,
one Parquet part per task) in ``validation/results/box_convergence_runs/<group>-<box>um-<voxel>um``;
the report is made from whatever has finished. Per packing the voxel bias is extrapolated
away with the law ``k(h) = k_0 (1 - c h^p)`` through the two voxels, with the order p of
``validation/results/voxel_bias_law.md`` (1.29, fitted on Al2O3-60: still to be checked for
AlN with a third voxel). The box a system needs is the smallest whose two-packing mean k_0
lies within 0.5 % of the next larger box's. Writes ``validation/results/box_convergence.md``.

Usage::

    python validation/box_convergence_study.py [--groups AlN,hybrid] [--threads 2]
    python validation/box_convergence_study.py --report-only
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RUNS = ROOT / "validation" / "results" / "box_convergence_runs"
OUT = ROOT / "validation" / "results" / "box_convergence.md"
BOXES_UM = (56, 64, 80)
VOXELS_UM = (0.25, 0.2)
#: Order of the voxel bias law (validation/results/voxel_bias_law.md, Al2O3-60).
BIAS_ORDER = 1.29
CRITERION = 0.005
R_M2K_PER_W = 3e-8
GROUPS = {
    "AlN": {"formulation": "AlN-60", "values": {"R_AlN_silicone": [R_M2K_PER_W]}},
    "hybrid": {"formulation": "Al2O3-30-AlN-30",
               "values": {"R_Al2O3_silicone": [R_M2K_PER_W], "R_AlN_silicone": [R_M2K_PER_W]}},
}


def folder(group: str, box: float, voxel: float) -> Path:
    return RUNS / f"{group}-{box:g}um-{voxel:g}um"


def campaign_dict(group: str, box: float, voxel: float, threads: int) -> dict:
    g = GROUPS[group]
    return {"name": f"boxconv-{group}-{box:g}-{voxel:g}", "box_um": float(box),
            "voxel_um": float(voxel), "replicas": 2, "seed": 1, "contact": "gap",
            "solver": "mg", "tol": 1e-7, "block_size": 1, "threads_per_worker": threads,
            "formulation": [{"name": g["formulation"]}],
            "design": {"kind": "grid", "values": g["values"]}}


def run(groups: list[str], threads: int) -> None:
    from itr_surrogate.campaign import Campaign
    from itr_surrogate.runner import run_campaign

    # the coarse voxel first, smallest boxes first: results land early
    for voxel in VOXELS_UM:
        for box in BOXES_UM:
            for g in groups:
                camp = Campaign.from_dict(campaign_dict(g, box, voxel, threads))
                print(f"== {g} {box} um at {voxel} um ({camp.shape[0]}^3)", flush=True)
                run_campaign(camp, folder(g, box, voxel), workers=1, progress=False)
                report()


def _k(group: str, box: float, voxel: float) -> dict[int, tuple[float, float, int]]:
    """replica -> (k_iso, wall s, voxels per edge) of a finished run."""
    from itr_surrogate.store import CampaignStore

    path = folder(group, box, voxel)
    if not path.is_dir():
        return {}
    store = CampaignStore(path)
    if not store.done_tasks():
        return {}
    return {int(r["replica"]): (float(r["k_iso"]), float(r["wall_s"]), int(r["n"]))
            for r in store.results().to_pylist()}


def extrapolate(k1: float, h1: float, k2: float, h2: float, p: float = BIAS_ORDER) -> float:
    """k_0 of ``k(h) = k_0 (1 - c h^p)`` through (h1, k1) and (h2, k2)."""
    a, b = h1**p, h2**p
    return (k2 * a - k1 * b) / (a - b)


def report() -> None:
    lines = ["# Converged boxes for AlN and the hybrid (issue 39)", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "Wall per solve as the campaign rows recorded it (2 cores; three load cases).", ""]
    for group, g in GROUPS.items():
        lines += [f"## {g['formulation']}", "",
                  "| box (um) | voxel (um) | n | k_iso seed 1 | k_iso seed 2 | mean | seed "
                  "spread | wall per solve (s) |", "|---|---|---|---|---|---|---|---|"]
        k0: dict[float, float] = {}
        for box in BOXES_UM:
            per_voxel = {}
            for voxel in VOXELS_UM:
                ks = _k(group, box, voxel)
                if not ks:
                    continue
                per_voxel[voxel] = ks
                vals = [ks[r][0] for r in sorted(ks)]
                mean = float(np.mean(vals))
                spread = f"{100 * abs(vals[0] - vals[1]) / mean:.2f} %" if len(vals) == 2 else ""
                lines.append(f"| {box} | {voxel:g} | {next(iter(ks.values()))[2]} | "
                             f"{ks.get(0, (float('nan'),))[0]:.4f} | "
                             f"{ks.get(1, (float('nan'),))[0]:.4f} | {mean:.4f} | {spread} | "
                             f"{np.mean([v[1] for v in ks.values()]):.0f} |")
            if len(per_voxel) == 2 and all(len(v) == 2 for v in per_voxel.values()):
                (h1, a), (h2, b) = sorted(per_voxel.items(), reverse=True)
                k0[box] = float(np.mean([extrapolate(a[r][0], h1, b[r][0], h2) for r in (0, 1)]))
        lines.append("")
        if k0:
            lines += ["| box (um) | k_0, voxel bias extrapolated (W/mK, mean of 2 packings) | "
                      "to the next box |", "|---|---|---|"]
            boxes = sorted(k0)
            for i, box in enumerate(boxes):
                step = (f"{100 * (k0[box] / k0[boxes[i + 1]] - 1):+.2f} %"
                        if i + 1 < len(boxes) else "")
                lines.append(f"| {box} | {k0[box]:.4f} | {step} |")
            ok = [b for i, b in enumerate(boxes[:-1])
                  if all(abs(k0[c] / k0[boxes[j + 1]] - 1) <= CRITERION
                         for j, c in enumerate(boxes[:-1]) if j >= i)]
            lines += ["", f"- box needed: {ok[0]} um" if ok else
                      "- no extrapolated box is yet within 0.5 % of the next larger one", ""]
        else:
            lines += ["(no box has both voxels and both packings yet)", ""]
    OUT.write_text("\n".join(lines) + "\n")
    print(f"wrote {OUT}", flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--groups", default="AlN,hybrid")
    ap.add_argument("--threads", type=int, default=2, help="solver threads of the one worker")
    ap.add_argument("--report-only", action="store_true")
    args = ap.parse_args()
    groups = args.groups.split(",")
    unknown = [g for g in groups if g not in GROUPS]
    if unknown:
        ap.error(f"--groups: unknown group {unknown[0]!r} (known: {sorted(GROUPS)})")
    if args.report_only:
        report()
    else:
        run(groups, args.threads)
    return 0


if __name__ == "__main__":
    sys.exit(main())
