"""Off-screen rendering set-up shared by the field and particle pictures (pyvista): the
plotter, a font that draws the micro sign, the box's edges as axes in µm, and the phase
colours of the paper's Fig. 4."""

from __future__ import annotations

import ctypes.util
import os
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

__all__ = ["DEFAULT_COLORS", "PALETTE", "add_box_axes", "offscreen_plotter", "unicode_font"]

#: Colours of the paper's Fig. 4 (Al2O3 red, AlN blue); other phases cycle through a palette.
DEFAULT_COLORS: dict[str, str] = {"Al2O3": "red", "AlN": "blue"}
PALETTE = ("orange", "green", "purple", "gold", "cyan", "magenta", "brown")


def _use_egl_without_display() -> None:
    """Off-screen VTK without an X display: choose the EGL window up front.

    VTK otherwise tries X first and prints "bad X server connection" before falling back.
    Left alone where the user chose a window class, where a display exists, or where no EGL
    library is installed.
    """
    if (sys.platform.startswith("linux") and not os.environ.get("DISPLAY")
            and not os.environ.get("WAYLAND_DISPLAY")
            and "VTK_DEFAULT_OPENGL_WINDOW" not in os.environ
            and ctypes.util.find_library("EGL")):
        os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = "vtkEGLRenderWindow"


def offscreen_plotter(**kwargs) -> "pyvista.Plotter":
    """A pyvista Plotter rendering off screen (no display needed, no X warnings)."""
    import pyvista as pv

    _use_egl_without_display()
    return pv.Plotter(off_screen=True, **kwargs)


def unicode_font(prop) -> None:
    """Draw a VTK text property with matplotlib's DejaVu Sans (VTK's built-in fonts lack
    the micro sign, theta and the middle dot); left as it is where that font file is
    missing."""
    from pathlib import Path

    import matplotlib
    import vtk

    font = Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans.ttf"
    if font.is_file():
        prop.SetFontFamily(vtk.VTK_FONT_FILE)
        prop.SetFontFile(str(font))


def add_box_axes(pl: pyvista.Plotter, bounds: tuple[float, ...], *, font_size: int,
                 n_labels: int = 4, fmt: str = "%.0f"):
    """Draw the box ``bounds`` (xmin, xmax, ymin, ymax, zmin, zmax in µm) of the active
    subplot with its three edges as axes: tick labels (``fmt``) and titles ``x (µm)``...
    in ``font_size`` points; returns the axes actor.

    FreeType text (3-D text actors) draws the micro sign; VTK 9.6 draws no 3-D text (vtk
    issue 19729), where the titles fall back to vector text in ASCII (``micrometres``).
    """
    import pyvista as pv

    text_3d = tuple(pv.vtk_version_info[:2]) != (9, 6)
    unit = "µm" if text_3d else "micrometres"
    axes = pl.show_bounds(bounds=bounds, xtitle=f"x ({unit})", ytitle=f"y ({unit})",
                          ztitle=f"z ({unit})", n_xlabels=n_labels, n_ylabels=n_labels,
                          n_zlabels=n_labels, fmt=fmt, font_size=font_size, color="black",
                          bold=False, location="outer", ticks="outside",
                          use_3d_text=text_3d)
    for i in range(3):
        unicode_font(axes.GetTitleTextProperty(i))
        unicode_font(axes.GetLabelTextProperty(i))
    return axes
