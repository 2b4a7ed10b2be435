"""``itr solve VOLUME`` verified (issue 63, part 1): every figure from an independent path.

(a) A labelled TIFF written by tifffile (as Fiji writes one: ImageJ spacing and resolution),
    not by the package's writer, solved by ``itr solve``; the tensor set against
    ``itr_fv.homogenize`` on the same labels through the Python API (same solver, same tol),
    particles from the generator's own sphere ids: (a1) separate spheres of two fillers,
    particles found by connected components; (a2) a dense packing of the paper's Al2O3 and
    AlN with contacts, particles given (``--particles``), per-area contact resistances.
(b) Sphere arrays as label images (BCC, SC, FCC; f = 0.4, the paper's silicone and Al2O3,
    R = 2e-7 m^2 K/W) against the multipole reference of the continuum problem
    (``itr_fv.analytic.sphere_array``), BCC at 64^3 and 128^3.
(c) Round trips: one label volume (the dense packing, uint16 labels) written in each format
    and read back; its tensor against the in-memory array's.
(d) Bad volumes: the one line each is refused with, before any work (no output folder).

Writes ``validation/results/image_solve.json``. About 1 min on 2 cores.

Usage::

    python validation/image_solve_study.py
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import tifffile

from itr_fv import (
    Materials,
    Microstructure,
    PhaseTable,
    analytic,
    homogenize,
    microstructure_from_image,
    read_volume,
    write_volume,
)
from itr_fv.rve import FillerSpec, build_rve
from itr_fv.rve.from_image import image_materials
from itr_fv.rve.spec import RVESpec
from itr_identify.cli import main

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "validation" / "results" / "image_solve.json"
K = {"silicone": 0.18, "Al2O3": 30.0, "AlN": 200.0}   # examples/paper/system.toml
R_FM = {("Al2O3", "silicone"): 2.2e-8, ("AlN", "silicone"): 1.5e-8}
R_FF = {("Al2O3", "Al2O3"): 2e-7, ("AlN", "AlN"): 1e-7, ("Al2O3", "AlN"): 1.5e-7}
TOL = 1e-10
FORMATS = (".tif", ".npy", ".npz", ".vti", ".vtk", ".raw")


def balls(n: int, centres, radius: float) -> np.ndarray:
    """Particle ids of periodic balls in voxel units (voxel centres at i + 1/2)."""
    g = np.indices((n, n, n)) + 0.5
    out = np.zeros((n, n, n), dtype=np.int32)
    for i, c in enumerate(centres):
        d = g - np.reshape(c, (3, 1, 1, 1))
        d -= n * np.round(d / n)
        out[(d * d).sum(axis=0) <= radius ** 2] = i + 1
    return out


def fiji_tiff(path: Path, labels: np.ndarray, voxel_um: float) -> None:
    tifffile.imwrite(path, labels, imagej=True, resolution=(1 / voxel_um, 1 / voxel_um),
                     metadata={"spacing": voxel_um, "unit": "um", "axes": "ZYX"})


def run_cli(args: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main(["solve", *map(str, args)])
    return status, out.getvalue(), err.getvalue()


def resistance_flags(pairs: dict) -> list[str]:
    return [x for (a, b), v in pairs.items() for x in ("--resistance", f"{a}-{b}={v}")]


def cli_against_api(work: Path, labels, pid, names, voxel_um, pairs, *, given: bool) -> dict:
    fiji_tiff(work / "scan.tif", labels.astype(np.uint8), voxel_um)
    args = [work / "scan.tif", *[x for i, p in enumerate(names)
                                 for x in ("--phase", f"{i}={p}")],
            *resistance_flags(pairs), "--tol", TOL, "--out", work / "out"]
    if given:
        np.save(work / "particles.npy", pid)
        args += ["--particles", work / "particles.npy"]
    t = time.perf_counter()
    status, _, err = run_cli(args)
    wall = time.perf_counter() - t
    assert status == 0, err
    res = json.loads((work / "out" / "result.json").read_text())
    ms = Microstructure.from_labels(labels.astype(np.int32), pid, voxel_um * 1e-6, names)
    mat = Materials({p: K[p] for p in names}, {p: v for p, v in pairs.items()
                                               if set(p) <= set(names)},
                    matrix=names[0], contact="area")
    api = homogenize(ms, mat, tol=TOL)
    cli = np.array(res["k_eff_W_per_mK"])
    return {"shape": list(labels.shape), "particles": res["particles"],
            "k_diag_W_per_mK": np.diag(cli).tolist(),
            "max_abs_difference": float(np.abs(cli - api.k_eff).max()),
            "iterations_cli": [c["iterations"] for c in res["load_cases"]],
            "iterations_api": api.iterations, "cli_wall_s": wall, "tol": TOL,
            "solver": res["solver"]["key"]}


def part_a(work: Path) -> dict:
    n = 40
    centres = [(8, 8, 8), (28, 10, 26), (0.5, 28, 14), (20, 32, 34), (32, 32, 6),
               (14, 20, 22), (6, 34, 34), (24, 4, 14)]
    pid = balls(n, centres, 5.5)
    phase = np.array([0, 1, 1, 2, 1, 2, 2, 1, 2], dtype=np.uint8)[pid]
    (work / "a1").mkdir()
    a1 = cli_against_api(work / "a1", phase, pid, ("silicone", "Al2O3", "AlN"), 0.25,
                         R_FM, given=False)
    rve = RVESpec(box_um=12.0, voxel_um=0.25, seed=1)
    ms, _ = build_rve(rve, [FillerSpec.from_table1("Al2O3", 0.35),
                            FillerSpec.from_table1("AlN", 0.2)], 0)
    (work / "a2").mkdir()
    a2 = cli_against_api(work / "a2", ms.material_ids, ms.particle_ids, ms.names, 0.25,
                         {**R_FM, **R_FF}, given=True)
    return {"a1_separate_spheres_connected_components": a1,
            "a2_dense_packing_given_particles": a2}, ms


def lattice(kind: str, n: int, f: float) -> tuple[np.ndarray, float]:
    """Label image of a cubic array in one cell of n^3 voxels, and the radius in voxels."""
    basis = {"sc": [(0, 0, 0)], "bcc": [(0, 0, 0), (0.5, 0.5, 0.5)],
             "fcc": [(0, 0, 0), (0.5, 0.5, 0), (0.5, 0, 0.5), (0, 0.5, 0.5)]}[kind]
    a = (3 * f / (4 * math.pi * len(basis))) ** (1 / 3) * n
    return (balls(n, [tuple(n * np.array(b)) for b in basis], a) > 0).astype(np.uint8), a


def part_b(work: Path) -> list[dict]:
    rows = []
    f, box_um, R = 0.4, 4.0, 2e-7
    for kind, n in (("bcc", 64), ("bcc", 128), ("sc", 64), ("fcc", 64)):
        labels, a_vox = lattice(kind, n, f)
        d = work / f"b_{kind}{n}"
        d.mkdir()
        fiji_tiff(d / "array.tif", labels, box_um / n)
        t = time.perf_counter()
        status, _, err = run_cli([d / "array.tif", "--phase", "0=matrix", "--phase",
                                  "1=Al2O3", "--resistance", f"Al2O3-matrix={R}",
                                  "--out", d / "out"])
        assert status == 0, err
        res = json.loads((d / "out" / "result.json").read_text())
        a_m = a_vox * box_um / n * 1e-6
        ref = K["silicone"] * analytic.sphere_array(kind, f, K["Al2O3"] / K["silicone"],
                                                    R * K["silicone"] / a_m)
        k = float(np.trace(np.array(res["k_eff_W_per_mK"])) / 3)
        rows.append({"lattice": kind, "n": n, "f": f, "voxel_fraction":
                     res["phase_fractions"]["Al2O3"], "radius_um": a_m * 1e6, "R_m2K_per_W": R,
                     "alpha": R * K["silicone"] / a_m, "k_image_W_per_mK": k,
                     "k_multipole_W_per_mK": ref, "difference_percent": 100 * (k - ref) / ref,
                     "wall_s": time.perf_counter() - t})
    return rows


def part_c(work: Path, ms: Microstructure) -> dict:
    """The dense packing's phases as uint16 labels 0, 10, 20 in every format; particles by
    connected components and per-area contacts."""
    labels = (10 * ms.material_ids).astype(np.uint16)
    table = PhaseTable.of({0: "matrix", 10: "Al2O3", 20: "AlN"}, "silicone")

    def tensor(vol) -> np.ndarray:
        img = microstructure_from_image(vol, table)
        return homogenize(img, image_materials(img, K, {**R_FM, **R_FF}), tol=TOL).k_eff

    reference = tensor(read_volume(_write(work / "ref.npy", labels), voxel_um=0.25))
    out = {}
    for suffix in FORMATS:
        path = write_volume(work / f"c{suffix}", labels, voxel_um=0.25)
        vol = read_volume(path, voxel_um=0.25 if suffix == ".npy" else None)
        assert np.array_equal(vol.labels, labels)
        out[suffix] = {"labels_identical": True, "voxel_um": vol.voxel_um,
                       "voxel_source": vol.voxel_source,
                       "max_abs_difference": float(np.abs(tensor(vol) - reference).max())}
    return {"shape": list(labels.shape), "k_diag_W_per_mK": np.diag(reference).tolist(),
            "formats": out}


def _write(path: Path, labels: np.ndarray) -> Path:
    np.save(path, labels)
    return path


def part_d(work: Path) -> list[dict]:
    good = (balls(12, [(6, 6, 6)], 3.0) > 0).astype(np.uint8)
    np.save(work / "float.npy", good.astype(np.float32))
    np.save(work / "flat.npy", good[0])
    np.save(work / "label3.npy", good * 3)
    np.save(work / "good.npy", good)
    (work / "empty.tif").write_bytes(b"")
    (work / "scan.png").write_bytes(b"\x89PNG\r\n")
    tifffile.imwrite(work / "aniso.tif", good, imagej=True, resolution=(4.0, 4.0),
                     metadata={"spacing": 0.5, "unit": "um"})
    fiji_tiff(work / "h25.tif", good, 0.25)
    base = ["--phase", "0=matrix", "--phase", "1=Al2O3", "--resistance", "Al2O3-matrix=1e-8"]
    cases = [("float label image", "float.npy", ["--voxel-um", "0.5"]),
             ("not 3-D", "flat.npy", ["--voxel-um", "0.5"]),
             ("label not in the phase table", "label3.npy", ["--voxel-um", "0.5"]),
             ("empty phase (a label without voxels)", "good.npy",
              ["--voxel-um", "0.5", *base, "--phase", "2=AlN"]),
             ("non-cubic voxel", "aniso.tif", []),
             ("voxel given against the file's", "h25.tif", ["--voxel-um", "0.3"]),
             ("no voxel size", "good.npy", []),
             ("empty file", "empty.tif", []),
             ("unknown extension", "scan.png", []),
             ("missing file", "missing.tif", []),
             ("no resistance for a pair the image has", "good.npy",
              ["--voxel-um", "0.5", *base[:4]])]
    rows = []
    for what, name, extra in cases:
        args = [work / name, *([] if "--phase" in extra else base), *extra,
                "--out", work / "refused"]
        status, out, err = run_cli(args)
        rows.append({"case": what, "status": status,
                     "stderr": err.strip().replace(str(work), "WORK"),
                     "lines": len(err.splitlines()), "stdout_empty": out == "",
                     "folder_made": (work / "refused").exists()})
    return rows


def main_study() -> int:
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        a, ms = part_a(work)
        print("(a) itr solve on a tifffile TIFF vs itr_fv.homogenize on the same labels:")
        for k, v in a.items():
            print(f"  {k}: {v['shape']}, {v['particles']} particles, max |dk| "
                  f"{v['max_abs_difference']:.2e} W/(m K), iterations {v['iterations_cli']} "
                  f"vs {v['iterations_api']}")
        b = part_b(work)
        print("(b) sphere arrays as images vs the multipole reference:")
        for r in b:
            print(f"  {r['lattice']} {r['n']}^3: k {r['k_image_W_per_mK']:.4f} vs "
                  f"{r['k_multipole_W_per_mK']:.4f} W/(m K), {r['difference_percent']:+.2f} %")
        c = part_c(work, ms)
        print("(c) round trips (max |dk| against the in-memory array, W/(m K)):")
        for s, r in c["formats"].items():
            print(f"  {s}: {r['max_abs_difference']:.1e} ({r['voxel_source']})")
        d = part_d(work)
        print("(d) refusals:")
        for r in d:
            print(f"  {r['case']}: status {r['status']}, {r['lines']} line, folder "
                  f"{'made' if r['folder_made'] else 'not made'}: {r['stderr']}")
    from itr_fv.run_folder import versions
    result = {"issue": 63, "api_vs_cli": a, "sphere_arrays": b, "round_trips": c,
              "refusals": d, "wall_s": time.perf_counter() - t0, "versions": versions()}
    OUT.parent.mkdir(parents=True, exist_ok=True)
    tmp_path = OUT.with_name(OUT.name + ".tmp")
    tmp_path.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    tmp_path.replace(OUT)
    print(f"wrote {OUT.relative_to(ROOT)} ({result['wall_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main_study())
