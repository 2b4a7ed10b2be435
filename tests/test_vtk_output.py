"""VTK output read back with pyvista; off-screen PNG render."""

import re

import numpy as np
import pytest
import pyvista as pv
from conftest import sc_sphere
from refusals import refuses

from itr_fv import Materials, homogenize


@pytest.fixture(scope="module")
def result():
    mat = Materials({"matrix": 1.0, "filler": 10.0}, {("filler", "matrix"): 0.02}, "matrix")
    return homogenize(sc_sphere(16, 0.2), mat, solver="fv", tol=1e-10, directions=(0, 2))


def test_vti_round_trip_holds_all_arrays(result, tmp_path):
    path = result.to_vtk(tmp_path / "field.vti")
    grid = pv.read(path)
    for name in ("material", "particle_id", "temperature_e1", "temperature_fluctuation_e1",
                 "flux_magnitude_e1", "temperature_e3", "flux_e1", "flux_magnitude_e3"):
        assert name in grid.cell_data, name
    assert grid.n_cells == 16**3
    ms = result.microstructure
    # x-fastest VTK ordering maps back onto the (i, j, k) arrays
    np.testing.assert_array_equal(
        np.asarray(grid.cell_data["particle_id"]).reshape(ms.shape, order="F"), ms.particle_ids)
    T = np.asarray(grid.cell_data["temperature_e1"]).reshape(ms.shape, order="F")
    assert grid.cell_data["temperature_e1"].dtype == np.float32  # default precision
    np.testing.assert_allclose(T, result.temperature[0], rtol=2e-7, atol=1e-7 * np.abs(T).max())
    theta = np.asarray(grid.cell_data["temperature_fluctuation_e1"]).reshape(ms.shape, order="F")
    np.testing.assert_allclose(theta, result.theta[0], rtol=2e-7,
                               atol=1e-6 * np.abs(result.theta[0]).max())
    # temperature falls along the load: T = -x + theta, theta periodic
    assert T[-1].mean() < T[0].mean()
    # the mean flux magnitude in the matrix is close to the effective conductivity for E = 1
    mag = np.asarray(grid.cell_data["flux_magnitude_e1"])
    assert 0.5 * result.k_eff[0, 0] < mag.mean() < 2.0 * result.k_eff[0, 0]
    np.testing.assert_allclose(np.asarray(grid.field_data["k_eff"]).reshape(3, 3)[:, 0],
                               result.k_eff[:, 0])
    assert str(np.asarray(grid.field_data["contact_model"])[0]) == "gap"
    assert str(np.asarray(grid.field_data["solver"])[0]) == "itr_fv"


def test_offscreen_png_render(result, tmp_path, monkeypatch):
    import itr_fv.output.vtk as vtk_out

    texts, axes = [], []
    real = vtk_out.offscreen_plotter

    def recording(**kwargs):   # the plotter, with its captions and axes recorded
        pl = real(**kwargs)
        add_text, show_bounds = pl.add_text, pl.show_bounds
        pl.add_text = lambda text, **kw: texts.append(text) or add_text(text, **kw)
        pl.show_bounds = lambda **kw: axes.append(kw) or show_bounds(**kw)
        return pl

    monkeypatch.setattr(vtk_out, "offscreen_plotter", recording)
    path = result.render_png(tmp_path / "field.png", load_case=1)
    # the caption defines the load E of the picture (load case 1 of directions (0, 2): e3)
    assert texts[0].startswith(
        "heat flux magnitude / mean flux, load E = e3 (z)\n"
        "E: the applied mean temperature gradient, 1 K/m, with T = -E·x + θ (T falls along z)\n"
        "k_11 = ")
    h_um = result.microstructure.voxel_m * 1e6
    assert texts[1] == f"phases (box {16 * h_um:.3g} x {16 * h_um:.3g} x {16 * h_um:.3g} µm, " \
                       f"voxel {h_um:.3g} µm)"
    assert not any(re.search(r"\bum\b", t) for t in texts)
    # both panels show the box's edges as axes, titled in µm (micrometres where VTK 9.6
    # draws no 3-D text)
    unit = "micrometres" if tuple(pv.vtk_version_info[:2]) == (9, 6) else "µm"
    assert [(a["xtitle"], a["ytitle"], a["ztitle"]) for a in axes] == \
        [(f"x ({unit})", f"y ({unit})", f"z ({unit})")] * 2
    assert path.stat().st_size > 10_000
    img = pv.read(path)
    pixels = np.asarray(img.point_data[img.point_data.keys()[0]])
    # a real picture: many distinct colours, not a blank window
    assert len(np.unique(pixels.reshape(len(pixels), -1), axis=0)) > 50


def test_vti_path_must_end_in_vti(result, tmp_path):
    with refuses(ValueError, "path"):
        result.to_vtk(tmp_path / "field.vtk")


def test_vti_subset_and_float64(result, tmp_path):
    path = result.to_vtk(tmp_path / "one.vti", load_cases=[1], vectors=False, precision="float64")
    grid = pv.read(path)
    assert "temperature_e3" in grid.cell_data and "temperature_e1" not in grid.cell_data
    assert "flux_e3" not in grid.cell_data
    T = np.asarray(grid.cell_data["temperature_e3"]).reshape(result.microstructure.shape,
                                                             order="F")
    np.testing.assert_array_equal(T, result.temperature[1])
    assert list(np.asarray(grid.field_data["load_directions"])) == [3]
    with refuses(ValueError, "load_cases"):
        result.to_vtk(tmp_path / "bad.vti", load_cases=[2])
    with refuses(ValueError, "precision"):
        result.to_vtk(tmp_path / "bad.vti", precision="float16")


def test_vti_onto_a_folder_is_refused(result, tmp_path):
    folder = tmp_path / "taken.vti"
    folder.mkdir()
    with refuses(ValueError, "path"):
        result.to_vtk(folder)
    png_folder = tmp_path / "taken.png"
    png_folder.mkdir()
    with refuses(ValueError, "path"):
        result.render_png(png_folder)
    assert list(folder.iterdir()) == [] and list(png_folder.iterdir()) == []
