"""The face geometry's build (numba kernels, issue of the host build) gives the same arrays as
the NumPy build it replaced.

The reference below is a frozen copy of the NumPy code of ``face_geometry`` (the per-axis
scan, staircase factors, films and contact pairs), ``fill_thin_films``, ``contact_zones`` and
``zone_segments`` as they were before the kernels, with the helpers they used
(``min_image``, ``staircase_factor``, ``segment_in_sphere``, ``near_contacts``,
``wedge_radius``, ``contact_films``, ``self_image_faces``). It is not the code under test:
do not edit it to follow the package. ``validation/bench_geometry.py`` times it as "before".
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
import scipy.ndimage
from refusals import refuses

from itr_fv import Microstructure
from itr_fv.discrete import _geometry_kernels as K
from itr_fv.discrete.contact_zones import contact_zones, fill_thin_films, zone_segments
from itr_fv.discrete.cut_cells import SHARES, surface_cuts
from itr_fv.discrete.face_geometry import face_geometry
from itr_fv.discrete.interface_law import SegmentLaw
from itr_fv.rve.contact_film import ContactFilm
from itr_fv.rve.sphere_geometry import particle_material_ids
from validation.gallery import build, rve_cases, touching_array

TOUCH_GAP_M = 5e-9


# ====================================================================== frozen reference
def ref_min_image(dx, box):
    return dx - box * np.round(dx / box)


def ref_staircase_factor(n):
    norm = np.sqrt((n * n).sum(axis=1))
    s = np.ones(n.shape[0])
    ok = norm > 0
    s[ok] = np.abs(n[ok]).sum(axis=1) / norm[ok]
    return s


def ref_staircase_share(n, d):
    return ref_staircase_factor(n)


def ref_normal_share(n, d):
    unit_d = np.abs(n[:, d]) / np.sqrt((n * n).sum(axis=1))
    return 1.0 / np.maximum(unit_d, 1e-6)


def ref_segment_in_sphere(x0, d, h, centre, radius, share):
    w = x0 - centre
    wd = w[:, d]
    disc = radius * radius - ((w * w).sum(axis=1) - wd * wd)
    root = np.sqrt(np.maximum(disc, 0.0))
    t1 = (-wd - root) / h
    t2 = (-wd + root) / h
    inside = np.where(disc > 0, np.clip(np.minimum(t2, 1.0) - np.maximum(t1, 0.0), 0.0, None),
                      0.0) * h
    w_sum = np.zeros(len(x0))
    for t in (t1, t2):
        cross = (disc > 0) & (t > 0.0) & (t < 1.0)
        if cross.any():
            n = w[cross]
            n[:, d] += t[cross] * h
            w_sum[cross] += 1.0 if share is None else share(n, d)
    return inside, w_sum


def ref_near_contacts(ms, max_gap):
    import scipy.spatial

    table = ms.particles
    box = np.array(ms.shape, dtype=np.float64) * ms.voxel_m
    c = np.mod(table.centers_m, box)
    r = table.radii_m
    reach = 2.0 * float(r.max()) + max_gap
    todo = []
    if reach < 0.5 * float(box.min()):
        if len(table) > 1:
            tree = scipy.spatial.cKDTree(c, boxsize=box * (1 + 1e-12))
            pairs = tree.query_pairs(reach, output_type="ndarray")
            D = ref_min_image(c[pairs[:, 1]] - c[pairs[:, 0]], box)
            near = np.sqrt((D * D).sum(axis=1)) < r[pairs[:, 0]] + r[pairs[:, 1]] + max_gap
            todo = [(int(i), int(j), dv) for (i, j), dv in zip(pairs[near], D[near])]
    else:
        shifts = np.array([(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1)
                           for z in (-1, 0, 1)])
        for i in range(len(r)):
            for j in range(i, len(r)):
                for sh in shifts:
                    if i == j and tuple(sh) <= (0, 0, 0):
                        continue
                    D = c[j] + sh * box - c[i]
                    if np.sqrt(D @ D) < r[i] + r[j] + max_gap:
                        todo.append((i, j, D))
    return todo


def ref_wedge_radius(dist, ra, rb, h):
    def film(rho):
        return dist - math.sqrt(max(ra * ra - rho * rho, 0.0)) - \
            math.sqrt(max(rb * rb - rho * rho, 0.0))
    lo, hi = 0.0, min(ra, rb)
    if film(hi) <= h:
        return hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if film(mid) <= h else (lo, mid)
    return lo


def ref_contact_zones(ms, thickness_m, margin_voxels):
    table = ms.particles
    shape, h = ms.shape, ms.voxel_m
    c = np.mod(table.centers_m, np.array(shape, dtype=np.float64) * h)
    r = table.radii_m
    for a, b, D in ref_near_contacts(ms, thickness_m):
        dist = float(np.sqrt(D @ D))
        gap0 = dist - r[a] - r[b]
        if gap0 >= thickness_m or dist <= 0.0:
            continue
        u = D / dist
        rho_max = ref_wedge_radius(dist, r[a], r[b], thickness_m)
        x_mid = c[a] + u * (r[a] + 0.5 * gap0)
        half = rho_max + margin_voxels * h
        lo_i = np.floor((x_mid - half) / h - 0.5).astype(int)
        hi_i = np.ceil((x_mid + half) / h - 0.5).astype(int)
        ii = [np.arange(lo_i[k], hi_i[k] + 1) for k in range(3)]
        cells = np.stack(np.meshgrid(*ii, indexing="ij"), axis=-1).reshape(-1, 3)
        yield dict(a=int(a), b=int(b), offset=D, distance=dist, gap=gap0, direction=u,
                   rho_max=rho_max, cells=cells)


def ref_contact_films(table, p_lo, p_hi, x_face, d, box):
    a = p_lo - 1
    b = p_hi - 1
    ca = x_face + ref_min_image(table.centers_m[a] - x_face, box)
    cb = x_face + ref_min_image(table.centers_m[b] - x_face, box)
    own = a == b
    if own.any():
        side = np.where(x_face[own, d] >= ca[own, d], 1.0, -1.0)
        cb[own, d] = ca[own, d] + side * box[d]
    D = cb - ca
    shift = np.rint((D - (table.centers_m[b] - table.centers_m[a])) / box).astype(np.int64)
    dist = np.sqrt((D * D).sum(axis=1))
    u = D / dist[:, None]
    w = x_face - ca
    along = (w * u).sum(axis=1)
    rho2 = np.maximum((w * w).sum(axis=1) - along * along, 0.0)
    ra = table.radii_m[a]
    rb = table.radii_m[b]
    gap0 = dist - ra - rb
    film = (dist - np.sqrt(np.maximum(ra * ra - rho2, 0.0))
            - np.sqrt(np.maximum(rb * rb - rho2, 0.0)))
    return np.maximum(film, np.maximum(gap0, 0.0)), gap0, shift


def ref_fill_thin_films(ms):
    table = ms.particles
    pid = ms.particle_ids.copy()
    mid = ms.material_ids.copy()
    if table is None or len(table) < 1:
        return pid, mid, 0
    shape, h = ms.shape, ms.voxel_m
    c = np.mod(table.centers_m, np.array(shape, dtype=np.float64) * h)
    r = table.radii_m
    mat_of = particle_material_ids(ms).astype(mid.dtype)
    filled = 0
    for z in ref_contact_zones(ms, h, 1.0):
        a, b = z["a"], z["b"]
        x = (z["cells"] + 0.5) * h
        w = x - c[a]
        t = w @ z["direction"]
        rho2 = (w * w).sum(axis=1) - t * t
        wrapped = tuple(np.mod(z["cells"][:, k], shape[k]) for k in range(3))
        free = pid[wrapped] == 0
        da = np.sqrt((w * w).sum(axis=1)) - r[a]
        wb = x - (c[a] + z["offset"])
        db = np.sqrt((wb * wb).sum(axis=1)) - r[b]
        sel = (free & (rho2 <= z["rho_max"] * z["rho_max"]) & (t > 0.0)
               & (t < z["distance"]) & (da > 0) & (db > 0))
        if not sel.any():
            continue
        owner = np.where(da[sel] <= db[sel], a, b) + 1
        target = tuple(w_[sel] for w_ in wrapped)
        pid[target] = owner
        mid[target] = mat_of[owner]
        filled += int(sel.sum())
    return pid, mid, filled


def ref_zone_segments(ms, share):
    table = ms.particles
    shape, h = ms.shape, ms.voxel_m
    c = np.mod(table.centers_m, np.array(shape, dtype=np.float64) * h)
    r = table.radii_m
    out = [[[] for _ in range(7)] for _ in range(3)]
    seen = [set() for _ in range(3)]
    for z in ref_contact_zones(ms, 3.0 * h, 2.0):
        a, b, u = z["a"], z["b"], z["direction"]
        x = (z["cells"] + 0.5) * h
        cb = c[a] + z["offset"]
        for d in range(3):
            xf = x.copy()
            xf[:, d] += 0.5 * h
            w = xf - c[a]
            t = w @ u
            rho2 = np.maximum((w * w).sum(axis=1) - t * t, 0.0)
            surf_a = np.sqrt(np.maximum(r[a] ** 2 - rho2, 0.0))
            surf_b = z["distance"] - np.sqrt(np.maximum(r[b] ** 2 - rho2, 0.0))
            sel = (rho2 <= z["rho_max"] ** 2) & (t > surf_a - h) & (t < surf_b + h)
            if not sel.any():
                continue
            la, sa = ref_segment_in_sphere(x[sel], d, h, c[a], r[a], share)
            lb, sb = ref_segment_in_sphere(x[sel], d, h, cb, r[b], share)
            flat = np.ravel_multi_index(
                tuple(np.mod(z["cells"][sel, k], shape[k]) for k in range(3)), shape)
            for f, la_, lb_, sa_, sb_ in zip(flat, la, lb, sa, sb):
                if f in seen[d]:
                    continue
                seen[d].add(f)
                for k, v in enumerate((f, la_, lb_, sa_, sb_, a + 1, b + 1)):
                    out[d][k].append(v)
    return tuple(tuple(np.asarray(col) for col in axis) for axis in out)


def ref_self_image_faces(table, pid, pq, d, shape, h):
    L = shape[d] * h
    big = np.flatnonzero(2.0 * table.radii_m > L - 2.0 * h) + 1
    if big.size == 0:
        return np.zeros(0, dtype=np.int64)
    cand = np.flatnonzero((np.isin(pid, big) & (pid == pq)).ravel())
    if cand.size == 0:
        return cand
    i_d = np.unravel_index(cand, shape)[d]
    c = table.centers_m[pid.ravel()[cand] - 1, d]
    u_p = ref_min_image((i_d + 0.5) * h - c, np.array(L))
    u_q = ref_min_image((i_d + 1.5) * h - c, np.array(L))
    return cand[np.abs(u_q - u_p - h) > 0.5 * h]


def reference_face_geometry(ms: Microstructure, staircase: bool = True, contact: str = "gap",
                            interface: str = "staircase", touch_gap_m: float = TOUCH_GAP_M
                            ) -> dict:
    """The arrays of ``face_geometry(ms, staircase, contact=..., interface=...)`` by the
    NumPy code before the kernels."""
    table = ms.particles
    segment_law = interface == "segment"
    if contact == "gap" and table is not None and not segment_law:
        pid, mid, filled = ref_fill_thin_films(ms)
    else:
        pid, mid, filled = ms.particle_ids, ms.material_ids, 0
    shape, h = ms.shape, ms.voxel_m
    box = np.array(shape, dtype=np.float64) * h
    index, lo, hi, is_contact_all, s_all = [], [], [], [], []
    films, pair_keys, gaps, keys_seen = [], [], [], []
    mode = "off" if not staircase else ("spheres" if table is not None else "image")
    grad = None
    if mode == "image" and ms.n_particles:
        solid = scipy.ndimage.gaussian_filter((pid > 0).astype(np.float64), 1.5, mode="wrap")
        grad = [0.5 * (np.roll(solid, -1, axis=a) - np.roll(solid, 1, axis=a)) for a in range(3)]
    for d in range(3):
        pq = np.roll(pid, -1, axis=d)
        idx = np.flatnonzero((pid != pq).ravel())
        if table is not None:
            idx = np.union1d(idx, ref_self_image_faces(table, pid, pq, d, shape, h))
        p_lo = pid.ravel()[idx]
        p_hi = pq.ravel()[idx]
        index.append(idx)
        lo.append(mid.ravel()[idx])
        hi.append(np.roll(mid, -1, axis=d).ravel()[idx])
        is_contact = (p_lo > 0) & (p_hi > 0)
        is_contact_all.append(is_contact)
        s = np.ones(idx.size)
        self_image = is_contact & (p_lo == p_hi)
        if mode == "spheres" and idx.size:
            ijk = np.stack(np.unravel_index(idx, shape), axis=1).astype(np.float64)
            x_face = (ijk + 0.5) * h
            x_face[:, d] += 0.5 * h
            pm = ~is_contact
            part = np.maximum(p_lo, p_hi)[pm] - 1
            n_pm = ref_min_image(x_face[pm] - table.centers_m[part], box)
            s[pm] = ref_staircase_factor(n_pm)
            pp = is_contact & ~self_image
            if pp.any():
                a = p_lo[pp] - 1
                b = p_hi[pp] - 1
                n_pp = ref_min_image(table.centers_m[b] - table.centers_m[a], box)
                s[pp] = ref_staircase_factor(n_pp)
        if table is not None:
            film = np.full(idx.size, np.nan)
            key = np.full(idx.size, -1, dtype=np.int64)
            gap0 = np.zeros(0)
            if is_contact.any():
                ijk = np.stack(np.unravel_index(idx[is_contact], shape), axis=1)
                x_c = (ijk + 0.5) * h
                x_c[:, d] += 0.5 * h
                pa = np.minimum(p_lo, p_hi)[is_contact].astype(np.int64)
                pb = np.maximum(p_lo, p_hi)[is_contact].astype(np.int64)
                film[is_contact], gap0, shift = ref_contact_films(table, pa, pb, x_c, d, box)
                own = pa == pb
                flip = own & (shift[:, d] < 0)
                shift[flip] *= -1
                keys_seen.extend(map(tuple, np.column_stack([pa, pb, shift])))
                key[is_contact] = np.arange(len(keys_seen) - pa.size, len(keys_seen))
            films.append(film)
            pair_keys.append(key)
            gaps.append(gap0)
        if mode == "image" and idx.size:
            pm = np.flatnonzero(~is_contact)
            p_flat = idx[pm]
            q_flat = np.ravel_multi_index(
                tuple(np.mod(c + (1 if a == d else 0), shape[a])
                      for a, c in enumerate(np.unravel_index(p_flat, shape))), shape)
            n_est = np.stack([0.5 * (grad[a].ravel()[p_flat] + grad[a].ravel()[q_flat])
                              for a in range(3)], axis=1)
            s[pm] = ref_staircase_factor(n_est)
        s_all.append(s)
    out = dict(index=tuple(index), mat_lo=tuple(lo), mat_hi=tuple(hi),
               contact=tuple(is_contact_all), s=tuple(s_all), material_ids=mid,
               staircase=mode, filled_voxels=filled)
    if table is not None:
        rows = np.array(keys_seen, dtype=np.int64).reshape(-1, 5)
        uniq, first, inverse, counts = np.unique(rows, axis=0, return_index=True,
                                                 return_inverse=True, return_counts=True)
        inverse = inverse.reshape(-1)
        gap_of_row = np.concatenate(gaps) if gaps else np.zeros(0)
        pairs = uniq[:, :2]
        face_pair = [np.where(k >= 0, inverse[np.maximum(k, 0)], -1) if inverse.size
                     else np.full_like(k, -1) for k in pair_keys]
        mat_of_particle = particle_material_ids(ms)
        out.update(film=tuple(films), pair=tuple(face_pair), pair_particles=pairs,
                   pair_gap_m=gap_of_row[first], pair_faces=counts,
                   pair_material_ids=mat_of_particle[pairs].astype(np.int32),
                   particle_mat=mat_of_particle)
        if segment_law:
            out.update(segments=None, cuts=surface_cuts(ms, "staircase"))
        elif contact == "gap":
            out.update(segments=ref_zone_segments(ms, ref_staircase_share if staircase
                                                  else None), cuts=None)
        else:
            out.update(segments=None, cuts=None)
    return out


# ====================================================================== comparison
def assert_same_array(new, ref, what: str) -> None:
    new, ref = np.asarray(new), np.asarray(ref)
    assert new.dtype == ref.dtype, f"{what}: dtype {new.dtype} != {ref.dtype}"
    assert new.shape == ref.shape, f"{what}: shape {new.shape} != {ref.shape}"
    if new.dtype.kind == "f":
        # same arithmetic in the same order: the same bits (NaN where NaN)
        same = (new == ref) | (np.isnan(new) & np.isnan(ref))
        assert same.all(), (f"{what}: {int((~same).sum())} values differ, largest relative "
                            f"{np.nanmax(np.abs(new - ref) / np.abs(ref)):.3g}")
    else:
        assert np.array_equal(new, ref), f"{what}: values differ"


def assert_same_geometry(geom, ref: dict) -> None:
    for name in ("index", "mat_lo", "mat_hi", "contact", "s", "film", "pair"):
        r = ref.get(name)
        if r is None:
            assert getattr(geom, name) is None, name
            continue
        for d in range(3):
            assert_same_array(getattr(geom, name)[d], r[d], f"{name}[{d}]")
    for name in ("pair_particles", "pair_gap_m", "pair_faces", "pair_material_ids",
                 "particle_mat", "material_ids"):
        if name in ref:
            assert_same_array(getattr(geom, name), ref[name], name)
    assert geom.filled_voxels == ref["filled_voxels"]
    assert geom.staircase == ref["staircase"]
    if ref.get("segments") is None:
        assert geom.segments is None
    else:
        for d in range(3):
            for k, name in enumerate(("flat", "la", "lb", "sa", "sb", "pa", "pb")):
                assert_same_array(geom.segments[d][k], ref["segments"][d][k],
                                  f"segments[{d}].{name}")
    if ref.get("cuts") is None:
        assert geom.cuts is None
    else:
        for d in range(3):
            for name in ("index", "length", "share"):
                assert_same_array(getattr(geom.cuts, name)[d], getattr(ref["cuts"], name)[d],
                                  f"cuts.{name}[{d}]")


# ====================================================================== the cases
@pytest.mark.parametrize("name", [case.name for case in rve_cases()])
def test_gallery_geometry_is_unchanged(name):
    ms, _ = build(name, 24, contact="gap")
    assert_same_geometry(face_geometry(ms, contact="gap"), reference_face_geometry(ms))


@pytest.mark.parametrize("kind", ["sc", "bcc", "fcc"])
def test_touching_arrays_geometry_is_unchanged(kind):
    """Spheres a 1.5 nm film apart (SC: each sphere touches its own periodic images)."""
    ms, _ = touching_array(kind, 1.5e-6, 1.5e-9, 6)
    geom = face_geometry(ms, contact="gap", workers=2)
    assert geom.pair_particles.shape[0] > 0 and sum(len(seg[0]) for seg in geom.segments) > 0
    assert_same_geometry(geom, reference_face_geometry(ms))


@pytest.fixture(scope="module")
def small_aln() -> Microstructure:
    from itr_fv.rve import FillerSpec, build_rve
    from itr_fv.rve.spec import RVESpec

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ms, _ = build_rve(RVESpec(box_um=8.0, voxel_um=0.25, seed=1),
                          [FillerSpec.from_table1("AlN", 0.6)], 0, matrix="silicone")
    # the reference predates stated contact films: compare the kernels on the gaps as packed
    # (tests/test_contact_film.py checks the stated film)
    return Microstructure(ms.material_ids, ms.particle_ids, ms.voxel_m, ms.names,
                          dataclasses.replace(ms.particles, contact=ContactFilm()))


@pytest.mark.parametrize("workers", [1, 2])
def test_small_aln_geometry_is_unchanged_on_any_thread_count(small_aln, workers):
    geom = face_geometry(small_aln, contact="gap", workers=workers)
    assert sum(len(seg[0]) for seg in geom.segments) > 0
    assert_same_geometry(geom, reference_face_geometry(small_aln))


@pytest.mark.parametrize("options", [dict(staircase=False), dict(contact="area"),
                                     dict(interface="segment")])
def test_other_options_are_unchanged(small_aln, options):
    kwargs = dict(staircase=True, contact="gap", interface="staircase") | options
    geom = face_geometry(small_aln, workers=2, **kwargs)
    assert_same_geometry(geom, reference_face_geometry(small_aln, **kwargs))


def test_segment_law_object_is_unchanged(small_aln):
    geom = face_geometry(small_aln, contact="gap", interface=SegmentLaw())
    assert_same_geometry(geom, reference_face_geometry(small_aln, interface="segment"))


def test_zone_segments_of_another_share_rule_are_unchanged(small_aln):
    """A share rule the kernel does not know runs zone by zone in NumPy."""
    new = zone_segments(small_aln, SHARES["normal"])
    ref = ref_zone_segments(small_aln, ref_normal_share)
    for d in range(3):
        for k in range(7):
            assert_same_array(new[d][k], ref[d][k], f"segments[{d}][{k}]")


def test_fill_thin_films_is_unchanged(small_aln):
    pid, mid, filled = fill_thin_films(small_aln)
    r_pid, r_mid, r_filled = ref_fill_thin_films(small_aln)
    assert filled == r_filled > 0
    assert_same_array(pid, r_pid, "particle_ids")
    assert_same_array(mid, r_mid, "material_ids")


def test_contact_zones_are_unchanged(small_aln):
    h = small_aln.voxel_m
    new = list(contact_zones(small_aln, 3.0 * h, 2.0))
    ref = list(ref_contact_zones(small_aln, 3.0 * h, 2.0))
    assert len(new) == len(ref) > 0
    for z, r in zip(new, ref):
        assert (z.a, z.b) == (r["a"], r["b"])
        for name in ("offset", "distance", "gap", "direction", "rho_max", "cells"):
            assert np.array_equal(getattr(z, name), r[name]), name


@pytest.mark.parametrize("staircase", [True, False])
def test_plain_label_image_is_unchanged(staircase):
    """No particle table: faces from the labels, s from the smoothed image."""
    ms, _ = build("random30", 24, contact="area")
    labels = Microstructure.from_labels(ms.material_ids, ms.particle_ids, voxel_m=ms.voxel_m,
                                        names=ms.names)
    geom = face_geometry(labels, staircase, contact="area", workers=2)
    assert geom.film is None and geom.pair is None
    assert_same_geometry(geom, reference_face_geometry(labels, staircase, contact="area"))


@pytest.mark.parametrize("workers", [0, -1, 1.5, True, "2"])
def test_workers_is_checked(workers):
    ms, _ = build("sc_R0", 8)
    with refuses(ValueError, "workers"):
        face_geometry(ms, workers=workers)


def test_thread_count_follows_the_grid_size():
    assert K.threads_for(8 ** 3) == 1
    assert K.threads_for(8 ** 3, workers=1) == 1
    assert 1 <= K.threads_for(512 ** 3) <= K.nb.config.NUMBA_NUM_THREADS


def test_contact_rows_are_grouped_as_by_np_unique():
    """The one-key grouping of the contact rows equals ``np.unique(rows, axis=0)``."""
    from itr_fv.discrete.face_geometry import _unique_contacts

    rng = np.random.default_rng(3)
    p = rng.integers(1, 40, size=(500, 2))
    rows = np.column_stack([p.min(axis=1), p.max(axis=1), rng.integers(-1, 2, size=(500, 3))])
    rows = rows.astype(np.int64)
    got = _unique_contacts(rows)
    want = np.unique(rows, axis=0, return_index=True, return_inverse=True, return_counts=True)
    for g, w in zip(got, want):
        assert_same_array(g, np.asarray(w).reshape(g.shape), "unique")
