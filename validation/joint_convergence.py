"""Convergence of the joint posterior's sampler on Table 3 (issue 59, point 1).

The gap parametrisation's models of ``itr reproduce`` (the SBC study's :func:`sbc_study.build`)
are sampled at the default length (the chain worth :data:`~itr_identify.inference.joint.
TARGET_DRAWS` independent draws), with another seed, and at twice the length; per
resistance the point and the 90 % interval's ends, and how far doubling moved each. Target
(fixed before the run): no interval end moves by more than 2 %. Also the evidence (its
importance-sampling estimate) with its standard error. Points and interval ends are read, as
the package quotes them, from the resistances' Rao-Blackwell marginals
(``itr_identify.inference.marginal``).

Writes ``validation/results/joint_convergence.md`` and ``.json``.

Usage::

    python validation/joint_convergence.py
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "validation"))
RESULTS = ROOT / "validation" / "results"
OUT, OUT_JSON = RESULTS / "joint_convergence.md", RESULTS / "joint_convergence.json"
TARGET_MOVE = 0.02


def main() -> int:
    import sbc_study

    from itr_identify.inference import joint

    lik, _ = sbc_study.build()
    runs = {}
    default = joint.TARGET_DRAWS
    for label, seed, target in (("default, seed 0", 0, default), ("default, seed 1", 1, default),
                                ("twice as long, seed 0", 0, 2 * default)):
        joint.TARGET_DRAWS = target
        t = time.perf_counter()
        post = joint.sample(lik, seed=seed)
        runs[label] = {"seconds": time.perf_counter() - t, "steps": post.steps,
                       "burn": post.burn, "effective_draws": post.effective_draws,
                       "converged": post.converged, "log_evidence": post.log_evidence,
                       "log_evidence_se": post.log_evidence_se,
                       "parameters": {r: {"point": post.point(r),
                                          "interval_90": list(post.interval(r))}
                                      for r in post.resistances}}
        print(label, runs[label], flush=True)
    joint.TARGET_DRAWS = default
    base, longer = runs["default, seed 0"], runs["twice as long, seed 0"]
    moves = {r: [abs(b / a - 1) for a, b in zip(base["parameters"][r]["interval_90"],
                                                  longer["parameters"][r]["interval_90"])]
             for r in base["parameters"]}
    worst = max(max(v) for v in moves.values())
    lines = ["# Convergence of the joint posterior's sampler (issue 59)", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "| run | steps (burn-in) | effective draws | seconds | ln Z (se) | "
             + " | ".join(f"{r}: point, 90 %" for r in base["parameters"]) + " |",
             "|---" * (5 + len(base["parameters"])) + "|"]
    for label, r in runs.items():
        lines.append(f"| {label} | {r['steps']} ({r['burn']}) | {r['effective_draws']:.0f} | "
                     f"{r['seconds']:.0f} | {r['log_evidence']:.3f} ({r['log_evidence_se']:.3f})"
                     " | " + " | ".join(
                         f"{p['point']:.3e}, {p['interval_90'][0]:.3e} - "
                         f"{p['interval_90'][1]:.3e}" for p in r["parameters"].values()) + " |")
    lines += ["", "Doubling the chain moved the interval ends by " + "; ".join(
        f"{r}: {100 * m[0]:.2f} % and {100 * m[1]:.2f} %" for r, m in moves.items())
        + f": the largest {100 * worst:.2f} % ("
        + ("within" if worst <= TARGET_MOVE else "MISSES") + f" the {100 * TARGET_MOVE:g} % "
        "target)."]
    OUT.write_text("\n".join(lines) + "\n")
    OUT_JSON.write_text(json.dumps({"runs": runs, "moves": moves, "largest_move": worst,
                                    "meets_target": worst <= TARGET_MOVE}, indent=1) + "\n")
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
