"""What every figure shares: the controllers' styles, matplotlib on Agg, decimation and saving.

Styles: the Okabe-Ito palette (distinguishable with the common colour-vision deficiencies) and a distinct line
style per controller, so two controllers differ in colour *and* dash pattern. Each packaged controller's style is
its YAML's ``display`` node (:mod:`.display`; SMC-NDO-NNO solid black and SMC-NDO dashed green as in the paper's
Figs. 8 and 13); any other controller gets a free (colour, dash, marker) combination, preferring one derived from
its name so it keeps its style from report to report. A :class:`StyleBook` built from all the controllers of a report gives each a style no other
controller of that report has, whatever their number.

The configuration (the controllers' ``display`` nodes) is imported when a style or a label is asked for, not with
this module: a process that only draws (:mod:`.processes`) imports this module, numpy and matplotlib alone.
"""

from __future__ import annotations

import itertools
import math
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Mapping

import numpy as np

from ddmr_cli.storage.io import atomic_write

if TYPE_CHECKING:
    from ddmr_cli.display import Display

#: Okabe & Ito (2008), "Color universal design": eight colours told apart with every common colour-vision deficiency.
OKABE_ITO = {
    "black": "#000000", "orange": "#E69F00", "sky_blue": "#56B4E9", "bluish_green": "#009E73",
    "blue": "#0072B2", "vermillion": "#D55E00", "reddish_purple": "#CC79A7", "yellow": "#F0E442",
}
#: Grey dashed: the reference path and the true disturbance (as the paper draws them).
REFERENCE_STYLE = {"color": "0.45", "ls": (0, (5, 2.5)), "lw": 1.3}

DPI = 110
MAX_POINTS = 5000
#: zlib level of the PNGs (Pillow's default: 6). Level 3 encodes ``ddmr run``'s three figures in 0.06 s instead of
#: 0.085 s, in files of about the same size (the paper run's 75/157/211 kB against 74/160/225 kB; up to 13 % larger
#: on other runs); the pixels are the same
PNG_COMPRESSION = 3


@dataclass(frozen=True)
class Style:
    color: str
    dash: str
    marker: str | None = None
    width: float = 1.1

    def kwargs(self, variant: int = 0) -> dict:
        """matplotlib keywords; a controller's further jobs (variants: e.g. a gain sweep) add a marker."""
        from ddmr_cli.display import DASHES, MARKERS
        marker = self.marker if variant == 0 else MARKERS[1 + (variant - 1) % (len(MARKERS) - 1)]
        kw = {"color": self.color, "ls": DASHES[self.dash], "lw": self.width}
        if marker:
            kw.update(marker=marker, markevery=0.07, markersize=4, markerfacecolor="none")
        return kw


def known_styles(displays: Mapping[str, Display] | None = None) -> dict[str, Style]:
    """The style of every controller whose display sets a colour and a dash: the packaged controllers' (their
    ``conf/controller/*.yaml``), then ``displays`` (a report's, from its jobs' configs) over them."""
    from ddmr_cli import display
    out = {}
    for d in [display.of(n) for n in display.packaged_all()] + list((displays or {}).values()):
        if d.colour and d.dash:
            out[d.name] = Style(d.colour, d.dash, d.marker, d.width or display.WIDTH)
        else:
            out.pop(d.name, None)
    return out


def _free_combinations(known: Iterable[Style]) -> list[Style]:
    """Every (colour, dash, marker) not taken by a known controller, in a fixed order (yellow last: it is faint)."""
    from ddmr_cli.display import DASHES, MARKERS
    taken = {(s.color, s.dash, s.marker) for s in known}
    return [Style(c, d, m) for m, c, d in itertools.product(MARKERS, OKABE_ITO.values(), DASHES)
            if (c, d, m) not in taken]


class StyleBook:
    """One style per controller, distinct within the book: a controller whose display sets its colour and dash
    (:func:`known_styles`) keeps its style; any other takes the free combination its name hashes to, or the next
    free one (so the style is stable while there is no clash), in its display's colour when it sets one. Past
    ``len(free)`` such controllers the combinations repeat (more than 400 controllers in one figure)."""

    def __init__(self, controllers: Iterable[str] = (), displays: Mapping[str, Display] | None = None):
        self._styles: dict[str, Style] = {}
        self._known = known_styles(displays)
        self._displays = dict(displays or {})
        self._free = _free_combinations(self._known.values())
        for c in sorted(set(controllers), key=lambda c: (c not in self._known, c)):
            self.add(c)

    def add(self, controller: str) -> Style:
        if controller in self._styles:
            return self._styles[controller]
        if controller in self._known:
            style = self._known[controller]
        else:
            used = set(self._styles.values())
            start = zlib.crc32(controller.encode()) % len(self._free)
            shown = self._displays.get(controller)
            colour = shown.colour if shown is not None else None
            free = [s for s in self._free[start:] + self._free[:start]
                    if s not in used and (colour is None or s.color == colour)]
            style = free[0] if free else self._free[start]
            if colour is not None and style.color != colour:
                style = Style(colour, style.dash, style.marker)
            if shown is not None and shown.width:
                style = Style(style.color, style.dash, style.marker, shown.width)
        self._styles[controller] = style
        return style

    def __getitem__(self, controller: str) -> Style:
        return self.add(controller)


