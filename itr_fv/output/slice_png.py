"""A PNG of one slice of a solved image (matplotlib, Agg): the phases beside the temperature
of one load case, the filler's surface drawn on it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..io import atomic_path, output_file
from .offscreen import DEFAULT_COLORS, PALETTE

__all__ = ["slice_png"]


def _phase_cmap(names: tuple[str, ...]):
    from matplotlib.colors import ListedColormap

    others = iter(PALETTE * (1 + len(names) // len(PALETTE)))
    colours = ["0.85"] + [DEFAULT_COLORS.get(n) or next(others) for n in names[1:]]
    return ListedColormap(colours)


def slice_png(result: Any, path: str | Path, *, load_case: int = 0, axis: int = 2,
              index: int | None = None) -> Path:
    """Write the slice ``index`` (default the middle) normal to array ``axis`` of a solved
    microstructure: phases (left) and the total temperature of load case ``load_case``
    (right, K for a 1 K/m load), the filler's surface as a line; returns the path.

    Parameters
    ----------
    result : HomogenizationResult
        Solved with ``store_fields=True``, holding its microstructure.
    path : path
        A ``.png`` file name; written atomically.
    load_case : int
        Index into ``result.directions``.
    axis : {0, 1, 2}
        Array axis the slice is normal to.
    index : int, optional
        Slice along ``axis`` (default ``n // 2``).
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = output_file(path, ".png")
    ms = result.microstructure
    if ms is None or result.temperature is None:
        raise ValueError("result: solve with store_fields=True to draw its temperature")
    if axis not in (0, 1, 2):
        raise ValueError(f"axis: expected 0, 1 or 2, got {axis!r}")
    n = ms.shape[axis]
    index = n // 2 if index is None else int(index)
    if not 0 <= index < n:
        raise ValueError(f"index: expected 0..{n - 1}, got {index}")
    mats = np.take(ms.material_ids, index, axis=axis)
    pids = np.take(ms.particle_ids, index, axis=axis)
    temp = np.take(result.temperature[load_case], index, axis=axis)
    (a, b) = [d for d in range(3) if d != axis]
    h_um = ms.voxel_m * 1e6
    extent = (0, ms.shape[b] * h_um, 0, ms.shape[a] * h_um)
    fig, (left, right) = plt.subplots(1, 2, figsize=(10.0, 4.6), dpi=110)
    left.imshow(mats, origin="lower", extent=extent, cmap=_phase_cmap(ms.names),
                vmin=-0.5, vmax=len(ms.names) - 0.5, interpolation="nearest")
    left.set_title("phases: " + ", ".join(f"{i} {p}" for i, p in enumerate(ms.names)),
                   fontsize=9)
    im = right.imshow(temp, origin="lower", extent=extent, cmap="coolwarm",
                      interpolation="nearest")
    right.contour((pids > 0).astype(float), levels=[0.5], colors="k", linewidths=0.5,
                  origin="lower", extent=extent)
    d = result.directions[load_case]
    right.set_title(f"temperature, load e{d + 1} (1 K/m along axis {d})", fontsize=9)
    fig.colorbar(im, ax=right, label="T (K)")
    for ax in (left, right):
        ax.set_xlabel(f"axis {b} (µm)")
        ax.set_ylabel(f"axis {a} (µm)")
    fig.suptitle(f"slice {index} of {n} normal to axis {axis}", fontsize=10)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path
