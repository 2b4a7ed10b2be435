"""Issue 47's AlN box study and tail cut as stores of the corrections-v2 plan.

Issue 47 solved AlN-60 with touching particles at the stated film on a lent H200: 64, 80 and
96 um boxes, 6 packings (seeds 201-206), and the tail cut at 80 um (number quantiles 1e-3
and 1e-5, 3 packings), R = 3e-8 m^2 K/W, tol 1e-6, 0.25 um. Those are the campaigns the plan
``examples/corrections.toml`` names ``box47-AlN`` and ``tail47-AlN-80``; their rows were
kept as JSON (``validation/results/device_issue47*/``). This writes them as campaign
stores (``validation/results/corrections_v2/issue47/<campaign>``: campaign.json and one
Parquet part per task), after checking that every row is the plan's task (formulation,
replica, seed, box, voxel, resistance), so that the rebuild reads and skips them like any
other finished task.

Usage::

    python validation/corrections_issue47_rows.py
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "validation" / "results"
OUT = RESULTS / "corrections_v2" / "issue47"
SOURCES = {"box47-AlN-64": ("device_issue47/box47__AlN-64um.rows.json", None),
           "box47-AlN-80": ("device_issue47/box47__AlN-80um.rows.json", None),
           "box47-AlN-96": ("device_issue47/box47__AlN-96um.rows.json", None),
           "tail47-AlN-80-q0.001": ("device_issue47_run2/rows.json", "tail47__AlN-80um-q0.001"),
           "tail47-AlN-80-q1e-05": ("device_issue47_run2/rows.json", "tail47__AlN-80um-q1e-05")}


def main() -> int:
    from itr_identify.forward.correction_plan import CorrectionPlan
    from itr_surrogate.store import CampaignStore

    plan = CorrectionPlan.from_toml(ROOT / "examples" / "corrections.toml")
    camps = {c.name: c for _, c in plan.campaigns(systems=("AlN",), solver="gpu")}
    for name, (path, key) in SOURCES.items():
        data = json.loads((RESULTS / path).read_text())
        rows = data[key] if key else data
        camp = camps[name]
        tasks = {t.task_id: t for t in camp.tasks()}
        (pset,) = camp.parameter_sets(camp.formulations[0])
        for r in rows:
            t = tasks[r["task_id"]]
            want = (t.formulation, t.replica, t.seed, camp.box_um, camp.voxel_um)
            got = (r["formulation"], r["replica"], r["seed"], r["box_um"], r["voxel_um"])
            if want != got or any(abs(r[k] / v - 1) > 1e-12 for k, v in pset.items()):
                raise SystemExit(f"{name}: row {r['task_id']} is not the plan's task: "
                                 f"{got} against {want}")
        store = CampaignStore(OUT / name)
        store.open_for(camp)
        for r in rows:
            store.write_part(r["task_id"], [r])
        print(f"{name}: {len(rows)} tasks -> {store.folder}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
