"""Packing and geometry building answer signals at once and report their progress.

The packer runs its sweeps in slices (returns to Python every few tens of milliseconds),
the face geometry kernels in calls of bounded work: a SIGTERM handler that raises
``SystemExit`` (as the ``itr`` command installs) or Ctrl-C stops them within the 2 s the
issue asks for. The slicing must not change a bit of the results: the reference numbers
below were computed by the packer before it was sliced (one numba call for the whole
packing), on x86-64 Linux with numpy 2.4 / numba 0.68 (the packer's bits are those of the
platform and library versions, see :func:`itr_fv.rve.generate_rve`).
"""

import hashlib
import itertools
import os
import signal
import subprocess
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from itr_fv.discrete import _geometry_kernels as K
from itr_fv.discrete import cut_cells
from itr_fv.discrete.face_geometry import face_geometry
from itr_fv.rve import FillerSpec, RVESpec, generate_rve
from itr_fv.rve import generate as gen
from itr_fv.rve import microstructure as micro
from itr_fv.rve import packing as P
from itr_fv.rve.packing import pack_spheres, pairs_within_gap, progress_fraction

#: The signal deadline of the issue, s.
DEADLINE_S = 2.0

BIN = Path(sys.executable).parent

# ------------------------------------------------------------------------- bit identity
#: name -> (sum of centres, sha256 of centres.tobytes(), sweeps, list builds, largest
#: relative overlap, converged), from the unsliced packer.
REFERENCE = {
    "mono": (6338.721605059291,
             "d6b7c44fd14e8bacfc05044fd539b8691dc304f000cee5f3cde6141480e6750b", 489, 17,
             0.0004993922263071696, True),
    "poly": (12182.408969075703,
             "83e896487ceaca04b3498a089d1856a8af4f72746a7a81a8c8b01a4b24f5a6bc", 5517, 45,
             0.0004986320839787702, True),
    "poly_gap": (12708.36356740225,
                 "07638c7b9ee7e88a615f2512a01fb1b4d2dc92d1d7a3c9f8b1f9a99cb43388ca", 4371, 45,
                 0.0004986683705427363, True),
    "poly_cut": (12590.277909048673,
                 "33c0a1ee399f189bcbbe71a68a0c9ba7bb7e56c7f8a77465ebfa3919c5ec796b", 300, 12,
                 0.011482758414700643, False),
}
#: Pairs of the packed "poly" case within a gap of 0.3: count and sha256 of i, j, g.
REFERENCE_PAIRS = (1830, "8ecd01dd9d3b2d9c29766f980a237d937b67361af2e0c56c0b1e75526a9e5ce0")

POLY_RADII = np.random.default_rng(3).uniform(0.5, 1.5, 500)  # phi 0.58 in a 16.5 box


def case(name: str) -> dict:
    """Arguments of :func:`pack_spheres` of a reference case."""
    if name == "mono":
        return {"radii": np.full(300, 1.0), "box": 14.0, "rng": np.random.default_rng(1)}
    kw = {"radii": POLY_RADII, "box": 16.5, "rng": np.random.default_rng(2)}
    if name == "poly_gap":
        kw.update(rng=np.random.default_rng(5), min_gap=0.01)
    elif name == "poly_cut":
        kw.update(max_iter=300)
    return kw


def summary(res) -> tuple:
    c = res.centers
    return (float(c.sum()), hashlib.sha256(c.tobytes()).hexdigest(), res.iterations,
            res.neighbour_builds, res.max_rel_overlap, res.converged)


@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_sliced_packing_is_bit_identical_to_the_unsliced_one(name):
    assert summary(pack_spheres(**case(name))) == REFERENCE[name]


@pytest.mark.parametrize("name", ["poly", "poly_cut"])
def test_the_slice_size_does_not_change_a_bit(name, monkeypatch):
    monkeypatch.setattr(P, "SLICE_WORK", 1)  # one sweep a call
    monkeypatch.setattr(P, "SEARCH_WORK", 1)  # one particle a call of the pair search
    assert summary(pack_spheres(**case(name))) == REFERENCE[name]


