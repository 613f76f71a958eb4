"""The calibrator interface: measurements, estimates and the registry of strategies.

A strategy has two halves, kept apart so a real machine's measured readings (a file) go
through the same estimator as a virtual experiment:

* ``collect(env)``: drives the environment through its public API only (actions in,
  observations out) and returns the :class:`Measurements` it read and the time spent;
* ``estimate(measurements, params, sigma)``: turns readings into an :class:`Estimate`.

Strategies register themselves by name with :func:`register`; every module of this
package is imported by :func:`available`, so adding a strategy is adding one module.
"""

from __future__ import annotations

import csv
import importlib
import json
import pkgutil
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from orthoglide_env.gauges import GaugeSpec, layout_from_names
from orthoglide_env.geometry import (
    AXIS_NAMES,
    ERROR_GROUPS,
    ERROR_NAMES,
    LEG_NAMES,
    MachineParams,
    error_group,
    read_user_file,
)
from orthoglide_env.kinematics import PAPER_POSTURES, paper_posture

PARAM_NAMES: tuple[str, ...] = ("drho_x", "drho_y", "drho_z", "dL_x", "dL_y", "dL_z")
#: Which of the six paper parameters each ``--params`` choice frees (the others stay 0).
PARAM_SETS: dict[str, tuple[int, ...]] = {
    "paper6": (0, 1, 2, 3, 4, 5),
    "full": (0, 1, 2, 3, 4, 5),
    "drho": (0, 1, 2),
    "dL": (3, 4, 5),
}
CSV_COLUMNS: tuple[str, ...] = ("leg", "axis", "posture", "repetition", "reading_mm")


class MeasurementFileError(ValueError):
    """A measurement file that cannot be read; the message names line and column."""


ZERO_RHO: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Measurement:
    """One gauge reading: which gauge, at which posture, in which repetition.

    ``rho`` is the commanded posture (control coordinates, mm); ``posture`` its label, a
    paper posture name (whose ``rho`` is filled in when not given) or any other label for
    a posture of a strategy's own.  Differences are taken against the Zero posture
    ``rho = (0, 0, 0)``, where the gauges were zeroed.
    """

    gauge: GaugeSpec
    posture: str
    repetition: int
    reading: float
    rho: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.rho is None:
            if self.posture not in PAPER_POSTURES:
                raise ValueError(f"posture '{self.posture}' is not a paper posture: give its rho")
            rho = paper_posture(self.posture)
        else:
            rho = np.asarray(self.rho, dtype=float)
            if rho.shape != (3,):
                raise ValueError("a measurement's rho must have 3 components")
        object.__setattr__(self, "rho", tuple(float(v) for v in rho))

    @property
    def is_zero(self) -> bool:
        return self.rho == ZERO_RHO

    def to_dict(self) -> dict[str, Any]:
        return {"leg": LEG_NAMES[self.gauge.leg], "axis": AXIS_NAMES[self.gauge.axis],
                "at": self.gauge.at, "posture": self.posture, "rho": list(self.rho),
                "repetition": self.repetition, "reading_mm": self.reading}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Measurement:
        gauge = GaugeSpec(LEG_NAMES.index(data["leg"]), AXIS_NAMES.index(data["axis"]),
                          float(data.get("at", 0.5)))
        return cls(gauge, str(data["posture"]), int(data["repetition"]),
                   float(data["reading_mm"]), data.get("rho"))


