"""The gap contact model against the multipole reference: arrays of nearly touching spheres.

SC, BCC and FCC arrays of spheres of radius a = 1.5 um whose nearest neighbours are
separated by a matrix film of 1.5, 10 or 20 nm, particle-matrix resistance R_b = 2e-8 or
5e-8 m^2 K/W, k_p = 30 or 200 W/(m K) in k_m = 0.18 W/(m K). Reference:
``itr_fv.analytic.sphere_array`` (the spheres with interface resistance R_b in the matrix:
the film is the matrix between them). Cells from ``validation.gallery.touching_array``.
Solvers: itr_fft and the FV reference itr_fv at tol 1e-8, ``contact="gap"``, h = a/8,
a/12, a/16, under three interface laws (``itr_fv.discrete.interface_law``): the staircase law, the
segment law with the staircase crossing share and with the normal share (issue 28). The
errors are itr_fft's; ``FV-FFT`` is the largest relative difference of the two solvers'
diagonals over the three laws. Rows are kept in ``gap_model.csv`` (a re-run skips the
solved ones). Writes ``validation/results/gap_model.md``.

Usage::

    python validation/gap_model_study.py [--per 8,12,16]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

A = 1.5e-6
K_M = 0.18
FINDINGS = """## Findings

- Staircase law: at h = a/16 every case is within 2 % of the reference (largest 1.63 %, SC),
  with both solvers (they agree to the solver tolerance). At a/12 the SC (up to 2.46 %) and
  FCC (up to 2.98 %) arrays with 1.5 nm films are not; BCC is (0.97 %). At a/8 BCC reaches
  4.16 % (1.5 nm, k_p 200, R_b 2e-8).
- Segment law (issue 28): no better. With the staircase share it is worse at every
  resolution (5.12 / 2.67 / 2.22 % at a/8 / a/12 / a/16); with the normal share it is the
  best at a/12 and a/16 (2.35 / 1.32 %) and on SC much better (0.95 % at a/12, 0.45 % at
  a/16), but worse on BCC and at a/8 (5.38 %). Neither meets 2 % at a/8 or 1 % at a/12. The
  errors are negative and first order in every law: the one-conductance-per-face interface
  under-conducts where the surface is tilted to the grid (``tilted_interface.md``: a flat
  interface at 45 degrees has the same first-order error under every law), and the segment
  law's exact bulk lengths remove the staircase law's partly compensating positive error of
  the centre labels.
