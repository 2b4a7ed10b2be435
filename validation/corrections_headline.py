"""The headline of ``itr reproduce`` before and after the rebuilt corrections (issue 58).

Before: ``validation/results/reproduce_identified.json`` as the clean-clone CI of e01f470
ran it (the corrections-v1 table of the earlier contact geometry, each factor with 3 % more
uncertainty). After: ``validation/results/reproduce_issue58/identified.json``, README command
1 from a fresh install in a clean clone of the commit that shipped corrections-v2 (the same
inference). Writes ``validation/results/corrections_headline.md``.

Usage::

    python validation/corrections_headline.py
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "validation" / "results"
BEFORE = RESULTS / "reproduce_identified.json"
AFTER = RESULTS / "reproduce_issue58" / "identified.json"
OUT = RESULTS / "corrections_headline.md"


def rows(path: Path) -> tuple[dict, dict]:
    data = json.loads(path.read_text())
    return data["headline"]["parameters"]["gap"], data["headline"]["fit"]["gap"]


def main() -> int:
    before, fit_b = rows(BEFORE)
    after, fit_a = rows(AFTER)
    wall = (RESULTS / "reproduce_issue58" / "wall.txt").read_text().strip().splitlines()
    lines = ["# `itr reproduce` before and after the rebuilt corrections (issue 58)", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "| parameter | before: best (90 %) | before: nominal inputs | after: best (90 %) |"
             " after: nominal inputs | after / before (best) |", "|---|---|---|---|---|---|"]
    for n in before:
        b, a = before[n], after[n]
        fmt = "{:.2e} ({:.2e} - {:.2e})"
        lines.append(f"| {n} | {fmt.format(b['best'], *b['interval_90'])} | "
                     f"{fmt.format(b['best_nominal_inputs'], *b['interval_90_nominal_inputs'])}"
                     f" | {fmt.format(a['best'], *a['interval_90'])} | "
                     f"{fmt.format(a['best_nominal_inputs'], *a['interval_90_nominal_inputs'])}"
                     f" | {a['best'] / b['best']:.2f} |")
    lines += ["", f"The gap fit's chi-square test: before {fit_b['chi2']:.1f} on {fit_b['dof']} "
              f"dof (model-form error {100 * fit_b['model_form_sd']:.1f} %), after "
              f"{fit_a['chi2']:.1f} on {fit_a['dof']} dof (model-form error "
              f"{100 * fit_a['model_form_sd']:.1f} %): the new factors carry their own "
              "uncertainty without the old table's 3 %, so more of the misfit shows.", "",
              "The run after: " + "; ".join(wall) + " (2 cores, `pip install .` included)."]
    OUT.write_text("\n".join(lines) + "\n")
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