@dataclass
class Measurements:
    """The readings of one experiment, plus the experiment time it cost (s)."""

    items: list[Measurement] = field(default_factory=list)
    experiment_time_s: float = 0.0

    def __len__(self) -> int:
        return len(self.items)

    def to_dict(self) -> dict[str, Any]:
        return {"experiment_time_s": self.experiment_time_s,
                "readings": [m.to_dict() for m in self.items]}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Measurements:
        return cls([Measurement.from_dict(m) for m in data["readings"]],
                   float(data["experiment_time_s"]))

    def to_csv(self, path: str | Path) -> None:
        """Write the documented CSV; only paper postures and mid-leg gauges have a place
        in it (a real machine is measured by the paper's procedure)."""
        for m in self.items:
            if m.posture not in PAPER_POSTURES or m.rho != tuple(paper_posture(m.posture)):
                raise ValueError(f"posture '{m.posture}' has no place in the measurement CSV")
            if m.gauge.at != 0.5:
                raise ValueError(f"gauge {m.gauge.name}@{m.gauge.at} has no place in the CSV")
        with Path(path).open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(CSV_COLUMNS)
            for m in self.items:
                writer.writerow([LEG_NAMES[m.gauge.leg], AXIS_NAMES[m.gauge.axis], m.posture,
                                 m.repetition, repr(m.reading)])

    @classmethod
    def from_csv(cls, path: str | Path) -> Measurements:
        """Read the documented CSV (header ``leg,axis,posture,repetition,reading_mm``)."""
        path = Path(path)
        text = read_user_file(path, "measurement file", MeasurementFileError)
        rows = list(csv.reader(text.splitlines()))
        if not rows or [c.strip() for c in rows[0]] != list(CSV_COLUMNS):
            raise MeasurementFileError(
                f"{path}:1: header must be '{','.join(CSV_COLUMNS)}'"
            )
        items = [_parse_row(path, n, row) for n, row in enumerate(rows[1:], start=2)
                 if any(c.strip() for c in row)]
        if not items:
            raise MeasurementFileError(f"{path}: no readings after the header")
        return cls(items)


def _parse_row(path: Path, line: int, row: list[str]) -> Measurement:
    def fail(column: int, message: str) -> MeasurementFileError:
        return MeasurementFileError(f"{path}:{line}: column {column} ({CSV_COLUMNS[column - 1]}): "
                                    f"{message}")

    if len(row) != len(CSV_COLUMNS):
        raise MeasurementFileError(f"{path}:{line}: expected {len(CSV_COLUMNS)} columns, "
                                   f"got {len(row)}")
    leg, axis, posture, repetition, reading = (c.strip() for c in row)
    if leg not in LEG_NAMES:
        raise fail(1, f"leg must be one of {list(LEG_NAMES)}, got '{leg}'")
    if axis not in AXIS_NAMES or axis == leg:
        raise fail(2, f"axis must be one of the two axes normal to the {leg} leg, got '{axis}'")
    if posture not in PAPER_POSTURES:
        raise fail(3, f"posture must be one of {list(PAPER_POSTURES)}, got '{posture}'")
    try:
        rep = int(repetition)
    except ValueError:
        raise fail(4, f"repetition must be an integer, got '{repetition}'") from None
    try:
        value = float(reading)
    except ValueError:
        raise fail(5, f"reading must be a number in mm, got '{reading}'") from None
    if not np.isfinite(value):
        raise fail(5, f"reading must be finite, got '{reading}'")
    return Measurement(layout_from_names([f"{leg}/{axis}"])[0], posture, rep, value)


