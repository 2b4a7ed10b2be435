"""The figures of an identification run, checked on the figure objects (not pixels): units
in µm, readable parameter names, distinct screening series, every posterior marker inside
its frame, the box cut of Fig. 2 stated with the size-cut module's number."""

import re
from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest
from refusals import refuses

matplotlib.use("Agg")

from itr_fv.rve import FillerSpec, size_cut  # noqa: E402
from itr_fv.rve.spec import RVESpec  # noqa: E402
from itr_identify.forward.model import ForwardSettings  # noqa: E402
from itr_identify.inference.screen import ScreenResult  # noqa: E402
from itr_identify.reporting import figures  # noqa: E402
from itr_identify.reporting.labels import (  # noqa: E402
    parameter_label,
    parameter_symbol,
    phase_label,
)

SETTINGS = ForwardSettings(RVESpec(box_um=12.0, voxel_um=0.25))
#: A parameter's code name (R_Al2O3_silicone, Rff_Al2O3_AlN, k_AlN, ...) in plain text.
RAW_NAME = re.compile(r"\b(?:k|R|Rff|Gc)_[A-Za-z][A-Za-z0-9]*(?:_[A-Za-z][A-Za-z0-9]*)?\b")


@pytest.fixture
def captured(monkeypatch):
    """The figures the functions draw, kept open instead of only saved."""
    figs = []

    def keep(fig, path):
        figs.append(fig)
        fig.canvas.draw()                      # mathtext must parse
        with figures.atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=40, format="png")
        return path
    monkeypatch.setattr(figures, "_save", keep)
    yield figs
    import matplotlib.pyplot as plt
    for f in figs:
        plt.close(f)


def texts(fig) -> list[str]:
    """Every text of a figure: titles, axis labels, tick labels, legends, annotations,
    colour-bar labels."""
    out = [t.get_text() for t in fig.findobj(matplotlib.text.Text)]
    return [t for t in out if t]


def check_units_and_names(fig):
    for t in texts(fig):
        assert not re.search(r"\bu[mK]\b", t), t          # µm, µK with the micro sign
        assert "+-" not in t, t
        assert not RAW_NAME.search(t), t                   # readable names, not code names


def fake_model(filler, phi, seed):
    """A single-filler model as the figures read it: fractions, settings and the particle
    tables of two replicas drawn from Table 1 within the size cut (no packing)."""
    spec = FillerSpec.from_table1(filler, phi)
    cut = size_cut(spec, SETTINGS.box_um, SETTINGS.voxel_um,
                   max_diameter_box_ratio=SETTINGS.max_diameter_box_ratio)
    rng = np.random.default_rng(seed)
    mss = []
    for _ in range(2):
        d = spec.psd.sample(60, rng, cut.d_lo_um, cut.d_hi_um)
        table = SimpleNamespace(material=np.array([filler] * d.size), radii_m=0.5e-6 * d)
        mss.append(SimpleNamespace(particles=table))
    return SimpleNamespace(fractions={filler: phi}, microstructures=mss, settings=SETTINGS)


# ------------------------------------------------------------------------------- labels
@pytest.mark.parametrize("name, parts", [
    ("R_Al2O3_silicone", ["R_{", "Al_{2}O_{3}/silicone", "m$^2$ K/W"]),
    ("R_AlN_silicone", ["AlN/silicone", "m$^2$ K/W"]),
    ("Rff_Al2O3_AlN", ["contact", "Al_{2}O_{3}/AlN", "m$^2$ K/W"]),
    ("Gc_Al2O3_AlN", ["contact", "W/K"]),
    ("k_AlN", ["k_{", "W/(m K)"]),
])
def test_parameter_label_is_a_symbol_with_its_unit(name, parts):
    label = parameter_label(name)
    for p in parts:
        assert p in label
    assert name not in label
    assert parameter_label(name, log10=True).startswith("$\\log_{10}$(" + parameter_symbol(name))
    # renders as mathtext
    from matplotlib.mathtext import MathTextParser
    MathTextParser("agg").parse(parameter_symbol(name))


def test_parameter_label_refuses_a_malformed_name():
    with refuses(ValueError, "parameter 'R_silicone'"):
        parameter_label("R_silicone")


