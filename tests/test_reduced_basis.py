"""The certified reduced-basis surrogate of one RVE (issue 11): against full solves, bounds,
storage without pickle, bad input."""

import pickle
import warnings

import numpy as np
import pytest
from refusals import refuses

from itr_fv import Materials, homogenize
from itr_fv.discrete.problem import DiscreteProblem
from itr_fv.rve import FillerSpec, RVESpec, generate_rve
from itr_surrogate.face_decomposition import ParameterBox, ResistanceDecomposition
from itr_surrogate.reduced_basis import ReducedBasis, _divergence, _project_divergence_free

BOUNDS = {"k_Al2O3": (20.0, 40.0), "R_Al2O3_silicone": (1e-8, 5e-5)}


@pytest.fixture(scope="module")
def problem():
    # Table 1's Al2O3 size distribution at 40 vol%: 24^3 voxels, 17 particles, with contacts
    spec = FillerSpec("Al2O3", mu=1.02, sigma=0.35, volume_fraction=0.40)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the box cuts the PSD's tail
        ms = generate_rve(RVESpec(6.0, 0.25, max_diameter_box_ratio=1 / 3), spec, 3,
                          matrix="silicone")
    return DiscreteProblem(ms, contact="gap")


@pytest.fixture(scope="module")
def materials():
    return Materials({"silicone": 0.18, "Al2O3": 30.0}, {("Al2O3", "silicone"): 1e-7},
                     matrix="silicone")


@pytest.fixture(scope="module")
def rb(problem, materials):
    return ReducedBasis(problem, materials, BOUNDS, tol=1e-4, max_solves=20, solver="fv",
                        solver_tol=1e-10).fit()


def truth(problem, materials, params):
    res = homogenize(problem, materials.with_parameters(params), solver="fv", tol=1e-11)
    return np.diag(res.k_eff_energy)


HELD_OUT = [{"k_Al2O3": 23.3, "R_Al2O3_silicone": 3.1e-8},
            {"k_Al2O3": 37.9, "R_Al2O3_silicone": 4.2e-6},
            {"k_Al2O3": 29.0, "R_Al2O3_silicone": 4.6e-5}]


@pytest.mark.parametrize("params", HELD_OUT)
def test_held_out_full_solves_lie_between_the_bounds(rb, problem, materials, params):
    k = truth(problem, materials, params)
    pred = np.diag(rb.predict(params)[0])
    lower, upper = rb.bounds_of(params)
    est = rb.error_estimate(params)[0]
    assert np.all(np.abs(pred - k) / k <= 1e-4)
    # the dual (flux) bound is rigorous; the primal one up to the interpolation error
    assert np.all(lower[0] <= k * (1 + 1e-12))
    assert np.all(k <= upper[0] * (1 + 1e-12))
    assert np.all(np.abs(pred - k) <= est)


def test_the_galerkin_value_is_exact_at_a_solved_parameter_set(rb, problem, materials):
    solved = rb.history_[1]["parameters"]
    k = truth(problem, materials, solved)
    np.testing.assert_allclose(np.diag(rb.predict(solved)[0]), k, rtol=1e-7)
    assert rb.error_estimate(solved)[0].max() / k.min() < 1e-6


def test_fit_records_a_converged_greedy(rb):
    assert rb.converged_ and rb.training_gap_ <= 1e-4
    assert 2 <= rb.n_solves_ <= 20 and len(rb.history_) == rb.n_solves_
    gaps = [h["training_gap"] for h in rb.history_]
    assert gaps[-1] < gaps[0]
    assert rb.interpolation_error_ < 1e-6


def test_k_eff_rises_with_filler_conductivity_and_falls_with_resistance(rb):
    k = np.linspace(20.0, 40.0, 5)
    up = rb.predict({"k_Al2O3": k, "R_Al2O3_silicone": np.full(5, 1e-8)})[:, 0, 0]
    assert np.all(np.diff(up) > 0)
    r = np.logspace(-8, np.log10(5e-5), 6)
    down = rb.predict({"k_Al2O3": np.full(6, 30.0), "R_Al2O3_silicone": r})[:, 0, 0]
    assert np.all(np.diff(down) < 0)


def test_input_forms_agree(rb):
    sets = [{"k_Al2O3": 25.0}, {"R_Al2O3_silicone": 2e-6}]
    as_list = rb.predict(sets)
    as_columns = rb.predict({"k_Al2O3": [25.0, 30.0], "R_Al2O3_silicone": [1e-7, 2e-6]})
    np.testing.assert_allclose(as_list, as_columns, rtol=1e-13)
    assert as_list.shape == (2, 3, 3)
    np.testing.assert_allclose(as_list, np.swapaxes(as_list, 1, 2), rtol=1e-12)


