"""The report as a paginated PDF: the same content as the HTML, figures as vector drawings.

Made with reportlab's page layout (platypus); each figure's SVG is converted to reportlab vector
drawing commands by svglib, so lines and text stay sharp at any zoom.  The HTML-only animation is
replaced by a sentence.  ``invariant=1`` fixes the document id and dates, so two builds of the same
report differ only in the printed build timestamp.
"""

from __future__ import annotations

import io
from xml.sax.saxutils import escape

from reportlab.graphics.shapes import Drawing
from reportlab.lib import colors
from reportlab.lib.pagesizes import A4
from reportlab.lib.styles import ParagraphStyle, getSampleStyleSheet
from reportlab.lib.units import mm
from reportlab.platypus import (KeepTogether, PageBreak, Paragraph, Preformatted,
                                SimpleDocTemplate, Table as PdfTable, TableStyle)
from svglib.svglib import svg2rlg

from mbh._harness.report.summary import Table, cell_text

#: Page margins, pt.
MARGIN = 15 * mm
#: Largest height of a figure on the page, pt (a figure is scaled to fit the width and this).
MAX_FIGURE_HEIGHT = 110 * mm

_STYLES = getSampleStyleSheet()
_BODY = _STYLES["BodyText"]
_SMALL = ParagraphStyle("small", parent=_BODY, fontSize=8, leading=10)
_NOTE = ParagraphStyle("note", parent=_SMALL, textColor=colors.HexColor("#5a5a5a"))
_OMITTED = ParagraphStyle("omitted", parent=_SMALL, textColor=colors.HexColor("#8a4b00"))
_CELL = ParagraphStyle("cell", parent=_BODY, fontSize=6.5, leading=8)
_HEAD = ParagraphStyle("head", parent=_CELL, fontName="Helvetica-Bold")
_CODE = ParagraphStyle("code", parent=_STYLES["Code"], fontSize=6.5, leading=8)
#: Space after a table or figure, pt: carried by its last flowable (``spaceAfter``), which
#: reportlab drops at the foot of a page, never by a trailing Spacer, which would open a blank
#: page when the block ends a page exactly.
_BLOCK_GAP = 4 * mm
_BLOCK_NOTE = ParagraphStyle("block_note", parent=_NOTE, spaceAfter=_BLOCK_GAP)


def _text(text: str, style=_BODY) -> Paragraph:
    """A paragraph of plain text (escaped: reportlab paragraphs parse markup)."""
    return Paragraph(escape(str(text)), style)


def _table(table: Table, width: float) -> list:
    """A report table as flowables: caption, the table (header repeated on every page), note."""
    parts = [_text(table.caption, ParagraphStyle("caption", parent=_SMALL, fontName="Helvetica-Bold"))]
    if not table.rows:
        return parts + [_text("No rows.", _BLOCK_NOTE)]
    data = [[_text(column, _HEAD) for column in table.columns]]
    data += [[_text(cell_text(value), _CELL) for value in row] for row in table.rows]
    flowable = PdfTable(data, colWidths=[width / len(table.columns)] * len(table.columns),
                        repeatRows=1)
    flowable.setStyle(TableStyle([
        ("BACKGROUND", (0, 0), (-1, 0), colors.HexColor("#f4f6f8")),
        ("LINEBELOW", (0, 0), (-1, -1), 0.25, colors.HexColor("#d0d0d0")),
        ("VALIGN", (0, 0), (-1, -1), "TOP"),
        ("LEFTPADDING", (0, 0), (-1, -1), 2), ("RIGHTPADDING", (0, 0), (-1, -1), 2),
        ("TOPPADDING", (0, 0), (-1, -1), 1), ("BOTTOMPADDING", (0, 0), (-1, -1), 1)]))
    parts.append(flowable)
    if table.note:
        return parts + [_text(table.note, _BLOCK_NOTE)]
    flowable.spaceAfter = _BLOCK_GAP
    return parts


def svg_drawing(svg: str, width: float, max_height: float = MAX_FIGURE_HEIGHT) -> Drawing:
    """``svg`` as a reportlab vector drawing scaled to fit ``width`` × ``max_height`` (pt).

    Raises
    ------
    ValueError
        When svglib cannot read the SVG.
    """
    drawing = svg2rlg(io.BytesIO(svg.encode("utf-8")))
    if drawing is None or not drawing.width or not drawing.height:
        raise ValueError("figure SVG could not be converted to a vector drawing")
    scale = min(width / drawing.width, max_height / drawing.height)
    drawing.scale(scale, scale)
    drawing.width, drawing.height = drawing.width * scale, drawing.height * scale
    return drawing


def _figure(fig, width: float) -> KeepTogether:
    return KeepTogether([svg_drawing(fig.svg, width),
                         Paragraph(f"<b>{escape(fig.title)}</b> {escape(fig.caption)}",
                                   _BLOCK_NOTE)])


def _omitted(report, section: str) -> list:
    return [_text(why, _OMITTED) for why in report.omitted.get(section, [])]


