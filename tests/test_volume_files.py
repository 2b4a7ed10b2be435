"""Segmented volumes on disk (itr_fv.rve.volume_files): every format round-trips the labels
and the voxel size, metadata written by other libraries is read, and bad volumes are refused
in one line naming the argument."""

import json

import numpy as np
import pytest
import tifffile

from itr_fv import read_volume, write_volume
from itr_fv.rve.volume_files import VOLUME_SUFFIXES
from tests.refusals import refuses

FORMATS = (".tif", ".npy", ".npz", ".vti", ".vtk", ".raw")


def labels(dtype=np.uint8, shape=(6, 7, 8)) -> np.ndarray:
    """Labels that differ along every axis, so that a transposed read shows."""
    i, j, k = np.indices(shape)
    return ((i + 2 * j + 3 * k) % 3).astype(dtype)


@pytest.mark.parametrize("suffix", FORMATS)
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int32])
def test_every_format_round_trips_labels_and_voxel(tmp_path, suffix, dtype):
    a = labels(dtype)
    path = write_volume(tmp_path / f"v{suffix}", a, voxel_um=0.3125)
    # an .npy file cannot hold the voxel size: it is given
    vol = read_volume(path, voxel_um=0.3125 if suffix == ".npy" else None)
    assert np.array_equal(vol.labels, a)
    assert vol.shape == a.shape
    assert vol.voxel_um == pytest.approx(0.3125, rel=1e-12)
    assert ("the file" in vol.voxel_source) == (suffix != ".npy")
    assert len(vol.sha256) == 64 and vol.format == suffix


def test_imagej_tiff_of_tifffile_states_its_voxel(tmp_path):
    """A stack written by tifffile the way ImageJ/Fiji writes one: Z spacing and X/Y
    resolution in micrometres."""
    a = labels()
    tifffile.imwrite(tmp_path / "s.tif", a, imagej=True, resolution=(1 / 0.25, 1 / 0.25),
                     metadata={"spacing": 0.25, "unit": "um", "axes": "ZYX"})
    vol = read_volume(tmp_path / "s.tif")
    assert np.array_equal(vol.labels, a) and vol.voxel_um == pytest.approx(0.25)
    assert vol.axes == ("page", "row", "column")
    # the same voxel given: accepted, and said so
    assert read_volume(tmp_path / "s.tif", voxel_um=0.25).voxel_source.startswith("voxel_um")


def test_tiff_resolution_in_centimetres(tmp_path):
    """X/Y resolution tags in pixels per cm (TIFF's own unit), no Z: two axes stated, the
    voxel given must agree with them."""
    tifffile.imwrite(tmp_path / "c.tif", labels(), resolution=(1e4 / 0.5, 1e4 / 0.5),
                     resolutionunit="CENTIMETER")
    with refuses(ValueError, "voxel_um") as info:
        read_volume(tmp_path / "c.tif")
    assert "2 of 3" in str(info.value)
    assert read_volume(tmp_path / "c.tif", voxel_um=0.5).voxel_um == 0.5
    with refuses(ValueError, "voxel_um"):
        read_volume(tmp_path / "c.tif", voxel_um=0.25)


def test_named_arrays_of_npz_and_vtk(tmp_path):
    a, b = labels(), labels(np.int32)[::-1].copy()
    np.savez(tmp_path / "two.npz", phases=a, particles=b)
    assert np.array_equal(read_volume(tmp_path / "two.npz", voxel_um=1.0,
                                      array="particles").labels, b)
    with refuses(ValueError, "volume") as info:
        read_volume(tmp_path / "two.npz", voxel_um=1.0)
    assert "particles" in str(info.value) and "phases" in str(info.value)
    import pyvista as pv
    grid = pv.ImageData(dimensions=(7, 8, 9), spacing=(2e-7,) * 3)
    grid.cell_data["phase"] = a.ravel(order="F")
    grid.cell_data["other"] = b.ravel(order="F")
    grid.save(str(tmp_path / "two.vti"))
    vol = read_volume(tmp_path / "two.vti", array="phase")
    assert np.array_equal(vol.labels, a) and vol.voxel_um == pytest.approx(0.2)


