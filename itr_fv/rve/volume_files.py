"""Segmented volumes on disk: label images of micro-CT or FIB-SEM scans read (and written) in
the common formats, with their voxel size.

=================  =====================================================================
suffix             what is read
=================  =====================================================================
``.tif .tiff``     a multi-page TIFF (tifffile): the first series, one page per slice;
                   voxel from ImageJ's ``spacing`` and ``unit`` with the X/Y resolution
                   tags, else a ``voxel_um`` key of tifffile's JSON description; the X/Y
                   resolution tags alone (with a physical resolution unit) state two axes
``.npy``           one array (``np.load(allow_pickle=False)``); no voxel size
``.npz``           one array, or the one named (``array``); a 0-d ``voxel_um`` entry is
                   the voxel size
``.vti .vtk``      VTK image data (pyvista): a cell array (one voxel per cell) or a point
                   array (one voxel per point), the only one or the one named; the VTK
                   spacing is read in metres when it lies in :data:`VTK_METRE_RANGE`
                   (the package's own ``.vti`` files), otherwise it is not read as a voxel
                   size (VTK states no unit)
``.raw``           raw binary with a header beside it, ``NAME.json`` or ``NAME.toml`` for
                   ``NAME.raw``: see :data:`RAW_HEADER_KEYS`
=================  =====================================================================

The label array keeps the axis order the file stores (TIFF: page, row, column; VTK: x, y, z;
NumPy and raw: the array's own): the tensor of a solve is given in that order, axis 0 first.

The voxel size is given (``voxel_um``) or read from the file; it is refused when the two
disagree, when neither states it, and when the file states different spacings per axis
(non-cubic voxels: the discrete model needs cubic ones). Labels must be integers >= 0 (a
boolean mask is read as 0/1); a float image is refused, integral values or not: segment it,
or store its labels as an integer type.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io import atomic_path, read_toml, sha256

__all__ = ["LabelVolume", "read_volume", "read_labels", "write_volume", "VOLUME_SUFFIXES",
           "RAW_HEADER_KEYS", "VTK_METRE_RANGE"]

VOLUME_SUFFIXES = (".tif", ".tiff", ".npy", ".npz", ".vti", ".vtk", ".raw")
#: The header of a ``.raw`` volume (JSON or TOML): ``shape`` (three ints, the NumPy shape),
#: ``dtype`` (``uint8``, ``uint16``, ``int32``, ... : integers only), ``byte_order``
#: (``little`` or ``big``; default ``little``), ``order`` (``C``: the last axis varies
#: fastest in the file, the default; ``F``: the first), ``header_bytes`` (bytes to skip at
#: the start; default 0) and ``voxel_um`` (optional).
RAW_HEADER_KEYS = ("shape", "dtype", "byte_order", "order", "header_bytes", "voxel_um")
#: VTK spacings read as metres, m (1 nm to 1 mm voxels); other values are not a voxel size.
VTK_METRE_RANGE = (1e-9, 1e-3)
#: Relative tolerance of "the same spacing" (TIFF resolutions are rationals).
SPACING_RTOL = 1e-5
_TIFF_UNITS_UM = {"um": 1.0, "micron": 1.0, "microns": 1.0, "micrometer": 1.0,
                  "micrometre": 1.0, "\u00b5m": 1.0, "\\u00B5m": 1.0, "nm": 1e-3,
                  "mm": 1e3, "cm": 1e4, "m": 1e6, "inch": 25400.0}
_RESUNIT_UM = {2: 25400.0, 3: 1e4, 4: 1e3, 5: 1.0}  # inch, cm, mm, um per resolution unit


@dataclass(frozen=True)
class LabelVolume:
    """A segmented volume: integer labels per voxel and the voxel edge.

    Attributes
    ----------
    labels : ndarray of int, shape (n1, n2, n3)
        One label per voxel, >= 0.
    voxel_um : float
        Voxel edge, um (cubic voxels).
    voxel_source : str
        Where the voxel size came from (``"voxel_um"``, ``"the file (...)"`` or both).
    path : str
        The file read ("" for an array).
    format : str
        The file's suffix (``".tif"``, ...).
    axes : tuple of str
        What the three array axes are in the file (``("page", "row", "column")``, ...).
    sha256 : str
        SHA-256 of the file ("" for an array).
    notes : tuple of str
        What was read and not used (a VTK spacing that is no voxel size, ...).
    """

    labels: np.ndarray
    voxel_um: float
    voxel_source: str = "voxel_um"
    path: str = ""
    format: str = ""
    axes: tuple[str, str, str] = ("axis 0", "axis 1", "axis 2")
    sha256: str = ""
    notes: tuple[str, ...] = field(default=())

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.labels.shape)  # type: ignore[return-value]

    @property
    def voxel_m(self) -> float:
        """Voxel edge, m."""
        return self.voxel_um * 1e-6

    def describe(self) -> dict:
        """JSON-able record of what was read (the labels left out)."""
        return {"path": self.path, "sha256": self.sha256, "format": self.format,
                "shape": list(self.shape), "axes": list(self.axes),
                "dtype": str(self.labels.dtype), "voxel_um": self.voxel_um,
                "voxel_source": self.voxel_source, "notes": list(self.notes)}


# ----------------------------------------------------------------------------- checks
def _label_array(a: object, where: str, argument: str) -> np.ndarray:
    """``a`` as a 3-D integer label array (a bool mask as uint8); ValueError naming
    ``argument`` for another dtype, dimension, no voxels or a negative label."""
    arr = np.asarray(a)
    if arr.dtype == bool:
        arr = arr.astype(np.uint8)
    if np.issubdtype(arr.dtype, np.floating):
        raise ValueError(f"{argument}: {where} holds a {arr.dtype} image, not integer "
                         "labels: segment it first (one label per phase), or store its "
                         "labels as integers (numpy: a.astype(np.uint8))")
    if not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"{argument}: {where} holds {arr.dtype} values, not integer labels")
    if arr.ndim != 3:
        raise ValueError(f"{argument}: {where} is not a 3-D label image (shape "
                         f"{tuple(arr.shape)}); a stack of slices is needed")
    if arr.size == 0:
        raise ValueError(f"{argument}: {where} holds no voxels (shape {tuple(arr.shape)})")
    if np.issubdtype(arr.dtype, np.signedinteger) and arr.min() < 0:
        raise ValueError(f"{argument}: {where} holds negative labels (min {int(arr.min())}); "
                         "labels are integers >= 0")
    return np.ascontiguousarray(arr)


def _voxel(stated: tuple[float | None, float | None, float | None] | None, how: str,
           given: float | None, argument: str) -> tuple[float, str]:
    """The voxel edge (um) and its source from the file's ``stated`` spacings per axis (um,
    None where not stated) and the ``given`` one; ValueError when they disagree, the file's
    differ by axis, or neither states it."""
    said = [s for s in (stated or ()) if s is not None]
    if said and not np.allclose(said, said[0], rtol=SPACING_RTOL, atol=0.0):
        raise ValueError(f"{argument}: non-cubic voxels: the file states spacings "
                         f"{', '.join(f'{s:.6g}' for s in said)} um by axis ({how}); the "
                         "discrete model needs cubic voxels: resample the volume")
    if given is not None:
        v = float(given)
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"voxel_um: expected a voxel edge > 0 (um), got {given!r}")
        if said and not math.isclose(v, said[0], rel_tol=SPACING_RTOL):
            raise ValueError(f"voxel_um: {v:g} um disagrees with the {said[0]:.6g} um the "
                             f"file states ({how}); give the file's value or none, or "
                             "correct the file")
        return v, "voxel_um, as the file states" if said else "voxel_um"
    if stated is not None and len(said) == 3:
        return float(said[0]), f"the file ({how})"
    what = f"states only {len(said)} of 3 axes ({how})" if said else "states no voxel size"
    raise ValueError(f"voxel_um: the file {what}; give the voxel edge (--voxel-um)")


def _existing(path: Path, argument: str) -> str:
    if not path.exists():
        raise ValueError(f"{argument}: no such file {str(path)!r}")
    if path.is_dir():
        raise ValueError(f"{argument}: {str(path)!r} is a folder, not a volume file")
    suffix = path.suffix.lower()
    if suffix not in VOLUME_SUFFIXES:
        raise ValueError(f"{argument}: unknown file type {suffix or '(no suffix)'!r} of "
                         f"{str(path)!r} (known: {', '.join(VOLUME_SUFFIXES)})")
    if path.stat().st_size == 0:
        raise ValueError(f"{argument}: {str(path)!r} is empty (0 bytes)")
    return suffix


# ----------------------------------------------------------------------------- readers
def _tiff_spacing(tif) -> tuple[tuple | None, str]:
    """Spacings per array axis (page, row, column), um, that a TIFF states, and how."""
    page = tif.pages.first if hasattr(tif.pages, "first") else tif.pages[0]
    xy = None
    res = page.tags.get("XResolution"), page.tags.get("YResolution")
    unit = int(page.tags["ResolutionUnit"].value) if "ResolutionUnit" in page.tags else 1
    ij = tif.imagej_metadata or {}
    scale = _TIFF_UNITS_UM.get(str(ij.get("unit", "")).strip()) if ij else None
    if scale is None:
        scale = _RESUNIT_UM.get(unit)
    if res[0] is not None and res[1] is not None and scale is not None:
        xy = [scale * r.value[1] / r.value[0] if r.value[0] else None for r in res]
    z = scale * float(ij["spacing"]) if ij and "spacing" in ij and scale else None
    for meta in (tif.shaped_metadata or ()):
        if isinstance(meta, Mapping) and "voxel_um" in meta:
            v = float(meta["voxel_um"])
            return (v, v, v), "its JSON description's voxel_um"
    if xy is None and z is None:
        return None, "no resolution"
    how = "ImageJ spacing and resolution" if z is not None else "X/Y resolution tags"
    return (z, xy[1] if xy else None, xy[0] if xy else None), how


def _read_tiff(path: Path, argument: str, array: str | None):
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            arr = tif.series[0].asarray()
            stated, how = _tiff_spacing(tif)
    except (tifffile.TiffFileError, ValueError, IndexError, KeyError) as exc:
        raise ValueError(f"{argument}: {str(path)!r} is not a readable TIFF ({exc})") from None
    return arr, stated, how, ("page", "row", "column"), ()


def _read_npy(path: Path, argument: str, array: str | None):
    try:
        arr = np.load(path, allow_pickle=False)
    except ValueError as exc:
        raise ValueError(f"{argument}: {str(path)!r} is not a plain NumPy array ({exc}); "
                         "object arrays (pickle) are not read") from None
    if isinstance(arr, np.lib.npyio.NpzFile):
        arr.close()
        raise ValueError(f"{argument}: {str(path)!r} is an .npz archive named .npy")
    return arr, None, "an .npy file states none", ("axis 0", "axis 1", "axis 2"), ()


def _read_npz(path: Path, argument: str, array: str | None):
    try:
        archive = np.load(path, allow_pickle=False)
    except (ValueError, OSError) as exc:
        raise ValueError(f"{argument}: {str(path)!r} is not an .npz archive ({exc})") from None
    with archive:
        names = [n for n in archive.files if n != "voxel_um"]
        if array is None:
            if len(names) != 1:
                raise ValueError(f"{argument}: {str(path)!r} holds {len(names)} arrays "
                                 f"({', '.join(names) or 'none'}); name the label array")
            array = names[0]
        if array not in names:
            raise ValueError(f"{argument}: {str(path)!r} holds no array {array!r} (arrays: "
                             f"{', '.join(names)})")
        try:
            arr = archive[array]
            voxel = float(archive["voxel_um"]) if "voxel_um" in archive.files else None
        except (ValueError, TypeError) as exc:
            raise ValueError(f"{argument}: {str(path)!r}: {exc}; object arrays (pickle) "
                             "are not read") from None
    stated = None if voxel is None else (voxel, voxel, voxel)
    return arr, stated, "its voxel_um entry", ("axis 0", "axis 1", "axis 2"), ()


def _read_vtk(path: Path, argument: str, array: str | None):
    import pyvista as pv

    quiet = pv.vtk_verbosity("off") if hasattr(pv, "vtk_verbosity") else _nothing()
    try:
        with quiet:
            grid = pv.read(str(path))
    except Exception as exc:  # noqa: BLE001 - VTK's readers raise anything
        raise ValueError(f"{argument}: {str(path)!r} is not a readable VTK file ({exc})") \
            from None
    if not isinstance(grid, pv.ImageData):
        raise ValueError(f"{argument}: {str(path)!r} holds {type(grid).__name__}, not VTK "
                         "image data (structured points)")
    cells, points = list(grid.cell_data.keys()), list(grid.point_data.keys())
    if array is None:
        if len(cells) + len(points) != 1:
            raise ValueError(f"{argument}: {str(path)!r} holds {len(cells)} cell and "
                             f"{len(points)} point arrays ({', '.join(cells + points) or 'none'}"
                             "); name the label array")
        array = (cells + points)[0]
    if array not in cells and array not in points:
        raise ValueError(f"{argument}: {str(path)!r} holds no array {array!r} (arrays: "
                         f"{', '.join(cells + points)})")
    on_cells = array in cells
    dims = tuple(int(d) - (1 if on_cells else 0) for d in grid.dimensions)
    data = np.asarray(grid.cell_data[array] if on_cells else grid.point_data[array])
    if data.ndim != 1:
        raise ValueError(f"{argument}: array {array!r} of {str(path)!r} has "
                         f"{data.shape[1]} components per voxel, not one label")
    arr = data.reshape(dims, order="F")
    spacing = [float(s) for s in grid.spacing]
    lo, hi = VTK_METRE_RANGE
    if all(lo <= s <= hi for s in spacing):
        return arr, tuple(s * 1e6 for s in spacing), "VTK spacing in m", ("x", "y", "z"), ()
    note = (f"the VTK spacing {', '.join(f'{s:g}' for s in spacing)} has no unit and is not "
            f"a voxel in metres ({lo:g} - {hi:g} m): not read as the voxel size")
    if not np.allclose(spacing, spacing[0], rtol=SPACING_RTOL):
        raise ValueError(f"{argument}: non-cubic voxels: the VTK spacing differs by axis "
                         f"({', '.join(f'{s:g}' for s in spacing)}); the discrete model needs "
                         "cubic voxels: resample the volume")
    return arr, None, "VTK spacing without a unit", ("x", "y", "z"), (note,)


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def _raw_header(path: Path, argument: str) -> tuple[dict, Path]:
    found = [p for p in (path.with_suffix(".json"), path.with_suffix(".toml")) if p.exists()]
    if len(found) != 1:
        raise ValueError(f"{argument}: a .raw volume needs one header beside it, "
                         f"{path.with_suffix('.json').name} or {path.with_suffix('.toml').name} "
                         f"({'both' if found else 'neither'} found)")
    head = found[0]
    if head.suffix == ".toml":
        try:
            return read_toml(head, "raw header"), head
        except ValueError as exc:
            raise ValueError(f"{argument}: {exc}") from None
    try:
        data = json.loads(head.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{argument}: {head}: not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{argument}: {head}: expected a JSON object of "
                         f"{', '.join(RAW_HEADER_KEYS)}")
    return data, head


def _raw_layout(head: dict, name: str, argument: str) -> tuple[tuple, np.dtype, str, int]:
    unknown = sorted(set(head) - set(RAW_HEADER_KEYS))
    if unknown:
        raise ValueError(f"{argument}: {name}: unknown key {unknown[0]!r} (known: "
                         f"{', '.join(RAW_HEADER_KEYS)})")
    shape = head.get("shape")
    if not (isinstance(shape, list) and all(isinstance(s, int) and not isinstance(s, bool)
                                            and s > 0 for s in shape)):
        raise ValueError(f"{argument}: {name}: shape: expected positive integers, got "
                         f"{shape!r}")
    try:
        dtype = np.dtype(str(head.get("dtype")))
    except TypeError:
        raise ValueError(f"{argument}: {name}: dtype: not a NumPy dtype name: "
                         f"{head.get('dtype')!r}") from None
    order = head.get("byte_order", "little")
    layout = head.get("order", "C")
    skip = head.get("header_bytes", 0)
    if order not in ("little", "big") or layout not in ("C", "F") or \
            not isinstance(skip, int) or skip < 0:
        raise ValueError(f"{argument}: {name}: byte_order little|big, order C|F and "
                         f"header_bytes >= 0 expected, got {order!r}, {layout!r}, {skip!r}")
    return tuple(shape), dtype.newbyteorder("<" if order == "little" else ">"), layout, skip


def _read_raw(path: Path, argument: str, array: str | None):
    head, head_path = _raw_header(path, argument)
    shape, dtype, layout, skip = _raw_layout(head, head_path.name, argument)
    if np.issubdtype(dtype, np.floating):
        raise ValueError(f"{argument}: {head_path.name} states dtype {dtype.name}, not integer "
                         "labels: segment the volume first, or store its labels as integers")
    need = skip + math.prod(shape) * dtype.itemsize
    size = path.stat().st_size
    if size != need:
        raise ValueError(f"{argument}: {str(path)!r} holds {size} bytes but its header "
                         f"({list(shape)} of {dtype.name} after {skip} bytes) needs {need}")
    arr = np.fromfile(path, dtype=dtype, offset=skip).reshape(shape, order=layout)
    arr = arr.astype(dtype.newbyteorder("="))
    voxel = head.get("voxel_um")
    stated = None if voxel is None else (float(voxel),) * 3
    return arr, stated, f"{head_path.name}'s voxel_um", ("axis 0", "axis 1", "axis 2"), ()


_READERS = {".tif": _read_tiff, ".tiff": _read_tiff, ".npy": _read_npy, ".npz": _read_npz,
            ".vti": _read_vtk, ".vtk": _read_vtk, ".raw": _read_raw}


def read_labels(path: str | os.PathLike, *, array: str | None = None,
                argument: str = "volume") -> tuple[np.ndarray, tuple | None, str, tuple, tuple]:
    """The label array of a volume file and what the file says of its voxel, unchecked for
    size: ``(labels, stated spacings per axis in um or None, how stated, axes, notes)``.

    Raises
    ------
    ValueError
        Naming ``argument``: a missing, empty or unreadable file, an unknown suffix, an
        array name that the file lacks, a float, non-3-D or negative label image.
    """
    p = Path(path)
    suffix = _existing(p, argument)
    if array is not None and suffix not in (".npz", ".vti", ".vtk"):
        raise ValueError(f"{argument}: an array name is for .npz and VTK files, not "
                         f"{suffix}")
    arr, stated, how, axes, notes = _READERS[suffix](p, argument, array)
    return _label_array(arr, repr(str(p)), argument), stated, how, axes, notes


def read_volume(path: str | os.PathLike, *, voxel_um: float | None = None,
                array: str | None = None, argument: str = "volume") -> LabelVolume:
    """Read a segmented volume (see the module notes for the formats).

    Parameters
    ----------
    path : path
        The file: ``.tif``/``.tiff``, ``.npy``, ``.npz``, ``.vti``, ``.vtk`` or ``.raw``
        (with its header).
    voxel_um : float, optional
        Voxel edge, um; needed where the file states none, refused where it disagrees.
    array : str, optional
        The label array of an ``.npz`` or VTK file that holds several.
    argument : str
        The name errors give the file (``"volume"``, ``"particles"``).

    Returns
    -------
    LabelVolume

    Raises
    ------
    ValueError
        One line naming ``argument`` (or ``voxel_um``): missing, empty or unreadable file,
        unknown suffix, float labels, not 3-D, no voxels, negative labels, non-cubic
        voxels, no voxel size, or a given voxel size the file contradicts.
    """
    labels, stated, how, axes, notes = read_labels(path, array=array, argument=argument)
    voxel, source = _voxel(stated, how, voxel_um, argument)
    return LabelVolume(labels, voxel, source, str(path), Path(path).suffix.lower(), axes,
                       sha256(path), notes)


# ----------------------------------------------------------------------------- writers
def write_volume(path: str | os.PathLike, labels: np.ndarray, *,
                 voxel_um: float | None = None, array: str = "labels") -> Path:
    """Write a label volume in the format of the suffix of ``path``; returns the path.

    TIFF: ImageJ metadata (spacing, X/Y resolution, unit um) for 8- and 16-bit labels, else
    the resolution tags in micrometres and ``voxel_um`` in tifffile's JSON description;
    ``.npz``: ``array`` and ``voxel_um``; VTK: cell array ``array``, spacing in m; ``.raw``:
    the bytes in C order and ``NAME.json`` (:data:`RAW_HEADER_KEYS`); ``.npy``: the array
    alone (no voxel size). Each file appears under its name only once complete.

    Raises
    ------
    ValueError
        ``path``: an unknown suffix; ``labels``: not a 3-D integer array.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in VOLUME_SUFFIXES:
        raise ValueError(f"path: unknown file type {suffix!r} (known: "
                         f"{', '.join(VOLUME_SUFFIXES)})")
    arr = _label_array(labels, "the array", "labels")
    if voxel_um is None and suffix in (".vti", ".vtk"):
        raise ValueError("voxel_um: a VTK file states its spacing: give voxel_um")
    with atomic_path(p) as tmp:
        _WRITERS[suffix](tmp, arr, voxel_um, array)
    if suffix == ".raw":
        head = {"shape": list(arr.shape), "dtype": arr.dtype.name,
                "byte_order": "big" if arr.dtype.byteorder == ">" else "little",
                "order": "C", "header_bytes": 0}
        if voxel_um is not None:
            head["voxel_um"] = float(voxel_um)
        with atomic_path(p.with_suffix(".json")) as tmp:
            tmp.write_text(json.dumps(head, indent=2) + "\n", encoding="utf-8")
    return p