def _failures(report, width: float) -> list:
    """The section "Where methods fail" (none when the report has no hard or swept scene)."""
    if not report.failure_scenes:
        return []
    h2, h3 = _STYLES["Heading2"], _STYLES["Heading3"]
    story = [_text("Where methods fail", h2),
             _text("The hard scenes (tag hard) and every scene of the stability sweep: the largest "
                   "stable step per engine and method, the outcome of every case per step size, "
                   "and for the hard scenes the reference's conditioning σ_r/σ_1 of the joint "
                   "Jacobian Φ_q (r: its rank at the start) with the failure times marked. The "
                   "reading under each name is generated from the stored rows.", _SMALL)]
    for scene in report.failure_scenes:
        story += [_text(scene.scenario, h3),
                  *(_text(f"• {line}", _SMALL) for line in scene.reading)]
        if scene.conditioning is not None:
            story.append(_figure(scene.conditioning, width))
        story += _table(scene.stable_steps, width) + _table(scene.outcomes, width)
    return story + _omitted(report, "failures")


def _story(report, width: float) -> list:
    """The flowables of the whole report, in the HTML's order."""
    h1, h2, h3 = _STYLES["Title"], _STYLES["Heading2"], _STYLES["Heading3"]
    story = [_text(f"mbh report: {report.run_id}", h1),
             _text(f"Campaign {report.campaign} (run {report.run_status})"
                   + (f", compared with run {report.against}" if report.against else "")
                   + f". Accuracy threshold of the campaign: {cell_text(report.accuracy)} on each "
                     f"scenario's main output."),
             _text(f"Built {report.built_at}", _NOTE),
             _text("Summary", h2),
             *_omitted(report, "store"),
             _text("For each scenario and accuracy level: the fastest case with status ok whose "
                   "main-output error (largest |y − y_ref| on the evaluation grid, rad or m) is at "
                   "most the level.", _SMALL)]
    for table in (report.pareto, *report.fastest):
        story += _table(table, width)
    story += [_text("Failures", h3), *_table(report.status_counts, width),
              *_table(report.failures, width), _text("Changes against the previous run", h3)]
    if report.changes is not None:
        story += _table(report.changes, width)
    story += _omitted(report, "changes")

    story += [PageBreak(), _text("Work–precision diagrams", h2)]
    for name, figs in report.work_precision:
        story += [_text(name, h3), *(_figure(fig, width) for fig in figs)]
    story += [_text("Stability maps", h2), *(_figure(fig, width) for fig in report.stability)]
    story += _failures(report, width)
    story += [_text("Time histories", h2), *(_figure(fig, width) for fig in report.histories),
              *_omitted(report, "histories")]
    story += [_text("Model size and cost", h2), *_table(report.model_size, width)]
    if report.coordinates:
        story.append(_text("The in-house formulation in both coordinates", h3))
    for table in report.coordinates:
        story += _table(table, width)
    story += [_text("Mechanisms", h2),
              _text("The animations are in the HTML report.", _NOTE)]
    for view in report.mechanisms:
        story += [_text(view.scenario, h3), _figure(view.snapshots, width)]
    story += _omitted(report, "mechanisms")

    seed = report.seed
    story += [PageBreak(), _text("The seed's comparison: Rouvinen 2003 and ours", h2),
              _text(f"Published: {seed['source']}", _NOTE)]
    if seed["missing"]:
        story.append(_text(seed["missing"], _OMITTED))
    story += [_text(line, _SMALL) for line in seed["summary"]]
    story += _table(seed["table"], width) + _table(seed["newton"], width)
    story += [_text("Why the numbers differ", h3), *(_text(f"• {n}", _SMALL) for n in seed["notes"]),
              _text("The seed's own remarks", h3), *(_text(f"• {r}", _SMALL) for r in seed["remarks"])]

    environment = Table(key="environment", caption="Run, machine and package versions",
                        columns=("item", "value"), rows=tuple(report.environment))
    story += [PageBreak(), _text("Environment and reproduction", h2), *_table(environment, width),
              *_table(report.scenario_hashes, width), _text("Commands", h3),
              Preformatted(report.command, _CODE), _text("Campaign file", h3),
              Preformatted(report.campaign_text, _CODE)]
    story += [PageBreak(), _text("All cases", h2), *_table(report.cases, width)]
    return story


def render_pdf(report) -> bytes:
    """The PDF bytes of ``report`` (:class:`mbh._harness.report.build.Report`)."""
    buffer = io.BytesIO()
    document = SimpleDocTemplate(
        buffer, pagesize=A4, leftMargin=MARGIN, rightMargin=MARGIN, topMargin=MARGIN,
        bottomMargin=MARGIN, title=f"mbh report {report.run_id}", author="mbh",
        invariant=1)

    def footer(canvas, doc):
        canvas.saveState()
        canvas.setFont("Helvetica", 7)
        canvas.setFillColor(colors.HexColor("#5a5a5a"))
        canvas.drawString(MARGIN, MARGIN / 2, f"mbh report {report.run_id}")
        canvas.drawRightString(A4[0] - MARGIN, MARGIN / 2, f"page {doc.page}")
        canvas.restoreState()

    document.build(_story(report, document.width), onFirstPage=footer, onLaterPages=footer)
    return buffer.getvalue()
