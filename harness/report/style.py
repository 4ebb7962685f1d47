"""The report's figure style: one colour-blind-safe palette, the outcome colours, and the
serialisation of a matplotlib figure into a deterministic :class:`Figure` record.

Colours are the Okabe–Ito palette (Okabe & Ito 2008, "Color Universal Design"), distinguishable
under the common colour-vision deficiencies; lines also differ by marker, and outcome cells carry a
letter, so no information rests on colour alone.

Determinism: the same figure gives byte-identical SVG and PDF.  SVG element ids are hashed with a
salt derived from the figure's title (``svg.hashsalt``; several figures inline in one HTML page so
do not share ids), the SVG carries no date, the PDF no creation or modification date.  SVG text is
kept as ``<text>`` (``svg.fonttype = 'none'``): sharp at every zoom, searchable, and escaped by the
SVG writer.  The root ``<svg>`` keeps its ``viewBox`` but no fixed width or height, so it scales to
its container (laptop or phone).
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import math
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from xml.sax.saxutils import escape

import matplotlib
from matplotlib.figure import Figure as MplFigure

from mbh._harness.common.numbers import is_missing
from mbh._harness.common.status import CaseStatus

#: Okabe–Ito colours for lines, in the order series take them (yellow left out: too light).
PALETTE = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000")
#: Markers cycled after the colours (series i: colour i mod 7, marker i div 7).
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
#: Colour of the reference solution wherever it is drawn.
REFERENCE_COLOUR = "#7F7F7F"

#: Outcome of a case → colour (Okabe–Ito plus greys).  ``unverified``: ended ``ok`` on a scene
#: without a verified reference, so its accuracy is unknown.
OUTCOME_COLOURS: dict[str, str] = {
    "accurate": "#009E73",
    "inaccurate": "#F0E442",
    "unverified": "#DDDDDD",
    CaseStatus.DIVERGED: "#D55E00",
    CaseStatus.FAILED: "#E69F00",
    CaseStatus.CRASHED: "#CC79A7",
    CaseStatus.TIMEOUT: "#56B4E9",
    CaseStatus.UNSUPPORTED: "#999999",
}
#: One letter per outcome, printed in stability-map cells (colour is never the only cue).
OUTCOME_LETTERS: dict[str, str] = {
    "accurate": "A", "inaccurate": "I", "unverified": "?", CaseStatus.DIVERGED: "D",
    CaseStatus.FAILED: "F", CaseStatus.CRASHED: "C", CaseStatus.TIMEOUT: "T",
    CaseStatus.UNSUPPORTED: "U",
}

_RC = {
    "svg.fonttype": "none",
    "pdf.fonttype": 42,
    "font.family": "sans-serif",
    "font.sans-serif": ["DejaVu Sans", "Arial", "Helvetica", "sans-serif"],
    "font.size": 9.0,
    "axes.titlesize": 9.5,
    "axes.labelsize": 9.0,
    "legend.fontsize": 7.5,
    "xtick.labelsize": 8.0,
    "ytick.labelsize": 8.0,
    "axes.grid": True,
    "grid.color": "#DDDDDD",
    "grid.linewidth": 0.5,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "lines.linewidth": 1.3,
    "lines.markersize": 4.5,
}


@dataclass(frozen=True)
class Figure:
    """A rendered report figure.

    Attributes
    ----------
    title : str
    svg : str
        Standalone ``<svg>`` text (no XML prolog), deterministic for the same input.
    pdf : bytes
        The same figure as a one-page vector PDF.
    caption : str
    alt : str
        Text alternative: what the figure shows, for readers who cannot see it.
    """

    title: str
    svg: str
    pdf: bytes
    caption: str
    alt: str


@contextlib.contextmanager
def apply_style(salt: str = "mbh") -> Iterator[None]:
    """Context in which figures get the report's style; ``salt`` seeds the SVG element ids."""
    with matplotlib.rc_context(_RC | {"svg.hashsalt": salt}):
        yield


