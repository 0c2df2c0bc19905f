"""The one plotting stack of the package: every figure is a matplotlib ``Figure`` drawn under the
house style ``ddvp.mplstyle`` (beside this module) and saved as PNG, SVG or PDF.

matplotlib is imported only inside these functions, when a figure is drawn (`load_matplotlib`):
``import ddvp_nlp`` and a run with ``--no-plot`` never load it. No pyplot: figures are plain
``Figure`` objects drawn by the Agg canvas, so there is no global figure registry to leak into
and no interactive backend to select.

Long series are reduced before they are drawn (`decimate`): the minimum and the maximum
of each of as many bins as the panel has pixel columns, which lights the same pixels as the
whole line, so a run of a million nodes draws as fast as one of a thousand; a cloud of
millions of dots, one dot per half pixel (`thin_points`).
"""

from __future__ import annotations

import contextlib
import functools
import math
import re
import sys
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..startup import started_as_command

STYLE = Path(__file__).with_name("ddvp.mplstyle")
FORMATS = ("png", "svg", "pdf")
# A journal's text width and column width, in inches: figures are drawn at the size they are
# printed, so the fonts of the style sheet are the fonts on the page.
TEXT_WIDTH, COLUMN_WIDTH = 7.0, 3.4
# What marks a failed run in every figure: a cross, named in the legend; red, or in its
# method's colour where several methods share a panel (the legend's entry in that colour).
FAILED = {"marker": "x", "color": "#CC3311", "linestyle": "none", "markersize": 5,
          "markeredgewidth": 1.2}


def check_format(value: str) -> str:
    """``value`` if it is one of `FORMATS`, else an `InputError`
    naming it."""
    if value not in FORMATS:
        raise InputError(f"figure format {value!r} is not one of {', '.join(FORMATS)}")
    return value


def file_name(stem: str, fmt: str = "png") -> str:
    """The file a figure ``stem`` is written to in format ``fmt``: ``stem.fmt``."""
    return f"{stem}.{check_format(fmt)}"


def other_formats(stem: str, fmt: str = "png") -> dict:
    """``{stem.other: None}`` for the formats other than ``fmt``: given to an output folder's
    ``commit``, it removes a figure an earlier run wrote in another format, so a folder never
    holds two figures of different runs."""
    return {f"{stem}.{other}": None for other in FORMATS if other != fmt}


# rcParams that configure the process rather than a figure's look: what matplotlib's style
# sheets may not set (its STYLE_BLACKLIST; tests/workbench/io/test_figures.py checks the two agree).
NOT_STYLE = frozenset({
    "backend", "backend_fallback", "date.epoch", "docstring.hardcopy", "figure.max_open_warning",
    "figure.raise_window", "interactive", "savefig.directory", "timezone", "tk.window_focus",
    "toolbar", "webagg.address", "webagg.open_in_browser", "webagg.port", "webagg.port_retries"})


def load_matplotlib(*, help_tables: bool | None = None) -> None:
    """Import what every figure uses, ``matplotlib.figure`` and the Agg canvas, if not yet
    imported. Without ``help_tables`` (the default in the ``ddvp`` command's own process,
    `started_as_command`; kept anywhere else), what only help and introspection read is left
    out of the import (`_without_help_tables`): the table of settable properties that
    matplotlib writes into each artist class's ``set`` and into its plotting methods'
    docstrings as their modules load (``matplotlib.artist.kwdoc``; a third of the import's
    CPU, 0.13 s of 0.45 s when it was measured), the signatures of those ``set`` methods and
    the 3-D toolkit: nothing a figure reads."""
    if "matplotlib.figure" in sys.modules:
        return
    if help_tables is None:
        help_tables = not started_as_command()
    if help_tables:
        import matplotlib.figure  # noqa: F401 - loads every artist class
        from matplotlib.backends import backend_agg  # noqa: F401
        return
    with _without_help_tables():
        import matplotlib.figure  # noqa: F401 - loads every artist class
        from matplotlib.backends import backend_agg  # noqa: F401


