"""The figures are checked on what they draw (labels, tick texts, legends, aspect, markers),
not on pixels: one house style (io/figures.py and its style sheet), the run figure's panels."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import load_scene, march
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.errors import InputError
from ddvp_nlp.io import figures
from ddvp_nlp.io import run_figure as plotting
from ddvp_nlp.io.run_folder import run_energies


def drawn(solution, scene, scheme=None):
    """The run figure of ``solution`` as ``ddvp march`` draws it, drawn (ticks laid out)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    scheme = scheme or Scheme()
    theta = scene.system.parameter_vector(scene.resolve({}).params)
    energies = run_energies(scene.system, scheme, solution, theta)
    energy = plotting._energy_panel(solution, scene.system, scheme, energies)
    with figures.styled():
        fig = plotting._figure(solution, plotting._rows(solution, True, energy), "test")
        FigureCanvasAgg(fig).draw()
    return fig


def marched(name, **settings):
    scene = load_scene(name)
    config = scene.resolve(settings)
    solution = march(scene.system, config.q0, config.p0, (config.t0, config.t_end),
                     tau0=config.tau0, params=config.params)
    assert solution.success
    return scene, solution


def test_importing_the_figure_modules_loads_no_matplotlib():
    code = ("import sys, ddvp_nlp.io.run_figure, ddvp_nlp.io.figures, ddvp_nlp.io.run_folder; "
            "print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "False"


def test_the_house_style_is_in_force_only_inside_the_block():
    import matplotlib

    before = matplotlib.rcParams["xtick.direction"]
    with figures.styled():
        assert matplotlib.rcParams["xtick.direction"] == "in"
        assert matplotlib.rcParams["font.family"] == ["serif"]
    assert matplotlib.rcParams["xtick.direction"] == before


def test_a_figure_format_outside_the_list_is_an_input_error_naming_it():
    with pytest.raises(InputError, match="'jpg'"):
        figures.check_format("jpg")
    assert figures.file_name("trajectory", "svg") == "trajectory.svg"
    assert set(figures.other_formats("trajectory", "png")) == {"trajectory.svg",
                                                              "trajectory.pdf"}


@pytest.mark.parametrize("bins", [7, 50])
def test_decimation_keeps_every_extreme_and_the_order(bins):
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0.0, 10.0, 5000))
    y = np.sin(7 * t) + 0.1 * rng.standard_normal(t.size)
    x, shown = figures.decimate(t, y, bins)
    assert x.size <= 2 * bins + 2 and np.all(np.diff(x) >= 0)
    assert shown.max() == y.max() and shown.min() == y.min()
    # within each bin the envelope holds the bin's own extremes
    edges = np.searchsorted(t, x[::2])
    for k, start in enumerate(edges):
        stop = edges[k + 1] if k + 1 < edges.size else t.size
        assert shown[2 * k] == y[start:stop].min() and shown[2 * k + 1] == y[start:stop].max()


def test_the_run_figure_of_a_long_run_has_mathematical_labels_and_distinct_ticks():
    scene, solution = marched("paper_pendulum", t_end=3000.0)
    fig = drawn(solution, scene)
    labels = [ax.get_ylabel() for ax in fig.axes if ax.get_ylabel()]
    assert labels[:3] == ["$q$", "$p$", r"step $\tau_k$"]
    assert "|H_0|" in labels[3]  # relative, and the axis says so
    for ax in fig.axes:
        for axis in "xy":
            texts = figures.distinct_tick_texts(ax, axis)
            assert len(texts) == len(set(texts)), (ax.get_ylabel(), texts)
    titles = [ax.get_title() for ax in fig.axes]
    assert f"first {plotting.ZOOM_STEPS} steps" in titles  # the zoom column of a long run
    phase = next(ax for ax in fig.axes if ax.get_title() == "phase portrait")
    assert phase.get_aspect() == 1.0  # a circle stays round
    # the start marker lies inside the axes, not on the frame
    (x0, y0), = [line.get_xydata()[0] for line in phase.lines if line.get_marker() == "o"]
    (left, right), (bottom, top) = phase.get_xlim(), phase.get_ylim()
    assert left < x0 < right and bottom < y0 < top
    # the whole run is drawn from its envelope: at most a few points per pixel column
    whole = fig.axes[0]
    assert max(line.get_xdata().size for line in whole.lines) < solution.t.size / 4


