"""``orthoglide plan``: a designed experiment as a procedure a technician follows
(:class:`calibrators.workflow.plan.Plan`, or with ``--verify`` the verification's
:class:`calibrators.workflow.verify.VerificationPlan`).

It writes into ``--out DIR``:

* ``plan.json``: the steps (:class:`~calibrators.workflow.plan.Procedure`), which
  ``fit --plan`` checks a filled sheet against;
* ``readings.csv``: the readings sheet, a measurement file with ``reading_mm`` blank, one
  row per reading to take, in step order, with its ``step``;
* ``setup.png`` and ``step-N.png``: the machine at Zero with the stands mounted at set-up
  and after each re-mount, each stand marked and labelled (the moved one in red);
* ``bars.png``: a leg's two bars and the distance d between them that a stand's place
  (+d/2, -d/2) refers to;
* ``procedure.html``: a printable page with all of it, the sheet with a stand column;
* with ``--pdf``, ``procedure.pdf``: the same page as a PDF to print, typeset from the
  HTML with the ``pdf`` extra, else drawn with matplotlib (and a line says so).
"""

from __future__ import annotations

import argparse

from calibrators.cli.common import (
    UsageError,
    add_conditions,
    add_design,
    add_gauges,
    add_instruments,
    conditions_of,
    held_design,
    workflow_instruments,
)
from calibrators.workflow.compensate import read_estimate
from calibrators.workflow.page import PDF_FILE, write_page
from calibrators.workflow.page import page as page  # the page's earlier path
from calibrators.workflow.page_pdf import TYPESET_HINT, typeset_problem
from calibrators.workflow.plan import Plan, planned_agents
from calibrators.workflow.verify import VerificationPlan
from orthoglide_env.lab.operations import DEFAULT_BUDGET_S
from orthoglide_env.model.design import load_design


def run(args: argparse.Namespace) -> None:
    if not args.budget > 0:
        raise UsageError(f"--budget must be a positive number of seconds, got {args.budget:g}")
    conditions = conditions_of(args, None)
    instruments = workflow_instruments(args, args.agent)
    try:
        if args.verify and set(instruments) - {"dial", "tracker"}:
            raise UsageError("--verify plans the verification with the dial gauges: leave "
                             "the other instruments out of --instruments")
        if args.verify:
            est = read_estimate(args.verify)
            held_design(args, est.readings.design, "estimate", args.verify)
            planner = VerificationPlan(est, agent=args.agent, conditions=conditions,
                                       budget_s=args.budget, seed=args.seed,
                                       sigma=args.sigma, resolution=args.resolution)
        else:
            planner = Plan(load_design(args.design), agent=args.agent,
                           conditions=conditions, budget_s=args.budget, seed=args.seed,
                           instruments=instruments, sigma=args.sigma,
                           resolution=args.resolution)
        procedure = planner.run()
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    plan_path, sheet_path = procedure.write(args.out)
    then = (f"orthoglide verify {args.verify} readings.csv" if args.verify
            else "orthoglide fit readings.csv --plan plan.json")
    page_path, pictures = write_page(procedure, args.out, then, pdf=args.pdf)
    pdf = f", {page_path.with_name(PDF_FILE)}" if args.pdf else ""
    print(f"{procedure.summary()}; wrote {page_path}{pdf}, {sheet_path}, {plan_path} and "
          f"{len(pictures) + 1} pictures")
    problem = typeset_problem() if args.pdf else None
    if problem:
        print(f"note: {PDF_FILE} is drawn with matplotlib, not typeset from the page, since "
              f"{problem}; for the typeset page: {TYPESET_HINT}")
    for note in procedure.notes:
        print(f"note: {note}")


def add(p: argparse.ArgumentParser) -> None:
    p.add_argument("--agent", default="paper",
                   help=f"an agent that decides its experiment at the start: "
                        f"{', '.join(planned_agents())} (default: %(default)s)")
    p.add_argument("--budget", type=float, default=DEFAULT_BUDGET_S, metavar="S",
                   help="the lab time the experiment may take, seconds (default: "
                        "%(default)g)")
    p.add_argument("--seed", type=int, default=0,
                   help="the stream of a random agent's choices (default: %(default)s)")
    p.add_argument("--verify", metavar="EST",
                   help="plan the verification of the estimate file EST: the experiment "
                        "with every command compensated, as the compensated controller "
                        "drives it; orthoglide verify reads its filled sheet")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder to write plan.json, readings.csv, the pictures and "
                        "procedure.html into (made if missing; files replaced)")
    p.add_argument("--pdf", action="store_true",
                   help="also write the page as procedure.pdf, to print: typeset with the "
                        "pdf extra (pip install -e '.[pdf]'), else drawn with matplotlib")
    add_design(p)
    add_conditions(p)
    add_gauges(p)
    add_instruments(p)
    p.set_defaults(func=run)
