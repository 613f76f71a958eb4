"""The printable page of a procedure, and its pictures of the stands.

:func:`write_page` writes into a plan's folder ``setup.png`` and ``step-N.png`` (the
machine at Zero with the stands mounted at set-up and after each re-mount, each stand
marked and labelled, the moved one in red) and ``procedure.html``, a printable page with
the stands, the steps, their pictures and the sheet to fill in (print it to PDF from a
browser).
"""

from __future__ import annotations

import html
from pathlib import Path

from calibrators.workflow.plan import Procedure
from orthoglide_env.lab.operations import slot_catalogue
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams

#: The page's file name in a plan's folder.
PAGE_FILE = "procedure.html"
#: The command that reads a plan's filled sheet, as the page names it.
FIT_COMMAND = "orthoglide fit readings.csv --plan plan.json"


def write_page(procedure: Procedure, folder: str | Path, then: str = FIT_COMMAND
               ) -> tuple[Path, dict[int, str]]:
    """Write the pictures and :data:`PAGE_FILE` of ``procedure`` into ``folder`` (made if
    missing); ``then``: the command that reads the filled sheet.  The page's path, and the
    pictures' file names by step number."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    drawn = pictures(procedure, MachineDesign.from_dict(procedure.design), folder)
    path = folder / PAGE_FILE
    path.write_text(page(procedure, drawn, then), encoding="utf-8")
    return path, drawn


def pictures(procedure: Procedure, design: MachineDesign, out: Path) -> dict[int, str]:
    """A picture per mounting: the set-up's stands, then the stands after each re-mount
    with the moved one highlighted; by step number, file names relative to ``out``."""
    from orthoglide_env.sim.report import render_stands_png

    machine = MachineParams(design=design)
    by_name = {s.slot: s for s in slot_catalogue(design, reference=True)}
    held = {s["stand"]: s["slot"] for s in procedure.stands}
    pictures = {}
    for step in procedure.steps:
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
    stands = "".join(f"<tr><td>{s['stand']}</td><td>{e(s['slot'])}</td><td>{e(s['place'])}</td>"
                     "</tr>" for s in procedure.stands)
    sheet = "".join(
        f"<tr><td>{k}</td><td>{m.step}</td><td>{e(m.mounting)}</td><td>{e(m.posture)}</td>"
        f"<td>{', '.join(f'{v:g}' for v in m.rho)}</td><td>{m.repetition}</td>"
        f"<td>{'' if m.time_s is None else f'{m.time_s:.0f}'}</td><td class='blank'></td></tr>"
        for k, m in enumerate(procedure.sheet, start=1))
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>Calibration procedure: {e(procedure.agent)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 60em; }}
table {{ border-collapse: collapse; width: 100%; margin-bottom: 1.5em; }}
td, th {{ border: 1px solid #888; padding: 0.25em 0.5em; vertical-align: top; }}
th {{ background: #eee; }}
td.blank {{ min-width: 8em; }}
tr.picture td {{ text-align: center; border: none; }}
img {{ max-width: 100%; }}
@media print {{ tr, img {{ page-break-inside: avoid; }} }}
</style></head><body>
<h1>Calibration procedure</h1>
<p>Agent <b>{e(procedure.agent)}</b>, {len(procedure.steps)} steps,
{len(procedure.sheet)} readings, <b>{procedure.total_s / 60:.1f} min</b> on the lab's clock
(budget {procedure.budget_s / 60:.0f} min), planned for <b>{e(conditions)}</b> conditions on
a machine of L = {procedure.design['L']:g} mm, control limits {procedure.design['rho_min']:g}
.. {procedure.design['rho_max']:g} mm.</p>
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
number counts the installations). A row whose gauge gives no reading (out of its travel)
is deleted. Write the lab clock in <code>time_s</code> when it differs from the planned
time: it starts at 0 when the set-up ends. Then run <code>{e(then)}</code>.</li>
<li>The set-up is not on the lab's clock. Each step's seconds are the lab's time table:
driving at 20 mm/s, 5 s to settle and read, 3 s per plunger lever, 120 s per re-mount.
Read the dials to their resolution (0.01 mm for the usual dial).</li>
</ul>
{''.join(f"<p><b>Note:</b> {e(n)}.</p>" for n in procedure.notes)}
<h2>The stands at set-up</h2>
<table><tr><th>stand</th><th>slot</th><th>where, and which way it reads plus</th></tr>
{stands}</table>
<h2>Steps</h2>
<table><tr><th>step</th><th>action</th><th>what to do</th><th>s</th><th>clock (min)</th>
<th>sheet rows</th></tr>
{''.join(rows)}</table>
<h2>Readings sheet</h2>
<table><tr><th>row</th><th>step</th><th>stand (mounting)</th><th>posture</th>
<th>rho (mm)</th><th>repetition</th><th>time (s)</th><th>reading (mm)</th></tr>
{sheet}</table>
</body></html>
"""
