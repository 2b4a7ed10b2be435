"""The figure of ``itr design``: k and its band over the design space (``design.png``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..inference.design_space import Choice, DesignSpace
from .figures import _pyplot, _save

__all__ = ["design_figure"]


def design_figure(space: DesignSpace, y: np.ndarray, shares: np.ndarray, totals: np.ndarray,
                  p: np.ndarray, choice: Choice | None, path: Path, *, target: float,
                  probability: float) -> Path:
    """Left: the predicted k (median and 90 % band of the measured mean) against the total
    filler fraction for each filler alone and the 1:1 blend, the target and the choice.
    Right (two fillers): the probability of reaching the target over shares x totals, its
    ``probability`` contour and the choice. Written atomically; returns ``path``."""
    plt = _pyplot()
    two = len(space.fillers) == 2
    fig, axes = plt.subplots(1, 2 if two else 1, figsize=(11 if two else 6, 4.2),
                             squeeze=False)
    ax = axes[0, 0]
    q = np.quantile(y, [0.05, 0.5, 0.95], axis=2)       # (3, S, T)
    for share in space.anchor_shares:
        i = int(np.argmin(np.abs(shares - share)))
        label = (space.fillers[0] if share == 1 else space.fillers[1] if share == 0
                 else f"{space.fillers[0]}:{space.fillers[1]} 1:1")
        line, = ax.plot(100 * totals, q[1, i], label=label)
        ax.fill_between(100 * totals, q[0, i], q[2, i], color=line.get_color(), alpha=0.2)
    ax.axhline(target, color="k", ls="--", lw=1, label=f"target {target:g}")
    if choice is not None:
        ax.errorbar([100 * choice.total], [choice.median],
                    yerr=[[choice.median - choice.interval[0]],
                          [choice.interval[1] - choice.median]],
                    fmt="o", color="crimson", label=f"chosen {choice.name}")
    ax.set_xlabel("total filler, vol%")
    ax.set_ylabel("k of a measured mean, W/(m K) (median, 90 %)")
    ax.legend(fontsize=8)
    if two:
        ax = axes[0, 1]
        im = ax.pcolormesh(100 * totals, shares, p, shading="nearest", vmin=0, vmax=1,
                           cmap="viridis")
        fig.colorbar(im, ax=ax, label=f"P(k >= {target:g})")
        if p.min() < probability < p.max():
            ax.contour(100 * totals, shares, p, levels=[probability], colors="w")
        if choice is not None:
            ax.plot([100 * choice.total], [choice.share], "o", color="crimson")
        ax.set_xlabel("total filler, vol%")
        ax.set_ylabel(f"{space.fillers[0]} share of the filler")
    fig.tight_layout()
    return _save(fig, Path(path))