def series_style(index: int) -> dict:
    """Colour and marker of the ``index``-th line of a plot (keyword arguments of ``plot``)."""
    return {"color": PALETTE[index % len(PALETTE)],
            "marker": MARKERS[(index // len(PALETTE)) % len(MARKERS)]}


def plain(text: str) -> str:
    """``text`` for a matplotlib label: dollar signs escaped so that no mathtext is parsed (a
    method or scenario name is shown as written)."""
    return str(text).replace("$", r"\$")


def outcome(row: Mapping, accuracy: float | None = None) -> str:
    """The outcome of a case row (a store row, dict or pandas Series).

    A run that did not end ``ok`` has its status as outcome (diverged, failed, crashed, timeout,
    unsupported).  An ``ok`` run is ``accurate`` or ``inaccurate``: by its main-output error
    against ``accuracy`` (rad or m; error ≤ accuracy is accurate, as the ``accurate`` column is
    computed) when given, else by the row's ``accurate`` column; ``unverified`` when that cannot
    be told (no reference: no error, ``accurate`` empty).

    Raises
    ------
    ValueError
        For a status outside the trajectory vocabulary.
    """
    status = row["status"]
    if status != CaseStatus.OK:
        if status not in OUTCOME_COLOURS:
            raise ValueError(f"case row {row.get('case_id', '?')!r}: unknown status {status!r}")
        return status
    if accuracy is not None:
        error = row.get("main_output_error")
        if is_missing(error) or not math.isfinite(error):
            return "unverified"
        return "accurate" if error <= accuracy else "inaccurate"
    accurate = row.get("accurate")
    if is_missing(accurate):
        return "unverified"
    return "accurate" if bool(accurate) else "inaccurate"


_SVG_OPEN = re.compile(r"<svg\b[^>]*>", re.DOTALL)


def _scalable_svg(text: str, alt: str) -> str:
    """The matplotlib SVG without its prolog, fixed width and height, labelled with ``alt``."""
    start = text.index("<svg")
    body = text[start:]
    opening = _SVG_OPEN.match(body).group(0)
    scalable = re.sub(r'\s(width|height)="[^"]*"', "", opening)
    scalable = scalable[:-1] + f' role="img" aria-label="{escape(alt, {chr(34): "&quot;"})}">'
    return scalable + f"\n<title>{escape(alt)}</title>" + body[len(opening):]


def render(figure: MplFigure, title: str, caption: str, alt: str) -> Figure:
    """Serialise a matplotlib figure (drawn inside :func:`apply_style`) into a :class:`Figure`.

    SVG and PDF are written with the style's rc settings and an id salt derived from ``title``.
    The constrained layout is computed once and then frozen, so both files (and a second call)
    get the same positions.
    """
    salt = "mbh-" + hashlib.sha256(title.encode()).hexdigest()[:12]
    with apply_style(salt):
        figure.draw_without_rendering()
        figure.set_layout_engine("none")
        svg_buffer, pdf_buffer = io.StringIO(), io.BytesIO()
        figure.savefig(svg_buffer, format="svg", metadata={"Date": None})
        figure.savefig(pdf_buffer, format="pdf",
                       metadata={"CreationDate": None, "ModDate": None, "Title": title})
    return Figure(title=title, svg=_scalable_svg(svg_buffer.getvalue(), alt),
                  pdf=pdf_buffer.getvalue(), caption=caption, alt=alt)


def new_figure(width: float, height: float) -> MplFigure:
    """A matplotlib figure (inches) with constrained layout, without pyplot's global state."""
    return MplFigure(figsize=(width, height), layout="constrained")


def no_data(title: str, message: str) -> Figure:
    """A small figure that says there is nothing to draw, and why."""
    with apply_style():
        figure = new_figure(6.4, 1.6)
        axes = figure.add_subplot()
        axes.set_axis_off()
        axes.text(0.5, 0.5, plain(f"no data: {message}"), ha="center", va="center",
                  transform=axes.transAxes)
        axes.set_title(plain(title))
    return render(figure, title, f"No data: {message}.", f"{title}: no data ({message}).")