@pytest.mark.slow(why="repetition")
def test_steps_that_differ_in_the_fifth_digit_get_distinct_tick_labels():
    # fpu's steps lie within 0.2% of 0.01: the old canvas labelled all six ticks "0.01"
    scene, solution = marched("fpu", t_end=5.0)
    fig = drawn(solution, scene)
    steps = next(ax for ax in fig.axes if "tau" in ax.get_ylabel())
    texts = figures.distinct_tick_texts(steps, "y")
    assert len(texts) >= 2 and len(set(texts)) == len(texts)


def test_two_degrees_of_freedom_get_a_configuration_panel_at_equal_aspect_and_legends():
    scene, solution = marched("kepler", t_end=7.0)
    fig = drawn(solution, scene)
    configuration = next(ax for ax in fig.axes if ax.get_title() == "configuration")
    assert (configuration.get_xlabel(), configuration.get_ylabel()) == ("$q_1$", "$q_2$")
    assert configuration.get_aspect() == 1.0
    q_panel = next(ax for ax in fig.axes if ax.get_ylabel() == "$q$")
    assert [t.get_text() for t in q_panel.get_legend().get_texts()] == ["$q_{1}$", "$q_{2}$"]
    energy = next(ax for ax in fig.axes if "H_0" in ax.get_ylabel())
    assert energy.get_yscale() == "log" and len(energy.get_legend().get_texts()) == 2


def test_march_writes_its_figure_in_the_format_asked_and_removes_another(tmp_path):
    from ddvp_nlp.cli import main

    out = tmp_path / "run"
    base = ["march", "harmonic", "--set", "t_end=2", "--out", str(out), "--no-progress"]
    assert main([*base, "--format", "pdf"]) == 0
    assert (out / "trajectory.pdf").read_bytes()[:4] == b"%PDF"
    assert main([*base, "--format", "svg"]) == 0
    assert (out / "trajectory.svg").is_file() and not (out / "trajectory.pdf").exists()
    with pytest.raises(SystemExit) as exc:
        main([*base, "--format", "jpg"])
    assert exc.value.code == 2


def test_the_process_settings_left_out_of_the_house_style_are_matplotlibs():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # matplotlib.style.core is deprecated in 3.11
        from matplotlib.style.core import STYLE_BLACKLIST
    assert figures.NOT_STYLE == frozenset(STYLE_BLACKLIST)
    assert not figures.NOT_STYLE & set(figures.house_style())


@pytest.mark.parametrize(("mathtext", "plain"), [
    (r"$\mathdefault{0.5}$", "0.5"),
    ("$\\mathdefault{\N{MINUS SIGN}0.25}$", "\N{MINUS SIGN}0.25"),
    (r"$\mathdefault{10^{-5}}$", "10⁻⁵"),
    (r"$\mathdefault{10^{12}}$", "10¹²"),
    (r"$\mathdefault{2\times10^{-3}}$", "2×10⁻³"),
    ("$\\times\\mathdefault{10^{\N{MINUS SIGN}3}}\\mathdefault{+1.5}$", "×10⁻³+1.5"),
    (r"$\mathdefault{10^{0.50}}$", r"$\mathdefault{10^{0.50}}$"),  # left to mathtext
    (r"$\tau_k$", r"$\tau_k$"),
    ("0.5", "0.5"),
])
def test_tick_labels_written_as_mathtext_become_the_same_plain_text(mathtext, plain):
    assert figures.plain_text(mathtext) == plain


