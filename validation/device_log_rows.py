"""Rows of the first device run of issue 39, read back from its log.

The first run of ``validation/faithful_solves_on_device.py`` on the lent H200 (2026-11-26)
solved the AlN corrections and the AlN truth, but its Parquet stores did not come back from
the device (three folder levels; the device returns two). Its log
(``validation/results/device_issue39/log.txt``) has every solve's k_iso to four decimals
(relative rounding 3e-5; after the voxel extrapolation about 2e-4), in the design's order.
This writes those of the fine voxel (0.2 um; the coarse ones of that run were packed with
the coarse voxel's fine-tail cut, other particles, and are redone on the CPU with
``cut_voxel_um``) as ``<store>.rows.json`` next to where the stores would be
(``validation/results/corrections_runs``, ``validation/results/truth_runs``), marked
``"source": "device log"`` and without the tensor's diagonal, which
:func:`itr_identify.forward.shipped.point_rows` and ``validation/shipped_recovery_study.py``
read in place of a store.

Usage::

    python validation/device_log_rows.py
"""

from __future__ import annotations

import ast
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "validation"))
RESULTS = ROOT / "validation" / "results"
LOG = RESULTS / "device_issue39" / "log.txt"
LINE = re.compile(r"\] (\S+) (\S+)__r(\d+)__b\d+: (\d+) solves in ([\d.]+) s k_iso (\[.*\])$")


def main() -> int:
    from recovery_truth import truth_campaign

    from itr_identify.forward.correction_plan import CorrectionPlan

    plan = CorrectionPlan.from_toml(ROOT / "examples" / "corrections.toml")
    camps = {f"corrections/{fold}": c for fold, c in plan.campaigns(solver="gpu")}
    for system in ("AlN", "Al2O3-AlN"):
        for v in (0.25, 0.2):
            camps[f"truth/truth-{system}-{v:g}um"] = truth_campaign(system, v, solver="gpu")
    rows: dict[str, list[dict]] = {}
    for line in LOG.read_text().splitlines():
        m = LINE.search(line)
        if not m:
            continue
        store, form, replica, n, wall, ks = m.groups()
        camp = camps[store]
        sets = camp.parameter_sets(camp.formulation(form))
        ks = [float(k) for k in ast.literal_eval(ks)]
        assert len(ks) == len(sets) == int(n), line
        for i, (pset, k) in enumerate(zip(sets, ks)):
            rows.setdefault(store, []).append({
                "formulation": form, "replica": int(replica), "set_index": i,
                "seed": camp.seed + int(replica), "box_um": camp.box_um,
                "voxel_um": camp.voxel_um, "n": camp.shape[0], "contact": camp.contact,
                "solver": "gpu (array_api, fft/portable, H200)", "tol": camp.tol, **pset,
                "k_iso": k, "wall_s": float(wall) / len(ks), "source": "device log"})
    for store, rs in rows.items():
        kind, name = store.split("/")
        if not name.endswith("-0.2um"):
            # the first run packed the coarse voxel with its own fine-tail cut: other
            # particles than the fine voxel's, no pair for the extrapolation (the coarse
            # solves are redone on the fine voxel's particles, cut_voxel_um)
            continue
        folder = RESULTS / ("corrections_runs" if kind == "corrections" else "truth_runs")
        path = folder / f"{name}.rows.json"
        path.write_text(json.dumps(rs, indent=1) + "\n")
        print(f"wrote {path} ({len(rs)} rows)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
