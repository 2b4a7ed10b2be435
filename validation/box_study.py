"""Issue 47's box study, with touching particles at the stated film (0 nm): k_iso of AlN-60
against the box, 6 packings per box, the tail cut at a fixed box and the voxel order per
system on the same particles.

The solves ran on one lent NVIDIA H200 (``validation/faithful_solves_on_device.py``, queues
``film`` and ``film2``; array-API FFT-PCG, tol 1e-6, three load cases; R = 3e-8 m^2 K/W at
every filler-matrix interface; the paper's conductivities; 0.25 um voxels unless said):

- ``validation/results/device_issue47/box47__AlN-<box>um.rows.json``: AlN-60 at 64, 80 and
  96 um, packing seeds 201-206;
- ``validation/results/device_issue47_run2/rows.json``: AlN-60 at 80 um with the size
  distribution cut at number quantiles 1e-3 and 1e-5 (the box study's 1e-4 between them),
  and the voxel order: 40 um boxes at 0.25, 0.2 and 0.16 um of the same particles (the fine
  tail cut at 0.25 um's two voxels), 2 packings, AlN-60 and Al2O3-30-AlN-30.

The criterion of ``validation/box_convergence_study.py`` is kept: a box is converged when
its mean k_iso lies within 0.5 % of the next larger box's; beside it, the difference's 90 %
interval (Welch, Student t), which says how far 6 packings resolve that criterion. The same
boxes under the earlier contact geometry (the packer's clearance read as a film,
``validation/results/box_convergence_runs``, other packings) are set beside, with the cheap
RVE's change on the same packings (``validation/results/contact_film.json``).

Writes ``validation/results/box_study.md`` and ``box_study.json``.

Usage::

    python validation/box_study.py
"""

from __future__ import annotations

import glob
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "validation" / "results"
RUN1 = RESULTS / "device_issue47"
RUN2 = RESULTS / "device_issue47_run2" / "rows.json"
OLD = RESULTS / "box_convergence_runs"
OUT = RESULTS / "box_study.md"
OUT_JSON = RESULTS / "box_study.json"
BOXES_UM = (64, 80, 96)
CRITERION = 0.005


def box_rows(box: int) -> np.ndarray:
    path = RUN1 / f"box47__AlN-{box}um.rows.json"
    rows = json.loads(path.read_text()) if path.exists() else []
    return np.array([r["k_iso"] for r in sorted(rows, key=lambda r: r["replica"])])


def run2() -> dict[str, list[dict]]:
    return json.loads(RUN2.read_text()) if RUN2.exists() else {}


def welch(a: np.ndarray, b: np.ndarray) -> dict:
    """b / a - 1 with its Welch 90 % interval (relative, first order)."""
    from scipy import stats

    ma, mb = a.mean(), b.mean()
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    se = math.sqrt(va + vb)
    dof = (va + vb) ** 2 / (va ** 2 / (a.size - 1) + vb ** 2 / (b.size - 1))
    t = stats.t.ppf(0.95, dof)
    d = mb - ma
    return {"rel": d / ma, "lo": (d - t * se) / ma, "hi": (d + t * se) / ma,
            "p": float(2 * stats.t.sf(abs(d) / se, dof)), "dof": dof}


def old_boxes() -> dict[int, np.ndarray]:
    import pyarrow.parquet as pq

    out = {}
    for box in (64, 80):
        ks = []
        for d in (OLD / f"AlN-{box}um-0.25um", OLD / f"AlN-{box}um-0.25um-s3"):
            for f in glob.glob(str(d / "parts" / "*.parquet")):
                ks += [r["k_iso"] for r in pq.read_table(f).to_pylist()]
        out[box] = np.array(ks)
    return out