def test_vtk_point_data_and_unitless_spacing(tmp_path):
    """A point array is one voxel per point; a spacing outside 1 nm - 1 mm is not read as
    metres (VTK states no unit), so the voxel must be given."""
    import pyvista as pv
    a = labels()
    grid = pv.ImageData(dimensions=a.shape, spacing=(0.5, 0.5, 0.5))
    grid.point_data["labels"] = a.ravel(order="F")
    grid.save(str(tmp_path / "p.vti"))
    with refuses(ValueError, "voxel_um"):
        read_volume(tmp_path / "p.vti")
    vol = read_volume(tmp_path / "p.vti", voxel_um=0.5)
    assert np.array_equal(vol.labels, a) and vol.notes


def test_raw_with_a_toml_header_big_endian_fortran_order(tmp_path):
    a = labels(np.uint16)
    (tmp_path / "s.raw").write_bytes(b"HEAD" + a.astype(">u2").tobytes(order="F"))
    (tmp_path / "s.toml").write_text('shape = [6, 7, 8]\ndtype = "uint16"\nbyte_order = '
                                     '"big"\norder = "F"\nheader_bytes = 4\nvoxel_um = 1.5\n')
    vol = read_volume(tmp_path / "s.raw")
    assert np.array_equal(vol.labels, a) and vol.voxel_um == 1.5


# ------------------------------------------------------------------------------ refusals
def test_float_labels_refused_even_when_integral(tmp_path):
    np.save(tmp_path / "f.npy", labels().astype(np.float32))
    with refuses(ValueError, "volume") as info:
        read_volume(tmp_path / "f.npy", voxel_um=1.0)
    assert "float32" in str(info.value) and "astype" in str(info.value)


@pytest.mark.parametrize("shape", [(5, 6), (2, 3, 4, 5), (0, 4, 4)])
def test_not_3d_or_no_voxels_refused(tmp_path, shape):
    np.save(tmp_path / "x.npy", np.zeros(shape, dtype=np.uint8))
    with refuses(ValueError, "volume"):
        read_volume(tmp_path / "x.npy", voxel_um=1.0)


def test_missing_empty_unknown_and_pickled_files_refused(tmp_path):
    with refuses(ValueError, "volume") as info:
        read_volume(tmp_path / "none.tif", voxel_um=1.0)
    assert "no such file" in str(info.value)
    (tmp_path / "e.tif").write_bytes(b"")
    with refuses(ValueError, "volume") as info:
        read_volume(tmp_path / "e.tif", voxel_um=1.0)
    assert "empty" in str(info.value)
    (tmp_path / "x.png").write_bytes(b"\x89PNG")
    with refuses(ValueError, "volume") as info:
        read_volume(tmp_path / "x.png", voxel_um=1.0)
    assert all(s in str(info.value) for s in VOLUME_SUFFIXES)
    np.save(tmp_path / "o.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with refuses(ValueError, "volume") as info:
        read_volume(tmp_path / "o.npy", voxel_um=1.0)
    assert "pickle" in str(info.value)


def test_negative_labels_refused(tmp_path):
    np.save(tmp_path / "n.npy", labels(np.int16) - 1)
    with refuses(ValueError, "volume"):
        read_volume(tmp_path / "n.npy", voxel_um=1.0)


def test_non_cubic_voxels_refused(tmp_path):
    tifffile.imwrite(tmp_path / "z.tif", labels(), imagej=True, resolution=(4.0, 4.0),
                     metadata={"spacing": 0.5, "unit": "um"})
    with refuses(ValueError, "volume") as info:
        read_volume(tmp_path / "z.tif")
    assert "non-cubic" in str(info.value)
    import pyvista as pv
    grid = pv.ImageData(dimensions=(7, 8, 9), spacing=(1.0, 1.0, 2.0))
    grid.cell_data["labels"] = labels().ravel(order="F")
    grid.save(str(tmp_path / "z.vtk"))
    with refuses(ValueError, "volume"):
        read_volume(tmp_path / "z.vtk", voxel_um=1.0)


def test_voxel_needed_where_the_file_states_none(tmp_path):
    write_volume(tmp_path / "v.npy", labels())
    with refuses(ValueError, "voxel_um"):
        read_volume(tmp_path / "v.npy")


def test_raw_whose_size_disagrees_with_its_header_refused(tmp_path):
    write_volume(tmp_path / "r.raw", labels(), voxel_um=1.0)
    head = json.loads((tmp_path / "r.json").read_text())
    head["shape"] = [6, 7, 9]
    (tmp_path / "r.json").write_text(json.dumps(head))
    with refuses(ValueError, "volume") as info:
        read_volume(tmp_path / "r.raw")
    assert "bytes" in str(info.value)
    (tmp_path / "r.json").unlink()
    with refuses(ValueError, "volume"):
        read_volume(tmp_path / "r.raw")
