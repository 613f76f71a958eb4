"""Declarative checks of an estimator's parameters, run once, when it is constructed.

In the spirit of scikit-learn's ``_parameter_constraints``: an estimator class declares,
per parameter of its ``__init__``, the constraints a value may meet (any one suffices),
and :func:`validate_params` refuses a value that meets none with an
:class:`InvalidParameterError` naming the parameter, the value and the allowed values.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any


class InvalidParameterError(ValueError):
    """A parameter value an estimator does not take; ``parameter`` names it."""

    def __init__(self, message: str, parameter: str) -> None:
        super().__init__(message)
        self.parameter = parameter


class Constraint:
    """One kind of value a parameter may take."""

    def check(self, value: Any) -> None:
        """Nothing when ``value`` meets the constraint, else ``ValueError`` saying why
        (an empty message: only that it does not)."""
        raise NotImplementedError

    def __str__(self) -> str:
        raise NotImplementedError


@dataclass(frozen=True)
class Options(Constraint):
    """One of a fixed set of values."""

    values: tuple[Any, ...]

    def check(self, value: Any) -> None:
        if isinstance(value, bool) or not any(value == v for v in self.values):
            raise ValueError("")

    def __str__(self) -> str:
        return "None" if self.values == (None,) else f"one of {list(self.values)}"


@dataclass(frozen=True)
class Interval(Constraint):
    """A finite real number (an integer if ``integer``) in the interval from ``low`` to
    ``high`` (None: unbounded), each end included when ``closed`` says so."""

    low: float | None
    high: float | None
    closed: str = "both"  # "both", "left", "right" or "neither"
    integer: bool = False

    def check(self, value: Any) -> None:
        kind = numbers.Integral if self.integer else numbers.Real
        if isinstance(value, bool) or not isinstance(value, kind) or not math.isfinite(value):
            raise ValueError("")
        left, right = self.closed in ("both", "left"), self.closed in ("both", "right")
        if self.low is not None and (value < self.low or (value == self.low and not left)):
            raise ValueError("")
        if self.high is not None and (value > self.high or (value == self.high and not right)):
            raise ValueError("")

    def __str__(self) -> str:
        kind = "an integer" if self.integer else "a number"
        low = "-inf" if self.low is None else f"{self.low:g}"
        high = "inf" if self.high is None else f"{self.high:g}"
        left = "[" if self.closed in ("both", "left") and self.low is not None else "("
        right = "]" if self.closed in ("both", "right") and self.high is not None else ")"
        return f"{kind} in {left}{low}, {high}{right}"


@dataclass(frozen=True)
class InstanceOf(Constraint):
    """An instance of ``kind`` (``bool`` is not taken for a number)."""

    kind: type
    name: str

    def check(self, value: Any) -> None:
        if not isinstance(value, self.kind) or (isinstance(value, bool)
                                                and self.kind is not bool):
            raise ValueError("")

    def __str__(self) -> str:
        return self.name


@dataclass(frozen=True)
class Satisfies(Constraint):
    """A value that ``test`` takes: it returns normally, or raises ``ValueError`` saying
    what is wrong; ``name`` says what is allowed."""

    test: Callable[[Any], Any]
    name: str

    def check(self, value: Any) -> None:
        self.test(value)

    def __str__(self) -> str:
        return self.name


#: The constraint of a parameter that may be None.
NONE: Options = Options((None,))
#: The constraint of a flag.
BOOLEAN: InstanceOf = InstanceOf(bool, "True or False")


def validate_params(owner: str, params: Mapping[str, Any],
                    constraints: Mapping[str, list[Constraint]]) -> None:
    """Check every one of ``params`` against its ``constraints`` (a value passes when it
    meets one of them); the first that meets none is refused with an
    :class:`InvalidParameterError` naming ``owner``, the parameter and what it may be."""
    for name, value in params.items():
        reasons = []
        for constraint in constraints[name]:
            try:
                constraint.check(value)
                break
            except ValueError as exc:
                if str(exc):
                    reasons.append(str(exc))
        else:
            allowed = " or ".join(str(c) for c in constraints[name])
            why = f" ({'; '.join(reasons)})" if reasons else ""
            raise InvalidParameterError(f"{owner}: parameter '{name}' must be {allowed}, got "
                                        f"{value!r}{why}", name)
