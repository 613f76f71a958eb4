"""Every constructor argument of the envs, declared once: its default, type, range, words.

Each env (and its native vector env) lists its arguments here as a table of
:class:`Arg` objects; :func:`check_arguments` checks a call against the table, so the
same argument is refused in the same words by every env that takes it, and
:func:`signature` makes the env's constructor signature of it.  A number is a
real number (``int`` or ``float``, numpy's too), finite, never a boolean or text; an
integer likewise; a flag is ``True`` or ``False``.  The checks that tie two arguments
together (the noise against the travel, a picture against the backend) are the
settings' (:mod:`orthoglide_env.lab.settings`).
"""

from __future__ import annotations

import inspect
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode

from orthoglide_env.instruments.catalogue import INSTRUMENT_NAMES, check_instruments
from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.instruments.slots import GaugeSpec, layout_from_names
from orthoglide_env.lab.operations import DEFAULT_BUDGET_S, PAPER_SLOTS, TRACKER_SIGMA
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import DEFAULT_PRESET, PRESETS
from orthoglide_env.sim.motion import MOTION_MODES
from orthoglide_env.world.conditions import DEFAULT_CONDITIONS, as_conditions
from orthoglide_env.world.faults import as_faults

BACKENDS: tuple[str, ...] = ("pybullet", "exact")
RENDER_MODES: tuple[str, ...] = ("rgb_array", "human")
REWARDS: tuple[str, ...] = ("time", "accuracy", "information")


@dataclass(frozen=True)
class Arg:
    """One argument's rule and default: :meth:`check` returns the value in its canonical
    type, or raises ``ValueError`` with ``"<name> must be <rule>, got <value>"`` (or
    ``"<name>: <why>"`` when the value has the form but cannot be made)."""

    default: Any = field(default=None, kw_only=True)
    rule = ""

    def check(self, name: str, value: Any) -> Any:
        if not self.accepts(value):
            raise ValueError(f"{name} must be {self.rule}, got {value!r}")
        try:
            return self.convert(value)
        except ValueError as exc:
            raise ValueError(f"{name}: {exc}") from None

    def accepts(self, value: Any) -> bool:
        raise NotImplementedError

    def convert(self, value: Any) -> Any:
        return value


def _is_real(value: Any) -> bool:
    # An integer is finite (and numpy cannot test one past float64's range).
    return (isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)
            and (isinstance(value, numbers.Integral) or bool(np.isfinite(value))))


@dataclass(frozen=True)
class Number(Arg):
    """A finite real number, above ``low`` (``open``: strictly) and at most ``high``;
    ``upper`` names a bound that is checked where it is known (the rule says it)."""

    unit: str = ""
    low: float | None = None
    open: bool = False
    high: float | None = None
    upper: str = ""
    optional: bool = False  # None is accepted too (the default it stands for)
    noun = "a number"

    @property
    def rule(self) -> str:  # type: ignore[override]
        unit = f" ({self.unit})" if self.unit else ""
        high = f"{self.high:g}" if self.high is not None else self.upper
        if self.low is not None and high:
            bounds = f" in {'(' if self.open else '['}{self.low:g}, {high}]"
        elif self.low is not None:
            bounds = f" {'>' if self.open else '>='} {self.low:g}"
        else:
            bounds = ""
        return f"{self.noun}{unit}{bounds}" + (" or None" if self.optional else "")

    def accepts(self, value: Any) -> bool:
        if value is None:
            return self.optional
        if not _is_real(value):
            return False
        above = self.low is None or (value > self.low if self.open else value >= self.low)
        return above and (self.high is None or value <= self.high)

    def convert(self, value: Any) -> float | None:
        return None if value is None else float(value)


@dataclass(frozen=True)
class Integer(Number):
    """An integer (not a boolean) in ``[low, high]``; with ``optional`` also None."""

    noun = "an integer"

    def accepts(self, value: Any) -> bool:
        return (value is None or isinstance(value, numbers.Integral)) and super().accepts(value)

    def convert(self, value: Any) -> int | None:
        return None if value is None else int(value)