@pytest.mark.parametrize("search_work", [1, 100, P.SEARCH_WORK])
def test_pairs_within_gap_are_those_of_the_unsliced_search(search_work, monkeypatch):
    centres = pack_spheres(**case("poly")).centers
    monkeypatch.setattr(P, "SEARCH_WORK", search_work)
    i, j, g = pairs_within_gap(centres, POLY_RADII, 16.5, 0.3)
    digest = hashlib.sha256(i.tobytes() + j.tobytes() + g.tobytes()).hexdigest()
    assert (i.size, digest) == REFERENCE_PAIRS


def test_a_pair_list_that_outgrows_its_arrays_is_complete(monkeypatch):
    rng = np.random.default_rng(0)
    centres = rng.uniform(0.0, 20.0, (400, 3))
    radii = np.full(400, 0.5)
    monkeypatch.setattr(P, "SEARCH_WORK", 50)
    i, j, g = pairs_within_gap(centres, radii, 20.0, 4.0)  # ~16 pairs a sphere: over 8 n + 16
    d = centres[:, None, :] - centres[None, :, :]
    d -= 20.0 * np.round(d / 20.0)
    gaps = np.sqrt((d ** 2).sum(axis=-1)) - 1.0
    ii, jj = np.nonzero(np.triu(gaps < 4.0, k=1))
    assert i.size > 8 * 400 + 16
    assert sorted(zip(i.tolist(), j.tolist())) == sorted(zip(ii.tolist(), jj.tolist()))
    np.testing.assert_allclose(g, gaps[i, j], rtol=0, atol=1e-12)


# ------------------------------------------------------------------------- progress
def test_progress_rises_to_one():
    seen: list[float] = []
    res = pack_spheres(**case("poly"), progress=seen.append)
    assert res.converged
    assert len(seen) >= 3
    assert all(0.0 <= f <= 1.0 for f in seen)
    assert all(a <= b for a, b in itertools.pairwise(seen))
    assert seen[-1] == 1.0
    assert seen[0] < P.GROWTH_SHARE  # it reports during the growth, not only at the end


def test_no_progress_one_without_convergence():
    seen: list[float] = []
    res = pack_spheres(**case("poly_cut"), progress=seen.append)
    assert not res.converged and seen and max(seen) < 1.0


def test_progress_fraction_covers_both_phases():
    args = {"s_start": 0.5, "s_end": 1.001, "grow_tol": 0.02, "tol_final": 5e-4}
    assert progress_fraction(0.5, 0.0, **args) == 0.0
    half = progress_fraction(0.5 * (1 + 1.001), 0.01, **args)
    assert 0.0 < half < P.GROWTH_SHARE
    assert progress_fraction(1.001, 0.05, **args) == P.GROWTH_SHARE
    assert P.GROWTH_SHARE < progress_fraction(1.001, 3e-3, **args) < 1.0
    assert progress_fraction(1.001, 4e-4, **args) == 1.0
    assert progress_fraction(1.001, 0.01, s_start=1.001, s_end=1.001, grow_tol=0.02,
                             tol_final=5e-4) > P.GROWTH_SHARE  # no growth phase at all


def test_voxelization_in_slabs_reports_its_progress(monkeypatch):
    c = np.random.default_rng(0).uniform(0, 8e-6, (30, 3))
    args = (c, np.full(30, 0.6e-6), ["Al2O3", "AlN"] * 15)
    plain = micro.Microstructure.from_spheres(*args, box_m=8e-6, shape=32)
    seen: list[float] = []
    monkeypatch.setattr(micro, "SLAB_VOXELS", 100)  # slabs of three rows
    ms = micro.Microstructure.from_spheres(*args, box_m=8e-6, shape=32, progress=seen.append)
    assert np.array_equal(ms.particle_ids, plain.particle_ids)
    assert np.array_equal(ms.material_ids, plain.material_ids)
    assert ms.volume_fractions() == plain.volume_fractions()
    assert seen[0] == 0.0 and seen[-1] == 1.0
    assert all(a <= b for a, b in itertools.pairwise(seen))