def voxel_order(rows: dict, group: str) -> list[dict]:
    """Per packing: k at 0.25, 0.2, 0.16 um and the order p of k(h) = k0 (1 - c h^p)
    through the three (solved for p by bisection on the ratio of the two differences)."""
    voxels = (0.25, 0.2, 0.16)
    per = {}
    for v in voxels:
        for r in rows.get(f"order47__{group}-40um-{v:g}um", []):
            per.setdefault(r["replica"], {})[v] = r["k_iso"]
    out = []
    for rep, ks in sorted(per.items()):
        if len(ks) < 3:
            continue
        k1, k2, k3 = (ks[v] for v in voxels)
        ratio = (k2 - k1) / (k3 - k2) if k3 != k2 else math.nan

        def g(p: float) -> float:
            return (voxels[0] ** p - voxels[1] ** p) / (voxels[1] ** p - voxels[2] ** p) - ratio

        p = math.nan
        if math.isfinite(ratio) and ratio > 0 and g(0.05) * g(6.0) < 0:
            lo, hi = 0.05, 6.0
            for _ in range(80):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if g(lo) * g(mid) > 0 else (lo, mid)
            p = 0.5 * (lo + hi)
        k0 = (k3 - (k2 - k3) * voxels[2] ** p / (voxels[1] ** p - voxels[2] ** p)
              if math.isfinite(p) else math.nan)
        out.append({"replica": rep, "k": [k1, k2, k3], "order": p, "k0": k0})
    return out


def pooled_order(fits: list[dict]) -> dict | None:
    """One order p for a system's packings: k_r(h) = a_r - b_r h^p, a_r and b_r per packing
    (linear least squares at each p), p minimising the summed squared residual over a grid
    of 0.2-6 (step 0.01); ``p_range``: the p whose residual is within a factor 2 of the
    least (with 2 packings x 3 voxels, one degree of freedom is left)."""
    voxels = np.array((0.25, 0.2, 0.16))
    if len(fits) < 2:
        return None
    grid = np.arange(0.2, 6.0001, 0.01)
    ssr = []
    for p in grid:
        X = np.column_stack([np.ones(3), -voxels ** p])
        ssr.append(sum(float(np.linalg.lstsq(X, np.array(f["k"]), rcond=None)[1].sum()
                             if len(np.linalg.lstsq(X, np.array(f["k"]), rcond=None)[1]) else 0.0)
                       for f in fits))
    ssr = np.array(ssr)
    i = int(np.argmin(ssr))
    ok = grid[ssr <= 2 * ssr[i] + 1e-30]
    X = np.column_stack([np.ones(3), -voxels ** grid[i]])
    k0 = [float(np.linalg.lstsq(X, np.array(f["k"]), rcond=None)[0][0]) for f in fits]
    bias = [1 - f["k"][0] / k for f, k in zip(fits, k0)]
    return {"order": float(grid[i]), "p_range": [float(ok.min()), float(ok.max())],
            "k0": k0, "bias_at_0.25um": bias}


