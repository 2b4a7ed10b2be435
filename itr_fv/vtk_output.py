"""VTK (.vti) output of homogenization fields and off-screen renders (pyvista)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

    from .result import HomogenizationResult

__all__ = ["to_image_data", "write_vti", "render_png", "cell_flux"]


def cell_flux(fluxes: np.ndarray) -> np.ndarray:
    """Cell-centred flux vector (W/m^2), the mean of the two faces of a voxel on each axis.

    Parameters
    ----------
    fluxes : ndarray, shape (3, n1, n2, n3)
        Face flux densities of one load case.

    Returns
    -------
    ndarray, shape (n1, n2, n3, 3)
    """
    return np.stack([0.5 * (fluxes[d] + np.roll(fluxes[d], 1, axis=d)) for d in range(3)],
                    axis=-1)


def to_image_data(result: "HomogenizationResult") -> "pyvista.ImageData":
    """pyvista ImageData of the microstructure and the fields of every load case.

    Cell arrays: ``material`` (id), ``particle_id``, ``temperature`` and ``flux_magnitude``
    of the first load case (K for E = 1 K/m; W/m^2), and per load case ``temperature_eN``,
    ``flux_eN`` (vector) and ``flux_magnitude_eN``. Field data: ``k_eff`` (W/(m K)) and
    the phase names.
    """
    import pyvista as pv

    ms = result.microstructure
    if ms is None:
        raise ValueError("result: holds no microstructure to write")
    if result.temperature is None or result.fluxes is None:
        raise ValueError("result: fields were not stored (solve with store_fields=True)")
    n = ms.shape
    h = ms.voxel_m
    grid = pv.ImageData(dimensions=(n[0] + 1, n[1] + 1, n[2] + 1), spacing=(h, h, h))

    def flat(a: np.ndarray) -> np.ndarray:  # VTK orders cells x fastest
        return np.asarray(a).ravel(order="F")

    grid.cell_data["material"] = flat(ms.material_ids)
    grid.cell_data["particle_id"] = flat(ms.particle_ids)
    for c, d in enumerate(result.directions):
        q = cell_flux(result.fluxes[c])
        mag = np.sqrt((q * q).sum(axis=-1))
        grid.cell_data[f"temperature_e{d + 1}"] = flat(result.temperature[c])
        grid.cell_data[f"flux_e{d + 1}"] = q.reshape(-1, 3, order="F")
        grid.cell_data[f"flux_magnitude_e{d + 1}"] = flat(mag)
        if c == 0:
            grid.cell_data["temperature"] = flat(result.temperature[c])
            grid.cell_data["flux_magnitude"] = flat(mag)
    grid.field_data["k_eff"] = result.k_eff.ravel()
    grid.field_data["phase_names"] = np.array(ms.names)
    grid.cell_data.active_scalars_name = "temperature"
    return grid


def write_vti(result: "HomogenizationResult", path: str | Path) -> Path:
    """Write the fields of ``result`` as a VTK XML image (``.vti``); returns the path."""
    path = Path(path)
    if path.suffix != ".vti":
        raise ValueError(f"path: expected a .vti file name, got {str(path)!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    to_image_data(result).save(str(path))
    return path


def render_png(result: "HomogenizationResult", path: str | Path, load_case: int = 0,
               window_size: tuple[int, int] = (1200, 600)) -> Path:
    """Off-screen render: temperature on three mid-plane slices, and the particles.

    No display is needed (pyvista ``off_screen``).

    Parameters
    ----------
    result : HomogenizationResult
    path : str or Path
        PNG file to write.
    load_case : int
        Index into ``result.directions`` whose temperature is shown.
    window_size : (int, int)
        Pixels.
    """
    import pyvista as pv

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"path: expected a .png file name, got {str(path)!r}")
    if not 0 <= load_case < len(result.directions):
        raise ValueError(f"load_case: expected 0..{len(result.directions) - 1}, got {load_case}")
    grid = to_image_data(result)
    name = f"temperature_e{result.directions[load_case] + 1}"
    grid.cell_data.active_scalars_name = name
    pl = pv.Plotter(off_screen=True, shape=(1, 2), window_size=list(window_size))
    pl.subplot(0, 0)
    pl.add_text(f"T for E = e{result.directions[load_case] + 1} (K)", font_size=10)
    pl.add_mesh(grid.cell_data_to_point_data().slice_orthogonal(), scalars=name, cmap="turbo",
                lighting=False, show_scalar_bar=True)
    pl.add_mesh(grid.outline(), color="black")
    pl.subplot(0, 1)
    pl.add_text("particles by material", font_size=10)
    solid = grid.threshold(0.5, scalars="particle_id")
    if solid.n_cells:
        pl.add_mesh(solid.extract_surface(algorithm="dataset_surface"), scalars="material",
                    cmap="Set1",
                    show_scalar_bar=False)
    pl.add_mesh(grid.outline(), color="black")
    pl.link_views()
    path.parent.mkdir(parents=True, exist_ok=True)
    pl.screenshot(str(path))
    pl.close()
    return path
