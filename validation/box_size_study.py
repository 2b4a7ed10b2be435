"""RVE-size study under today's model (issue 24, part 1): the box each filler needs.

For AlN-60, Al2O3-60 and the hybrid Al2O3-30-AlN-30 (Table 1 size distributions, largest
diameter 0.45 x box, 0.16 um voxels, gap contact model, two packings per box) this solves
k_iso at the paper's particle-matrix resistances (Table 5) and at those the default
``itr reproduce`` identifies (gap parametrisation), for boxes of 12 ... 56 um. Every box is one
campaign run on the campaign engine (``itr_surrogate.runner``: Dask, one Parquet part per
task, resumable: a killed run started again redoes no finished task), in
``validation/results/box_size_runs/<group>-<box>um``; the report is made from whatever has
finished, so it can be written while the study runs. The box a filler needs is the smallest
whose two-packing mean k_iso lies within 0.5 % of the next larger box's (at both resistances),
with the packings' spread beside it. Writes ``validation/results/box_size.md``.

Usage::

    python validation/box_size_study.py [--groups AlN,Al2O3,hybrid] [--workers 2]
    python validation/box_size_study.py --report-only
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "validation" / "results" / "box_size_runs"
VOXEL_UM = 0.16
#: identified by the default ``itr reproduce`` (gap parametrisation, validation/results/
#: reproduce_engine.md's runs) and the paper's Table 5, m^2 K/W
R_VALUES = {"R_Al2O3_silicone": [1.67e-8, 2.2e-8], "R_AlN_silicone": [7.7e-9, 3.0e-8]}
GROUPS = {
    "Al2O3": {"formulation": "Al2O3-60", "boxes": [12, 16, 24, 32],
              "values": {"R_Al2O3_silicone": R_VALUES["R_Al2O3_silicone"]}},
    "AlN": {"formulation": "AlN-60", "boxes": [16, 24, 32, 40, 48, 56],
            "values": {"R_AlN_silicone": R_VALUES["R_AlN_silicone"]}},
    "hybrid": {"formulation": "Al2O3-30-AlN-30", "boxes": [16, 24, 40],
               "values": {"R_Al2O3_silicone": [2.2e-8], "R_AlN_silicone": [3.0e-8]}},
}
CRITERION = 0.005


def campaign_dict(group: str, box: float) -> dict:
    g = GROUPS[group]
    return {"name": f"box-{group}-{box:g}", "box_um": float(box), "voxel_um": VOXEL_UM,
            "replicas": 2, "seed": 1, "contact": "gap", "solver": "fft", "tol": 1e-7,
            "block_size": 4, "formulation": [{"name": g["formulation"]}],
            "design": {"kind": "grid", "values": g["values"]}}


def run(groups: list[str], workers: int) -> None:
    from itr_surrogate.campaign import Campaign
    from itr_surrogate.runner import run_campaign

    # smallest boxes first, so that results land early
    order = sorted(((box, g) for g in groups for box in GROUPS[g]["boxes"]))
    for box, g in order:
        camp = Campaign.from_dict(campaign_dict(g, box))
        print(f"== {g} {box} um ({camp.shape[0]}^3)", flush=True)
        run_campaign(camp, RUNS / f"{g}-{box:g}um", workers=workers, progress=False)
        report()


def _rows(group: str) -> list[dict]:
    from itr_surrogate.store import CampaignStore

    rows = []
    for box in GROUPS[group]["boxes"]:
        folder = RUNS / f"{group}-{box:g}um"
        store = CampaignStore(folder)
        if not folder.is_dir() or not store.done_tasks():
            continue
        for r in store.results().to_pylist():
            rows.append({**r, "box": box})
    return rows


def report(out: Path = ROOT / "validation" / "results" / "box_size.md") -> None:
    lines = ["# RVE size under today's model: the box each filler needs", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "Wall per solve: as the campaign rows recorded it, on 2 cores that the first run "
             "(2026-11-25) shared with a second study and the tests: not a benchmark.", ""]
    for group, g in GROUPS.items():
        rows = _rows(group)
        lines += [f"## {g['formulation']}", ""]
        if not rows:
            lines += ["(not run yet)", ""]
            continue
        rnames = list(g["values"])
        lines += ["| box (um) | n | " + " | ".join(rnames) + " | k_iso seed 1 | k_iso seed 2 | "
                  "mean (W/mK) | seed spread | to next box | wall per solve (s) |",
                  "|" + "---|" * (9 + len(rnames) - 1)]
        sets = sorted({tuple(r[n] for n in rnames) for r in rows})
        means: dict[tuple, dict[float, float]] = {s: {} for s in sets}
        for s in sets:
            for box in g["boxes"]:
                ks = {r["replica"]: r["k_iso"] for r in rows
                      if r["box"] == box and tuple(r[n] for n in rnames) == s}
                if len(ks) == 2:
                    means[s][box] = float(np.mean(list(ks.values())))
        needed = {}
        for s in sets:
            for box in g["boxes"]:
                sel = [r for r in rows if r["box"] == box and tuple(r[n] for n in rnames) == s]
                if not sel:
                    continue
                ks = {r["replica"]: r["k_iso"] for r in sel}
                mean = float(np.mean(list(ks.values())))
                larger = [b for b in g["boxes"] if b > box and b in means[s]]
                step = (f"{100 * (mean / means[s][larger[0]] - 1):+.2f} %"
                        if larger and len(ks) == 2 else "")
                spread = (f"{100 * abs(ks[0] - ks[1]) / mean:.2f} %" if len(ks) == 2 else "")
                lines.append(f"| {box} | {sel[0]['n']} | " + " | ".join(f"{v:g}" for v in s)
                             + f" | {ks.get(0, float('nan')):.4f} | {ks.get(1, float('nan')):.4f}"
                             f" | {mean:.4f} | {spread} | {step} | "
                             f"{np.mean([r['wall_s'] for r in sel]):.0f} |")
            done = sorted(means[s])
            ok = [b for i, b in enumerate(done[:-1])
                  if all(abs(means[s][c] / means[s][done[j + 1]] - 1) <= CRITERION
                         for j, c in enumerate(done[:-1]) if j >= i)]
            needed[s] = ok[0] if ok else None
        lines.append("")
        for s, box in needed.items():
            at = ", ".join(f"{n} = {v:g}" for n, v in zip(rnames, s))
            lines.append(f"- at {at}: " + (
                f"box {box} um is within {100 * CRITERION:.1f} % of every larger box solved"
                if box is not None else
                "no solved box is yet within 0.5 % of the next larger one (or only one box "
                "has both packings)"))
        lines.append("")
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}", flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--groups", default="Al2O3,AlN,hybrid")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--report-only", action="store_true")
    args = ap.parse_args()
    groups = args.groups.split(",")
    unknown = [g for g in groups if g not in GROUPS]
    if unknown:
        ap.error(f"--groups: unknown group {unknown[0]!r} (known: {sorted(GROUPS)})")
    if args.report_only:
        report()
    else:
        run(groups, args.workers)
    return 0


if __name__ == "__main__":
    sys.exit(main())
