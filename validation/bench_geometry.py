"""Benchmark of the face geometry build (gap contact model, staircase law): before and after
the numba kernels.

"Before" is the NumPy build the kernels replaced, as frozen in the test suite
(``reference_face_geometry`` of ``tests/test_geometry_build.py``, imported from there: the
thin-film fill, the per-axis scan with ``np.roll``, staircase factors, films and contact
pairs, and the contact-zone segments). "After" is
:func:`itr_fv.discrete.face_geometry.face_geometry` on 1 thread and on ``--threads`` threads.
Every "after" geometry is checked against "before" (every array the same; see the test).

Cases: AlN-60 (Table 1's AlN at 60 %, voxel 0.125 um, box n * 0.125 um, seed 1) and
``al2o3_60`` of the common RVE set (``validation.gallery``), both at n^3 for every
``--sizes`` entry. Times are the best of ``--repeat`` runs after one warm-up build; the
kernels' compile time from an empty numba cache is measured apart, in a fresh process.
Writes ``validation/results/bench_geometry.md``.

Usage::

    python validation/bench_geometry.py [--sizes 128,192] [--threads N] [--repeat 2]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from itr_fv.discrete import _geometry_kernels as K  # noqa: E402
from itr_fv.discrete.face_geometry import face_geometry  # noqa: E402
from tests.test_geometry_build import assert_same_geometry, reference_face_geometry  # noqa: E402
from validation.gallery import build  # noqa: E402

OUT = ROOT / "validation" / "results" / "bench_geometry.md"


def aln_60(n: int):
    """AlN-60 in an n * 0.125 um box at 0.125 um (n^3 voxels)."""
    from itr_fv.rve import FillerSpec, build_rve
    from itr_fv.rve.spec import RVESpec

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the box cuts AlN's coarse tail (said in the report)
        ms, _ = build_rve(RVESpec(box_um=n * 0.125, voxel_um=0.125, seed=1),
                          [FillerSpec.from_table1("AlN", 0.6)], 0, matrix="silicone")
    return ms


def cold_compile_s() -> float:
    """Seconds of the first build (32^3 AlN-60) in a fresh process with an empty numba
    cache: what a CI run pays to compile the kernels (less the process start and imports)."""
    code = ("import time, warnings; warnings.simplefilter('ignore');"
            "from validation.bench_geometry import aln_60;"
            "from itr_fv.discrete.face_geometry import face_geometry;"
            "ms = aln_60(32); t = time.perf_counter(); face_geometry(ms, workers=1);"
            "print(time.perf_counter() - t)")
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, check=True,
                             capture_output=True, text=True)
    return float(out.stdout.split()[-1])


def best_of(fn, repeat: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="128,192", help="grid sizes n (n^3 voxels)")
    ap.add_argument("--threads", type=int, default=K.threads_for(10 ** 9),
                    help="threads of the 'after' build (default: the package's default)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args()
    sizes = [int(v) for v in args.sizes.split(",")]

    cold = cold_compile_s()
    print(f"kernels compiled from an empty cache: {cold:.2f} s", flush=True)
    face_geometry(aln_60(32), contact="gap", workers=1)  # warm-up: load the cached kernels

    rows = []
    for name, make in (("AlN-60", aln_60),
                       ("al2o3_60", lambda n: build("al2o3_60", n, contact="gap")[0])):
        for n in sizes:
            ms = make(n)
            before, ref = best_of(lambda: reference_face_geometry(ms), args.repeat)
            one, _ = best_of(lambda: face_geometry(ms, contact="gap", workers=1), args.repeat)
            many, geom = best_of(lambda: face_geometry(ms, contact="gap", workers=args.threads),
                                 args.repeat)
            assert_same_geometry(geom, ref)
            row = dict(case=name, n=n, particles=ms.n_particles, faces=geom.n_interface_faces,
                       segments=sum(len(s[0]) for s in geom.segments), before=before, one=one,
                       many=many)
            rows.append(row)
            print(f"{name} {n}^3: {row['particles']} particles, {row['faces']} faces; "
                  f"before {before:.2f} s, after {one:.3f} s (1 thread), {many:.3f} s "
                  f"({args.threads} threads); arrays equal", flush=True)

    lines = [
        "# Face geometry build: before and after the numba kernels",
        "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores (shared with other jobs: "
        "times scatter by 10-20 %), Python "
        f"{platform.python_version()}, numpy {np.__version__}; 'after' on 1 and "
        f"{args.threads} threads (``face_geometry(..., workers=)``). Best of {args.repeat} "
        f"runs, after a warm-up build. Compiling the kernels from an empty numba cache (first "
        f"build of a 32^3 AlN-60 in a fresh process): {cold:.2f} s; from the cache: well "
        f"under 0.1 s.",
        "",
        "Before: the NumPy build as frozen in ``tests/test_geometry_build.py`` "
        "(``reference_face_geometry``, imported from there). Every 'after' geometry was "
        "checked equal to it (indices, material ids, contact flags, staircase factors, films, "
        "pairs, pair gaps and face counts, segments, filled voxels).",
        "",
        f"| case | grid | particles | interface faces | zone segments | before s | "
        f"after s (1 thread) | after s ({args.threads} threads) | speed-up |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['case']} | {r['n']}^3 | {r['particles']} | {r['faces']} | "
                     f"{r['segments']} | {r['before']:.2f} | {r['one']:.3f} | {r['many']:.3f} "
                     f"| {r['before'] / r['many']:.1f}x |")
    lines += [
        "",
        "Cases: AlN-60 = Table 1's AlN at 60 %, voxel 0.125 um, box n x 0.125 um, seed 1 "
        "(the box cuts AlN's coarse tail: the generator warns); al2o3_60 = the common RVE "
        "set's dense 60 % Al2O3 (16 um box). Geometry only (``face_geometry(ms, "
        "contact='gap')``): the class arrays and conductances are not timed here.",
        "",
    ]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines), encoding="utf-8")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