def style_of(controller: str) -> Style:
    """The style of one controller alone (a run's figures): ``StyleBook([controller])[controller]``, read from its
    own config only when it sets a colour and a dash (every packaged controller; the book reads them all)."""
    from ddmr_cli import display

    own = display.of(controller)
    if own.colour and own.dash:
        return Style(own.colour, own.dash, own.marker, own.width or display.WIDTH)
    return StyleBook([controller])[controller]


def label_of(controller: str) -> str:
    """The label of a controller known by name (its packaged YAML's ``display.label``; else its name)."""
    from ddmr_cli import display

    return display.label(controller)


#: The report's font sizes and line simplification; no automatic layout engine (:func:`save` lays a figure out once).
#: Figures are made at the dpi they are saved at (:data:`DPI`), so that the save draws with the renderer, and the text
#: layouts, that :func:`save`'s ``tight_layout`` made (at matplotlib's 100 dpi each text was laid out twice: 3-6 %
#: of table4's figure CPU, 3 alternating pairs).
#:
#: Titles sit at the top of their axes (``axes.titley``: 1.0) instead of being placed at every draw: matplotlib's
#: automatic placement lays out the y axis' tick labels once more for each titled axes, in every draw and every
#: ``tight_layout``, only to lift the title over a top x axis (no figure here has one) or over the y axis' offset
#: text ("1e-3", "+1.1e1"), which :func:`save` does itself when it happens (:func:`lift_titles`). The same pixels on
#: every figure of table4's report and ``ddmr run``; 0.93x the CPU of table4's report figures (6 alternating pairs),
#: 0.93-0.98x the wall of its ``ddmr report`` and 0.95-0.98x that of ``ddmr run`` (paired runs, two sessions each).
RC_PARAMS = {"font.size": 9, "axes.titlesize": 10, "legend.fontsize": 8, "path.simplify": True,
             "agg.path.chunksize": 10000, "figure.autolayout": False, "figure.constrained_layout.use": False,
             "figure.dpi": DPI, "axes.titley": 1.0}


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend, with the report's font sizes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update(RC_PARAMS)
    return plt


def figure(**kwargs):
    """A figure outside pyplot (``matplotlib.figure.Figure``, drawn by Agg when saved), with the report's font
    sizes: for a process that draws a few figures and quits, such as ``ddmr run``, whose plots then do not import
    pyplot (0.25 s). Lay out its axes with ``fig.subplots``."""
    import matplotlib
    from matplotlib.figure import Figure

    matplotlib.rcParams.update(RC_PARAMS)
    return Figure(**kwargs)


