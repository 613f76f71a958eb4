"""What several commands share: the parser class, usage errors, machine options, output."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from calibrators.cli.parser import Parser as Parser
from calibrators.cli.parser import UsageError as UsageError
from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.model.design import PROTOTYPE, MachineDesign, load_design
from orthoglide_env.model.errors import MachineParams, check_rho, random_machine
from orthoglide_env.world.conditions import (
    AUTO,
    CONDITION_NAMES,
    DEFAULT_CONDITIONS,
    DRIVES,
    EFFECT_NAMES,
    INDICATORS,
    Conditions,
)
from orthoglide_env.world.faults import FAULT_KINDS, Faults, as_faults
from orthoglide_env.world.machine_file import read_machine_file
from orthoglide_env.world.truth import World

if TYPE_CHECKING:
    from calibrators.agents import Agent

#: Help of ``--design``, on every command that builds a machine.
DESIGN_HELP = ("machine design file, JSON or TOML: the nominal dimensions, joint limits and "
               "link shapes (see docs/machines.md; keys left out take the "
               "prototype's values; default: the prototype)")


def machine_design_of(args: argparse.Namespace) -> MachineDesign:
    """The design of ``--design FILE``, or the prototype."""
    return load_design(getattr(args, "design", None))


def machine_of(args: argparse.Namespace) -> MachineParams:
    """The machine of ``--machine FILE`` (its design: the file's, else ``--design``'s),
    else a random machine of ``--design`` drawn from ``--seed`` and ``--errors``."""
    return truth_of(args)[0]


def truth_of(args: argparse.Namespace) -> tuple[MachineParams, World | None]:
    """:func:`machine_of` and the world the machine file holds (None when it holds none,
    or for a random machine).  A machine file that names its design (an estimate's, a
    compensation's ``machine.json``) is of that design; ``--design`` is for a file that
    names none, and one that names another is refused."""
    if getattr(args, "machine", None):
        return read_machine_file(args.machine, given_design(args))
    return random_machine(args.seed, args.errors, design=machine_design_of(args)), None


def given_design(args: argparse.Namespace) -> MachineDesign | None:
    """The design of ``--design FILE`` when given, else None (a file's own, or the
    prototype)."""
    return load_design(args.design) if getattr(args, "design", None) else None


def held_design(args: argparse.Namespace, own: MachineDesign, what: str, path: str
                ) -> MachineDesign:
    """``own``, the design the ``what`` file at ``path`` holds (a plan, an estimate);
    :class:`UsageError` in one line when ``--design`` names another."""
    given = given_design(args)
    if given is not None and given != own:
        raise UsageError(f"--design {args.design} is another design than the {what}'s "
                         f"({path}): leave --design out, the {what} holds its design")
    return own


def rho_of(values: list[float], design: MachineDesign) -> np.ndarray:
    return check_rho(np.array(values, dtype=float), design=design)


def vec(values: list[float], digits: int) -> str:
    return "(" + ", ".join(f"{v:.{digits}f}" for v in values) + ")"


def add_machine_posture(p: argparse.ArgumentParser) -> None:
    add_machine(p)
    p.add_argument("--rho", nargs=3, type=float, required=True, metavar=("X", "Y", "Z"),
                   help="joint targets, control coordinates (mm, 0 at the Zero posture, "
                   "each within the design's joint limits, the prototype's "
                   f"[{PROTOTYPE.rho_min:g}, {PROTOTYPE.rho_max:g}]; required)")


def add_design(p: argparse.ArgumentParser) -> None:
    p.add_argument("--design", metavar="FILE", help=DESIGN_HELP)


def add_conditions(p: argparse.ArgumentParser, replays: bool = False,
                   measured: bool = False, told: bool = False) -> None:
    """``--conditions`` and ``--effects``; ``replays``: the command takes a machine file,
    whose world (when it holds one) gives the conditions; ``measured``: the command fits
    readings taken under them (a real machine's), and ``auto`` has the fit estimate
    them; ``told``: the command draws a lab's readings and fits them, and
    ``--fit-conditions`` tells the fit another world than the lab's."""
    default = (f"the machine file's world, else {DEFAULT_CONDITIONS}" if replays
               else f"{READINGS_CONDITIONS}: name lab for a real lab's readings, which then "
               "need each reading's time_s" if measured else DEFAULT_CONDITIONS)
    what = ("the world the readings were taken in, whose effects beyond the geometry the "
            "fit puts into its error bars" if measured else "the world beyond the geometry")
    auto = (", or auto: the fit estimates them from the readings (docs/world.md)"
            if measured else "")
    p.add_argument("--conditions", choices=(*CONDITION_NAMES, AUTO) if measured or told
                   else CONDITION_NAMES, default=None,
                   help=f"{what}: ideal (none), lab (a controlled "
                   "room, a well-kept machine) or workshop (a shop floor, an ordinary "
                   f"machine){auto}; docs/conditions.md lists every effect and its size "
                   f"(default: {default})")
    if told:
        p.add_argument("--fit-conditions", choices=(*CONDITION_NAMES, AUTO), default=None,
                       help="the world the fit is told, when not the lab's: ideal, lab, "
                       "workshop, or auto: the fit estimates it from the readings "
                       "(docs/world.md) (default: --conditions)")
    p.add_argument("--effects", metavar="LIST", default=None,
                   help="only these effects of --conditions act, comma-separated: "
                   f"{','.join(EFFECT_NAMES)} (default: all of them)")
    p.add_argument("--indicator", choices=INDICATORS, default=None,
                   help="the gauges' indicators under lab or workshop conditions: dial "
                   "(ISO 463) or digital (its own error rows in docs/conditions.md; read it at "
                   "1 um with --resolution 0.001 where the "
                   "command has it) (default: dial)")
    p.add_argument("--drives", choices=DRIVES, default=None,
                   help="the machine's drives under lab or workshop conditions: screw "
                   "(semi-closed loop, the encoders on the motors) or scales (closed loop "
                   "on linear scales: no lead, periodic error, warm-up or lost motion, but "
                   "the scale's grade and expansion; docs/instruments.md) (default: screw)")


def add_gauges(p: argparse.ArgumentParser, *, planned: bool = False) -> None:
    """``--sigma`` and ``--resolution``: the gauges the lab reads, the dial gauges' by
    default (``planned``: the plan's when the command is given one, which was designed
    for its gauges)."""
    plan = "the plan's with --plan, else " if planned else ""
    p.add_argument("--sigma", type=float, default=None if planned else DEFAULT_SIGMA,
                   help=f"gauge repeatability (mm, default {plan}{DEFAULT_SIGMA})")
    p.add_argument("--resolution", type=float,
                   default=None if planned else DEFAULT_RESOLUTION,
                   help=f"gauge display resolution (mm, default {plan}{DEFAULT_RESOLUTION})")


def add_faults(p: argparse.ArgumentParser) -> None:
    """``--faults``: what can go wrong in the lab."""
    p.add_argument("--faults", metavar="LIST", default=None,
                   help="faults that can happen in the lab, comma-separated: "
                   f"{','.join(FAULT_KINDS)}, each at its rate and size in "
                   "docs/faults.md (default: none)")


def faults_of(args: argparse.Namespace) -> Faults:
    """The faults of ``--faults``; :class:`UsageError` naming the kinds if bad."""
    try:
        return as_faults(args.faults)
    except ValueError as exc:
        raise UsageError(f"--faults: {exc}") from None


def add_thermometer(p: argparse.ArgumentParser) -> None:
    """``--thermometer``: the lab has a room thermometer."""
    p.add_argument("--thermometer", action="store_true",
                   help="the lab has a room thermometer: every reading carries the room's "
                   "temperature, against which the full estimator fits the stands' growth "
                   "(its error: docs/conditions.md, rows thermometer)")


#: The world a command that fits readings takes them to come from when not told: none
#: beyond the geometry.  Unlike a world a command builds (``DEFAULT_CONDITIONS``), a
#: readings file may carry no time, which a real lab's terms need; so it is named, not
#: assumed.
READINGS_CONDITIONS = "ideal"


def add_instruments(p: argparse.ArgumentParser) -> None:
    """``--instruments``: what the lab owns."""
    p.add_argument("--instruments", metavar="LIST", default=None,
                   help="what the lab owns, comma-separated: dial, interferometer, "
                   "step-gauge, ballbar, tracker; an agent that needs "
                   "one the lab does not own is refused (default: the dial gauges, and the "
                   "tracker for an agent that reads one; docs/instruments.md)")


def instruments_of(args: argparse.Namespace, agents: tuple[Agent, ...] = ()
                   ) -> tuple[str, ...]:
    """The instruments of ``--instruments`` (empty when not given: today's lab), each of
    ``agents`` checked against them and against ``--budget`` on ``--design``'s machine;
    :class:`UsageError` in one line if bad."""
    # (Here, not at the top: the labs import Gymnasium, which --help does without.)
    from calibrators.study.labs import lab_kwargs
    from orthoglide_env.instruments.catalogue import check_instruments
    from orthoglide_env.lab.spec import LAB
    if args.instruments is None:
        owned: tuple[str, ...] = ()
    else:
        try:
            owned = check_instruments([n.strip() for n in args.instruments.split(",")
                                       if n.strip()])
        except ValueError as exc:
            raise UsageError(f"--instruments: {exc}") from None
    for agent in agents:
        try:
            lab_kwargs(agent, owned)
        except ValueError as exc:
            raise UsageError(f"{exc}: add it to --instruments") from None
        try:
            # The lab's own stands: the commands that check here give no other count.
            agent.check_budget(args.budget, machine_design_of(args), LAB["stands"].default)
        except ValueError as exc:
            raise UsageError(f"{exc}: give a longer --budget") from None
    return owned


def workflow_instruments(args: argparse.Namespace, agent: str) -> tuple[str, ...]:
    """``--instruments`` of a workflow command (``plan``, ``session``), checked with
    ``agent`` (:func:`instruments_of`; :class:`UsageError` in one line if bad)."""
    from calibrators.agents import get_agent
    try:
        owned = instruments_of(args, (get_agent(agent),))
    except ValueError as exc:  # an unknown agent
        raise UsageError(str(exc)) from None
    return owned


def conditions_of(args: argparse.Namespace, world: World | None = None,
                  default: str = DEFAULT_CONDITIONS) -> Conditions:
    """The conditions of ``--conditions`` and ``--effects`` (``default``'s name when not
    given), or those of a machine file's ``world`` (which the options, when given, must
    name); :class:`UsageError` if bad."""
    effects = None if args.effects is None else tuple(
        e.strip() for e in args.effects.split(",") if e.strip())
    indicator = getattr(args, "indicator", None)
    drives = getattr(args, "drives", None)
    if (world is not None and args.conditions is None and effects is None
            and indicator is None and drives is None):
        return world.conditions
    if args.conditions == AUTO and hasattr(args, "fit_conditions"):
        raise UsageError("--conditions auto: the lab draws its readings from a named world "
                         "(ideal, lab or workshop); give it with --conditions and tell the "
                         "fit --fit-conditions auto")
    if args.conditions == AUTO and (effects is not None or indicator is not None):
        raise UsageError("--conditions auto estimates the world from the readings: leave "
                         "--effects and --indicator out")
    try:
        conditions = Conditions(default if args.conditions in (None, AUTO)
                                else args.conditions, effects,
                                indicator or "dial", drives or "screw")
    except ValueError as exc:
        option = next((f"--{word}" for word in ("indicator", "drives") if word in str(exc)),
                      "--effects")
        raise UsageError(f"{option}: {exc}") from None
    if world is not None and conditions != world.conditions:
        raise UsageError(f"--conditions {conditions.label}: the machine file's world was drawn "
                         f"under {world.conditions.label}; leave --conditions, --effects "
                         "and --indicator out to replay it")
    return conditions


def fit_conditions_of(args: argparse.Namespace, conditions: Conditions
                      ) -> Conditions | str:
    """The world the fit is told: ``--conditions`` of a command that fits readings
    (``auto`` as is), else ``--fit-conditions`` (the lab's gauges' indicator with
    it), else the lab's ``conditions``."""
    told = getattr(args, "fit_conditions", None)
    if told is None:
        return AUTO if args.conditions == AUTO else conditions
    if told in (AUTO, "ideal"):
        return told if told == AUTO else Conditions(told)
    return Conditions(told, indicator=conditions.indicator, drives=conditions.drives)


def add_machine(p: argparse.ArgumentParser) -> None:
    p.add_argument("--machine", required=True, metavar="FILE",
                   help="machine JSON file: errors in mm and rad, see docs/machines.md "
                   "(required; a file holding {} is the nominal machine)")
    add_design(p)


def print_json(data: Any) -> None:
    """Print ``data`` as strict JSON: a NaN or an infinity is an error, never the
    ``NaN``/``Infinity`` tokens that Python's json writes by default and no JSON reader
    accepts."""
    try:
        text = json.dumps(data, indent=2, allow_nan=False)
    except ValueError as exc:
        raise RuntimeError(f"the report holds a number JSON cannot carry ({exc})") from None
    print(text)


#: The ``-o`` value that means standard output.
STDOUT = "-"


def write_output(out: str, text: str, kind: str) -> None:
    """``text`` to standard output (``out`` is :data:`STDOUT`) or to the file ``out``, which
    it replaces; a folder is refused, naming the ``kind`` of file wanted."""
    if out == STDOUT:
        sys.stdout.write(text)
        return
    path = Path(out)
    if path.is_dir():
        raise ValueError(f"-o {path}: is a directory; give the {kind} file to write")
    path.write_text(text)
    print(f"wrote {path}")