def test_save_and_load_predict_identically_without_pickle(rb, tmp_path, monkeypatch):
    path = rb.save(tmp_path / "rb.npz")
    X = {"k_Al2O3": np.linspace(20, 40, 7), "R_Al2O3_silicone": np.logspace(-8, -4.5, 7)}

    def refuse(*args, **kwargs):
        raise AssertionError("pickle was used")

    monkeypatch.setattr(pickle, "loads", refuse)
    monkeypatch.setattr(pickle, "load", refuse)
    again = ReducedBasis.load(path)
    np.testing.assert_array_equal(again.predict(X), rb.predict(X))
    np.testing.assert_array_equal(again.error_estimate(X), rb.error_estimate(X))
    assert again.history_ == rb.history_


def test_a_file_holding_an_object_array_is_refused(tmp_path):
    path = tmp_path / "evil.npz"
    np.savez(path, meta=np.array([{"format": "itr-reduced-basis"}], dtype=object))
    with refuses(ValueError, "path"):
        ReducedBasis.load(path)


def test_the_face_resistance_is_affine_in_inverse_conductivity_and_resistance(problem, materials):
    box = ParameterBox(BOUNDS, materials)
    dec = ResistanceDecomposition(problem.geometry, materials, box)
    assert dec.check_error < 1e-12
    # inside particles g = k / h exactly: the pure faces of k_Al2O3
    assert dec.pure[0].size > 0 and dec.pure[1].size == 0
    np.testing.assert_allclose(dec.a[dec.pure[0], 0], problem.voxel_m, rtol=1e-12)


def test_projection_removes_divergence_and_keeps_the_mean_flux():
    rng = np.random.default_rng(0)
    q = rng.normal(size=(3, 6, 5, 4)) + np.array([1.0, 2.0, 3.0])[:, None, None, None]
    p = _project_divergence_free(q)
    assert np.abs(_divergence(p)).max() < 1e-12
    np.testing.assert_allclose(p.mean(axis=(1, 2, 3)), q.mean(axis=(1, 2, 3)), rtol=1e-12)


@pytest.mark.parametrize("bounds,match", [
    ({"Gc_Al2O3_Al2O3": (1e-7, 1e-6)}, "contact-spot"),
    ({"k_nosuch": (1.0, 2.0)}, "not a parameter of materials"),
    ({"R_Al2O3_silicone": (1e-6, 1e-7)}, "lo < hi"),
    ({"R_silicone_Al2O3": (1e-8, 1e-7)}, "sorted order"),
    ({}, "non-empty"),
])
def test_bad_bounds_name_the_argument(problem, materials, bounds, match):
    with pytest.raises(ValueError, match=match):
        ReducedBasis(problem, materials, bounds, max_solves=1).fit()


@pytest.mark.parametrize("kwargs,match", [
    ({"tol": 0.0}, "tol"), ({"max_solves": 0}, "max_solves"), ({"solver": "quantum"}, "solver"),
    ({"n_train": 2.5}, "n_train"),
])
def test_bad_settings_name_the_argument(problem, materials, kwargs, match):
    with refuses(ValueError, match):
        ReducedBasis(problem, materials, BOUNDS, **kwargs).fit()


def test_contact_spots_are_refused(problem, materials):
    spotted = Materials({"silicone": 0.18, "Al2O3": 30.0}, {("Al2O3", "silicone"): 1e-7},
                        matrix="silicone", contact_conductance={("Al2O3", "Al2O3"): 1e-6})
    with refuses(ValueError, "materials"):
        ReducedBasis(problem, spotted, BOUNDS).fit()


@pytest.mark.parametrize("sets,match", [
    ({"R_Al2O3_silicone": 1e-3}, "outside the reduced basis bounds"),
    ({"k_silicone": 0.3}, "fixed at 0.18"),
    ({"k_nosuch": 1.0}, "unknown parameter"),
    ({"k_Al2O3": float("nan")}, "NaN"),
    ({"k_Al2O3": [20.0, 30.0], "R_Al2O3_silicone": [1e-7]}, "different lengths"),
    ("k_Al2O3", "expected a mapping"),
])
def test_bad_parameter_sets_name_the_parameter(rb, sets, match):
    with pytest.raises(ValueError, match=match):
        rb.predict(sets)


def test_unfitted_model_says_so(problem, materials):
    with refuses(ValueError, "ReducedBasis"):
        ReducedBasis(problem, materials, BOUNDS).predict({"k_Al2O3": 30.0})


def test_stopping_at_max_solves_warns_and_says_so(problem, materials):
    from itr_surrogate.reduced_basis import ReducedBasisWarning

    with pytest.warns(ReducedBasisWarning, match="above tol"):
        rb = ReducedBasis(problem, materials, BOUNDS, tol=1e-6, max_solves=1, solver="fv").fit()
    assert not rb.converged_ and rb.n_solves_ == 1 and rb.training_gap_ > 1e-6