@pytest.mark.parametrize("minlength", [0, 3, 50])
def test_label_counts_are_those_of_bincount(minlength, monkeypatch):
    labels = np.random.default_rng(1).integers(0, 40, (6, 5, 7)).astype(np.int32)
    monkeypatch.setattr(micro, "SLAB_VOXELS", 9)
    assert np.array_equal(micro.label_counts(labels, minlength),
                          np.bincount(labels.ravel(), minlength=minlength))
    assert np.array_equal(micro.label_counts(labels[:0], minlength), np.zeros(minlength))


def test_generate_rve_bars_are_quiet_when_fast_and_can_be_switched_off(capsys):
    spec = FillerSpec.from_table1("Al2O3", 0.4)
    with pytest.warns(UserWarning, match="box limits diameters"):
        a = generate_rve(RVESpec(12, 0.5, max_diameter_box_ratio=1 / 3), [spec], 3)
    assert capsys.readouterr().err == ""  # faster than PROGRESS_DELAY_S: no bar
    with pytest.warns(UserWarning, match="box limits diameters"):
        b = generate_rve(RVESpec(12, 0.5, max_diameter_box_ratio=1 / 3), [spec], 3,
                         progress=False)
    assert np.array_equal(a.particle_ids, b.particle_ids)


def test_stage_bar_shows_after_its_delay(monkeypatch, capsys):
    monkeypatch.setattr(gen, "PROGRESS_DELAY_S", 0.0)
    with gen.stage_bar("packing") as bar:
        for f in (0.1, 0.5, 1.0):
            bar(f)
    assert "packing:" in capsys.readouterr().err
    with gen.stage_bar("packing", enabled=False) as bar:
        assert bar is None
    assert capsys.readouterr().err == ""


# ------------------------------------------------------------------------- geometry
@pytest.fixture(scope="module")
def small_rve():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the 12 um box cuts the coarse tail
        return generate_rve(RVESpec(12, 0.25, max_diameter_box_ratio=0.4),
                            [FillerSpec.from_table1("Al2O3", 0.5)], 3, progress=False)


def geometry_digest(g) -> str:
    h = hashlib.sha256()

    def add(obj):
        if isinstance(obj, np.ndarray):
            h.update(str(obj.dtype).encode())
            h.update(np.ascontiguousarray(obj).tobytes())
        elif isinstance(obj, (tuple, list)):
            for o in obj:
                add(o)
        elif isinstance(obj, dict):
            for k in sorted(obj):
                h.update(k.encode())
                add(obj[k])
        elif isinstance(obj, (int, float, str, bool)) or obj is None:
            h.update(repr(obj).encode())

    for name in sorted(vars(g)):
        add(getattr(g, name))
    return h.hexdigest()


@pytest.mark.parametrize("interface", ["staircase", "segment"])
@pytest.mark.parametrize("workers", [1, 2])
def test_geometry_in_tiny_calls_is_unchanged(small_rve, interface, workers, monkeypatch):
    whole = geometry_digest(face_geometry(small_rve, interface=interface, workers=workers))
    for name, value in (("SCAN_VOXELS", 1), ("FACE_WORK", 7), ("ZONE_CELLS", 5),
                        ("SEGMENT_ROWS", 3)):
        monkeypatch.setattr(K, name, value)
    monkeypatch.setattr(cut_cells, "ADD_ROWS", 11)
    assert geometry_digest(face_geometry(small_rve, interface=interface,
                                         workers=workers)) == whole


