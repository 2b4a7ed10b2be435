"""Truth of a synthetic second material system (ZnO in epoxy) and its measurement table.

What
----
The effective conductivity of three ZnO-in-epoxy formulations, solved at a higher fidelity
than any identification will use (a converged 20 um box, voxels of 0.125 and 0.1 um on the
same particles, the voxel bias Richardson-extrapolated away with the gap model's order
:data:`itr_identify.forward.fidelity.BIAS_ORDER`, two packings per formulation), from
chosen true inputs (the module constants below), and from it a table of synthetic
measurements: two replicates per formulation with 2 % relative noise.

Why
---
A second system, with another matrix, filler, size distribution and resistance than the
paper's, tests that the identification recovers a known resistance outside the system it
was built on. The truth is solved once, here, at a fidelity the identification never uses,
so that its result does not share the identification's discretisation error.

How
---
Each voxel edge is one campaign of the campaign engine (:mod:`itr_surrogate.campaign`;
3 formulations x 2 packings, one task each) under
``validation/results/second_system_truth_runs/<voxel>um/``; a re-run resumes (a finished
task is never solved again; a killed run loses at most the task in flight). Both campaigns
pack with the 0.1 um voxel's fine-tail cut (``cut_voxel_um``) and the same seeds, so the
two voxels see the same particles (checked when the truth is assembled). Per packing,
``k_iso`` (trace / 3) at both voxels is extrapolated by
:func:`itr_identify.forward.fidelity.richardson` (ratio 0.125 / 0.1); the truth of a
formulation is the mean over its packings.

Writes ``examples/zno_epoxy/truth.json`` (inputs, per-packing values, truth, fidelity) and
``examples/zno_epoxy/measurements.csv`` (``formulation,replicate,k_W_per_mK``), each
atomically. Both are synthetic: no specimen was measured.

Usage::

    python validation/second_system_truth.py [--workers 0]
    python validation/second_system_truth.py --report-only   # outputs from finished runs
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "validation" / "results" / "second_system_truth_runs"
OUT_DIR = ROOT / "examples" / "zno_epoxy"
TRUTH_JSON = OUT_DIR / "truth.json"
MEASUREMENTS_CSV = OUT_DIR / "measurements.csv"

# ---------------------------------------------------------------------- the truth
#: Matrix phase name (phase names hold no underscore).
MATRIX = "epoxy"
#: Filler phase name.
FILLER = "ZnO"
#: Volume-weighted lognormal of ln(D / 1 um) of the ZnO diameters: median 2.6 um (what a
#: laser diffractometer reports), and its shape sigma.
MU_VOLUME = math.log(2.6)
SIGMA = 0.377
#: The number-weighted lognormal the campaign packs from (its ``psd`` key): the same sigma,
#: the median exp(mu_v - 3 sigma^2) (about 1.70 um).
MU_NUMBER = MU_VOLUME - 3.0 * SIGMA ** 2
#: True bulk conductivities, W/(m K).
K_TRUE = {f"k_{MATRIX}": 0.21, f"k_{FILLER}": 45.0}
#: True filler-matrix interface resistance, m^2 K/W (the flat name: phase names sorted).
R_TRUE = {"R_" + "_".join(sorted((FILLER, MATRIX))): 2.0e-8}
#: Contact model and the film touching particles meet at, um (the stated-film contacts of
#: the ``nominal`` truth of ``validation/input_truths.py``: touching at no film).
CONTACT = "gap"
FILM_UM = 0.0
#: Bulk densities, g/cm^3 (for the mass-fraction formulation).
DENSITY_G_PER_CM3 = {FILLER: 5.61, MATRIX: 1.15}


def volume_fraction_of_mass(w: float) -> float:
    """ZnO volume fraction of a ZnO mass fraction ``w`` in epoxy (the densities above)."""
    vf = w / DENSITY_G_PER_CM3[FILLER]
    vm = (1.0 - w) / DENSITY_G_PER_CM3[MATRIX]
    return vf / (vf + vm)


#: Formulations: name -> ZnO volume fraction (``ZnO-80wt``: 80 wt% ZnO, about 0.4505).
FORMULATIONS = {"ZnO-35": 0.35, "ZnO-80wt": volume_fraction_of_mass(0.80), "ZnO-55": 0.55}

# ------------------------------------------------------------------- the fidelity
#: RVE box edge, um (converged for particles of a 2.6 um volume median).
BOX_UM = 20.0
#: Voxel edges, um (coarse, fine), on the same particles: both pack with the fine voxel's
#: fine-tail cut (:data:`CUT_VOXEL_UM`).
VOXELS_UM = (0.125, 0.1)
CUT_VOXEL_UM = 0.1
#: Packing seed of replica 0 and the packings per formulation (replica r packs with
#: SEED + r: 851 and 852).
SEED = 851
PACKINGS = 2
#: Solver (the package default, the numba FFT-PCG) and the relative residual of every solve.
SOLVER = "fft"
TOL = 1e-8
#: Solver threads in the process (or each Dask worker).
THREADS = 2

# ------------------------------------------------------------------- measurements
#: Replicates per formulation, their relative noise sd and the noise's seed.
REPLICATES = 2
NOISE_REL_SD = 0.02
NOISE_SEED = 2026
SYNTHETIC_NOTE = ("synthetic: computed from the stated true inputs by "
                  "validation/second_system_truth.py; no specimen was measured")


# ------------------------------------------------------------------------ campaigns
def truth_campaign(voxel_um: float):
    """The campaign at one voxel edge (um): every formulation, :data:`PACKINGS` packings."""
    from itr_surrogate.campaign import Campaign

    forms = [{"name": name, "fractions": {FILLER: vf}, "psd": {FILLER: [MU_NUMBER, SIGMA]}}
             for name, vf in FORMULATIONS.items()]
    return Campaign.from_dict({
        "name": f"zno-epoxy-truth-{voxel_um:g}um", "box_um": BOX_UM, "voxel_um": voxel_um,
        "cut_voxel_um": CUT_VOXEL_UM, "replicas": PACKINGS, "seed": SEED,
        "contact": CONTACT, "film_um": FILM_UM, "solver": SOLVER, "tol": TOL,
        "threads_per_worker": THREADS, "block_size": 1, "matrix": MATRIX,
        "base": dict(K_TRUE), "formulation": forms,
        "design": {"kind": "grid", "values": {k: [v] for k, v in R_TRUE.items()}}})


def folder(voxel_um: float) -> Path:
    return RUNS / f"{voxel_um:g}um"


def run(workers: int) -> None:
    """Run (or resume) both campaigns, the coarse voxel first; each checked for memory and
    its plan printed before it starts."""
    from itr_surrogate.runner import run_campaign
    from itr_surrogate.workload import campaign_workload

    for v in VOXELS_UM:
        camp = truth_campaign(v)
        load = campaign_workload(camp, workers=workers)
        print(load.summary(), flush=True)
        load.check()
        t = time.perf_counter()
        run_campaign(camp, folder(v), workers=workers, progress=False,
                     echo=lambda line: print(line, flush=True))
        print(f"{v:g} um: {time.perf_counter() - t:.0f} s", flush=True)


# -------------------------------------------------------------------------- results
def _rows(voxel_um: float) -> dict[tuple[str, int], dict]:
    """(formulation, replica) -> the finished row of the campaign at ``voxel_um``."""
    from itr_surrogate.store import CampaignStore

    store = CampaignStore(folder(voxel_um))
    if not store.campaign_file.is_file() or not store.done_tasks():
        return {}
    if store.failures():
        print(f"{voxel_um:g} um: failed tasks {store.failures()}", flush=True)
    return {(r["formulation"], int(r["replica"])): r for r in store.results().to_pylist()}


def _same_particles(coarse: dict, fine: dict) -> bool:
    """Whether two rows' RVEs hold the same particles (centres and radii)."""
    from itr_surrogate.store import CampaignStore

    a, _ = CampaignStore(folder(VOXELS_UM[0])).read_rve(coarse["rve_id"])
    b, _ = CampaignStore(folder(VOXELS_UM[1])).read_rve(fine["rve_id"])
    if a.num_rows != b.num_rows:
        return False
    return all(np.allclose(np.asarray(a[c]), np.asarray(b[c]), rtol=0, atol=1e-15)
               for c in ("x_m", "y_m", "z_m", "radius_m"))