@dataclass
class Estimate:
    """A calibration result with its uncertainty and identifiability.

    ``covariance``, ``fisher`` (for readings of unit variance: divide by sigma^2) and
    ``crlb`` are over the free parameters, named in ``names``; ``theta`` holds every
    parameter of the fit (the 27 machine errors, then four per stand mounting, named in
    ``space``).  ``residuals`` are per reading for exact-model fits (``reading -
    model - zero``, mm) and per difference for the paper's linear fit.  ``readings`` are
    the readings the estimate was computed from.
    """

    strategy: str
    params: str
    drho: np.ndarray
    dL: np.ndarray
    covariance: np.ndarray
    residuals: np.ndarray
    singular_values: np.ndarray
    crlb: np.ndarray
    weak_directions: list[dict[str, float]]
    n_readings: int
    experiment_time_s: float
    verification_rms_mm: float | None = None
    iterations: int = 0
    sigma: float = 0.0
    fisher: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    readings: Measurements = field(default_factory=Measurements)
    names: list[str] = field(default_factory=list)
    space: list[str] = field(default_factory=list)
    theta: np.ndarray = field(default_factory=lambda: np.zeros(0))
    prior: str = "none"
    chi2: float | None = None
    dof: int | None = None
    covariance_scale: float = 1.0
    warnings: list[str] = field(default_factory=list)
    identifiable: list[str] = field(default_factory=list)
    unidentifiable: list[str] = field(default_factory=list)
    outliers: list[int] = field(default_factory=list)
    holdout_rms_mm: float | None = None
    #: Data information over the free parameters in units of their ``scale`` (the
    #: identifiability analysis of exact-model fits).
    information: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    scale: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: Covariance of (estimate - truth) over every parameter of ``space``, with the errors
    #: the model leaves out when the data show them (what a TCP prediction needs).
    error_covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    def __post_init__(self) -> None:
        if not self.names:
            self.names = [PARAM_NAMES[k] for k in PARAM_SETS[self.params]]
        if not len(self.theta):
            self.space = list(ERROR_NAMES)
            self.theta = np.concatenate([self.drho, self.dL, np.zeros(len(ERROR_NAMES) - 6)])
        if not self.error_covariance.size:
            # A fit that does not say otherwise takes its model to be the machine.
            idx = [self.space.index(n) for n in self.names]
            self.error_covariance = np.zeros((len(self.space), len(self.space)))
            self.error_covariance[np.ix_(idx, idx)] = self.covariance

    @property
    def std(self) -> dict[str, Any]:
        """Standard deviation of every parameter in the machine-file schema (``None`` for
        the ones the fit kept fixed), stands under ``"stands"``."""
        full: list[float | None] = [None] * len(self.space)
        for k, name in enumerate(self.names):
            full[self.space.index(name)] = float(np.sqrt(max(self.covariance[k, k], 0.0)))
        return schema(full, self.space)

    @property
    def estimate(self) -> dict[str, Any]:
        """Every parameter's value in the machine-file schema, stands under ``"stands"``."""
        return schema(self.theta.tolist(), self.space)

    @property
    def residual_rms_mm(self) -> float:
        return float(np.sqrt(np.nanmean(self.residuals**2))) if self.residuals.size else 0.0

    @property
    def condition_number(self) -> float:
        sv = self.singular_values
        return float(sv[0] / sv[-1]) if sv.size and sv[-1] > 0 else float("inf")

    @property
    def machine(self) -> MachineParams:
        """The estimated machine (every machine error the fit has)."""
        return MachineParams.from_vector(self.theta[: len(ERROR_NAMES)])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready; the derived ``std``, ``residual_rms_mm`` and ``condition_number``
        are included for readers and ignored by :meth:`from_dict`."""
        data = {f.name: getattr(self, f.name) for f in fields(self)}
        for key, value in data.items():
            if isinstance(value, np.ndarray):
                data[key] = value.tolist()
        data.update(readings=self.readings.to_dict(), std=self.std,
                    residual_rms_mm=self.residual_rms_mm, condition_number=self.condition_number)
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Estimate:
        kwargs = {f.name: data[f.name] for f in fields(cls) if f.name in data}
        for key in _ARRAY_FIELDS:
            if key in kwargs:
                kwargs[key] = np.array(kwargs[key], dtype=float)
        for key in ("covariance", "fisher", "information", "error_covariance"):
            if key in kwargs and kwargs[key].size == 0:
                kwargs[key] = np.zeros((0, 0))  # an empty matrix comes back from JSON as []
        if "readings" in kwargs:
            kwargs["readings"] = Measurements.from_dict(kwargs["readings"])
        return cls(**kwargs)

    def to_json(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def from_json(cls, path: str | Path) -> Estimate:
        return cls.from_dict(json.loads(Path(path).read_text()))


def schema(values: list, space: list[str]) -> dict[str, Any]:
    """Per-parameter ``values`` (in the order of the names ``space``) in the machine-file
    schema; stand parameters go under ``"stands"`` keyed by mounting."""
    n = len(ERROR_NAMES)
    out: dict[str, Any] = {}
    start = 0
    for key in ERROR_GROUPS:
        size = len([name for name in ERROR_NAMES if error_group(name) == key])
        block = values[start:start + size]
        out[key] = block if key in ("drho", "dL") else [block[i:i + len(block) // 3]
                                                       for i in range(0, size, size // 3)]
        start += size
    stands: dict[str, list] = {}
    for name, value in zip(space[n:], values[n:], strict=True):
        mounting = name.rsplit(".", 1)[0]
        stands.setdefault(mounting, []).append(value)
    if stands:
        out["stands"] = stands
    return out


_ARRAY_FIELDS: tuple[str, ...] = ("drho", "dL", "covariance", "residuals", "singular_values",
                                  "crlb", "fisher", "theta", "information", "scale",
                                  "error_covariance")


class Calibrator:
    """Base class of strategies: ``collect`` then ``estimate``."""

    name: ClassVar[str] = ""
    #: Strategies with the same (non-empty) experiment key run the same experiment, so a
    #: comparison may measure once and hand the readings to each estimator.
    experiment: ClassVar[str] = ""

    @property
    def experiment_key(self) -> str:
        """What identifies this strategy's experiment (its name unless it shares one)."""
        return self.experiment or self.name

    def collect(self, env: gym.Env) -> Measurements:
        raise NotImplementedError

    def estimate(self, data: Measurements, params: str = "paper6", sigma: float = 0.01,
                 *, verify: bool = True, **options: Any) -> Estimate:
        """Estimate from ``data``; ``options`` are the estimator's own (see
        :meth:`calibrators.gauss_newton.GaussNewtonCalibrator.estimate`)."""
        raise NotImplementedError

    def run(self, env: gym.Env, params: str = "paper6", sigma: float | None = None,
            *, verify: bool = True, **options: Any) -> Estimate:
        """Run one experiment on ``env`` (already reset) and estimate.  ``sigma`` defaults
        to the gauges' spec-sheet noise (``env.unwrapped.gauge_noise``)."""
        if sigma is None:
            sigma = env.unwrapped.gauge_noise.effective_sigma
        return self.estimate(self.collect(env), params, sigma, verify=verify, **options)