def _write_tiff(tmp: Path, arr: np.ndarray, voxel_um: float | None, array: str) -> None:
    import tifffile

    if voxel_um is None:
        tifffile.imwrite(tmp, arr)
    elif arr.dtype in (np.uint8, np.uint16):
        tifffile.imwrite(tmp, arr, imagej=True, resolution=(1 / voxel_um, 1 / voxel_um),
                         metadata={"spacing": voxel_um, "unit": "um", "axes": "ZYX"})
    else:
        tifffile.imwrite(tmp, arr, resolution=(1 / voxel_um, 1 / voxel_um),
                         resolutionunit="MICROMETER", metadata={"voxel_um": voxel_um})


def _write_npy(tmp: Path, arr: np.ndarray, voxel_um: float | None, array: str) -> None:
    np.save(tmp, arr, allow_pickle=False)


def _write_npz(tmp: Path, arr: np.ndarray, voxel_um: float | None, array: str) -> None:
    extra = {} if voxel_um is None else {"voxel_um": np.float64(voxel_um)}
    np.savez_compressed(tmp, **{array: arr}, **extra)


def _write_vtk(tmp: Path, arr: np.ndarray, voxel_um: float | None, array: str) -> None:
    import pyvista as pv

    h = float(voxel_um) * 1e-6
    grid = pv.ImageData(dimensions=tuple(n + 1 for n in arr.shape), spacing=(h, h, h))
    grid.cell_data[array] = arr.ravel(order="F")
    if tmp.suffix.lower() == ".vti":
        grid.save(str(tmp), binary=True, compression="zlib")
    else:
        grid.save(str(tmp), binary=True)


def _write_raw(tmp: Path, arr: np.ndarray, voxel_um: float | None, array: str) -> None:
    arr.tofile(tmp)


_WRITERS = {".tif": _write_tiff, ".tiff": _write_tiff, ".npy": _write_npy,
            ".npz": _write_npz, ".vti": _write_vtk, ".vtk": _write_vtk, ".raw": _write_raw}
