"""The printable page of a procedure, and its pictures of the stands.

:func:`write_page` writes into a plan's folder ``setup.png`` and ``step-N.png`` (the
machine at Zero with the stands mounted at set-up and after each re-mount, each stand
marked and labelled, the moved one in red; at an instrument's set-up, the machine with
that instrument in place: :mod:`calibrators.workflow.instruments`), ``bars.png`` (a
leg's two bars, the distance d between them that a stand's place "+d/2" or "-d/2"
refers to, and where along a bar a stand's "at" is measured from), ``procedure.html``, a
printable page with the stands, the steps, their pictures and the sheet to fill in, and
``procedure.pdf``, the same to print: that page typeset with the ``pdf`` extra, else
drawn with matplotlib (:mod:`calibrators.workflow.page_pdf`).
"""

from __future__ import annotations

import html
from pathlib import Path

from calibrators.workflow.instruments import used_in, work_of_action
from calibrators.workflow.plan import Procedure, rho_words, sheet_readers
from orthoglide_env.lab.operations import slot_catalogue
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams

#: The page's file name in a plan's folder, and its PDF's.
PAGE_FILE, PDF_FILE = "procedure.html", "procedure.pdf"
#: The picture of a leg's bars and the distance d between them.
BARS_FILE = "bars.png"
#: The command that reads a plan's filled sheet, as the page names it.
FIT_COMMAND = "orthoglide fit readings.csv --plan plan.json"


def write_page(procedure: Procedure, folder: str | Path, then: str = FIT_COMMAND,
               pdf: bool = False) -> tuple[Path, dict[int, str]]:
    """Write the pictures and :data:`PAGE_FILE` of ``procedure`` into ``folder`` (made if
    missing), and with ``pdf`` :data:`PDF_FILE` too: the page typeset when
    :func:`~calibrators.workflow.page_pdf.typeset_problem` finds none, else drawn with
    matplotlib; ``then``: the command that reads the filled sheet.  The page's path, and
    the pictures' file names by step number."""
    from calibrators.workflow.page_pdf import draw_pdf, typeset_pdf, typeset_problem

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    design = MachineDesign.from_dict(procedure.design)
    drawn = pictures(procedure, design, folder)
    draw_bars(design, folder / BARS_FILE)
    path = folder / PAGE_FILE
    path.write_text(page(procedure, drawn, then), encoding="utf-8")
    if pdf and typeset_problem() is None:
        typeset_pdf(path, folder / PDF_FILE)
    elif pdf:
        draw_pdf(procedure, folder, drawn, BARS_FILE, sheet_readers(procedure), then,
                 folder / PDF_FILE)
    return path, drawn