_REGISTRY: dict[str, type[Calibrator]] = {}


def register(cls: type[Calibrator]) -> type[Calibrator]:
    """Class decorator: make a strategy available by its ``name``."""
    if not cls.name or cls.name in _REGISTRY:
        raise ValueError(f"strategy name '{cls.name}' is empty or taken")
    _REGISTRY[cls.name] = cls
    return cls


def available() -> list[str]:
    """Names of every strategy (imports each module of this package once)."""
    package = importlib.import_module("calibrators")
    for module in pkgutil.iter_modules(package.__path__):
        if module.name not in ("cli", "__main__"):
            importlib.import_module(f"calibrators.{module.name}")
    return sorted(_REGISTRY)


def get_strategy(name: str) -> Calibrator:
    names = available()
    if name not in _REGISTRY:
        raise ValueError(f"unknown strategy '{name}'; choose from {names}")
    return _REGISTRY[name]()


def check_params(params: str) -> tuple[int, ...]:
    if params not in PARAM_SETS:
        raise ValueError(f"unknown parameter set '{params}'; choose from {list(PARAM_SETS)}")
    return PARAM_SETS[params]


def move_and_read(env: gym.Env, posture: str) -> tuple[dict[str, np.ndarray], float]:
    """Drive to a paper posture; returns the observation and the time it cost (s)."""
    obs, reward, terminated, truncated, info = env.step(paper_posture(posture))
    if terminated or truncated:
        reason = info.get("collision") or "the episode's step limit"
        raise RuntimeError(f"experiment stopped at {posture}: {reason}")
    return obs, -float(reward)