# ------------------------------------------------------------------------------- Fig. 2
def test_psd_figure_states_the_box_cut_of_the_size_cut_module(tmp_path, captured):
    models = {"Al2O3-60": fake_model("Al2O3", 0.6, 1), "AlN-60": fake_model("AlN", 0.6, 2),
              "Al2O3-30-AlN-30": SimpleNamespace(fractions={"Al2O3": 0.3, "AlN": 0.3})}
    ident = SimpleNamespace(models=models)
    path, fits = figures.psd_figure(ident, tmp_path / "fig2_psd.png")
    assert path.is_file() and set(fits) == {"Al2O3", "AlN"}
    fig, = captured
    check_units_and_names(fig)
    for ax in fig.axes:
        filler = "AlN" if "AlN" in ax.get_title() else "Al2O3"
        cut = size_cut(FillerSpec.from_table1(filler, 0.6), 12.0, 0.25,
                       max_diameter_box_ratio=SETTINGS.max_diameter_box_ratio,
                       tail_quantile=SETTINGS.rve.tail_quantile)
        assert cut.box_limited and cut.d_hi_um == pytest.approx(5.4)
        note = [t.get_text() for t in ax.texts]
        assert note == [figures.box_cut_text(filler, cut, 12.0)]
        assert (f"removes {100 * cut.volume_high:.0f} % of the {phase_label(filler)} volume"
                in note[0])
        assert "box cut at 5.4 µm (0.45 × the 12 µm box)" in note[0]
        # the report quotes the same share
        from itr_identify.reporting.report import box_cut
        assert round(100 * box_cut(SETTINGS, {filler})[filler]) == round(
            100 * cut.volume_high)
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        # the comparable curve: Table 1 cut to the drawn range, renormalised (integral 1)
        cut_line = next(ln for k, ln in lines.items() if k.startswith("Table 1, cut"))
        x, y = cut_line.get_data()
        assert x.min() >= cut.d_lo_um and x.max() <= cut.d_hi_um
        assert np.trapezoid(y, x) == pytest.approx(1.0, abs=0.03)
        # the uncut curve is dashed, and the range the box removes is shaded
        uncut = next(ln for k, ln in lines.items() if k.startswith("Table 1, uncut"))
        assert uncut.get_linestyle() == "--"
        xu, yu = uncut.get_data()
        assert np.allclose(yu, FillerSpec.from_table1(filler, 0.6).psd.pdf(xu))
        # the cut curve is the uncut one over the share the cut keeps
        kept = 1.0 - cut.number_low - cut.number_high
        assert np.allclose(y, FillerSpec.from_table1(filler, 0.6).psd.pdf(x) / kept)
        spans = [p for p in ax.patches if "cut off by the box" in str(p.get_label())]
        assert len(spans) == 1
        assert spans[0].get_x() == pytest.approx(cut.d_hi_um)
        assert "µm" in ax.get_xlabel() and "µm" in ax.get_ylabel()
    aln = next(ax for ax in fig.axes if "AlN" in ax.get_title())
    assert "removes 85 % of the AlN volume" in aln.texts[0].get_text()     # issue 37


# ------------------------------------------------------------------------------- Fig. 8
def screening(system, names, seed, scale):
    rng = np.random.default_rng(seed)
    grid = np.logspace(-9, -5, 9)
    delta = scale * rng.lognormal(0.0, 1.0, grid.size ** len(names))
    return ScreenResult(tuple(system), ("x",), list(names), {}, delta, grid)


def test_screening_series_have_distinct_colours_and_a_legend(tmp_path, captured):
    idents = {
        "area": SimpleNamespace(screening=[
            screening(["Al2O3"], ["R_Al2O3_silicone"], 1, 0.1),
            screening(["AlN"], ["R_AlN_silicone"], 2, 0.2),
            screening(["Al2O3", "AlN"], ["Rff_Al2O3_AlN"], 3, 0.3)]),
        "gap": SimpleNamespace(screening=[
            screening(["Al2O3"], ["R_Al2O3_silicone"], 4, 0.15),
            screening(["AlN"], ["R_AlN_silicone"], 5, 0.25)]),
    }
    figures.screening_figure(idents, tmp_path / "fig8.png")
    fig, = captured
    check_units_and_names(fig)
    colour_of = {}
    for ax in fig.axes:
        curves = [ln for ln in ax.get_lines() if len(ln.get_xdata()) > 2]
        marks = [ln for ln in ax.get_lines() if ln.get_label().split(":")[-1].startswith(
            " lowest")]
        # one curve and one threshold line per parametrisation screened in this panel
        assert len(curves) == len(marks) >= 1
        styles = {(matplotlib.colors.to_hex(ln.get_color()), str(ln.get_linestyle()))
                  for ln in curves}
        assert len(styles) == len(curves)
        assert len({matplotlib.colors.to_hex(ln.get_color()) for ln in marks}) == len(marks)
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        for ln in curves + marks:
            assert ln.get_label() in legend
            par = ln.get_label().split(":")[0]
            colour = matplotlib.colors.to_hex(ln.get_color())
            # a series' threshold has its colour, and so has the series in every panel
            assert colour_of.setdefault(par, colour) == colour
    assert len(set(colour_of.values())) == 2


# ------------------------------------------------------------------------------ posterior
def stage(system, params, axes, density):
    return SimpleNamespace(system=tuple(system), parameters=tuple(params),
                           axes_log10=None if axes is None else tuple(axes), density=density)


