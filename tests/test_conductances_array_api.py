"""Face conductances from the geometry's face classes in array-API code (issue: conductances
where the backend's arrays live): NumPy and array-api-strict give the conductances of a
frozen copy of the former host-only law on the common RVE set, the class arrays are built
and moved once per geometry, a parameter change changes only the faces it should, and
missing resistances raise the same messages as before."""

import pickle
import warnings

import array_api_strict as xs
import numpy as np
import pytest
from refusals import refuses

from itr_fv import Materials
from itr_fv.discrete import face_classes as face_classes_module
from itr_fv.discrete import interface_law as interface_law_module
from itr_fv.discrete.face_classes import FaceClasses
from itr_fv.discrete.interface_law import SegmentLaw, StaircaseLaw
from itr_fv.discrete.problem import DiscreteProblem
from validation.gallery import build, rve_cases, touching_array, with_contact

SPOTS = {("Al2O3", "Al2O3"): 2e-6}
CPU = xs.Device("CPU_DEVICE")


# ------------------------------------------------- the former law, frozen as the reference
def frozen_conductances(geometry, materials) -> np.ndarray:
    """The host NumPy conductances as the laws computed them before the face classes (a
    frozen copy of StaircaseLaw/SegmentLaw.conductances, _spots and _refine)."""
    law = geometry.law
    segment = isinstance(law, SegmentLaw)
    if segment and geometry.particle_mat is not None:
        for m in np.unique(geometry.particle_mat[1:]):
            materials.resistance_between(geometry.names[m], geometry.names[0])
    k, R = materials.tables(geometry.names)
    gap_model = law.contact == "gap"
    if gap_model and geometry.film is None and geometry.n_contact_faces:
        raise ValueError("contact: the gap model needs the particle geometry (a "
                         "Microstructure from from_spheres or generate_rve); this label "
                         "image has faces between different particles: pass "
                         "Materials(..., contact='area') for a per-area contact resistance")
    h = geometry.voxel_m
    half_r = (0.5 * h) / k
    rc = half_r[geometry.material_ids]
    spots = _frozen_spots(geometry, materials, gap_model)
    g = np.empty((3,) + geometry.shape, dtype=np.float64)
    for d in range(3):
        np.add(rc, np.roll(rc, -1, axis=d), out=g[d])
        np.divide(1.0, g[d], out=g[d])
        idx = geometry.index[d]
        if idx.size == 0:
            continue
        lo, hi = geometry.mat_lo[d], geometry.mat_hi[d]
        r_face = R[lo, hi]
        cont = geometry.contact[d]
        if gap_model and cont.any():
            r_face[cont] = R[lo[cont], 0] + R[hi[cont], 0] + geometry.film[d][cont] / k[0]
        if np.isnan(r_face).any():
            j = int(np.flatnonzero(np.isnan(r_face))[0])
            if gap_model and cont[j]:
                m = lo[j] if np.isnan(R[lo[j], 0]) else hi[j]
                materials.resistance_between(geometry.names[m], geometry.names[0])
            materials.resistance_between(geometry.names[lo[j]], geometry.names[hi[j]])
        with np.errstate(invalid="ignore"):
            series = half_r[lo] + half_r[hi] + np.where(np.isinf(r_face), np.inf,
                                                        r_face * geometry.s[d])
        g[d].reshape(-1)[idx] = 1.0 / series
        if segment:
            _frozen_refine_cuts(geometry, g[d], d, k, R)
        elif gap_model:
            _frozen_refine_zones(geometry, g[d], d, k, R)
        if spots is not None and cont.any():
            g[d].reshape(-1)[idx[cont]] += spots[geometry.pair[d][cont]]
    return g


def _frozen_spots(geometry, materials, gap_model):
    if not gap_model or geometry.pair_material_ids is None or not materials.contact_conductance:
        return None
    names = geometry.names
    spots = np.array([materials.spot_conductance(names[a], names[b])
                      for a, b in geometry.pair_material_ids])
    spots[geometry.pair_gap_m > geometry.touch_gap_m] = 0.0
    h = geometry.voxel_m
    return spots / (geometry.pair_faces * h * h)