def draw_bars(design: MachineDesign, out: Path) -> Path:
    """A leg's parallelogram seen square on: its two bars, d apart, the bar at +d/2 and
    the one at -d/2 named, and a stand's place ``at`` measured from the centre of the
    platform-end hinge; what a stand's place in words refers to."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    length, d = design.L, design.d
    figure, axes = plt.subplots(figsize=(9, 3.6), dpi=100)
    try:
        for sign, words in ((1, "bar at +d/2: a stand measuring square to this picture "
                             "touches it"),
                            (-1, "bar at -d/2: a stand measuring up this picture\ntouches "
                             "it from below")):
            axes.plot([0, length], [sign * d / 2] * 2, color="dimgray", lw=7,
                      solid_capstyle="round")
            axes.text(0.78 * length if sign < 0 else length / 2,
                      sign * d / 2 + sign * 0.22 * d, words, ha="center", va="center",
                      fontsize=9)
            for end in (0, length):
                axes.plot(end, sign * d / 2, "o", ms=9, mfc="white", mec="black")
            axes.plot([length, 1.07 * length], [sign * d / 2] * 2, color="red", lw=0.6)
        axes.plot([0, length], [0, 0], "k-.", lw=0.8)
        axes.annotate("", (1.05 * length, d / 2), xytext=(1.05 * length, -d / 2),
                      arrowprops={"arrowstyle": "<->", "lw": 1.5, "color": "red"})
        axes.text(1.07 * length, 0, f"d = {d:g} mm", color="red", va="center",
                  fontsize=11, fontweight="bold")
        at = 0.4 * length
        axes.annotate("", (0, -1.0 * d), xytext=(at, -1.0 * d),
                      arrowprops={"arrowstyle": "<->", "lw": 1.2, "color": "navy"})
        axes.text(at / 2, -1.08 * d, "at × L from the centre of\nthe platform-end hinge",
                  color="navy", ha="center", va="top", fontsize=9)
        axes.plot([at, at], [-d / 2 - 0.05 * d, -0.9 * d], color="navy", lw=3)
        axes.text(at - 0.01 * length, -0.75 * d, "stand", color="navy", fontsize=9, ha="right")
        axes.text(0, 0.05 * d, "platform end", ha="left", va="bottom", fontsize=9)
        axes.text(length, 0.05 * d, "carriage end", ha="right", va="bottom", fontsize=9)
        axes.set_title(f"A leg's two bars, L = {length:g} mm long, d apart along the hinges' "
                       "axis (z on the x leg, x on the y leg, y on the z leg)", fontsize=10)
        axes.set_xlim(-0.05 * length, 1.25 * length)
        axes.set_ylim(-1.5 * d, 0.95 * d)
        axes.set_aspect("equal")
        axes.set_axis_off()
        figure.tight_layout()
        figure.savefig(out)
    finally:
        plt.close(figure)
    return out


def pictures(procedure: Procedure, design: MachineDesign, out: Path) -> dict[int, str]:
    """A picture per mounting: the set-up's stands, then the stands after each re-mount
    with the moved one highlighted; by step number, file names relative to ``out``."""
    from orthoglide_env.sim.report import render_stands_png

    machine = MachineParams(design=design)
    by_name = {s.slot: s for s in slot_catalogue(design, reference=True)}
    held = {s["stand"]: s["slot"] for s in procedure.stands}
    pictures = {}
    for step in procedure.steps:
        work = work_of_action(step.action)
        if work is not None and step.setup is not None:
            name = f"step-{step.number}.png"
            work.draw(design, step.setup, out / name,
                      f"Step {step.number}: {work.action}")
            pictures[step.number] = name
            continue
        if step.action not in ("set up", "re-mount"):
            continue
        if step.action == "re-mount":
            held[step.stand] = step.slot
        stands = sorted(held)
        name = "setup.png" if step.action == "set up" else f"step-{step.number}.png"
        title = ("Set-up: every stand" if step.action == "set up"
                 else f"Step {step.number}: stand {step.stand} moves to {step.slot}")
        render_stands_png(machine, [by_name[held[k]] for k in stands],
                          [f"stand {k}: {held[k]}" for k in stands], out / name,
                          highlight=None if step.stand is None else stands.index(step.stand),
                          title=title)
        pictures[step.number] = name
    return pictures


def page(procedure: Procedure, pictures: dict[int, str], then: str = FIT_COMMAND) -> str:
    """The printable page: what it is, the sign rule, the stands, the steps with their
    pictures, and the sheet to fill in; ``then``: the command that reads the sheet."""
    e = html.escape
    conditions = procedure.conditions.get("name", "ideal")
    rows = []
    for step in procedure.steps:
        sheet = (f"{step.rows[0]}-{step.rows[-1]}" if len(step.rows) > 1
                 else str(step.rows[0]) if step.rows else "")
        rows.append(f"<tr><td>{step.number}</td><td>{e(step.action)}</td>"
                    f"<td>{e(step.text)}</td><td>{step.seconds:.0f}</td>"
                    f"<td>{step.start_s / 60:.1f}</td><td>{sheet}</td></tr>")
        if step.number in pictures:
            rows.append(f'<tr class="picture"><td colspan="6"><img src="{pictures[step.number]}"'
                        f' alt="{e(step.text[:80])}"></td></tr>')
    instruments = "".join(
        f"<h2>The {e(w.name)}</h2>" + "".join(f"<p>{e(t)}</p>" for t in w.before(
            MachineDesign.from_dict(procedure.design)))
        for w in used_in([s.action for s in procedure.steps]))
    stands = "".join(f"<tr><td>{s['stand']}</td><td class='name'>{e(s['slot'])}</td>"
                     f"<td>{e(s['place'])}</td></tr>" for s in procedure.stands)
    sheet = "".join(
        f"<tr><td>{k}</td><td>{m.step}</td><td>{e(n)}</td>"
        f"<td>{e(m.mounting)}</td><td>{e(m.posture)}</td>"
        f"<td>{rho_words(m.rho)}</td><td>{m.repetition}</td>"
        f"<td>{'' if m.time_s is None else f'{m.time_s:.0f}'}</td><td class='blank'></td></tr>"
        for k, (m, n) in enumerate(zip(procedure.sheet, sheet_readers(procedure),
                                       strict=True), start=1))
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>Calibration procedure: {e(procedure.agent)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 60em; }}
table {{ border-collapse: collapse; width: 100%; margin-bottom: 1.5em; }}
td, th {{ border: 1px solid #888; padding: 0.25em 0.5em; vertical-align: top; }}
th {{ background: #eee; }}
td.blank {{ min-width: 8em; }}
table.sheet td, td.name {{ white-space: nowrap; }}
tr.picture td {{ text-align: center; border: none; }}
img {{ max-width: 100%; }}
@page {{ size: A4; margin: 14mm 12mm;
  @bottom-right {{ content: "page " counter(page) " of " counter(pages); font-size: 8pt; }} }}
@media print {{
  body {{ margin: 0; max-width: none; font-size: 10pt; }}
  table.sheet {{ font-size: 8.5pt; }}
  table.sheet td {{ padding: 0.35em 0.4em; }}
  tr, img {{ page-break-inside: avoid; }}
  h2 {{ page-break-after: avoid; }}
}}
</style></head><body>
<h1>Calibration procedure</h1>
<p>Agent <b>{e(procedure.agent)}</b>, {len(procedure.steps)} steps,
{len(procedure.sheet)} readings, <b>{procedure.total_s / 60:.1f} min</b> on the lab's clock
(budget {procedure.budget_s / 60:.0f} min), planned for <b>{e(conditions)}</b> conditions and
{e(procedure.gauges_words())} on a machine of L = {procedure.design['L']:g} mm, control
limits {procedure.design['rho_min']:g} .. {procedure.design['rho_max']:g} mm.</p>
<h2>Before you start</h2>
<ul>
<li>Postures are control coordinates rho (mm): 0, 0, 0 is the Zero posture, and each value
is a drive's command. The machine drives all three axes together.</li>
<li>Every reading is written in mm, <b>positive when the touched face moves toward the
+ world axis</b> the stand measures along (the pictures show the axes). Each stand's place
says whether its plunger then comes out or is pushed in, and so whether to write what a
dial that reads plus when pressed shows, or minus that.</li>
<li>Fill in <code>reading_mm</code> in <code>readings.csv</code> row by row, as the steps
say: sheet row N is line N + 1 of the file (the first line names the columns). A
mounting such as <code>x-leg/z@0.8#7</code> is the stand's installation at that place (the
number counts the installations). The <code>stand</code> column names the stand each row
is read on: read that stand's dial (<code>fit --plan</code> refuses a row whose stand is
not its step's). A row whose gauge gives no reading (out of its travel) is deleted. Write
the lab clock in <code>time_s</code> when it differs from the planned time: it starts at 0
when the set-up ends. Then run <code>{e(then)}</code>.</li>
<li>The set-up is not on the lab's clock. Each step's seconds are the lab's time table:
driving at 20 mm/s, 5 s to settle and read, 3 s per plunger lever, 120 s per re-mount.
Read the dials to their resolution (0.01 mm for the usual dial).</li>
</ul>
{''.join(f"<p><b>Note:</b> {e(n)}.</p>" for n in procedure.notes)}
{instruments}
<h2>Where a stand goes on a bar</h2>
<p>Each leg has two parallel bars, d apart. A stand's place names its bar by its side,
+d/2 or -d/2, and the distance along the bar from the centre of the platform-end
hinge:</p>
<p><img src="{BARS_FILE}" alt="A leg's two bars, the distance d between them, and where a
stand's place along a bar is measured from"></p>
<h2>The stands at set-up</h2>
<table><thead><tr><th>stand</th><th>slot</th><th>where, and which way it reads plus</th>
</tr></thead>
{stands}</table>
<h2>Steps</h2>
<table><thead><tr><th>step</th><th>action</th><th>what to do</th><th>s</th>
<th>clock (min)</th><th>sheet rows</th></tr></thead>
{''.join(rows)}</table>
<h2>Readings sheet</h2>
<table class="sheet"><thead><tr><th>row</th><th>step</th><th>stand</th><th>mounting</th>
<th>posture</th><th>rho (mm)</th><th>rep.</th><th>time (s)</th><th>reading (mm)</th></tr>
</thead>
{sheet}</table>
</body></html>
"""
