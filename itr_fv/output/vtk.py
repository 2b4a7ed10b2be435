"""VTK (.vti) output of homogenization fields and off-screen renders (pyvista).

Files are written atomically (:mod:`itr_fv.io`): a killed write leaves no truncated file.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..io import atomic_path, output_file
from .offscreen import DEFAULT_COLORS, PALETTE, add_box_axes, offscreen_plotter, unicode_font

if TYPE_CHECKING:  # pragma: no cover
    import pyvista


class FieldResult(Protocol):
    """What this module reads of a :class:`~itr_fv.solvers.result.HomogenizationResult` (named
    structurally, so that the result may import this module and not the other way round)."""

    k_eff: np.ndarray
    directions: tuple[int, ...]
    temperature: np.ndarray | None
    theta: np.ndarray | None
    fluxes: np.ndarray | None
    microstructure: Any
    solver: str
    info: dict


__all__ = ["to_image_data", "write_vti", "render_png", "cell_flux", "FieldResult"]


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


def _case_indices(result: FieldResult, load_cases: Sequence[int] | None) -> list[int]:
    n = len(result.directions)
    if load_cases is None:
        return list(range(n))
    try:
        cases = [int(c) for c in load_cases]
    except (TypeError, ValueError):
        raise ValueError(f"load_cases: expected indices into result.directions, "
                         f"got {load_cases!r}") from None
    if not cases or any(not 0 <= c < n for c in cases) or len(set(cases)) != len(cases):
        raise ValueError(f"load_cases: expected distinct indices in 0..{n - 1}, got {load_cases!r}")
    return cases


def to_image_data(result: FieldResult, *, load_cases: Sequence[int] | None = None,
                  vectors: bool = True, precision: str = "float32") -> "pyvista.ImageData":
    """pyvista ImageData of the microstructure and the fields of the chosen load cases.

    Cell arrays: ``material`` (id), ``particle_id``; per load case ``eN`` (N = 1, 2, 3 for
    E = e_1, e_2, e_3 of 1 K/m) ``temperature_eN`` (K), ``temperature_fluctuation_eN``
    (theta = T + E.x, K), ``flux_magnitude_eN`` (W/m^2) and, with ``vectors``, ``flux_eN``
    (W/m^2); the first case's temperature is the active scalar. Field data: ``k_eff``
    (W/(m K), float64), ``phase_names``, ``load_directions``, ``contact_model`` and
    ``solver``.

    Parameters
    ----------
    result : HomogenizationResult
        Solved with ``store_fields=True``.
    load_cases : sequence of int, optional
        Indices into ``result.directions`` (default all).
    vectors : bool
        Include the flux vectors (three components per cell).
    precision : {"float32", "float64"}
        Storage of the field arrays; float32 halves the file and keeps 7 digits.
    """
    import pyvista as pv

    ms = result.microstructure
    if ms is None:
        raise ValueError("result: holds no microstructure to write")
    if result.temperature is None or result.fluxes is None or result.theta is None:
        raise ValueError("result: fields were not stored (solve with store_fields=True)")
    if precision not in ("float32", "float64"):
        raise ValueError(f"precision: expected 'float32' or 'float64', got {precision!r}")
    cases = _case_indices(result, load_cases)
    dt = np.dtype(precision)
    n = ms.shape
    h = ms.voxel_m
    grid = pv.ImageData(dimensions=(n[0] + 1, n[1] + 1, n[2] + 1), spacing=(h, h, h))

    def flat(a: np.ndarray) -> np.ndarray:  # VTK orders cells x fastest
        return np.asarray(a).ravel(order="F")

    small = np.uint8 if len(ms.names) < 256 else np.int32
    grid.cell_data["material"] = flat(ms.material_ids.astype(small))
    grid.cell_data["particle_id"] = flat(ms.particle_ids.astype(np.int32))
    for c in cases:
        tag = f"e{result.directions[c] + 1}"
        q = cell_flux(result.fluxes[c])
        mag = np.sqrt((q * q).sum(axis=-1)).astype(dt)
        temp = result.temperature[c].astype(dt)
        grid.cell_data[f"temperature_{tag}"] = flat(temp)
        grid.cell_data[f"temperature_fluctuation_{tag}"] = flat(result.theta[c].astype(dt))
        if vectors:
            grid.cell_data[f"flux_{tag}"] = q.astype(dt).reshape(-1, 3, order="F")
        grid.cell_data[f"flux_magnitude_{tag}"] = flat(mag)
    grid.field_data["k_eff"] = result.k_eff.ravel()
    grid.field_data["phase_names"] = np.array(ms.names)
    grid.field_data["load_directions"] = np.array([result.directions[c] + 1 for c in cases])
    grid.field_data["contact_model"] = np.array([str(result.info.get("contact", "unknown"))])
    grid.field_data["solver"] = np.array([str(result.solver)])
    grid.cell_data.active_scalars_name = f"temperature_e{result.directions[cases[0]] + 1}"
    return grid


def write_vti(result: FieldResult, path: str | Path, *,
              load_cases: Sequence[int] | None = None, vectors: bool = True,
              precision: str = "float32") -> Path:
    """Write the fields of ``result`` as a zlib-compressed VTK XML image; returns the path.

    The file appears under its name only once complete. Arguments after ``path`` are those
    of :func:`to_image_data`.

    Raises
    ------
    ValueError
        If ``path`` does not end in ``.vti`` or names an existing folder.
    """
    path = output_file(path, ".vti")
    grid = to_image_data(result, load_cases=load_cases, vectors=vectors, precision=precision)
    with atomic_path(path) as tmp:
        grid.save(str(tmp), binary=True, compression="zlib")
    return path


def _phase_colours(names: Sequence[str]) -> list[str]:
    extra = iter(PALETTE)
    return [DEFAULT_COLORS.get(n) or next(extra, "grey") for n in names]


#: Axis names of the load directions 0, 1, 2.
_AXES = "xyz"


def load_caption(result: FieldResult, load_case: int, k_text: str | None = None) -> str:
    """The flux panel's caption: the load E it shows (T = -E·x + θ, E = e_d of 1 K/m along
    axis d: the temperature falls along that axis) and the solved diagonal of k_eff,
    W/(m K), or ``k_text`` in its place (a caller that says what the k is, e.g. raw and
    at a fidelity level)."""
    d = result.directions[load_case]
    # only the solved directions: the others' entries are not known (NaN)
    ktxt = ", ".join(f"k_{j + 1}{j + 1} = {result.k_eff[j, j]:.4g}" for j in result.directions
                     if np.isfinite(result.k_eff[j, j])) + " W/(m K)"
    return (f"heat flux magnitude / mean flux, load E = e{d + 1} ({_AXES[d]})\n"
            f"E: the applied mean temperature gradient, 1 K/m, with T = -E·x + θ "
            f"(T falls along {_AXES[d]})\n"
            f"{ktxt if k_text is None else k_text}")


def phase_caption(ms: Any) -> str:
    """The phase panel's caption: the box and voxel edges of ``ms``, µm."""
    h_um = ms.voxel_m * 1e6
    box = " x ".join(f"{s * h_um:.3g}" for s in ms.shape)
    return f"phases (box {box} µm, voxel {h_um:.3g} µm)"