def main() -> int:
    from itr_fv.io import write_text

    data: dict = {"boxes_um": list(BOXES_UM), "criterion": CRITERION}
    ks = {b: box_rows(b) for b in BOXES_UM}
    lines = ["# Box study of issue 47: AlN-60 with touching particles at the stated film", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "## k_iso against the box (AlN-60, 0.25 um, 6 packings per box)", "",
             "| box (um) | packings | k_iso per packing | mean | sd | standard error |",
             "|---|---|---|---|---|---|"]
    for b, k in ks.items():
        if k.size < 2:
            lines.append(f"| {b} | {k.size} | - | - | - | - |")
            continue
        lines.append(f"| {b} | {k.size} | {', '.join(f'{x:.4f}' for x in k)} | {k.mean():.4f} "
                     f"| {k.std(ddof=1):.4f} | {k.std(ddof=1) / math.sqrt(k.size):.4f} |")
    data["k_iso"] = {str(b): k.tolist() for b, k in ks.items()}
    lines += ["", "| step | change of the mean | 90 % interval (Welch) | p | within 0.5 %? |",
              "|---|---|---|---|---|"]
    steps = {}
    for a, b in zip(BOXES_UM, BOXES_UM[1:]):
        if ks[a].size < 2 or ks[b].size < 2:
            continue
        w = welch(ks[a], ks[b])
        steps[f"{a}->{b}"] = w
        lines.append(f"| {a} -> {b} um | {100 * w['rel']:+.2f} % | {100 * w['lo']:+.2f} to "
                     f"{100 * w['hi']:+.2f} % | {w['p']:.2f} | "
                     f"{'yes' if abs(w['rel']) <= CRITERION else 'no'} |")
    data["steps"] = steps
    conv = [a for a, b in zip(BOXES_UM, BOXES_UM[1:])
            if f"{a}->{b}" in steps and abs(steps[f"{a}->{b}"]["rel"]) <= CRITERION]
    data["converged_box_um"] = conv[0] if conv else None
    if conv:
        w = steps[f"{conv[0]}->{BOXES_UM[BOXES_UM.index(conv[0]) + 1]}"]
        lines += ["", f"By the criterion the AlN-60 box converges at {conv[0]} um; the 90 % "
                  f"interval of the next step ({100 * w['lo']:+.2f} to {100 * w['hi']:+.2f} %) "
                  "is what 6 packings resolve of it."]
    old = old_boxes()
    lines += ["", "## The contact geometry's share", "",
              "| box (um) | earlier geometry: packings, mean | stated film: mean | change |",
              "|---|---|---|---|"]
    data["earlier_geometry"] = {}
    for b, k in old.items():
        if k.size and ks.get(b, np.array([])).size:
            ch = ks[b].mean() / k.mean() - 1
            data["earlier_geometry"][str(b)] = {"k_iso": k.tolist(), "change": ch}
            lines.append(f"| {b} | {k.size}, {k.mean():.4f} | {ks[b].mean():.4f} | "
                         f"{100 * ch:+.1f} % |")
    lines += ["", "(Other packings in each column: the change holds the packing scatter, a "
              "standard error of about 0.5 %.) The earlier geometry read the packer's "
              "clearance as a silicone film; it grows with the particles, so with the box "
              "(`validation/results/contact_film.md`), and the earlier box study's "
              "64 -> 80 um step held it."]
    rows = run2()
    tail = {}
    for q in ("0.001", "1e-05"):
        tail[q] = [r["k_iso"] for r in rows.get(f"tail47__AlN-80um-q{q}", [])]
    data["tail_cut_80um"] = tail
    lines += ["", "## The tail cut at a fixed box (AlN-60, 80 um)", "",
              "| number quantile cut off each tail | packings | mean k_iso | against 1e-4 |",
              "|---|---|---|---|"]
    base = ks.get(80, np.array([]))
    for q, label in (("0.001", "1e-3"), ("1e-05", "1e-5")):
        k = np.array(tail[q])
        if k.size == 0:
            lines.append(f"| {label} | 0 | not run | - |")
            continue
        vs = (f"{100 * (k.mean() / base.mean() - 1):+.2f} %" if base.size else "-")
        lines.append(f"| {label} | {k.size} | {k.mean():.4f} | {vs} (other packings) |")
    if base.size:
        lines.append(f"| 1e-4 (the box study) | {base.size} | {base.mean():.4f} | - |")
    lines += ["", "## The voxel order per system (40 um, the same particles at 0.25, 0.2 and "
              "0.16 um)", "",
              "| system | packing | k_iso at 0.25 / 0.2 / 0.16 um | order p | k0 |",
              "|---|---|---|---|---|"]
    data["voxel_order"] = {}
    for group, label in (("AlN", "AlN-60"), ("hybrid", "Al2O3-30-AlN-30")):
        fits = voxel_order(rows, group)
        data["voxel_order"][label] = fits
        if not fits:
            lines.append(f"| {label} | - | not run | - | - |")
        for f in fits:
            lines.append(f"| {label} | {f['replica']} | "
                         f"{' / '.join(f'{x:.4f}' for x in f['k'])} | {f['order']:.2f} | "
                         f"{f['k0']:.4f} |")
    lines += ["", "An order from three voxels of one packing has no degree of freedom left "
              "(nan: increments not monotone in h). Pooled over the packings (one p, a level "
              "and a slope per packing; p_range: residual within twice its least):", "",
              "| system | pooled order p | p_range | bias of 0.25 um against h -> 0, per "
              "packing |", "|---|---|---|---|"]
    data["voxel_order_pooled"] = {}
    for label, fits in data["voxel_order"].items():
        pooled = pooled_order(fits)
        data["voxel_order_pooled"][label] = pooled
        if pooled is None:
            lines.append(f"| {label} | not run | - | - |")
            continue
        lines.append(f"| {label} | {pooled['order']:.2f} | {pooled['p_range'][0]:.2f} - "
                     f"{pooled['p_range'][1]:.2f} | "
                     f"{', '.join(f'{100 * b:.2f} %' for b in pooled['bias_at_0.25um'])} |")
    write_text(OUT, "\n".join(lines) + "\n")
    write_text(OUT_JSON, json.dumps(data, indent=1, default=float) + "\n")
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