def _frozen_refine_zones(geometry, gd, d, k, R):
    if geometry.segments is None or not geometry.segments[d][0].size:
        return
    flat, la, lb, sa, sb, pa, pb = geometry.segments[d]
    ma = geometry.particle_mat[pa]
    mb = geometry.particle_mat[pb]
    lm = np.maximum(geometry.voxel_m - la - lb, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        ra = np.where(sa > 0, sa * R[ma, 0], 0.0)
        rb = np.where(sb > 0, sb * R[mb, 0], 0.0)
        series = la / k[ma] + lb / k[mb] + lm / k[0] + ra + rb
    gd.reshape(-1)[flat] = np.where(np.isinf(series), 0.0, 1.0 / series)


def _frozen_refine_cuts(geometry, gd, d, k, R):
    cuts = geometry.cuts
    if cuts is None or not cuts.index[d].size:
        return
    L, W = cuts.length[d], cuts.share[d]
    lm = np.maximum(geometry.voxel_m - L.sum(axis=1), 0.0)
    Rb = R[:, 0].copy()
    Rb[0] = 0.0
    with np.errstate(invalid="ignore", divide="ignore"):
        r_int = np.where(W > 0, W * Rb[None, :], 0.0)
        series = (L @ (1.0 / k)) + lm / k[0] + r_int.sum(axis=1)
    gd.reshape(-1)[cuts.index[d]] = np.where(np.isinf(series), 0.0, 1.0 / series)


# ------------------------------------------------------------------------ the cases
def _is_strict(x) -> bool:
    return type(x).__module__.startswith("array_api_strict")


def _host(x) -> np.ndarray:
    return np.from_dlpack(x.to_device(CPU)) if _is_strict(x) else x


def _problem(name: str, size: int, contact: str, law: str) -> tuple[DiscreteProblem, Materials]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        ms, mat = build(name, size)
    if contact == "gap":
        fillers = [p for p in mat.phases if p != mat.matrix]
        spots = {(a, b): 1e-6 * (1 + i + j) for i, a in enumerate(fillers)
                 for j, b in enumerate(fillers) if i <= j}
        mat = with_contact(mat, "gap", spots)
    return DiscreteProblem(ms, contact=contact, interface=law), mat


def _touching(lattice: str, law: str) -> tuple[DiscreteProblem, Materials]:
    ms, _ = touching_array(lattice, 1.5e-6, 1.5e-9, 6)
    mat = Materials({"silicone": 0.18, "Al2O3": 30.0}, {("Al2O3", "silicone"): 2e-8},
                    matrix="silicone", contact="gap", contact_conductance=SPOTS)
    return DiscreteProblem(ms, contact="gap", interface=law), mat


def _assert_same(problem: DiscreteProblem, mat: Materials) -> None:
    """NumPy bitwise, array-api-strict to 1e-14, against the frozen law."""
    ref = frozen_conductances(problem.geometry, mat)
    g_np = problem.system(mat).g
    assert isinstance(g_np, np.ndarray)
    np.testing.assert_array_equal(g_np, ref)
    g_strict = problem.system(mat, xp=xs).g
    assert _is_strict(g_strict)
    np.testing.assert_allclose(_host(g_strict), ref, rtol=1e-14, atol=0.0)


CASES = [c.name for c in rve_cases()]
#: cases whose gap-model staircase geometry (thin-film filling, zone segments) is quick
GAP_CASES = ["laminate", "sc_R5e-5", "bcc_R1e-8", "fcc_R1e-6", "random30", "random30_Rinf",
             "al2o3_55"]


@pytest.mark.parametrize("name", CASES)
def test_area_model_equals_the_frozen_law(name):
    _assert_same(*_problem(name, 24, "area", "staircase"))


@pytest.mark.parametrize("name", GAP_CASES)
def test_gap_model_with_spots_equals_the_frozen_law(name):
    _assert_same(*_problem(name, 24 if name != "al2o3_55" else 20, "gap", "staircase"))


@pytest.mark.parametrize("name", [c for c in CASES if c != "laminate"])
def test_segment_law_equals_the_frozen_law(name):
    _assert_same(*_problem(name, 16, "gap", "segment"))


@pytest.mark.parametrize("lattice", ["sc", "bcc", "fcc"])
@pytest.mark.parametrize("law", ["staircase", "segment"])
def test_touching_arrays_with_spots_equal_the_frozen_law(lattice, law):
    problem, mat = _touching(lattice, law)
    geometry = problem.geometry
    assert geometry.n_contact_faces and geometry.touching_pairs().size
    refined = geometry.segments if law == "staircase" else geometry.cuts.index
    assert refined is not None
    _assert_same(problem, mat)


def test_conductances_live_on_the_device_asked_for():
    problem, mat = _touching("fcc", "segment")
    device = xs.Device("device1")
    g = problem.system(mat, xp=xs, device=device).g
    assert g.device == device
    np.testing.assert_allclose(_host(g), frozen_conductances(problem.geometry, mat),
                               rtol=1e-14, atol=0.0)


def test_insulating_interfaces_give_the_same_clusters_in_any_namespace():
    problem, mat = _problem("random30_Rinf", 16, "area", "staircase")
    host, strict = problem.system(mat), problem.system(mat, xp=xs)
    assert strict.floating.count == host.floating.count > 0
    np.testing.assert_array_equal(strict.floating.voxels, host.floating.voxels)
    np.testing.assert_array_equal(strict.labels, host.labels)
    connected = problem.system(mat.with_values(resistance={("Al2O3", "silicone"): 1e-7}),
                               xp=xs)
    assert connected.floating.count == 0 and connected.labels is None


# --------------------------------------------------------------- built and moved once
def test_class_arrays_are_built_and_moved_once_per_geometry(monkeypatch):
    built, moved = [], []
    build_classes = interface_law_module.build_face_classes
    move = FaceClasses.to

    def counting_build(*args, **kwargs):
        built.append(1)
        return build_classes(*args, **kwargs)

    def counting_move(self, *args, **kwargs):
        moved.append(1)
        return move(self, *args, **kwargs)

    monkeypatch.setattr(interface_law_module, "build_face_classes", counting_build)
    monkeypatch.setattr(FaceClasses, "to", counting_move)
    problem, mat = _touching("bcc", "staircase")
    other = mat.with_values(conductivity={"Al2O3": 40.0},
                            resistance={("Al2O3", "silicone"): 5e-8})
    for m in (mat, other):
        for xp in (None, xs):
            problem.system(m, xp=xp)
    assert len(built) == 1 and len(moved) == 1
    problem.system(other, xp=xs, device=xs.Device("device1"))
    assert len(built) == 1 and len(moved) == 2
    assert problem.face_classes() is problem.geometry.face_classes()
    assert problem.face_classes(xp=xs) is problem.face_classes(xp=xs)


def test_pickled_problems_leave_their_class_arrays_behind():
    problem, mat = _touching("sc", "segment")
    g = problem.system(mat, xp=xs).g
    copy = pickle.loads(pickle.dumps(problem))
    assert "_face_classes" not in copy.geometry.__dict__ and not copy._classes
    np.testing.assert_array_equal(copy.system(mat).g, _host(g))


# ------------------------------------------------------- what a parameter change changes
def _interface_mask(geometry, d: int, pair: tuple[int, int] | None = None) -> np.ndarray:
    """Faces of axis d in the geometry's interface list (of one material pair)."""
    mask = np.zeros(int(np.prod(geometry.shape)), dtype=bool)
    sel = np.ones(geometry.index[d].size, dtype=bool)
    if pair is not None:
        lo, hi = geometry.mat_lo[d], geometry.mat_hi[d]
        sel = ((lo == pair[0]) & (hi == pair[1])) | ((lo == pair[1]) & (hi == pair[0]))
        sel &= ~geometry.contact[d]
    mask[geometry.index[d][sel]] = True
    return mask.reshape(geometry.shape)


def test_a_new_resistance_changes_only_its_interface_faces():
    problem, mat = _problem("hybrid_30_30", 24, "area", "staircase")
    geometry = problem.geometry
    al, si = geometry.names.index("Al2O3"), geometry.names.index("silicone")
    new = mat.with_values(resistance={("Al2O3", "silicone"): 3e-7})
    g0, g1 = problem.system(mat, xp=xs).g, problem.system(new, xp=xs).g
    g0, g1 = _host(g0), _host(g1)
    for d in range(3):
        own = _interface_mask(geometry, d, (al, si))
        assert own.any()
        np.testing.assert_array_equal(g1[d][~own], g0[d][~own])
        # the former R = 1e-7 weighs s times in 1 / g: 1/g grows by s (3e-7 - 1e-7)
        lo_hi = _interface_mask(geometry, d, (al, si)).reshape(-1)[geometry.index[d]]
        s = geometry.s[d][lo_hi]
        flat = geometry.index[d][lo_hi]
        grow = 1.0 / g1[d].reshape(-1)[flat] - 1.0 / g0[d].reshape(-1)[flat]
        np.testing.assert_allclose(grow, s * 2e-7, rtol=1e-9)


def test_a_new_spot_conductance_changes_only_the_contact_faces_of_touching_pairs():
    problem, mat = _touching("fcc", "staircase")
    geometry = problem.geometry
    h = geometry.voxel_m
    new = mat.with_values(contact_conductance={("Al2O3", "Al2O3"): 5e-6})
    g0, g1 = (_host(problem.system(m, xp=xs).g) for m in (mat, new))
    for d in range(3):
        flat = geometry.index[d][geometry.contact[d]]
        pair = geometry.pair[d][geometry.contact[d]]
        touching = geometry.pair_gap_m[pair] <= geometry.touch_gap_m
        expected = np.zeros(int(np.prod(geometry.shape)))
        expected[flat[touching]] = 3e-6 / (geometry.pair_faces[pair[touching]] * h * h)
        delta = (g1[d] - g0[d]).reshape(-1)
        np.testing.assert_array_equal(delta[expected == 0], 0.0)
        np.testing.assert_allclose(delta[expected > 0], expected[expected > 0], rtol=1e-9)


def test_a_new_matrix_conductivity_leaves_the_particle_interiors_alone():
    problem, mat = _problem("fcc_R1e-6", 24, "area", "staircase")
    geometry = problem.geometry
    h = geometry.voxel_m
    new = mat.with_values(conductivity={"silicone": 0.36})
    g0, g1 = (_host(problem.system(m, xp=xs).g) for m in (mat, new))
    mid = geometry.material_ids
    for d in range(3):
        bulk = ~_interface_mask(geometry, d)
        inside = bulk & (mid > 0) & (np.roll(mid, -1, axis=d) > 0)
        matrix = bulk & (mid == 0) & (np.roll(mid, -1, axis=d) == 0)
        np.testing.assert_array_equal(g1[d][inside], g0[d][inside])
        np.testing.assert_allclose(g1[d][matrix], 0.36 / h, rtol=1e-14)
        np.testing.assert_allclose(g0[d][matrix], 0.18 / h, rtol=1e-14)
        assert np.all(g1[d][~bulk] > g0[d][~bulk])


# ---------------------------------------------------------------- the same messages
def _message(fn) -> str:
    with pytest.raises(ValueError) as info:
        fn()
    return str(info.value)


@pytest.mark.parametrize("case", ["area_ff", "area_hybrid", "gap_pm", "segment_pm", "k"])
def test_missing_values_raise_the_former_messages(case):
    if case == "area_ff":
        problem, mat = _problem("al2o3_60", 24, "area", "staircase")
        bad = Materials(mat.conductivity, {("Al2O3", "silicone"): 1e-7}, "silicone",
                        contact="area")
    elif case == "area_hybrid":
        problem, mat = _problem("hybrid_30_30", 24, "area", "staircase")
        bad = Materials(mat.conductivity, {p: v for p, v in mat.resistance.items()
                                           if set(p) != {"Al2O3", "AlN"}}, "silicone",
                        contact="area")
    elif case in ("gap_pm", "segment_pm"):
        problem, mat = _touching("bcc", "staircase" if case == "gap_pm" else "segment")
        bad = Materials({"silicone": 0.18, "Al2O3": 30.0}, {("Al2O3", "Al2O3"): 1e-7},
                        "silicone", contact="gap")
    else:
        problem, mat = _touching("sc", "staircase")
        bad = Materials({"silicone": 0.18, "AlN": 30.0}, {}, "silicone", contact="gap")
    former = _message(lambda: frozen_conductances(problem.geometry, bad))
    assert former == _message(lambda: problem.system(bad))
    assert former == _message(lambda: problem.system(bad, xp=xs))
    assert case == "k" or former.startswith("resistance: the microstructure needs the pair")


def test_a_label_image_with_contacts_has_no_gap_model():
    problem, mat = _touching("fcc", "staircase")
    from itr_fv import Microstructure

    ms = problem.microstructure
    labels = Microstructure(ms.material_ids, ms.particle_ids, ms.voxel_m, ms.names)
    geometry = DiscreteProblem(labels, contact="gap").geometry
    former = _message(lambda: frozen_conductances(geometry, mat))
    assert former.startswith("contact: the gap model needs the particle geometry")
    assert former == _message(lambda: geometry.conductances(mat))


# ------------------------------------------------------------------------- bad input
def test_bad_namespaces_and_devices_name_the_argument():
    problem, _ = _touching("sc", "staircase")
    with refuses(ValueError, "device"):
        problem.face_classes(device="cuda")
    with refuses(ValueError, "xp"):
        problem.geometry.face_classes().to(object())
    strict = problem.face_classes(xp=xs)
    with refuses(ValueError, "xp"):
        strict.to(np)


def test_host_classes_are_the_laws_geometry():
    """Every special face is an interface face or a refined face of the geometry, listed
    once; the slots of moved classes point back at them."""
    problem, _ = _touching("fcc", "staircase")
    geometry = problem.geometry
    host = geometry.face_classes()
    strict = host.to(xs)
    assert isinstance(geometry.law, StaircaseLaw)
    for d, (ax, moved) in enumerate(zip(host.axes, strict.axes)):
        zone = np.asarray(geometry.segments[d][0], dtype=np.int64)
        expected = np.union1d(geometry.index[d], zone)
        np.testing.assert_array_equal(np.sort(ax.faces), expected)
        np.testing.assert_array_equal(ax.faces[:ax.n_refined], zone)
        slot = _host(moved.slot).reshape(-1)
        np.testing.assert_array_equal(slot[ax.faces], np.arange(1, ax.size + 1))
        assert np.count_nonzero(slot) == ax.size
    assert face_classes_module.to_host(host.material_ids) is host.material_ids