def _caption(pl: pyvista.Plotter, text: str) -> None:
    """``text`` in the upper left of the active subplot, in a font with µm and θ."""
    actor = pl.add_text(text, position="upper_left", font_size=11, color="black")
    unicode_font(actor.GetTextProperty())


def _box_axes(pl: pyvista.Plotter, grid: pyvista.ImageData) -> None:
    """The box outline of the active subplot and its edges as axes in µm."""
    pl.add_mesh(grid.outline(), color="black")
    add_box_axes(pl, grid.bounds, font_size=20, n_labels=5, fmt="%.3g")
    pl.camera_position = "iso"
    pl.camera.zoom(0.8)                       # room for the axis labels around the cube


def render_png(result: FieldResult, path: str | Path, load_case: int = 0,
               window_size: tuple[int, int] = (1600, 800), *,
               k_text: str | None = None) -> Path:
    """Off-screen figure of one load case: heat-flux magnitude with the interfaces, and phases.

    Left: the heat-flux magnitude |q| / |<q>| (dimensionless, log colour scale) on three
    orthogonal mid-planes, with the particle surfaces traced in white on the planes, so
    the hot paths through particles and contacts and the resistive interfaces stand out.
    Right: the same planes coloured by phase with a legend. Both panels show the box's
    edges as axes in µm; the captions define the load E (:func:`load_caption`: the mean
    temperature gradient, 1 K/m along one axis), give k_eff (W/(m K)) and the box and
    voxel (:func:`phase_caption`).

    Parameters
    ----------
    result : HomogenizationResult
        Solved with ``store_fields=True``.
    path : str or Path
        PNG file to write (atomically).
    load_case : int
        Index into ``result.directions``.
    window_size : (int, int)
        Pixels.
    k_text : str, optional
        The caption's k line instead of the solved diagonal (:func:`load_caption`).
    """
    path = output_file(path, ".png")
    if not 0 <= load_case < len(result.directions):
        raise ValueError(f"load_case: expected 0..{len(result.directions) - 1}, got {load_case}")
    grid = to_image_data(result, load_cases=[load_case], vectors=False)
    grid.spacing = (result.microstructure.voxel_m * 1e6,) * 3    # drawn in µm
    ms = result.microstructure
    d = result.directions[load_case]
    tag = f"e{d + 1}"
    mean_q = float(np.linalg.norm(np.nan_to_num(result.k_eff[:, d])))
    rel = np.asarray(grid.cell_data[f"flux_magnitude_{tag}"], dtype=np.float64)
    rel = rel / mean_q if mean_q > 0 else rel
    grid.cell_data["relative_flux"] = np.clip(rel, 1e-3, None).astype(np.float32)
    grid.cell_data["solid"] = (np.asarray(grid.cell_data["particle_id"]) > 0).astype(np.float32)
    points = grid.cell_data_to_point_data(pass_cell_data=True)
    slices = points.slice_orthogonal().combine()
    edges = slices.contour([0.5], scalars="solid")

    pl = offscreen_plotter(shape=(1, 2), window_size=list(window_size), border=False)
    pl.set_background("white")
    bar = dict(vertical=True, position_x=0.84, position_y=0.12, width=0.05, height=0.66,
               title_font_size=15, label_font_size=13, n_labels=5, fmt="%.2g", color="black")
    pl.subplot(0, 0)
    hi = float(np.percentile(rel, 99.5)) if rel.size else 1.0
    pl.add_mesh(slices, scalars="relative_flux", cmap="inferno", log_scale=True,
                clim=(max(1e-2, hi * 1e-3), max(hi, 1.0)), lighting=False,
                preference="cell", scalar_bar_args=dict(bar, title="flux / mean flux\n"))
    if edges.n_points:
        pl.add_mesh(edges, color="white", line_width=1.5)
    _caption(pl, load_caption(result, load_case, k_text))
    _box_axes(pl, grid)
    pl.subplot(0, 1)
    names = list(ms.names)
    colours = _phase_colours(names)
    colours[0] = "lightgrey"
    legend = dict(bar, title="phase\n", n_labels=0, height=0.08 * len(names) + 0.04,
                  position_y=0.1, width=0.04)
    pl.add_mesh(slices, scalars="material", cmap=colours, clim=(-0.5, len(names) - 0.5),
                categories=True, preference="cell", lighting=False,
                annotations={float(i): n for i, n in enumerate(names)},
                scalar_bar_args=legend)
    if edges.n_points:
        pl.add_mesh(edges, color="black", line_width=1.0)
    _caption(pl, phase_caption(ms))
    _box_axes(pl, grid)
    with atomic_path(path) as tmp:
        pl.screenshot(str(tmp))
    pl.close()
    return path
