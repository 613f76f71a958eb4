"""The procedure's page as a PDF to print.

With the ``pdf`` extra (WeasyPrint, which needs the system's Pango), :func:`typeset_pdf`
typesets the very HTML page the technician sees, its pictures included.  Without it,
:func:`draw_pdf` draws the same content with matplotlib (a dependency already): A4 pages of
text, the pictures and the readings sheet; :func:`typeset_problem` says why the page could
not be typeset and :data:`TYPESET_HINT` how to get it typeset.

Both hold what :func:`calibrators.workflow.page.page` holds: the summary, the rules, the
picture of a leg's bars, the stands, the steps with their pictures, and the sheet with a
blank column to write each reading in.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

from calibrators.workflow.instruments import used_in
from calibrators.workflow.plan import Procedure, rho_words
from orthoglide_env.model.design import MachineDesign

#: A4 portrait, inches.
A4 = (8.27, 11.69)
#: Characters per line of the page's text, and text lines per page, at its font size.
WIDTH, LINES = 95, 62
#: Rows of the readings sheet per page.
SHEET_ROWS = 40
#: How to get the typeset PDF: the ``pdf`` extra and the system library WeasyPrint loads.
TYPESET_HINT = ("pip install -e '.[pdf]' in the workbench's folder (WeasyPrint; it needs "
                "Pango: apt-get install libpango-1.0-0 libpangoft2-1.0-0 on Debian/Ubuntu)")


def typeset_problem() -> str | None:
    """Why the page cannot be typeset here (WeasyPrint is missing, or cannot load Pango),
    or None when :func:`typeset_pdf` can."""
    try:
        import weasyprint  # noqa: F401
    except ImportError:
        return "WeasyPrint (the pdf extra) is not installed"
    except OSError as exc:  # WeasyPrint found, the system's Pango not
        return f"WeasyPrint cannot load Pango: {str(exc).splitlines()[0]}"
    return None


def typeset_pdf(page: Path, out: Path) -> Path:
    """Typeset the HTML ``page`` (its pictures beside it) as the PDF ``out``, with
    WeasyPrint; ``ImportError`` or ``OSError`` when :func:`typeset_problem` says it cannot."""
    import weasyprint

    weasyprint.HTML(filename=str(page)).write_pdf(out)
    return out


def draw_pdf(procedure: Procedure, folder: Path, pictures: dict[int, str], bars: str,
              stands: list[str], then: str, out: Path) -> Path:
    """Write the PDF of ``procedure``'s page to ``out``; ``folder`` holds the pictures
    (``pictures``: file names by step number; ``bars``: the picture of a leg's bars),
    ``stands`` where each row of the sheet is read (its stand, or a step gauge's face:
    :func:`~calibrators.workflow.plan.sheet_readers`), ``then`` the command that reads the
    filled sheet."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backends.backend_pdf import PdfPages

    with PdfPages(out, metadata={"Title": f"Calibration procedure: {procedure.agent}"}) as pdf:
        _text_pages(pdf, _opening(procedure, then))
        _picture_page(pdf, folder / bars, "Where a stand goes on a bar: each leg has "
                      "two parallel bars, d apart; a stand's place names its bar by its side, "
                      "+d/2 or -d/2, and the distance along it from the centre of the "
                      "platform-end hinge.")
        lines = []
        for work in used_in([s.action for s in procedure.steps]):
            lines += [f"The {work.name}", ""]
            for text in work.before(MachineDesign.from_dict(procedure.design)):
                lines += [*_wrapped(text, "  "), ""]
        lines += ["The stands at set-up", ""]
        for s in procedure.stands:
            lines += _wrapped(f"stand {s['stand']} at {s['slot']}: {s['place']}", "  ")
        lines += ["", "Steps", ""]
        for step in procedure.steps:
            rows = (f" (sheet rows {step.rows[0]}-{step.rows[-1]})" if len(step.rows) > 1
                    else f" (sheet row {step.rows[0]})" if step.rows else "")
            lines += _wrapped(f"{step.number}. {step.action}, {step.seconds:.0f} s from "
                              f"{step.start_s / 60:.1f} min{rows}: {step.text}", "   ")
        _text_pages(pdf, lines)
        for number, name in pictures.items():
            step = procedure.steps[number - 1]
            _picture_page(pdf, folder / name, f"Step {number}: {step.text}")
        _sheet_pages(pdf, procedure, stands)
    return out


def _opening(procedure: Procedure, then: str) -> list[str]:
    design = procedure.design
    lines = ["Calibration procedure", ""]
    lines += _wrapped(
        f"Agent {procedure.agent}, {len(procedure.steps)} steps, {len(procedure.sheet)} "
        f"readings, {procedure.total_s / 60:.1f} min on the lab's clock (budget "
        f"{procedure.budget_s / 60:.0f} min), planned for "
        f"{procedure.conditions.get('name', 'ideal')} conditions and "
        f"{procedure.gauges_words()} on a machine of L = "
        f"{design['L']:g} mm, control limits {design['rho_min']:g} .. {design['rho_max']:g} "
        "mm.")
    lines += ["", "Before you start", ""]
    for rule in (
            "Postures are control coordinates rho (mm): 0, 0, 0 is the Zero posture, and each "
            "value is a drive's command. The machine drives all three axes together.",
            "Every reading is written in mm, positive when the touched face moves toward the "
            "+ world axis the stand measures along (the pictures show the axes). Each "
            "stand's place says whether its plunger then comes out or is pushed in, and so "
            "whether to write what a dial that reads plus when pressed shows, or minus that.",
            "Fill in reading_mm in readings.csv row by row, as the steps say: sheet row N is "
            "line N + 1 of the file. The stand column names the stand each row is read on: "
            "read that stand's dial. A row whose gauge gives no reading (out of its travel) "
            "is deleted. Write the lab clock in time_s when it differs from the planned "
            f"time: it starts at 0 when the set-up ends. Then run {then}.",
            "The set-up is not on the lab's clock. Each step's seconds are the lab's time "
            "table: driving at 20 mm/s, 5 s to settle and read, 3 s per plunger lever, 120 s "
            "per re-mount. Read the dials to their resolution (0.01 mm for the usual dial).",
            *(f"Note: {n}." for n in procedure.notes)):
        lines += _wrapped(f"- {rule}", "  ")
    return lines


def _wrapped(text: str, indent: str = "") -> list[str]:
    return textwrap.wrap(text, WIDTH, subsequent_indent=indent) or [""]


def _text_pages(pdf: Any, lines: list[str]) -> None:
    """``lines`` on as many pages as they take, a heading (a line followed by a blank one,
    starting a section) in bold."""
    from matplotlib import pyplot as plt

    for start in range(0, len(lines), LINES):
        figure = plt.figure(figsize=A4)
        try:
            for k, line in enumerate(lines[start:start + LINES]):
                heading = (line and not line.startswith((" ", "-")) and start + k + 1 < len(lines)
                           and lines[start + k + 1] == "" and len(line) < 40)
                figure.text(0.07, 0.95 - k * 0.9 / LINES, line, fontsize=11 if heading else 8,
                            fontweight="bold" if heading else "normal", family="monospace"
                            if not heading else "sans-serif", va="top")
            pdf.savefig(figure)
        finally:
            plt.close(figure)


def _picture_page(pdf: Any, path: Path, caption: str) -> None:
    from matplotlib import image
    from matplotlib import pyplot as plt

    figure = plt.figure(figsize=A4)
    try:
        axes = figure.add_axes((0.05, 0.3, 0.9, 0.6))
        axes.imshow(image.imread(path))
        axes.set_axis_off()
        figure.text(0.07, 0.27, "\n".join(_wrapped(caption)), fontsize=8, va="top",
                    family="monospace")
        pdf.savefig(figure)
    finally:
        plt.close(figure)


def _sheet_pages(pdf: Any, procedure: Procedure, stands: list[str]) -> None:
    """The readings sheet, :data:`SHEET_ROWS` rows a page, its last column blank."""
    from matplotlib import pyplot as plt

    header = ["row", "step", "stand", "mounting", "posture", "rho (mm)", "rep.", "time (s)",
              "reading (mm)"]
    cells = [[str(k), str(m.step), n, m.mounting, m.posture,
              rho_words(m.rho), str(m.repetition),
              "" if m.time_s is None else f"{m.time_s:.0f}", ""]
             for k, (m, n) in enumerate(zip(procedure.sheet, stands, strict=True), start=1)]
    for start in range(0, len(cells), SHEET_ROWS):
        figure = plt.figure(figsize=A4)
        try:
            figure.text(0.07, 0.965, f"Readings sheet, rows {start + 1}-"
                        f"{min(start + SHEET_ROWS, len(cells))} of {len(cells)}",
                        fontsize=11, fontweight="bold")
            axes = figure.add_axes((0.04, 0.04, 0.92, 0.9))
            axes.set_axis_off()
            table = axes.table(cellText=cells[start:start + SHEET_ROWS], colLabels=header,
                               loc="upper center", cellLoc="left",
                               colWidths=[0.05, 0.05, 0.06, 0.2, 0.1, 0.22, 0.05, 0.08, 0.16])
            table.auto_set_font_size(False)
            table.set_fontsize(7)
            table.scale(1, 1.35)
            pdf.savefig(figure)
        finally:
            plt.close(figure)
