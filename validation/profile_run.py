"""Where `itr reproduce` and `itr identify` spend their time (issue 61, point 1).

Runs one command of the package's command line under :mod:`cProfile` in this process and
writes what it measured: the wall per stage as the run's own report states it (its
``report.md`` "wall time" line), the functions that take the most cumulative and own time,
and the shares of the cost centres that decide what to cut (the posterior sampler, the
full solves, the reduced bases, the figures).

Usage::

    python validation/profile_run.py NAME -- reproduce [ARGS ...]
    python validation/profile_run.py NAME -- identify --example [ARGS ...]

Writes ``validation/results/profile_NAME.md`` and ``.json``. The command's own output
folder is a temporary one unless ``--out`` is among its arguments.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import shutil
import sys
import tempfile
import time
from pathlib import Path

from itr_fv.io import write_text

#: Cost centres: a name and the functions (file suffix, function name) whose cumulative
#: time is that centre's (the first match on the call stack counts; nested ones are not
#: added twice because each centre is read as one function's cumulative time).
CENTRES = {
    "posterior sampling (emcee, joint likelihood)": ("inference/joint.py", "sample"),
    "joint likelihood evaluations": ("inference/joint.py", "log_posterior"),
    "full solves (solve engine)": ("surrogate/engine.py", "run_request"),
    "reduced-basis fits": ("surrogate/reduced_basis.py", "fit"),
    "figures": ("workflows/reproduce.py", "_figures"),
    "free-input fit (L-BFGS-B, Nelder-Mead)": ("inference/free_inputs_fit.py",
                                               "fit_with_inputs_free"),
}


def _centre_times(stats: pstats.Stats) -> dict[str, float]:
    """Each centre's cumulative time, s (the largest over the functions that match)."""
    out = dict.fromkeys(CENTRES, 0.0)
    for (filename, _, func), (_, _, _, cum, _) in stats.stats.items():
        for centre, (suffix, name) in CENTRES.items():
            if func == name and filename.replace(os.sep, "/").endswith(suffix):
                out[centre] = max(out[centre], cum)
    return out


def _top(stats: pstats.Stats, key: str, n: int) -> list[dict]:
    rows = []
    for (filename, line, func), (cc, nc, tt, ct, _) in sorted(
            stats.stats.items(), key=lambda kv: -kv[1][2 if key == "tottime" else 3])[:n]:
        rows.append({"function": f"{Path(filename).name}:{line}({func})", "calls": nc,
                     "own_s": round(tt, 2), "cumulative_s": round(ct, 2)})
    return rows


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--" not in argv:
        print("usage: profile_run.py NAME -- COMMAND [ARGS ...]", file=sys.stderr)
        return 2
    cut = argv.index("--")
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("name")
    p.add_argument("--results", default="validation/results")
    args = p.parse_args(argv[:cut])
    command = argv[cut + 1:]
    from itr_identify.cli import main as itr

    tmp = None
    if "--out" not in command:
        tmp = tempfile.mkdtemp(prefix="itr-profile-")
        command += ["--out", str(Path(tmp) / "out")]
    out = Path(command[command.index("--out") + 1])
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    rc = itr(command)
    prof.disable()
    wall = time.perf_counter() - t0
    results = Path(args.results)
    stats = pstats.Stats(prof)
    centres = _centre_times(stats)
    report = out / "report.md"
    stages = next((line.split(":", 1)[1].strip() for line in report.read_text().splitlines()
                   if "wall time (s)" in line), "") if report.exists() else ""
    data = {"command": "itr " + " ".join(command), "rc": rc, "wall_s": round(wall, 1),
            "cpus": os.cpu_count(), "stages_from_report": stages,
            "centres_s": {k: round(v, 1) for k, v in centres.items()},
            "top_cumulative": _top(stats, "cumtime", 25),
            "top_own": _top(stats, "tottime", 25)}
    write_text(results / f"profile_{args.name}.json", json.dumps(data, indent=1) + "\n")
    lines = [f"# Profile: `{data['command']}`", "",
             f"`python validation/profile_run.py {args.name} -- {' '.join(command)}` on "
             f"{os.cpu_count()} CPUs under cProfile (which slows Python-heavy parts more "
             f"than array work); wall {wall:.0f} s, exit status {rc}.", "",
             f"Stages as the run's report states them: {stages or '(no report)'}", "",
             "## Cost centres (cumulative, s; a centre nested in another counts in both)", "",
             "| centre | s | share of the wall |", "|---|---|---|"]
    lines += [f"| {k} | {v:.1f} | {100 * v / wall:.0f} % |" for k, v in centres.items()]
    for title, key in (("cumulative", "top_cumulative"), ("own", "top_own")):
        lines += ["", f"## Top functions by {title} time", "",
                  "| function | calls | own s | cumulative s |", "|---|---|---|---|"]
        lines += [f"| `{r['function']}` | {r['calls']} | {r['own_s']} | {r['cumulative_s']} |"
                  for r in data[key]]
    write_text(results / f"profile_{args.name}.md", "\n".join(lines) + "\n")
    print("\n".join(lines[:12 + len(centres)]))
    if tmp is not None:
        shutil.rmtree(tmp, ignore_errors=True)
    return int(rc)


if __name__ == "__main__":
    sys.exit(main())
