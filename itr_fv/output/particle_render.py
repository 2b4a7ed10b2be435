"""Off-screen 3-D picture of an RVE's particles coloured by material (paper Fig. 4)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..rve.microstructure import Microstructure
from .offscreen import DEFAULT_COLORS, PALETTE, add_box_axes, offscreen_plotter, unicode_font

__all__ = ["render_particles"]

#: Digits of a phase name drawn as subscripts in the legend (Al2O3 -> Al₂O₃).
_SUBSCRIPTS = str.maketrans("0123456789", "".join(chr(0x2080 + i) for i in range(10)))


def _with_periodic_images(c: np.ndarray, r: np.ndarray, mats: np.ndarray,
                          box_um: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres (um), radii (um) and phases of the spheres with the periodic images of those
    that reach into the box from its 26 neighbours."""
    cs, rs, ms_ = [c], [r], [mats]
    for sx in (-1, 0, 1):
        for sy in (-1, 0, 1):
            for sz in (-1, 0, 1):
                if sx == sy == sz == 0:
                    continue
                moved = c + np.array([sx, sy, sz]) * box_um
                # keep images that reach into the box
                keep = np.all((moved + r[:, None] > 0) & (moved - r[:, None] < box_um), axis=1)
                cs.append(moved[keep])
                rs.append(r[keep])
                ms_.append(mats[keep])
    return np.concatenate(cs), np.concatenate(rs), np.concatenate(ms_)


def render_particles(ms: Microstructure, path: str, colors: Mapping[str, str] | None = None,
                     window_size: tuple[int, int] = (900, 900), resolution: int = 16,
                     periodic_images: bool = True, show_box: bool = True,
                     axes_font_size: int = 26) -> str:
    """Render the particle table of ``ms`` as spheres, off screen, to a PNG file.

    Particles that cross the box faces are drawn with their periodic images and the
    scene is clipped to the box, so the picture shows the periodic RVE as a cube.

    Parameters
    ----------
    ms : Microstructure
        Needs :attr:`Microstructure.particles` (e.g. from :func:`itr_fv.rve.generate_rve`).
    path : str
        Output image (PNG).
    colors : mapping of str to colour, optional
        Colour per material name (default :data:`DEFAULT_COLORS`).
    window_size : (int, int)
        Image size in pixels.
    resolution : int
        Sphere tessellation (theta and phi resolution).
    periodic_images : bool
        Add the images of particles that cross a face, and clip to the box.
    show_box : bool
        Draw the box outline and its three edges as axes (ticks and titles in µm).
    axes_font_size : int
        Font size of the axis tick labels and titles (points of the render window).

    Returns
    -------
    str
        ``path``.
    """
    import pyvista as pv

    from ..io import atomic_path, output_file

    output_file(path, ".png")
    if ms.particles is None or len(ms.particles) == 0:
        raise ValueError("ms: the microstructure has no particle table to render")
    table = ms.particles
    box_um = np.asarray(ms.box_m, dtype=np.float64) * 1e6
    c = np.asarray(table.centers_m, dtype=np.float64) * 1e6
    r = np.asarray(table.radii_m, dtype=np.float64) * 1e6
    mats = np.asarray(table.material).astype(str)
    cmap = dict(DEFAULT_COLORS)
    extra = [m for m in dict.fromkeys(mats.tolist()) if m not in cmap]
    for k, m in enumerate(extra):
        cmap[m] = PALETTE[k % len(PALETTE)]
    if colors:
        cmap.update(colors)

    if periodic_images:
        c, r, mats = _with_periodic_images(c, r, mats, box_um)

    pl = offscreen_plotter(window_size=list(window_size))
    pl.set_background("white")
    sphere = pv.Sphere(radius=1.0, theta_resolution=resolution, phi_resolution=resolution)
    bounds = (0.0, box_um[0], 0.0, box_um[1], 0.0, box_um[2])
    for name in dict.fromkeys(mats.tolist()):
        sel = mats == name
        cloud = pv.PolyData(c[sel])
        cloud["radius"] = r[sel]
        mesh = cloud.glyph(geom=sphere, scale="radius", orient=False)
        if periodic_images:
            mesh = mesh.clip_box(bounds, invert=False)
        pl.add_mesh(mesh, color=cmap[name], smooth_shading=True)
    if show_box:
        pl.add_mesh(pv.Box(bounds).outline(), color="black", line_width=2)
        add_box_axes(pl, bounds, font_size=axes_font_size)
    # the legend: each phase's name in its colour, upper left (vtk's legend box scales a
    # lone entry's text past the window's edge)
    for i, name in enumerate(dict.fromkeys(mats.tolist())):
        text = pl.add_text(str(name).translate(_SUBSCRIPTS),
                           position=(12, window_size[1] - 34 * (i + 1)), font_size=14,
                           color=cmap[name])
        unicode_font(text.GetTextProperty())
    pl.camera_position = "iso"
    if show_box:
        pl.camera.zoom(0.8)                    # room for the axis labels around the cube
    with atomic_path(path) as tmp:
        pl.screenshot(str(tmp))
    pl.close()
    return path