def assemble() -> dict:
    """The truth from the finished campaigns (ValueError if a solve is missing)."""
    sys.path.insert(0, str(ROOT))
    from itr_identify.forward.fidelity import BIAS_ORDER, richardson

    coarse_v, fine_v = VOXELS_UM
    ratio = coarse_v / fine_v
    by_voxel = {v: _rows(v) for v in VOXELS_UM}
    forms = {}
    for name, vf in FORMULATIONS.items():
        packings = []
        for r in range(PACKINGS):
            missing = [f"{v:g} um" for v in VOXELS_UM if (name, r) not in by_voxel[v]]
            if missing:
                raise ValueError(f"{name} packing {r}: not solved at {', '.join(missing)}")
            c, f = by_voxel[coarse_v][(name, r)], by_voxel[fine_v][(name, r)]
            if c["seed"] != f["seed"] or not _same_particles(c, f):
                raise ValueError(f"{name} packing {r}: the two voxels hold other particles")
            k0 = float(richardson(np.array([f["k_iso"]]), np.array([c["k_iso"]]), ratio,
                                  BIAS_ORDER)[0])
            packings.append({
                "replica": r, "seed": int(f["seed"]),
                "k_iso": {f"{coarse_v:g}um": c["k_iso"], f"{fine_v:g}um": f["k_iso"]},
                "k_diagonal": {f"{v:g}um": [row[f"k_{a}{a}"] for a in "xyz"]
                               for v, row in ((coarse_v, c), (fine_v, f))},
                "k_extrapolated": k0,
                "voxel_bias_fine": (f["k_iso"] - k0) / k0,
                "voxel_bias_coarse": (c["k_iso"] - k0) / k0,
                "iterations": {f"{coarse_v:g}um": int(c["iterations"]),
                               f"{fine_v:g}um": int(f["iterations"])},
                "residual": {f"{coarse_v:g}um": c["residual"], f"{fine_v:g}um": f["residual"]},
                "wall_s": {f"{coarse_v:g}um": c["wall_s"], f"{fine_v:g}um": f["wall_s"]}})
        k0 = np.array([p["k_extrapolated"] for p in packings])
        truth = float(k0.mean())
        sd = float(k0.std(ddof=1)) if len(k0) > 1 else float("nan")
        forms[name] = {
            "volume_fraction": vf,
            "mass_fraction": vf * DENSITY_G_PER_CM3[FILLER]
            / (vf * DENSITY_G_PER_CM3[FILLER] + (1 - vf) * DENSITY_G_PER_CM3[MATRIX]),
            "k_truth": truth,
            "packings": packings,
            "k_iso_mean": {f"{v:g}um": float(np.mean([p["k_iso"][f"{v:g}um"]
                                                      for p in packings])) for v in VOXELS_UM},
            "voxel_bias_fine": float(np.mean([p["voxel_bias_fine"] for p in packings])),
            "voxel_bias_coarse": float(np.mean([p["voxel_bias_coarse"] for p in packings])),
            "packing_sd_rel": sd / truth,
            "packing_se_rel": sd / truth / math.sqrt(len(k0))}
    return {
        "system": "ZnO in epoxy (synthetic second material system)",
        "note": SYNTHETIC_NOTE,
        "date": _dt.date.today().isoformat(),
        "inputs": {
            "matrix": MATRIX, "fillers": [FILLER],
            "psd": {FILLER: {
                "volume_weighted": {"mu": MU_VOLUME, "sigma": SIGMA,
                                    "median_um": math.exp(MU_VOLUME)},
                "number_weighted": {"mu": MU_NUMBER, "sigma": SIGMA,
                                    "median_um": math.exp(MU_NUMBER)},
                "of": "ln(D / 1 um)"}},
            "conductivities_W_per_mK": dict(K_TRUE),
            "resistances_m2K_per_W": dict(R_TRUE),
            "contact": CONTACT, "film_um": FILM_UM,
            "density_g_per_cm3": dict(DENSITY_G_PER_CM3),
            "formulations": dict(FORMULATIONS)},
        "fidelity": {
            "box_um": BOX_UM, "voxels_um": list(VOXELS_UM), "cut_voxel_um": CUT_VOXEL_UM,
            "packings": PACKINGS, "seeds": [SEED + r for r in range(PACKINGS)],
            "solver": SOLVER, "tol": TOL, "extrapolation": "richardson",
            "ratio": ratio, "bias_order": BIAS_ORDER,
            "k": "k_iso = trace / 3; truth = mean over packings of the extrapolated k_iso",
            "campaigns": {f"{v:g}um": str(folder(v).relative_to(ROOT)) for v in VOXELS_UM},
            "fingerprints": {f"{v:g}um": truth_campaign(v).fingerprint()
                             for v in VOXELS_UM}},
        "measurements": {"file": "measurements.csv", "replicates": REPLICATES,
                         "relative_sd": NOISE_REL_SD, "rng": "numpy default_rng",
                         "seed": NOISE_SEED,
                         "model": "truth k * (1 + relative_sd * z), z standard normal"},
        "formulations": forms}