@contextlib.contextmanager
def _without_help_tables():
    """What a process that draws its figures and exits never reads, left out of matplotlib's
    import (`load_matplotlib`): the tables of settable properties in the artists' docstrings
    (``kwdoc``) and the keyword signature of each artist class's ``set`` (both from
    ``ArtistInspector``, which inspects every ``set_*`` method of every class; ``set`` itself
    works as before), and the 3-D axes toolkit that ``matplotlib.projections`` imports to
    register them (no figure of the package is 3-D). Everything is put back after the
    import."""
    import warnings

    import matplotlib.artist

    inspector = matplotlib.artist.ArtistInspector
    tables, setters = matplotlib.artist.kwdoc, inspector.get_setters
    matplotlib.artist.kwdoc = lambda artist: ""
    inspector.get_setters = lambda self: []
    toolkit = "mpl_toolkits.mplot3d"
    blocked = toolkit not in sys.modules
    if blocked:
        sys.modules[toolkit] = None  # its import fails: matplotlib warns and goes on
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "Unable to import Axes3D")
            yield
    finally:
        matplotlib.artist.kwdoc = tables
        inspector.get_setters = setters
        if blocked and sys.modules.get(toolkit, 0) is None:
            del sys.modules[toolkit]


@functools.cache
def house_style() -> dict:
    """Every rcParam of a figure: matplotlib's defaults under ``ddvp.mplstyle``, so that a
    figure looks the same whatever a user's ``matplotlibrc`` says. Read once per process:
    ``rc_context(fname=...)`` imported matplotlib's style library and re-read the file at each
    figure (6 ms of the run figure)."""
    import matplotlib

    params = matplotlib.rc_params_from_file(str(STYLE), use_default_template=True)
    return {key: value for key, value in params.items() if key not in NOT_STYLE}


@contextlib.contextmanager
def styled():
    """The house style in force inside the block (matplotlib's ``rc_context``: nothing global
    is changed after it)."""
    load_matplotlib()
    import matplotlib

    with matplotlib.rc_context(house_style()):
        yield


def new_figure(width: float, height: float, *, layout: str | None = "constrained"):
    """A ``matplotlib.figure.Figure`` of ``width`` by ``height`` inches (no pyplot). Call it
    inside `styled`, which must also surround `save`."""
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), layout=layout)


class Keep:
    """A target for `save` that keeps the figure, drawn, instead of writing it: ``figure``
    holds it afterwards (tests look at the drawn objects; a notebook can show it)."""

    def __init__(self):
        self.figure = None


def save(fig, target, fmt: str = "png") -> None:
    """Write ``fig`` to ``target`` (a path, a binary file or a `Keep`) in format ``fmt``, its
    numeric tick labels as plain text (`plain_tick_labels`), data constant to round-off drawn
    as constant (`steady_limits`) and a y axis' offset in its label (`offset_in_label`)."""
    plain_tick_labels(fig)
    for ax in fig.axes:
        for axis in "xy":
            steady_limits(ax, axis)
        offset_in_label(ax)
    if isinstance(target, Keep):
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        FigureCanvasAgg(fig).draw()
        target.figure = fig
        return
    if check_format(fmt) == "png":
        write_png(fig, target)
        return
    fig.savefig(target, format=fmt)


def write_png(fig, target) -> None:
    """``fig`` drawn by the Agg canvas at the house style's resolution (``savefig.dpi``; call
    it inside `styled`) and written to ``target`` (a path or a binary file) as a PNG: RGB
    where every pixel is opaque (the house style's white face), each row stored as its
    difference from the row above (PNG's "Up" filter), zlib level 1, the resolution in a
    ``pHYs`` chunk (a page sizes the figure by it). The same pixels as ``savefig``, which
    spent 63 ms of the run figure in Pillow's encoder (an adaptive filter per row) where
    this takes 31 ms, for a file 12% smaller (``scripts/benchmarks/bench_figure.py``)."""
    import zlib

    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    dpi = matplotlib.rcParams["savefig.dpi"]
    dpi = fig.dpi if dpi == "figure" else float(dpi)
    shown = fig.dpi
    fig.dpi = dpi
    try:
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        pixels = np.asarray(canvas.buffer_rgba())
    finally:
        fig.dpi = shown
    if pixels[..., 3].min() == 255:
        pixels = pixels[..., :3]
    height, width, channels = pixels.shape
    rows = np.empty((height, 1 + width * channels), dtype=np.uint8)
    rows[:, 1:] = pixels.reshape(height, -1)
    rows[1:, 1:] -= rows[:-1, 1:].copy()  # modulo 256, as the filter is defined
    rows[:, 0] = 2  # "Up" (the first row's prior row is zeros: itself)
    per_metre = round(dpi / 0.0254)
    chunks = [(b"IHDR", _packed(width, height) + bytes([8, 6 if channels == 4 else 2, 0, 0, 0])),
              (b"pHYs", _packed(per_metre, per_metre) + b"\x01"),
              (b"IDAT", zlib.compress(rows.tobytes(), 1)), (b"IEND", b"")]
    data = b"\x89PNG\r\n\x1a\n" + b"".join(
        len(body).to_bytes(4, "big") + kind + body
        + zlib.crc32(kind + body).to_bytes(4, "big") for kind, body in chunks)
    if isinstance(target, (str, Path)):
        with open(target, "wb") as file:
            file.write(data)
    else:
        target.write(data)