def warm_up(fig) -> None:
    """Draw ``fig`` once on the Agg canvas that :func:`save` then draws it on again (a :func:`figure`'s own canvas
    draws nothing): its ticks, text layouts and glyphs are made and cached now, so the save redraws only what
    changed since. Drawn at ``fig``'s dpi: a figure made with ``dpi=DPI`` reuses the renderer and its caches."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()


def log_scale(ax, axis: str = "y") -> None:
    """Put ``ax``'s ``axis`` ("x" or "y") on a log scale labelled in plain numbers (0.01, 0.1, 1, 10; on an axis
    shorter than a decade also 2, 3 and 5 times those), not matplotlib's default 10^k, which goes through its mathtext
    parser: 0.13 s the first time in a process, of a 0.6 s ``ddmr run`` plot set (measured)."""
    from matplotlib.ticker import FuncFormatter

    getattr(ax, f"set_{axis}scale")("log")
    scale_axis = getattr(ax, f"{axis}axis")

    def minor(value, _pos):
        low, high = sorted(scale_axis.get_view_interval())
        mantissa = value / 10.0 ** math.floor(math.log10(value) + 1e-9) if value > 0 else 0.0
        short = low > 0 and high / low < 10.0
        return f"{value:g}" if short and any(abs(mantissa - m) < 1e-6 for m in (2.0, 3.0, 5.0)) else ""

    scale_axis.set_major_formatter(FuncFormatter(lambda value, _pos: f"{value:g}"))
    scale_axis.set_minor_formatter(FuncFormatter(minor))


def lift_titles(fig) -> bool:
    """After a draw of ``fig``, lift each axes' title that overlaps its y axis' offset text ("1e-3", "+1.1e1",
    drawn above the axes' top left corner) just above it, as matplotlib's automatic title placement would (which
    :data:`RC_PARAMS` turns off); True when a title moved (``fig`` then needs drawing again)."""
    moved = False
    for ax in fig.axes:
        title, offset = ax.title, ax.yaxis.offsetText
        if not (title.get_text() and offset.get_visible() and offset.get_text()):
            continue
        box, above = title.get_window_extent(), offset.get_window_extent()
        if box.overlaps(above):
            baseline = ax.transAxes.transform((0.0, title.get_position()[1]))[1]  # pixels
            title.set_y(ax.transAxes.inverted().transform((0.0, baseline + above.y1 - box.y0))[1])
            moved = True
    return moved


def save(fig, path: Path, tight: bool = True, dpi: int = DPI) -> Path:
    """Save a figure atomically as PNG and close it: one layout pass (``tight_layout`` unless the figure placed
    its axes itself), then a single draw (``bbox_inches="tight"`` would draw twice).

    ``tight_layout`` leaves a placeholder layout engine on the figure, and ``savefig`` runs a full draw without
    rendering (every tick and text laid out again) before the real one whenever a figure has an engine. The layout
    is done, so the engine is removed first: the same pixels, a quarter less of the save's CPU (measured on
    table4's figures).

    A title that the draw shows running into its y axis' offset text is lifted (:func:`lift_titles`) and the
    figure laid out and written again."""
    def lay_out_and_write() -> None:
        if tight:
            fig.tight_layout()
            fig.set_layout_engine(None)
        atomic_write(Path(path), lambda tmp: fig.savefig(tmp, format="png", dpi=dpi,
                                                         pil_kwargs={"compress_level": PNG_COMPRESSION}))

    lay_out_and_write()
    for _ in range(3):  # seldom: a title ran into its axis' offset text; lifted, laid out and written again (the
        if not lift_titles(fig):  # new layout can move the axes' top by a pixel or so: then once more)
            break
        lay_out_and_write()
    if getattr(fig.canvas, "manager", None) is not None:  # a pyplot figure: release it (a Figure() has no manager)
        pyplot().close(fig)
    return Path(path)


def thin(y: np.ndarray, max_points: int = MAX_POINTS) -> np.ndarray:
    """Indices of at most about ``max_points`` samples of ``y`` keeping each bin's minimum and maximum (and the
    first and last sample), so a decimated plot of a chattering signal keeps its full envelope; NaN-safe."""
    n = len(y)
    if n <= max_points:
        return np.arange(n)
    k = int(math.ceil(n / (max_points // 2)))
    m = n // k * k
    bins = np.nan_to_num(np.asarray(y[:m], float), nan=0.0).reshape(-1, k)
    base = np.arange(0, m, k)
    keep = np.zeros(n, dtype=bool)  # sorted and unique, as np.unique would give them, without its sort or hash
    keep[base + bins.argmin(axis=1)] = keep[base + bins.argmax(axis=1)] = True
    keep[m:] = keep[0] = keep[n - 1] = True
    return np.flatnonzero(keep)


def spread(a) -> float:
    """1st-99th percentile range of the finite values of ``a`` (0 when there are none)."""
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    return float(np.percentile(a, 99) - np.percentile(a, 1)) if a.size else 0.0


def draw_order(arrays: list[np.ndarray], widths: list[float] | None = None, rtol: float = 0.15) -> list[int]:
    """Indices of ``arrays`` from the widest spread (drawn first, at the back) to the narrowest (drawn last, on
    top), so a quiet line is never buried under a noisy one. Lines whose spreads agree within ``rtol`` (they
    overlap) go thickest first, so a thin dashed line stays visible on a thick solid one."""
    spreads = [spread(a) for a in arrays]
    widths = list(widths) if widths is not None else [1.0] * len(arrays)
    order = sorted(range(len(arrays)), key=lambda i: -spreads[i])
    groups: list[list[int]] = []
    for i in order:
        if groups and spreads[groups[-1][0]] - spreads[i] <= rtol * max(spreads[groups[-1][0]], 1e-300):
            groups[-1].append(i)
        else:
            groups.append([i])
    return [i for g in groups for i in sorted(g, key=lambda i: (-widths[i], -spreads[i]))]


def equal_aspect(ax) -> None:
    """Same scale on x and y (a circle stays a circle); the data limits grow to fill the axes box."""
    ax.set_aspect("equal", adjustable="datalim")
