"""``orthoglide session``: a sequential experiment run with a person or a script at the
machine (:mod:`calibrators.workflow.session`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from calibrators.cli.common import (
    UsageError,
    add_conditions,
    add_design,
    add_gauges,
    add_instruments,
    conditions_of,
    workflow_instruments,
)
from orthoglide_env.lab.operations import DEFAULT_BUDGET_S
from orthoglide_env.model.design import load_design


def run(args: argparse.Namespace) -> None:
    from calibrators.study.episodes import machine_seed
    from calibrators.workflow.session import Session, parse_answer

    instruments = workflow_instruments(args, args.agent)
    out = Path(args.out)
    notebook = out / "notebook.jsonl"
    if notebook.exists() and not args.resume:
        raise UsageError(f"{notebook} holds a session: give --resume to go on with it, or "
                         "another --out")
    if args.resume and not notebook.exists():
        raise UsageError(f"--resume: {notebook} does not exist")
    out.mkdir(parents=True, exist_ok=True)
    session = Session(args.agent, args.budget, notebook, design=load_design(args.design),
                      conditions=conditions_of(args, None),
                      seed=machine_seed(args.seed, 0), target_mm=args.target_mm,
                      sigma=args.sigma, resolution=args.resolution, instruments=instruments)

    def say(text: str, action: dict[str, Any] | None = None) -> None:
        if args.json:
            item: dict[str, Any] = {"say": text}
            if action is not None:
                item["action"] = {k: np.asarray(v).tolist() for k, v in action.items()}
            print(json.dumps(item), flush=True)
        else:
            print(text, flush=True)

    def answer(question: dict[str, Any]) -> float | None:
        prompt = (json.dumps({"ask": question}) if args.json else
                  (f"  {question['again']}\n" if "again" in question else "")
                  + (f"  stand {question['stand']} ({question['gauge']}): reading"
                     if "stand" in question else
                     f"  {question['what']} ({question['gauge']})")
                  + " in mm (- for none)? ")
        while True:
            print(prompt, end="\n" if args.json else "", flush=True)
            line = sys.stdin.readline()
            if not line:
                raise UsageError(f"the input ended: {notebook} holds the answers so far; "
                                 "--resume goes on")
            try:
                return parse_answer(line)
            except ValueError as exc:
                # A slip of the finger is asked again, never the end of a session.
                say(f"{exc}: asked again")

    data = session.run(answer, say)
    Session.write(data, out)
    say(f"the experiment is over after {data.experiment_time_s / 60:.1f} min: "
        f"{len(data)} readings in {out / 'readings.csv'}; fit them with orthoglide fit "
        f"{out / 'readings.csv'}")


def add(p: argparse.ArgumentParser) -> None:
    p.description = ("Run an agent that decides as it reads (active) with the readings typed "
        "in, one per line: a number in mm, - for none (out of travel), or a JSON line "
        "{\"reading_mm\": 0.12}.  Every answer goes to --out's notebook.jsonl at once; "
        "--resume replays it and goes on.  At the end the readings are written to "
        "--out's readings.csv, for orthoglide fit.")
    p.add_argument("--agent", default="active",
                   help="an agent that decides as it reads (default: %(default)s)")
    p.add_argument("--budget", type=float, default=DEFAULT_BUDGET_S, metavar="S",
                   help="lab time the experiment may take, seconds (default: %(default)g)")
    p.add_argument("--target-mm", type=float, default=0.0, metavar="MM",
                   help="stop once the predicted TCP error after rigid motion is at most "
                        "this (default: 0, use the budget)")
    p.add_argument("--seed", type=int, default=0,
                   help="the seed of the agent's own choices, as calibrate's (default: "
                        "%(default)s)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder for notebook.jsonl and readings.csv")
    p.add_argument("--resume", action="store_true",
                   help="go on with the session whose notebook --out holds")
    p.add_argument("--json", action="store_true",
                   help="JSON lines on stdout: {\"say\": text, \"action\": ...} per step and "
                        "{\"ask\": {step, text, stand, gauge, rho, time_s}} per reading (an "
                        "instrument's: instrument and what in place of stand)")
    add_design(p)
    add_conditions(p)
    add_gauges(p)
    add_instruments(p)
    p.set_defaults(func=run)