def measurements(truth: dict) -> list[tuple[str, int, float]]:
    """(formulation, replicate, value) rows: the truth times (1 + 0.02 z), z from
    ``default_rng(2026)`` drawn formulation by formulation in :data:`FORMULATIONS` order."""
    rng = np.random.default_rng(NOISE_SEED)
    out = []
    for name in FORMULATIONS:
        z = rng.standard_normal(REPLICATES)
        k = truth["formulations"][name]["k_truth"]
        out += [(name, i + 1, float(k * (1.0 + NOISE_REL_SD * zi))) for i, zi in enumerate(z)]
    return out


def _sig4(x: float) -> str:
    """``x`` with 4 significant digits (trailing zeros kept)."""
    return np.format_float_positional(x, precision=4, unique=False, fractional=False,
                                      trim="k")


def _write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to a temporary file beside ``path``, then move it there."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(text)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp's 0600 would outlive the move
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_outputs() -> dict:
    truth = assemble()
    rows = measurements(truth)
    _write_atomic(TRUTH_JSON, json.dumps(truth, indent=1) + "\n")
    _write_atomic(MEASUREMENTS_CSV, "formulation,replicate,k_W_per_mK\n"
                  + "".join(f"{f},{i},{_sig4(v)}\n" for f, i, v in rows))
    for name, d in truth["formulations"].items():
        vals = ", ".join(f"{d['packings'][p]['k_extrapolated']:.4f}"
                         for p in range(PACKINGS))
        print(f"{name}: phi {d['volume_fraction']:.4f}, k_truth {d['k_truth']:.4f} W/(m K) "
              f"(packings {vals}; voxel bias at {VOXELS_UM[1]:g} um "
              f"{100 * d['voxel_bias_fine']:+.2f} %, packing sd "
              f"{100 * d['packing_sd_rel']:.2f} %)", flush=True)
    for f, i, v in rows:
        print(f"measured {f} #{i}: {_sig4(v)}", flush=True)
    print(f"wrote {TRUTH_JSON.relative_to(ROOT)} and {MEASUREMENTS_CSV.relative_to(ROOT)}",
          flush=True)
    return truth


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=0,
                    help="0: solve in this process (default); N: a local Dask cluster")
    ap.add_argument("--report-only", action="store_true",
                    help="solve nothing; write the outputs from the finished campaigns")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    t = time.perf_counter()
    if not args.report_only:
        run(args.workers)
    write_outputs()
    print(f"total {time.perf_counter() - t:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