- Contacts are not the limit: on the a/12 cases (1.5 nm films), widening the staircase law's
  segment zone from 3 to 6 voxels changes SC from -2.10 to -2.18 % and FCC from -2.98 to
  -2.65 %; averaging the film conductance over 4 x 4 or 8 x 8 points of each contact face
  changes SC by 0.05 % and FCC not at all."""


LAWS = {"staircase": "staircase", "segment": ("segment", "staircase"),
        "segment-normal": ("segment", "normal")}
FIELDS = ["per", "lattice", "film_nm", "k_p", "R_b", "law", "n", "f", "k_fft", "k_fv",
          "reference", "err_pct", "wall_s"]
CSV = ROOT / "validation" / "results" / "gap_model.csv"


def law_object(name: str):
    from itr_fv.discrete.interface_law import SegmentLaw

    spec = LAWS[name]
    return spec if isinstance(spec, str) else SegmentLaw(share=spec[1])


def solve(per: int, lat: str, film: float, kp: float, rb: float, law: str) -> dict:
    from itr_fv import Materials, analytic, homogenize
    from itr_fv.discrete.problem import DiscreteProblem
    from validation.gallery import touching_array

    ms, f = touching_array(lat, A, film, per)
    mat = Materials({"silicone": K_M, "Al2O3": kp}, {("Al2O3", "silicone"): rb},
                    matrix="silicone", contact="gap")
    ref = analytic.sphere_array(lat, f, kp / K_M, rb * K_M / A) * K_M
    t = time.perf_counter()
    problem = DiscreteProblem(ms, contact="gap", interface=law_object(law))
    k_fft = np.diag(homogenize(problem, mat, solver="fft", tol=1e-8, store_fields=False).k_eff)
    k_fv = np.diag(homogenize(problem, mat, solver="fv", tol=1e-8, store_fields=False).k_eff)
    k = float(k_fft.mean())
    return {"per": per, "lattice": lat, "film_nm": f"{film * 1e9:g}", "k_p": f"{kp:g}",
            "R_b": f"{rb:g}", "law": law, "n": ms.shape[0], "f": f"{f:.6f}",
            "k_fft": " ".join(f"{v:.10g}" for v in k_fft),
            "k_fv": " ".join(f"{v:.10g}" for v in k_fv), "reference": f"{ref:.10g}",
            "err_pct": f"{100 * (k / ref - 1):.6f}", "wall_s": f"{time.perf_counter() - t:.2f}"}


def key(row: dict) -> tuple:
    return (int(row["per"]), row["lattice"], float(row["film_nm"]), float(row["k_p"]),
            float(row["R_b"]), row["law"])


def fv_fft(row: dict) -> float:
    a = np.array(row["k_fft"].split(), dtype=float)
    b = np.array(row["k_fv"].split(), dtype=float)
    return float(np.max(np.abs(a - b) / b))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per", default="8,12,16", help="voxels per radius")
    ap.add_argument("--out", default=str(ROOT / "validation" / "results" / "gap_model.md"))
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "validation"))
    import csv_store

    pers = [int(p) for p in args.per.split(",")]
    done = {key(r) for r in csv_store.load_rows(CSV)}
    for per in pers:
        for lat in ("sc", "bcc", "fcc"):
            for film in (1.5e-9, 10e-9, 20e-9):
                for kp in (30.0, 200.0):
                    for rb in (2e-8, 5e-8):
                        for law in LAWS:
                            if (per, lat, film * 1e9, kp, rb, law) in done:
                                continue
                            row = solve(per, lat, film, kp, rb, law)
                            csv_store.append_row(CSV, FIELDS, row)
                            print(per, lat, film, kp, rb, law, row["err_pct"], flush=True)
    for per in REFINE:
        for law in LAWS:
            if (per, "sc", 1.5, 30.0, 2e-8, law) not in done:
                row = solve(per, "sc", 1.5e-9, 30.0, 2e-8, law)
                csv_store.append_row(CSV, FIELDS, row)
    write_report(csv_store.load_rows(CSV), pers, Path(args.out))
    print(f"wrote {args.out}")


#: Resolutions of the refinement table (voxels per radius), SC, 1.5 nm, k_p 30, R_b 2e-8.
REFINE = (8, 10, 12, 14, 16, 20, 24, 32)


def write_report(rows: list[dict], pers: list[int], out: Path) -> None:
    by = {key(r): r for r in rows}
    names = list(LAWS)
    lines = ["# Gap contact model vs the multipole reference (issues 9 and 28)", "",
             __doc__.split("\n\n")[1].replace("\n", " "), "",
             "| h | lattice | film (nm) | k_p | R_b | n | f | reference | "
             + " | ".join(f"error {n} (%)" for n in names) + " | FV-FFT |",
             "|---" * (8 + len(names) + 1) + "|"]
    cases = sorted({k[:5] for k in by if k[0] in pers},
                   key=lambda k: (k[0], ["sc", "bcc", "fcc"].index(k[1])) + k[2:])
    for c in cases:
        rs = [by.get(c + (n,)) for n in names]
        if any(r is None for r in rs):
            continue
        r0 = rs[0]
        lines.append(f"| a/{c[0]} | {c[1]} | {c[2]:g} | {c[3]:g} | {c[4]:.0e} | {r0['n']} | "
                     f"{float(r0['f']):.4f} | {float(r0['reference']):.5f} | "
                     + " | ".join(f"{float(r['err_pct']):+.2f}" for r in rs)
                     + f" | {max(fv_fft(r) for r in rs):.1e} |")
    lines += ["", "## Largest |error| over the 36 cases, per law and resolution", "",
              "| h | " + " | ".join(names) + " |", "|---" * (1 + len(names)) + "|"]
    for per in pers:
        cells = []
        for n in names:
            errs = [abs(float(r["err_pct"])) for k, r in by.items()
                    if k[0] == per and k[5] == n and k[:5] in cases]
            cells.append(f"{max(errs):.2f} ({len(errs)} cases)" if errs else "")
        lines.append(f"| a/{per} | " + " | ".join(cells) + " |")
    lines += ["", "Per lattice (largest |error|, %):", "",
              "| h | lattice | " + " | ".join(names) + " |", "|---" * (2 + len(names)) + "|"]
    for per in pers:
        for lat in ("sc", "bcc", "fcc"):
            cells = []
            for n in names:
                errs = [abs(float(r["err_pct"])) for k, r in by.items()
                        if k[0] == per and k[1] == lat and k[5] == n]
                cells.append(f"{max(errs):.2f}" if errs else "")
            lines.append(f"| a/{per} | {lat} | " + " | ".join(cells) + " |")
    diffs = [fv_fft(r) for k, r in by.items() if k[0] in pers]
    lines.append(f"\nLargest FV-FFT difference over all cases and laws: {max(diffs):.1e}")
    lines += ["", "## Refinement of one case (SC, 1.5 nm film, k_p 30, R_b 2e-8, itr_fft)", "",
              "| h | n | " + " | ".join(f"error {n} (%)" for n in names) + " |",
              "|---" * (2 + len(names)) + "|"]
    for per in REFINE:
        rs = [by.get((per, "sc", 1.5, 30.0, 2e-8, n)) for n in names]
        if all(rs):
            lines.append(f"| a/{per} | {rs[0]['n']} | "
                         + " | ".join(f"{float(r['err_pct']):+.2f}" for r in rs) + " |")
    lines += ["", FINDINGS]
    out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
