"""The contact-film table of issue 47: every Table 2 formulation at the cheap RVE and at the
converged box, touching particles meeting at films of 0, 1, 2 and 5 nm.

Touching pairs meet at exactly the stated film (``itr_fv.rve.contact_film``): the same
particles and voxels at every film (campaign key ``film_um``), so the columns differ by the
film alone. R = 3e-8 m^2 K/W at every filler-matrix interface; the paper's conductivities.

- The cheap RVE: the default of ``itr reproduce`` (12 um at 0.25 um, packings 1, 2, 3), on
  the campaign engine here (``validation/results/contact_film_runs``; a re-run resumes).
- The converged box: AlN-60 and Al2O3-30-AlN-30 at 64 um, 0.25 um, one packing (seed 201),
  from the device run of ``validation/faithful_solves_on_device.py --queue film`` on one
  NVIDIA H200 (``validation/results/device_issue47/film47__*.rows.json``; "(log)": a row
  that did not come back from the device, read from the run's log line to four decimals);
  the other formulations were not run at the converged box ("not run").

It also lists the clearance the packer leaves between touching pairs (which the contact
geometry no longer reads as a film) in the cheap RVE and in a 64 um box.

Writes ``validation/results/contact_film.md`` and ``contact_film.json``.

Usage::

    python validation/contact_film_study.py [--report-only]
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RUNS = ROOT / "validation" / "results" / "contact_film_runs"
DEVICE = ROOT / "validation" / "results" / "device_issue47"
OUT = ROOT / "validation" / "results" / "contact_film.md"
OUT_JSON = ROOT / "validation" / "results" / "contact_film.json"
FILMS_NM = (0.0, 1.0, 2.0, 5.0)
R_M2K_PER_W = 3e-8
DEVICE_GROUP = {"AlN-60": "AlN", "Al2O3-30-AlN-30": "hybrid"}


def formulations() -> list[str]:
    from itr_fv.materials import paper_data

    return list(paper_data.formulations())


def resistances(name: str) -> dict[str, list[float]]:
    return {f"R_{f}_silicone": [R_M2K_PER_W] for f in ("Al2O3", "AlN") if f in name}


def cheap_campaign(name: str, film_nm: float):
    from itr_surrogate.campaign import Campaign

    return Campaign.from_dict({
        "name": f"film-cheap-{name}-{film_nm:g}nm", "box_um": 12.0, "voxel_um": 0.25,
        "replicas": 3, "seed": 1, "contact": "gap", "solver": "fft", "tol": 1e-6,
        "block_size": 1, "film_um": film_nm / 1000, "formulation": [{"name": name}],
        "design": {"kind": "grid", "values": resistances(name)}})


def folder(name: str, film_nm: float) -> Path:
    return RUNS / f"cheap-{name}-{film_nm:g}nm"


def run() -> None:
    from itr_surrogate.runner import run_campaign

    for film in FILMS_NM:          # the film 0 column first: it lands whole
        for name in formulations():
            run_campaign(cheap_campaign(name, film), folder(name, film), workers=0,
                         progress=False, echo=lambda *_: None)
        print(f"film {film:g} nm: done", flush=True)


def cheap_k(name: str, film_nm: float) -> list[float] | None:
    from itr_surrogate.store import CampaignStore

    path = folder(name, film_nm)
    if not (path / "campaign.json").exists():
        return None
    rows = CampaignStore(path).results().to_pylist()
    if len(rows) < 3:
        return None
    return [r["k_iso"] for r in sorted(rows, key=lambda r: r["replica"])]


#: A solve's line in the device run's output (``faithful_solves_on_device.py``'s log).
LOG_LINE = re.compile(r"\] (\S+) (\S+)__r(\d+)__b\d+: \d+ solves in [\d.]+ s k_iso "
                      r"\['([\d.]+)'\]")


def device_k(name: str, film_nm: float) -> tuple[float, str] | None:
    """k_iso of the converged box and where it was read: the run's rows, or (rows that did
    not come back from the device) its log line, to four decimals."""
    group = DEVICE_GROUP.get(name)
    if group is None:
        return None
    store = f"film47/{group}-64um-{film_nm:g}nm"
    path = DEVICE / f"{store.replace('/', '__')}.rows.json"
    if path.exists():
        rows = json.loads(path.read_text())
        return (float(rows[0]["k_iso"]), "rows") if rows else None
    tail = DEVICE / "output_tail.txt"
    for line in (tail.read_text().replace("\r", "\n").splitlines() if tail.exists() else []):
        m = LOG_LINE.search(line)
        if m and m.group(1) == store and m.group(2) == name and m.group(3) == "0":
            return float(m.group(4)), "log"
    return None


def clearances() -> dict[str, dict[str, float]]:
    """Median and largest clearance (nm) the packer leaves between touching pairs, and the
    film the contact geometry reads there, for AlN-60 in the cheap RVE and a 64 um box."""
    from itr_fv.discrete.contact_zones import zone_table
    from itr_fv.rve import build_rve
    from itr_fv.rve.packing import pairs_within_gap
    from itr_fv.rve.spec import RVESpec
    from itr_surrogate.campaign import Campaign

    out = {}
    for label, box, seed in (("cheap 12 um", 12.0, 1), ("64 um box", 64.0, 201)):
        camp = Campaign.from_dict({"box_um": box, "voxel_um": 0.25, "seed": seed,
                                   "formulation": [{"name": "AlN-60"}],
                                   "design": {"kind": "grid",
                                              "values": {"R_AlN_silicone": [3e-8]}}})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ms, _ = build_rve(RVESpec(**{**camp.rve.to_dict()}),
                              camp.formulation("AlN-60").specs(), 0, progress=False)
        t = ms.particles
        i, j, g = pairs_within_gap(t.centers_m, t.radii_m, ms.box_m[0], 5e-8)
        touch = g <= 1e-3 * (t.radii_m[i] + t.radii_m[j])
        zt = zone_table(ms, ms.voxel_m, 0.0)
        read = zt.gap[zt.gap < 1e-9]
        out[label] = {"touching_pairs": int(touch.sum()),
                      "clearance_median_nm": float(np.median(g[touch]) * 1e9),
                      "clearance_max_nm": float(g[touch].max() * 1e9),
                      "film_read_max_abs_nm": float(np.abs(read).max() * 1e9)}
    return out


def report() -> None:
    from itr_fv.io import write_text

    data = {"films_nm": list(FILMS_NM), "R_m2K_per_W": R_M2K_PER_W, "rows": {}}
    lines = ["# Contact films at the cheap RVE and the converged box (issue 47)", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "k_iso in W/(m K); the cheap RVE: mean of 3 packings (their standard error in "
             "brackets); the ratio is k(5 nm) / k(0 nm) of the same particles.", "",
             "| formulation | cheap 0 nm | cheap 1 nm | cheap 2 nm | cheap 5 nm | cheap "
             "5/0 | 64 um 0 nm | 64 um 1 nm | 64 um 2 nm | 64 um 5 nm | 64 um 5/0 |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in formulations():
        cells, row = [], {}
        for film in FILMS_NM:
            ks = cheap_k(name, film)
            row[f"cheap_{film:g}nm"] = ks
            if ks is None:
                cells.append("not run")
            else:
                m = statistics.fmean(ks)
                se = statistics.stdev(ks) / len(ks) ** 0.5
                cells.append(f"{m:.4f} ({se:.4f})")
        k0, k5 = row.get("cheap_0nm"), row.get("cheap_5nm")
        cells.append(f"{statistics.fmean(k5) / statistics.fmean(k0):.4f}"
                     if k0 and k5 else "-")
        for film in FILMS_NM:
            got = device_k(name, film)
            k = None if got is None else got[0]
            row[f"box64_{film:g}nm"] = k
            cells.append("not run" if got is None else
                         f"{k:.4f}" + (" (log)" if got[1] == "log" else ""))
        b0, b5 = row.get("box64_0nm"), row.get("box64_5nm")
        cells.append(f"{b5 / b0:.4f}" if b0 and b5 else "-")
        data["rows"][name] = row
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    clear = clearances()
    data["clearance"] = clear
    lines += ["", "## The packer's clearance, no longer read as a film", "",
              "Touching pairs of AlN-60 (the packer's contact distance: gap <= 1e-3 (r_i + "
              "r_j)); 'read' is the largest |film| the contact geometry uses at their closest "
              "point (stated film 0).", "",
              "| RVE | touching pairs | clearance median (nm) | clearance max (nm) | film "
              "read, max abs (nm) |", "|---|---|---|---|---|"]
    for label, c in clear.items():
        lines.append(f"| {label} | {c['touching_pairs']} | {c['clearance_median_nm']:.2f} | "
                     f"{c['clearance_max_nm']:.2f} | {c['film_read_max_abs_nm']:.1e} |")
    write_text(OUT, "\n".join(lines) + "\n")
    write_text(OUT_JSON, json.dumps(data, indent=1) + "\n")
    print(f"wrote {OUT}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--report-only", action="store_true")
    args = ap.parse_args()
    if not args.report_only:
        run()
    report()
    return 0


if __name__ == "__main__":
    sys.exit(main())