def _packed(*values: int) -> bytes:
    return b"".join(value.to_bytes(4, "big") for value in values)


# Superscripts of the characters a tick label's exponent holds.
SUPERSCRIPTS = str.maketrans("0123456789-\N{MINUS SIGN}+", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻⁻⁺")


def plain_text(label: str) -> str:
    """A tick label that matplotlib's formatters write as mathtext (``$\\mathdefault{0.5}$``,
    ``$\\mathdefault{10^{-5}}$``, ``$\\times\\mathdefault{10^{-3}}$``) as the same text in
    Unicode: ``0.5``, ``10⁻⁵``, ``×10⁻³``. A label holding anything else is returned as it is
    (mathtext typesets it)."""
    if not (len(label) > 2 and label[0] == label[-1] == "$" and label.count("$") == 2):
        return label
    body = label[1:-1].replace(r"\mathdefault", "").replace(r"\times", "\N{MULTIPLICATION SIGN}")
    exponents = re.findall(r"\^\{([^{}]*)\}", body)
    if any(c not in "0123456789-\N{MINUS SIGN}+" for exponent in exponents for c in exponent):
        return label
    body = re.sub(r"\^\{([^{}]*)\}", lambda m: m.group(1).translate(SUPERSCRIPTS), body)
    body = body.replace("{", "").replace("}", "").replace(" ", "")
    return label if any(c in body for c in "\\^_$") else body


def plain_tick_labels(fig) -> None:
    """Every numeric tick label and offset of ``fig`` drawn as plain Unicode text
    (`plain_text`) instead of mathtext: the same characters in the house style's serif, with
    true superscripts and minus signs, without the mathtext parse of each distinct label (85 ms
    of the 370 ms drawing of the run figure of ``paper_pendulum``,
    ``scripts/benchmarks/bench_figure.py``).
    Only matplotlib's own scalar and log formatters are changed (a formatter a figure chose
    stays), and each keeps its settings (offset, limits, the axis it labels)."""
    plain = plain_formatters()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            minor = axis.get_minor_formatter()
            if axis is ax.xaxis and hasattr(minor, "minor_thresholds"):
                # a log x axis over one to two decades labelled every minor tick ("2x10^-3
                # 3x10^-3 ..." side by side), unreadable in a narrow panel: minor labels only
                # below half a decade, where there is at most one major label
                minor.minor_thresholds = (0.5, 0.2)
            for formatter in (axis.get_major_formatter(), minor):
                if type(formatter) in plain:
                    # the class swapped in place: its state is what the new methods read
                    formatter.__class__ = plain[type(formatter)]


# What `unicode_math` writes for mathtext's letters, subscripts and symbols: mathematical
# italic letters (U+1D434..; the italic small h is Planck's constant, U+210E), subscript
# characters, upright Greek (the serif has no italic Greek of its own), a true minus sign.
ITALIC = {**{c: chr(0x1D434 + i) for i, c in enumerate("ABCDEFGHIJKLMNOPQRSTUVWXYZ")},
          **{c: chr(0x1D44E + i) for i, c in enumerate("abcdefghijklmnopqrstuvwxyz")},
          "h": "\N{PLANCK CONSTANT}"}
SUBSCRIPTS = dict(zip("0123456789+-=()aehijklmnoprstuvx", "₀₁₂₃₄₅₆₇₈₉₊₋₌₍₎ₐₑₕᵢⱼₖₗₘₙₒₚᵣₛₜᵤᵥₓ",
                      strict=True))
GREEK = {"tau": "τ", "omega": "ω", "theta": "θ", "phi": "φ", "alpha": "α", "beta": "β",
         "epsilon": "ε", "lambda": "λ", "mu": "μ", "sigma": "σ", "Delta": "Δ"}
_MATH_TOKEN = re.compile(r"\\([A-Za-z]+)|_\{([^{}]*)\}|_(.)|([A-Za-z])|([0-9 .,()|/+=])|(-)")


def unicode_math(label: str) -> str:
    """A label whose mathtext is a few letters, digits, Greek, subscripts and ``+ - = ( ) ,
    | /`` (``$q$``, ``step $\\tau_k$``, ``$|H - H_0|$``, ``node $H(q_k, p_k)$``) written
    as the same text in Unicode: italic letters, subscript characters, a minus sign
    (``𝑞``, ``step τₖ``, ``|𝐻 − 𝐻₀|``), drawn as plain text (mathtext parsed each label
    and built its grammar once per process: about a tenth of a second of the run figure).
    A label holding anything else (a fraction, a superscript, an unknown command) is returned
    as it is, for mathtext to typeset."""
    parts = label.split("$")
    if len(parts) % 2 == 0 or len(parts) == 1:
        return label  # no mathtext, or an unpaired $ (mathtext's own error then)
    for index in range(1, len(parts), 2):
        converted = _unicode_segment(parts[index])
        if converted is None:
            return label
        parts[index] = converted
    return "".join(parts)


def _unicode_segment(math: str) -> str | None:
    """One ``$...$`` segment of `unicode_math` in Unicode, or ``None`` if it holds anything
    that has no plain form."""
    out, position = [], 0
    for match in _MATH_TOKEN.finditer(math):
        if match.start() != position:
            return None
        position = match.end()
        command, braced, single, letter, plain, minus = match.groups()
        if command is not None:
            if command not in GREEK:
                return None
            out.append(GREEK[command])
        elif braced is not None or single is not None:
            text = braced if braced is not None else single
            if not text or any(c not in SUBSCRIPTS for c in text):
                return None
            out.append("".join(SUBSCRIPTS[c] for c in text))
        else:
            out.append(ITALIC[letter] if letter else plain if plain else "\N{MINUS SIGN}")
    return "".join(out) if position == len(math) else None


def unicode_labels(fig) -> None:
    """The axes' titles, axis labels, legend entries and annotations of ``fig`` whose
    mathtext has a plain form written in Unicode (`unicode_math`; a figure's own title is
    written so where it is set); numeric tick labels are `plain_tick_labels`' part."""
    texts = []
    for ax in fig.axes:
        texts += [ax.xaxis.label, ax.yaxis.label, ax.title, *ax.texts]
        legend = ax.get_legend()
        if legend is not None:
            texts += legend.get_texts()
    for text in texts:
        label = text.get_text()
        if "$" in label:
            text.set_text(unicode_math(label))


@functools.cache
def plain_formatters() -> dict:
    """``{matplotlib formatter class: its subclass with plain-text labels}``, built on first
    use (matplotlib is imported only when a figure is drawn)."""
    from matplotlib import ticker

    class PlainScalarFormatter(ticker.ScalarFormatter):
        def __call__(self, x, pos=None):
            return plain_text(super().__call__(x, pos))

        def get_offset(self):
            return plain_text(super().get_offset())

    class PlainLogFormatter(ticker.LogFormatterSciNotation):
        def __call__(self, x, pos=None):
            return plain_text(super().__call__(x, pos))

    return {ticker.ScalarFormatter: PlainScalarFormatter,
            ticker.LogFormatterSciNotation: PlainLogFormatter}


# Data whose spread is at most this fraction of their size are constant to round-off (a fixed
# step, the period of a harmonic family): the autoscaled axis would magnify the last bits into
# a "dip" under an offset label.
STEADY = 1e-9


def steady_limits(ax, axis: str = "y") -> None:
    """An autoscaled ``axis`` of ``ax`` whose data (its lines in data coordinates) vary by at
    most `STEADY` of their size drawn as a constant: a range of +-10% about it (a decade on a
    log axis) and no offset, so round-off is not magnified into structure."""
    autoscaled = ax.get_autoscaley_on() if axis == "y" else ax.get_autoscalex_on()
    if not autoscaled or not ax.lines:
        return
    columns = [line.get_ydata(orig=False) if axis == "y" else line.get_xdata(orig=False)
               for line in ax.lines if line.get_transform() == ax.transData]
    values = np.concatenate([np.asarray(c, dtype=float).ravel() for c in columns] or [[]])
    values = values[np.isfinite(values)]
    if values.size < 2:
        return
    low, high = float(values.min()), float(values.max())
    size = max(abs(low), abs(high))
    if size == 0.0 or high - low > STEADY * size or high == low:
        return  # varying, zero, or exactly constant (matplotlib's own range is sensible then)
    centre = 0.5 * (low + high)
    scale = ax.get_yscale() if axis == "y" else ax.get_xscale()
    if scale == "log":
        limits = (centre / 10 ** 0.5, centre * 10 ** 0.5) if centre > 0 else None
    else:
        limits = (centre - 0.1 * abs(centre), centre + 0.1 * abs(centre))
    if limits is None:
        return
    (ax.set_ylim if axis == "y" else ax.set_xlim)(*limits)
    formatter = (ax.yaxis if axis == "y" else ax.xaxis).get_major_formatter()
    if hasattr(formatter, "set_useOffset"):
        formatter.set_useOffset(False)


def offset_in_label(ax) -> None:
    """The y axis' offset and power of ten (matplotlib's ``x10^-4 +6.283`` drawn above the
    panel, over its title) written into the axis label instead: ``(T - 6.283) / 10⁻⁴``; a
    label that was hidden (the run figure's second column names its axis only then) is shown
    once it carries them."""
    axis = ax.yaxis
    formatter = axis.get_major_formatter()
    if not hasattr(formatter, "set_powerlimits") or ax.get_yscale() != "linear":
        return
    low, high = sorted(ax.get_ylim())
    formatter.set_locs([loc for loc in axis.get_majorticklocs() if low <= loc <= high])
    power = _power_of(formatter.get_offset())
    offset = float(getattr(formatter, "offset", 0.0))
    if not offset and not power:
        return
    label = ax.get_ylabel() or "value"
    if offset:
        sign = "\N{MINUS SIGN}" if offset > 0 else "+"
        label = f"{label} {sign} {abs(offset):.12g}"
        label = f"({label})" if power else label
    if power:
        label = f"{label} / 10{str(power).translate(SUPERSCRIPTS)}"
    ax.set_ylabel(label)
    ax.yaxis.label.set_visible(True)  # a label hidden until it carries an offset shows now
    # the same offset and power at the draw, whatever ticks the final layout gives
    formatter.set_useOffset(offset if offset else False)
    if power:
        formatter.set_powerlimits((power, power))
    axis.get_offset_text().set_visible(False)


def _power_of(offset_text: str) -> int:
    """The power of ten in an offset text (``×10⁻⁴+6.283``, or its mathtext), else 0 (the
    formatter's own attribute is private from matplotlib 3.11)."""
    text = offset_text.translate(str.maketrans("⁰¹²³⁴⁵⁶⁷⁸⁹⁻", "0123456789-"))
    text = text.replace("\N{MINUS SIGN}", "-")
    match = re.search(r"(?:×|\\times)(?:\\mathdefault\{)?10\^?\{?(-?\d+)", text)
    return int(match.group(1)) if match else 0


def format_of(path, default: str = "png") -> str:
    """The format a path's suffix names (``.png``, ``.svg``, ``.pdf``), else ``default``."""
    suffix = Path(path).suffix.lower().lstrip(".") if isinstance(path, (str, Path)) else ""
    return check_format(suffix) if suffix else default


def decimate(t: np.ndarray, values: np.ndarray, bins: int):
    """``(t, values)`` reduced to the minimum and the maximum of each of ``bins`` equal bins of
    ``t``, in the order they occur: a line through them covers the same pixels as the whole
    line at one bin per pixel column, and its extremes are exact. ``values`` is ``(N,)`` or
    ``(N, m)``; a series of at most ``2 * bins`` points is returned as it is. NaN values are
    skipped within a bin."""
    values = np.asarray(values, dtype=float)
    t = np.asarray(t, dtype=float)
    if t.size <= 2 * bins or not (np.isfinite(t[0]) and np.isfinite(t[-1])) or t[-1] <= t[0]:
        return t, values
    flat = values.reshape(t.size, -1)
    edges = np.linspace(t[0], t[-1], bins + 1)
    starts = np.unique(np.searchsorted(t, edges[:-1], side="left"))
    starts = starts[starts < t.size]
    shown = []
    with np.errstate(invalid="ignore"):
        for column in flat.T:
            low = np.fmin.reduceat(column, starts)
            high = np.fmax.reduceat(column, starts)
            shown.append(np.column_stack([low, high]).ravel())
    return np.repeat(t[starts], 2), np.column_stack(shown).reshape(-1, *values.shape[1:])


BAND_ALPHA = 0.3  # the envelope's fill; its edges are drawn opaque


def envelope_band(ax, t, values, bins: int, **style) -> None:
    """One series on ``ax`` as it would look drawn whole: the line itself while it has at most
    ``2 * bins`` points, else the band between the minimum and the maximum of each bin
    (`decimate`) filled in a light shade of the line's colour, its edges as wide as the line:
    a fast oscillation over a long run reads as its envelope, not as a solid block. Filling
    the band costs a polygon where the zigzag through the extremes cost a full-height stroke
    per pixel column."""
    t = np.asarray(t, dtype=float)
    values = np.asarray(values, dtype=float)
    x, y = decimate(t, values, bins)
    if x.size == t.size:
        ax.plot(x, y, **style)
        return
    line = ax.plot(x[::2], y[::2], **style)[0]  # legend entry, colour; the minima
    ax.plot(x[1::2], y[1::2], color=line.get_color(), lw=line.get_linewidth())
    ax.fill_between(x[::2], y[::2], y[1::2], color=line.get_color(), lw=0, alpha=BAND_ALPHA)


def thin_points(x: np.ndarray, y: np.ndarray, cells: int) -> np.ndarray:
    """The indices (ascending) of the points ``(x, y)`` a scatter of single pixels needs: the
    points of least and greatest ``x`` and ``y`` (the axes' limits stay those of the whole
    cloud) and one point of each other occupied cell of a ``cells`` by ``cells`` grid over
    their range (which one is unspecified); non-finite points left out. At two or more cells
    per pixel it lights the pixels the whole cloud lights, but for a few at its sparse edges
    (2% of 12900 for three million nodes on a circle), and a million points cost what the
    cells they fill cost."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    finite = np.isfinite(x) & np.isfinite(y)
    if not finite.all():
        index = np.flatnonzero(finite)
        return index[thin_points(x[index], y[index], cells)]
    if x.size <= cells:
        return np.arange(x.size)
    ids = None
    for values in (x, y):
        low, high = float(values.min()), float(values.max())
        column = np.subtract(values, low)
        column *= (cells - 1e-9) / (high - low) if high > low else 0.0
        column = column.astype(np.intp)
        ids = column if ids is None else ids * cells + column
    owner = np.full(cells * cells, -1, dtype=np.intp)
    owner[ids] = np.arange(ids.size)  # a cell filled twice keeps one of its points
    extremes = [int(f(values)) for values in (x, y) for f in (np.argmin, np.argmax)]
    return np.union1d(owner[owner >= 0], extremes)


def bins_for(ax) -> int:
    """The number of `decimate` bins for a panel: one per pixel column at the resolution the
    figure is saved at (the house style's ``savefig.dpi``, 200; call it inside `styled`)."""
    import matplotlib

    dpi = matplotlib.rcParams["savefig.dpi"]
    dpi = ax.figure.dpi if dpi == "figure" else float(dpi)
    width = ax.get_position().width * ax.figure.get_figwidth()
    return max(64, int(width * dpi))


def positive(values) -> np.ndarray:
    """``values`` with zeros and negative or non-finite entries as NaN: what a log axis shows
    (an exact zero has no place on it and is left out rather than drawn at an invented floor)."""
    values = np.asarray(values, dtype=float)
    return np.where(np.isfinite(values) & (values > 0), values, np.nan)


def log_norm(values, *, decades: float = 16.0):
    """A ``LogNorm`` over the finite positive ``values``: from their smallest to their largest,
    widened to whole decades, at most ``decades`` below the largest (a colour bar that never
    saturates: an error of 4 and one of 30 get different colours)."""
    from matplotlib.colors import LogNorm

    values = positive(values)
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return LogNorm(1e-16, 1.0)
    high = 10.0 ** math.ceil(math.log10(float(finite.max())))
    low = max(10.0 ** math.floor(math.log10(float(finite.min()))), high * 10.0 ** -decades)
    return LogNorm(low, high if high > low else low * 10)


def failed_legend(ax, label: str = "failed") -> None:
    """An entry in ``ax``'s legend for the failed-run marker, drawn once."""
    ax.plot([], [], label=label, **FAILED)


def distinct_tick_texts(ax, axis: str = "y") -> list[str]:
    """The texts of ``ax``'s visible major tick labels on ``axis`` after the figure is drawn,
    with the offset text appended to each (what a reader sees): tests check they differ."""
    target = ax.yaxis if axis == "y" else ax.xaxis
    low, high = sorted(ax.get_ylim() if axis == "y" else ax.get_xlim())
    offset = target.get_offset_text().get_text()
    return [f"{label.get_text()}{offset}" for tick, label in
            zip(target.get_majorticklocs(), target.get_majorticklabels(), strict=False)
            if low <= tick <= high and label.get_text()]


# On a log axis that holds exact zeros, the decade they are drawn at (`zero_floor`) lies this
# many decades below the smallest positive value, and no other tick is labelled closer to it
# than this fraction of the axis' height (a "10⁻¹⁶" beside the "0" overlapped it).
ZERO_FLOOR_DECADES = 1
ZERO_TICK_CLEARANCE = 0.12


def zero_floor(arrays) -> float | None:
    """Where a log panel draws the exact zeros of ``arrays`` (non-finite entries ignored): the
    decade `ZERO_FLOOR_DECADES` below their smallest positive value (1e-17 if none is
    positive), or ``None`` if none of them is exactly zero (then nothing changes)."""
    values = [np.asarray(a, dtype=float) for a in arrays]
    if not any((v == 0).any() for v in values):
        return None
    found = [v[np.isfinite(v) & (v > 0)] for v in values]
    positives = np.concatenate(found) if found else np.array([])
    smallest = float(positives.min()) if positives.size else 1e-16
    return 10.0 ** (math.floor(math.log10(smallest)) - ZERO_FLOOR_DECADES)


def with_zeros_at(values, floor: float | None) -> np.ndarray:
    """``values`` as a log axis shows them (`positive`), their exact zeros at ``floor``."""
    shown = positive(values)
    if floor is None:
        return shown
    return np.where(np.asarray(values, dtype=float) == 0, floor, shown)


def zero_tick(ax, floor: float) -> None:
    """The bottom of ``ax``'s log y axis at ``floor``, where `with_zeros_at` put the exact
    zeros, with a tick there labelled ``0``; the usual decades above it, each label in plain
    text as `plain_tick_labels` writes them, none crowding the ``0``."""
    from matplotlib import ticker

    class ZeroLocator(ticker.LogLocator):
        def tick_values(self, vmin, vmax):
            ticks = super().tick_values(vmin, vmax)
            low, high = math.log10(max(min(vmin, vmax), floor)), math.log10(max(vmin, vmax))
            clear = ZERO_TICK_CLEARANCE * max(high - low, 1e-12)
            kept = [t for t in ticks if t > 0 and math.log10(t) - math.log10(floor) >= clear]
            return np.array([floor, *kept])

    class ZeroFormatter(ticker.LogFormatterSciNotation):
        def __call__(self, x, pos=None):
            if math.isclose(x, floor, rel_tol=1e-9):
                return "0"
            return plain_text(super().__call__(x, pos))

    ax.set_ylim(bottom=floor)
    ax.yaxis.set_major_locator(ZeroLocator())
    ax.yaxis.set_major_formatter(ZeroFormatter())
