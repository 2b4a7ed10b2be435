"""Off-screen rendering set-up shared by the field and particle pictures (pyvista), and
the phase colours of the paper's Fig. 4."""

from __future__ import annotations

import ctypes.util
import os
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

__all__ = ["offscreen_plotter", "DEFAULT_COLORS", "PALETTE"]

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