@pytest.mark.parametrize(("mathtext", "plain"), [
    ("$q$", "\U0001d45e"),
    ("$h$", "\N{PLANCK CONSTANT}"),
    (r"step $\tau_k$", "step \u03c4\u2096"),
    ("$|H - H_0|$ / $|H_0|$", "|\U0001d43b \N{MINUS SIGN} \U0001d43b\u2080| / |\U0001d43b\u2080|"),
    ("node $H(q_k, p_k)$", "node \U0001d43b(\U0001d45e\u2096, \U0001d45d\u2096)"),
    ("$q_{12}$", "\U0001d45e\u2081\u2082"),
    ("drifted from $t = 1.5$", "drifted from \U0001d461 = 1.5"),
    (r"$E^{(k)} - E^{(l-1)}$", r"$E^{(k)} - E^{(l-1)}$"),  # a superscript: left to mathtext
    (r"$\frac{1}{2}$", r"$\frac{1}{2}$"),  # a command without a plain form
    ("$q_{y}$", "$q_{y}$"),  # no subscript y in Unicode
    ("a $ b", "a $ b"),  # unpaired
    ("no math", "no math"),
])
def test_labels_whose_mathtext_is_letters_and_subscripts_become_the_same_unicode_text(
        mathtext, plain):
    assert figures.unicode_math(mathtext) == plain


def test_a_saved_figure_has_plain_text_ticks_with_superscripts_on_a_log_axis(tmp_path):
    with figures.styled():
        fig = figures.new_figure(3, 2)
        ax = fig.add_subplot()
        ax.semilogy([0, 1, 2], [1e-9, 1e-6, 1e-3])
        twin = fig.add_subplot(2, 2, 1)
        twin.plot([0, 1], [1e-4, 1.0001e-4])  # an offset axis
        figures.save(fig, tmp_path / "f.png")
    texts = figures.distinct_tick_texts(ax)
    assert "10⁻⁵" in texts and not any("$" in text for text in texts)
    assert len(set(texts)) == len(texts)
    offset = twin.yaxis.get_offset_text().get_text()
    assert offset and "$" not in offset


@pytest.mark.parametrize("transparent", [False, True])
def test_a_png_holds_the_canvas_pixels_and_its_resolution(tmp_path, transparent):
    import io

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    with figures.styled():
        fig = figures.new_figure(1.2, 0.8, layout=None)
        ax = fig.add_axes([0.2, 0.2, 0.7, 0.7])
        ax.plot([0, 1, 2], [0, 1, 0.5])
        if transparent:  # a face that is not opaque keeps its alpha channel
            fig.patch.set_alpha(0.5)
        dpi = float(figures.house_style()["savefig.dpi"])
        figures.save(fig, tmp_path / "f.png")
        in_memory = io.BytesIO()
        figures.save(fig, in_memory)
        fig.dpi = dpi
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        expected = np.asarray(canvas.buffer_rgba())
    for source in (tmp_path / "f.png", io.BytesIO(in_memory.getvalue())):
        image = Image.open(source)
        assert image.mode == ("RGBA" if transparent else "RGB")
        assert np.allclose(image.info["dpi"], dpi, rtol=1e-4)
        pixels = np.asarray(image.convert("RGBA"))
        assert pixels.shape == expected.shape and np.array_equal(pixels, expected)


@settings(max_examples=60, deadline=None)
@given(st.text(alphabet="$qpHtk_{}()|-+= ,.01\\tau^", max_size=24))
def test_a_label_is_either_converted_whole_or_left_to_mathtext(label):
    converted = figures.unicode_math(label)
    assert converted == label or "$" not in converted
    if label.count("$") in (0, 1) or label.count("$") % 2:
        assert converted == label  # no pair of $: nothing is mathtext
    # converting twice changes nothing more
    assert figures.unicode_math(converted) == converted