@dataclass(frozen=True)
class Choice(Arg):
    """One of ``options`` (compared as they are: ``1`` is not ``'1'``)."""

    options: tuple[Any, ...] = ()
    what: str = ""

    @property
    def rule(self) -> str:  # type: ignore[override]
        return f"{self.what or 'one of'} {list(self.options)}"

    def accepts(self, value: Any) -> bool:
        return any(type(value) is type(o) and value == o for o in self.options)


@dataclass(frozen=True)
class Kind(Arg):
    """A value that ``test`` accepts, in the canonical form ``make`` makes of it."""

    rule: str = ""
    test: Callable[[Any], bool] = bool
    make: Callable[[Any], Any] | None = None

    def accepts(self, value: Any) -> bool:
        return self.test(value)

    def convert(self, value: Any) -> Any:
        return value if self.make is None else self.make(value)


FLAG = Kind("True or False", lambda v: isinstance(v, bool | np.bool_), bool, default=False)
FUNCTION = Kind("a function (records, sigma) -> MachineParams, or None",
                lambda v: v is None or callable(v))
AUTORESET = Kind(f"one of {[m.value for m in AutoresetMode]}",
                 lambda v: isinstance(v, AutoresetMode) or (
                     isinstance(v, str) and v in {m.value for m in AutoresetMode}),
                 AutoresetMode, default=AutoresetMode.NEXT_STEP)


@dataclass(frozen=True)
class Layout(Arg):
    """A gauge layout: names such as ``"x-leg/y"`` or ``"z/x@0.3"``, or ``GaugeSpec``
    objects (not both); None is the paper's six gauges (``default``)."""

    rule: str = "a list of gauge names like 'x-leg/y' or of GaugeSpec objects, or None"

    def accepts(self, value: Any) -> bool:
        return value is None or (isinstance(value, list | tuple) and len(value) > 0 and (
            all(isinstance(g, GaugeSpec) for g in value)
            or all(isinstance(g, str) for g in value)))

    def convert(self, value: Any) -> tuple[GaugeSpec, ...] | None:
        if value is None or all(isinstance(g, GaugeSpec) for g in value):
            return None if value is None else tuple(value)
        return layout_from_names(list(value))


@dataclass(frozen=True)
class DesignArg(Arg):
    """The machines' :class:`~orthoglide_env.model.design.MachineDesign`, or None (the
    prototype)."""

    def check(self, name: str, value: Any) -> Any:
        if value is not None and not isinstance(value, MachineDesign):
            raise ValueError(f"{name} must be a MachineDesign, got {type(value).__name__}")
        return value


INSTRUMENTS = Kind(f"a list of instrument names from {list(INSTRUMENT_NAMES)}, or None",
                   lambda v: v is None or (isinstance(v, list | tuple) and all(
                       isinstance(n, str) for n in v)),
                   lambda v: None if v is None else check_instruments(v))

# Arguments both envs take, by the same rule in the same words.
ERRORS = Choice(tuple(sorted(PRESETS)), "the name of an error preset, one of",
                default=DEFAULT_PRESET)
SIGMA = Number("mm", 0.0, default=DEFAULT_SIGMA)  # the range that depends on the travel:
RESOLUTION = Number("mm", 0.0, default=DEFAULT_RESOLUTION)  # check_noise
RENDER_MODE = Choice((None, *RENDER_MODES))


@dataclass(frozen=True)
class ConditionsArg(Arg):
    """The conditions: a name of :data:`CONDITION_NAMES`, a ``Conditions``, or a dict of
    its ``name``, ``effects`` and ``indicator``."""

    def check(self, name: str, value: Any) -> Any:
        try:
            return as_conditions(value)
        except ValueError as exc:
            raise ValueError(f"{name}: {exc}") from None


