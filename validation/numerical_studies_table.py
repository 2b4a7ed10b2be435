"""Collect the numerical studies' figures into the package's one table of them
(``identify/data/numerical_studies.csv``), which every identification report's error budget
reads (:mod:`itr_identify.reporting.error_budget`).

Reads whatever has finished of ``validation/results/box_size_runs`` (mean k_iso of the two
packings per box, at the paper's resistances), ``validation/results/box_convergence_runs``
(56-80 um boxes at 0.25 um for AlN-60 and the hybrid),
``validation/results/inputs_sensitivity_runs``
(relative change of k_iso for a 2 and 5 nm film and a volume-weighted Table 1) and
``validation/results/voxel_bias_law.json`` (relative bias of the gap model per voxel edge).
Run it again as the studies land.

Usage::

    python validation/numerical_studies_table.py
"""

from __future__ import annotations

import csv
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "validation" / "results"
OUT = ROOT / "identify" / "data" / "numerical_studies.csv"
#: the paper's Table 5 particle-matrix resistances, at which the studies report, m^2 K/W
PAPER_R = {"Al2O3": 2.2e-8, "AlN": 3.0e-8}
BOX_GROUPS = {"Al2O3": ("Al2O3",), "AlN": ("AlN",), "hybrid": ("Al2O3", "AlN")}


def _results(folder: Path) -> list[dict]:
    from itr_surrogate.store import CampaignStore

    if not folder.is_dir():
        return []
    store = CampaignStore(folder)
    return store.results().to_pylist() if store.done_tasks() else []


def _at_paper_r(row: dict, fillers: tuple[str, ...]) -> bool:
    return all(math.isclose(row.get(f"R_{f}_silicone", -1.0), PAPER_R[f], rel_tol=1e-9)
               for f in fillers)


def box_rows() -> list[dict]:
    out = []
    for group, fillers in BOX_GROUPS.items():
        for folder in sorted((RESULTS / "box_size_runs").glob(f"{group}-*um")):
            rows = [r for r in _results(folder) if _at_paper_r(r, fillers)]
            if len(rows) < 2:
                continue
            out.append({"system": group, "quantity": "k_iso_box", "box_um": rows[0]["box_um"],
                        "voxel_um": rows[0]["voxel_um"], "value": float(np.mean(
                            [r["k_iso"] for r in rows])), "unit": "W/(m K)",
                        "source": f"validation/results/box_size.md ({len(rows)} packings)"})
    return sorted(out, key=lambda r: (r["system"], r["box_um"]))


def large_box_rows() -> list[dict]:
    """k_iso per box of the large-box study (56-80 um at 0.25 um, AlN-60 and the hybrid)."""
    sys.path.insert(0, str(ROOT / "validation"))
    from box_convergence_study import box_table

    out = []
    for group, system in (("AlN", "AlN"), ("hybrid", "hybrid")):
        for box, (k, se, n) in box_table(group).items():
            out.append({"system": system, "quantity": "k_iso_box_large", "box_um": box,
                        "voxel_um": 0.25, "value": k, "unit": "W/(m K)",
                        "source": f"validation/results/box_convergence.md ({n} packings, "
                                  f"standard error {100 * se / k:.2f} %)"})
    return out


def sensitivity_rows() -> list[dict]:
    runs = RESULTS / "inputs_sensitivity_runs"
    variants = {"film_2nm": "film-2-nm", "film_5nm": "film-5-nm",
                "psd_volume": "volume-weighted-Table-1"}
    out = []
    for filler, form in (("Al2O3", "Al2O3-60"), ("AlN", "AlN-60")):
        ref = [r for r in _results(runs / f"{form}-reference") if _at_paper_r(r, (filler,))]
        if len(ref) < 2:
            continue
        k_ref = float(np.mean([r["k_iso"] for r in ref]))
        for quantity, slug in variants.items():
            rows = [r for r in _results(runs / f"{form}-{slug}") if _at_paper_r(r, (filler,))]
            if len(rows) < 2:
                continue
            out.append({"system": filler, "quantity": quantity, "box_um": rows[0]["box_um"],
                        "voxel_um": rows[0]["voxel_um"],
                        "value": float(np.mean([r["k_iso"] for r in rows])) / k_ref - 1,
                        "unit": "relative", "source": "validation/results/inputs_sensitivity.md"})
    return out


def bias_rows() -> list[dict]:
    law = json.loads((RESULTS / "voxel_bias_law.json").read_text())
    return [{"system": "Al2O3", "quantity": "voxel_bias", "box_um": 16.0, "voxel_um": float(h),
             "value": float(v["mean"]), "unit": "relative",
             "source": "validation/results/voxel_bias_law.md (Al2O3-60, gap model)"}
            for h, v in sorted(law["relative_bias"].items(), key=lambda kv: -float(kv[0]))]


def main() -> int:
    rows = box_rows() + large_box_rows() + sensitivity_rows() + bias_rows()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    tmp = OUT.with_suffix(".tmp")
    with tmp.open("w", newline="") as fh:
        w = csv.DictWriter(fh, ["system", "quantity", "box_um", "voxel_um", "value", "unit",
                                "source"], lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({**r, "value": f"{r['value']:.6g}"})
    tmp.replace(OUT)
    print(f"wrote {OUT} ({len(rows)} rows)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
