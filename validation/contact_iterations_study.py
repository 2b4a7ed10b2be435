"""Why AlN-60 at 0.125 um takes more CG iterations since the contacts meet at the stated film
(issue 61: 46 iterations per load case on 2026-11-26, 82-83 now).

The problem of ``resolution.md``'s row ``aln-gap``, seed 1, 0.125 um (60 vol% AlN, mu = 1.25,
sigma = 0.59, k = 200 W/(m K), R_b = 3e-8 m^2 K/W, gap model, 16 um box packed at 0.4 um and
re-voxelized at 128^3; ``resolution_study.solve``), solved with the numba multigrid
(``itr_fft``, tol 1e-8, three load cases):

1. at the film touching pairs meet at, from 0 (the default since commit b96ff91: the packer's
   touching pairs meet at exactly the stated film, 0 nm) to 50 nm; before b96ff91 the pairs
   met at the packer's own clearance, 1.4-22 nm, size-dependent;
2. at the default film, with the multigrid's settings changed one at a time (three Jacobi
   sweeps instead of two, a W-cycle, another over-correction, a float64 hierarchy), with
   the FFT preconditioner, and with the groups the multigrid and the deflation follow:
   the particle ids as they were, or the coupled groups (``itr_fft.multigrid.
   coupled_groups``: matrix cells of the contact necks whose faces carry the filler's
   conductance join their particle), to see which preconditioner handles the stiffer
   contacts.

The films of part 1 and the settings of part 2 are solved with the particle ids as the
groups (the preconditioner before the coupled groups), unless a row says otherwise.

Writes ``validation/results/contact_iterations.md`` and ``.json``. About 5 min on 2 cores.

Usage::

    python validation/contact_iterations_study.py [--voxel-um 0.125]
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: Films touching pairs meet at (nm); 0 is the package's default.
FILMS_NM = (0.0, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0)
#: Multigrid settings tried at the default film (name -> AggregationMultigrid options).
VARIANTS = {"default (2 sweeps, V, over-correction 1.6)": {},
            "3 sweeps": {"sweeps": 3},
            "W-cycle": {"cycle": "W"},
            "over-correction 1.3": {"over_correction": 1.3},
            "float64 hierarchy": {"dtype": np.float64}}
#: resolution.md's row (package at 1519f12, before the stated film), iterations per case.
BEFORE = {"commit": "1519f12 (2026-11-26)", "iterations": [46, 46, 46], "k_iso": 1.7552}


def problem(voxel_um: float, film_nm: float | None):
    """The resolution study's AlN-60 seed-1 problem at ``voxel_um``, touching pairs at
    ``film_nm`` (None: the package's default)."""
    from itr_fv import Microstructure
    from itr_fv.discrete.problem import DiscreteProblem
    from itr_fv.rve import FillerSpec, RVESpec, generate_rve
    from validation.resolution_study import BOX_UM, materials

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        spec = FillerSpec("AlN", mu=1.25, sigma=0.59, volume_fraction=0.60)
        ms0 = generate_rve(RVESpec(BOX_UM, 0.4, max_diameter_box_ratio=0.45), [spec], 1,
                           matrix="silicone")
    t = ms0.particles
    contact = t.contact if film_nm is None else dataclasses.replace(t.contact,
                                                                     film_m=film_nm * 1e-9)
    n = int(round(BOX_UM / voxel_um))
    ms = Microstructure.from_spheres(t.centers_m, t.radii_m, t.material, box_m=BOX_UM * 1e-6,
                                     shape=n, matrix="silicone", contact=contact)
    mat = materials("aln-gap")
    return DiscreteProblem(ms, contact=mat.contact, interface="staircase"), mat


def solve(prob, mat, *, preconditioner: str = "multigrid", options: dict | None = None,
          coupled: bool = False) -> dict:
    """Three load cases at tol 1e-8; the multigrid built with ``options``, following the
    particle ids (or the coupled groups where ``coupled``)."""
    import itr_fft.numba_backend as nb
    from itr_fft.multigrid import AggregationMultigrid, coupled_groups
    from itr_fv import homogenize, resolve_solver

    nb.AggregationMultigrid = functools.partial(AggregationMultigrid, **(options or {}))
    nb.coupled_groups = coupled_groups if coupled else (lambda g, ids: ids)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t = time.perf_counter()
            res = homogenize(prob, mat,
                             solver=resolve_solver("fft", preconditioner=preconditioner),
                             tol=1e-8, store_fields=False)
            wall = time.perf_counter() - t
    finally:
        nb.AggregationMultigrid = AggregationMultigrid
        nb.coupled_groups = coupled_groups
    its = [int(i) for i in res.iterations]
    return {"iterations": its, "k_iso": float(np.trace(res.k_eff) / 3), "wall_s": wall,
            "ms_per_iteration": 1e3 * float(sum(res.solve_times)) / max(sum(its), 1),
            "converged": bool(res.converged)}


def markdown(res: dict) -> str:
    b = res["before"]
    lines = ["# CG iterations of AlN-60 at 0.125 um against the contact film", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             (f"Machine: {os.cpu_count()} cores. Before the stated film (package at "
              f"{b['commit']}, `resolution.md`): iterations "
              f"{'/'.join(map(str, b['iterations']))}, k_iso {b['k_iso']:.4f} W/(m K)."), "",
             "## Film of touching pairs (multigrid, default settings)", "",
             "| film (nm) | iterations, particle ids | iterations, coupled groups | k_iso "
             "(W/(m K)) | k_iso, coupled groups | ms/iteration |",
             "| --- | --- | --- | --- | --- | --- |"]
    for r in res["films"]:
        c = r["coupled"]
        lines.append(f"| {r['film_nm']:g} | {'/'.join(map(str, r['iterations']))} | "
                     f"{'/'.join(map(str, c['iterations']))} | {r['k_iso']:.6f} | "
                     f"{c['k_iso']:.6f} | {r['ms_per_iteration']:.1f} |")
    lines += ["", "## Preconditioners at the default film", "",
              "| preconditioner | iterations | wall (s) | ms/iteration |",
              "| --- | --- | --- | --- |"]
    for r in res["variants"]:
        lines.append(f"| {r['name']} | {'/'.join(map(str, r['iterations']))} | "
                     f"{r['wall_s']:.1f} | {r['ms_per_iteration']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voxel-um", type=float, default=0.125)
    ap.add_argument("--out", type=Path, default=ROOT / "validation" / "results"
                    / "contact_iterations.md")
    args = ap.parse_args(argv)
    res: dict = {"voxel_um": args.voxel_um, "before": BEFORE, "films": [], "variants": []}
    for film in FILMS_NM:
        prob, mat = problem(args.voxel_um, film)
        row = {"film_nm": film, **solve(prob, mat)}
        row["coupled"] = solve(prob, mat, coupled=True)
        res["films"].append(row)
        print(f"film {film:g} nm: iterations {row['iterations']} (coupled groups "
              f"{row['coupled']['iterations']}), k_iso {row['k_iso']:.4f}, "
              f"{row['ms_per_iteration']:.1f} ms/iteration", flush=True)
    prob, mat = problem(args.voxel_um, None)
    runs = [(name, "multigrid", opts, False) for name, opts in VARIANTS.items()]
    runs.append(("FFT (reference-medium Laplacian)", "fft", None, False))
    runs.append(("default, coupled groups (the package now)", "multigrid", None, True))
    for name, pre, opts, coupled in runs:
        row = {"name": name, **solve(prob, mat, preconditioner=pre, options=opts,
                                     coupled=coupled)}
        res["variants"].append(row)
        print(f"{name}: iterations {row['iterations']}, wall {row['wall_s']:.1f} s",
              flush=True)
    for path, text in ((args.out, markdown(res)),
                       (args.out.with_suffix(".json"), json.dumps(res, indent=1))):
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