#: The earlier names of :class:`DesignArg` and :class:`ConditionsArg` ("design" means a
#: MachineDesign, "world" a drawn truth).
Design, World = DesignArg, ConditionsArg
CONDITIONS = ConditionsArg(default=DEFAULT_CONDITIONS)


@dataclass(frozen=True)
class FaultsArg(Arg):
    """The faults that can happen: None, a list of kinds or a comma-separated string
    (:data:`~orthoglide_env.world.faults.FAULT_KINDS`), or a ``Faults``."""

    def check(self, name: str, value: Any) -> Any:
        try:
            return as_faults(value)
        except ValueError as exc:
            raise ValueError(f"{name}: {exc}") from None


#: ``OrthoglideCalibration-v0``'s arguments.
CALIBRATION: dict[str, Arg] = {
    "errors": ERRORS, "gauge_sigma": SIGMA, "gauge_resolution": RESOLUTION,
    "motion": Choice(MOTION_MODES, default="quasi-static"),
    "backend": Choice(BACKENDS, default="pybullet"), "gauges": Layout(),
    "travel": Number("mm", 0.0, open=True, optional=True),  # None: the design's
    "max_episode_steps": Integer(low=1, optional=True), "render_mode": RENDER_MODE,
    "clip_actions": FLAG, "design": DesignArg(), "conditions": CONDITIONS,
}
#: ``OrthoglideLab-v0``'s arguments.
LAB: dict[str, Arg] = {
    "errors": ERRORS, "gauge_sigma": SIGMA, "gauge_resolution": RESOLUTION,
    "backend": Choice(BACKENDS, default="exact"),
    # At most the design's slot count: lab_settings checks it against the design.
    "stands": Integer(low=1, upper="the design's slot count", default=len(PAPER_SLOTS)),
    "tracker": FLAG,
    "tracker_sigma": Number("mm", 0.0, open=True, default=TRACKER_SIGMA),
    "thermometer": FLAG,
    "budget_s": Number("s", 0.0, open=True, default=DEFAULT_BUDGET_S),
    "reward": Choice(REWARDS, default="time"), "estimator": FUNCTION,
    "time_weight": Number("", 0.0, default=1.0),
    "success_mm": Number("mm", 0.0, open=True, default=0.01),
    "travel": Number("mm", 0.0, open=True, optional=True), "design": DesignArg(),
    "conditions": CONDITIONS, "reference": FLAG, "render_mode": RENDER_MODE,
    # None: what the lab owns without it, its dial gauges and a tracker where ``tracker``.
    "instruments": INSTRUMENTS,
    "faults": FaultsArg(),
}
#: A native vector env's arguments: ``num_envs``, its single env's (the lab's draws no
#: picture) and ``autoreset_mode``.
CALIBRATION_VECTOR: dict[str, Arg] = {
    "num_envs": Integer(low=1, default=1), **CALIBRATION, "autoreset_mode": AUTORESET}
LAB_VECTOR: dict[str, Arg] = {
    "num_envs": Integer(low=1, default=1),
    **{name: arg for name, arg in LAB.items() if name != "render_mode"},
    "autoreset_mode": AUTORESET}


def check_arguments(spec: Mapping[str, Arg], values: Mapping[str, Any]) -> dict[str, Any]:
    """Every argument of ``spec`` (one entry per argument): ``values``' or its default,
    checked, in canonical types; or ``ValueError`` naming the first bad argument and its
    rule."""
    unknown = sorted(set(values) - set(spec))
    if unknown:
        raise ValueError(f"unknown argument(s) {unknown}; allowed: {', '.join(spec)}")
    return {name: arg.check(name, values.get(name, arg.default)) for name, arg in spec.items()}


def signature(spec: Mapping[str, Arg]) -> inspect.Signature:
    """The constructor signature of an env taking ``spec``'s arguments (keywords, with
    their defaults), as ``inspect.signature`` and ``help`` show it."""
    return inspect.Signature([inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY,
                                                default=arg.default)
                              for name, arg in spec.items()])