def test_posterior_markers_lie_inside_the_frame(tmp_path, captured):
    a = np.linspace(-9, -5, 41)
    d2 = np.exp(-((a[:, None] + 7) ** 2 + (a[None, :] + 5.5) ** 2))
    d1 = np.exp(-(a + 8) ** 2)
    best = {"R_Al2O3_silicone": 1e-7, "R_AlN_silicone": 1e-5,      # on the grid's edge
            "Rff_Al2O3_AlN": 1e-9}
    post = SimpleNamespace(best=best, stages=[
        stage(["Al2O3", "AlN"], ["R_Al2O3_silicone", "R_AlN_silicone"], [a, a],
              d2 / d2.sum()),
        stage(["Al2O3", "AlN"], ["Rff_Al2O3_AlN"], [a], d1 / d1.sum()),
        stage(["AlN"], [], None, None)])
    ident = SimpleNamespace(parametrisation="area", posterior=post, at_nominal=post)
    figures.posterior_figure(ident, tmp_path / "posterior_area.png")
    fig, = captured
    check_units_and_names(fig)
    panels = [ax for ax in fig.axes if ax.get_title()]
    assert len(panels) == 2
    for ax in panels:
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        for ln in ax.get_lines():
            x, y = (np.asarray(v, dtype=float) for v in ln.get_data())
            if ln.get_transform() != ax.transData:        # a vertical line: x only
                assert np.all((x > x0) & (x < x1)), ln.get_label()
                continue
            # a marker is whole inside: at least 3 % of the span from every edge
            if ln.get_marker() not in ("None", None, ""):
                assert np.all(x >= x0 + 0.03 * (x1 - x0)) and np.all(x <= x1 - 0.03 * (x1 - x0))
                assert np.all(y >= y0 + 0.03 * (y1 - y0)) and np.all(y <= y1 - 0.03 * (y1 - y0))
        assert "log_{10}" in ax.get_xlabel() and "m$^2$ K/W" in ax.get_xlabel()
    best_mark = next(ln for ln in panels[0].get_lines() if ln.get_label() == "best (ours)")
    assert best_mark.get_ydata()[0] == pytest.approx(-5.0)
    legend = [t.get_text() for t in panels[0].get_legend().get_texts()]
    assert "outside the posterior grid" in legend



def test_size_cut_is_the_cut_generate_rve_draws_with():
    """Fig. 2's numbers come from :func:`itr_fv.rve.size_cut`, the function the RVE
    generator cuts with: its report gives the same range and shares."""
    import warnings

    from itr_fv.rve import generate_rve_with_report
    spec = FillerSpec.from_table1("AlN", 0.3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _, rep = generate_rve_with_report(RVESpec(12.0, 0.25, max_diameter_box_ratio=0.45),
                                          spec, 0)
    f, = rep.fillers
    cut = size_cut(spec, 12.0, 0.25, max_diameter_box_ratio=0.45)
    assert (f.d_lo_um, f.d_hi_um) == (cut.d_lo_um, cut.d_hi_um)
    assert (f.cut_number_low, f.cut_number_high, f.cut_volume_low, f.cut_volume_high) == (
        cut.number_low, cut.number_high, cut.volume_low, cut.volume_high)
    assert cut.box_limited and f"{cut.volume_high:.1%}" in str(caught[0].message)


def test_rve_render_labels_its_three_axes_in_micrometres(tmp_path, monkeypatch):
    """Fig. 4: every box edge an axis with tick labels and a title in µm, in a font size
    readable at the figure's scale (the render is checked through its pyvista call)."""
    import warnings

    import pyvista as pv

    from itr_fv.output.particle_render import render_particles
    from itr_fv.rve import generate_rve
    calls = []
    show_bounds = pv.Plotter.show_bounds

    def spy(self, *args, **kwargs):
        calls.append(kwargs)
        return show_bounds(self, *args, **kwargs)
    monkeypatch.setattr(pv.Plotter, "show_bounds", spy)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        ms = generate_rve(RVESpec(8.0, 0.25, max_diameter_box_ratio=1 / 3),
                          FillerSpec.from_table1("Al2O3", 0.3), 0)
    out = render_particles(ms, str(tmp_path / "rve.png"), window_size=(300, 300),
                           resolution=6)
    assert open(out, "rb").read(8) == b"\x89PNG\r\n\x1a\n"
    kw, = calls
    unit = "µm" if kw["use_3d_text"] else "micrometres"      # VTK 9.6: ASCII vector text
    assert [kw[f"{a}title"] for a in "xyz"] == [f"{a} ({unit})" for a in "xyz"]
    assert all(kw.get(f"show_{a}labels", True) for a in "xyz")
    assert kw["font_size"] >= 20