def test_cost_ranges_cover_everything_within_the_budget():
    cost = np.array([5, 1, 1, 1, 9, 0, 0, 2, 3])
    for threads in (1, 2, 3):
        for budget in (1, 3, 4, 100):
            r = K.cost_ranges(cost, threads, budget)
            assert r[0][0] == 0 and r[-1][1] == cost.size
            assert all(a[1] == b[0] for a, b in itertools.pairwise(r))
            assert all(hi > lo for lo, hi in r)
            assert all(hi - lo == 1 or cost[lo:hi].sum() <= budget for lo, hi in r)
            assert len(r) >= min(cost.size, 1 if threads == 1 else threads)
    assert K.cost_ranges(np.zeros(0), 1, 10) == [(0, 0)]
    assert K.chunk_ranges(10, 1, most=3) == [(0, 2), (2, 5), (5, 7), (7, 10)]
    assert K.chunk_ranges(10, 1) == [(0, 10)]


# ------------------------------------------------------------------------- signals
CHILD = r"""
import signal, sys
import numpy as np
from itr_fv.rve.packing import pack_spheres

def on_sigterm(signum, frame):  # what the itr command installs
    raise SystemExit(128 + signum)

signal.signal(signal.SIGTERM, on_sigterm)
signal.signal(signal.SIGINT, signal.default_int_handler)  # even where SIGINT was ignored
rng = np.random.default_rng(0)
pack_spheres(np.full(8, 1.0), 10.0, rng, max_iter=3)  # compile or load the kernels first
radii = rng.uniform(0.5, 1.5, 6000)  # 6000 spheres to 0.64: a packing of many seconds
box = float((4.0 / 3.0 * np.pi * np.sum(radii ** 3) / 0.64) ** (1.0 / 3.0))
print("packing", flush=True)
pack_spheres(radii, box, rng)
print("packed", flush=True)
"""


def stop_child_while_packing(sig: int) -> tuple[float, int, str]:
    """Start the packing child, send ``sig`` 0.5 s into its packing; returns the seconds
    from the signal to its exit, its status and its stderr."""
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    p = subprocess.Popen([sys.executable, "-c", CHILD], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "packing", p.stderr.read()
        time.sleep(0.5)
        assert p.poll() is None, "the packing ended before the signal"
        t0 = time.perf_counter()
        p.send_signal(sig)
        try:
            p.wait(timeout=30)
        finally:
            seconds = time.perf_counter() - t0
        return seconds, p.returncode, p.stderr.read()
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        p.stdout.close()
        p.stderr.close()


def test_sigterm_stops_a_packing_within_the_deadline():
    seconds, status, err = stop_child_while_packing(signal.SIGTERM)
    assert status == 128 + signal.SIGTERM, err
    assert seconds < DEADLINE_S


def test_sigint_stops_a_packing_within_the_deadline():
    seconds, status, err = stop_child_while_packing(signal.SIGINT)
    assert status != 0
    assert "KeyboardInterrupt" in err
    assert seconds < DEADLINE_S


def read_stderr(p: subprocess.Popen, into: list[bytes]) -> threading.Thread:
    """A thread that collects ``p``'s stderr (a progress bar writes no newline)."""
    def run():
        into.extend(iter(lambda: p.stderr.read1(4096), b""))

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def test_itr_demo_stops_within_the_deadline_while_packing(tmp_path):
    """The real command: SIGTERM while its progress bar says it is packing (the 60 um box
    packs for over 5 s); it ends within the deadline, and the output folder is gone."""
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    p = subprocess.Popen([str(BIN / "itr"), "demo", "--box-um", "60", "--voxel-um", "0.3",
                          "--out", "run"], cwd=tmp_path, env=env, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE)
    err: list[bytes] = []
    reader = read_stderr(p, err)
    try:
        deadline = time.time() + 300
        while b"packing:" not in b"".join(err) and p.poll() is None \
                and time.time() < deadline:
            time.sleep(0.05)
        assert p.poll() is None, b"".join(err).decode()
        t0 = time.perf_counter()
        p.send_signal(signal.SIGTERM)
        p.wait(timeout=30)
        seconds = time.perf_counter() - t0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    reader.join(timeout=5)
    text = b"".join(err).decode()
    assert p.returncode == 128 + signal.SIGTERM, text
    assert "stopped by signal 15" in text and "Traceback" not in text
    assert seconds < DEADLINE_S
    assert not (tmp_path / "run").exists()
