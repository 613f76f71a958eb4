"""The estimator interface: the :class:`Estimate`, the :class:`Estimator` base class and
the registry of estimator classes.

An estimator is configured when it is constructed (``GaussNewtonCalibrator(params="full",
sigma=0.01)``, checked there) and its ``fit(measurements)`` returns an :class:`Estimate`.
It reads a lab notebook (an agent's experiment, :mod:`calibrators.study.episodes`) exactly
as it reads a real machine's measurement file.  The configured instances that commands
name (``paper``, ``paper6``, ``extended``, ``full``, ...) are in
:mod:`calibrators.estimators.catalogue`.

Estimator classes register themselves by name with :func:`register`; every module of this
package is imported by :func:`available`, so adding one is adding one module.
"""

from __future__ import annotations

import inspect
import json
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from calibrators.estimators.consider import (
    TABLE_TERM,
    WORLD_PREFIX,
    backlash_sizes,
    lead_terms,
    table_prior,
)
from calibrators.estimators.constraints import Constraint, InvalidParameterError, validate_params
from calibrators.measurements import Measurements
from calibrators.registry import Registry
from orthoglide_env.instruments.dial import DEFAULT_SIGMA
from orthoglide_env.model.compensation import PitchTable
from orthoglide_env.model.errors import (
    AXIS_NAMES,
    ERROR_GROUPS,
    ERROR_NAMES,
    MachineParams,
    error_group,
)
from orthoglide_env.world.conditions import as_conditions

PARAM_NAMES: tuple[str, ...] = ("drho_x", "drho_y", "drho_z", "dL_x", "dL_y", "dL_z")
#: Which of the six paper parameters each ``--params`` choice frees (the others stay 0).
PARAM_SETS: dict[str, tuple[int, ...]] = {
    "paper6": (0, 1, 2, 3, 4, 5),
    "drho": (0, 1, 2),
    "dL": (3, 4, 5),
}


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
    #: Per outlier, why it was flagged (``reading``: unlike its repetitions, a mistyped
    #: or misread reading; ``unrepeated``: no repetition to tell) and its residual (mm)
    #: against the fit without it.
    outlier_causes: list[str] = field(default_factory=list)
    outlier_residuals: list[float] = field(default_factory=list)
    #: Readings as far from the model as an outlier, whose repetitions read as they do:
    #: model error, kept in the fit.
    misfits: list[int] = field(default_factory=list)
    holdout_rms_mm: float | None = None
    #: Data information over the free parameters in units of their ``scale`` (the
    #: identifiability analysis of exact-model fits).
    information: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    scale: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: Covariance of (estimate - truth) over every parameter of ``space``, with the errors
    #: the model leaves out when the data show them (what a TCP prediction needs).
    error_covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    #: The real lab's effects the fit did not model but put into its covariance
    #: (:mod:`calibrators.estimators.consider`), empty under ``ideal`` conditions.
    considered: list[str] = field(default_factory=list)
    #: The lead error's terms (:func:`~calibrators.estimators.consider.lead_terms`), fitted
    #: ones with their estimate in ``lead_values`` and considered ones at 0, and the joint
    #: covariance of (estimate - truth) over the 27 machine errors, then these terms'
    #: coefficients: the drives' part of the tool's error after compensation.
    lead_terms: list[str] = field(default_factory=list)
    lead_values: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lead_covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    #: The conditions the readings were taken under (their ``to_dict``), and the
    #: pitch-error table's node spacing (mm) when the lead error was fitted as one.
    conditions: dict[str, Any] = field(default_factory=dict)
    node_spacing: float | None = None
    #: Under ``conditions="auto"``: each effect family's second moment over the
    #: workshop's, as the readings show it (:mod:`calibrators.estimators.world_sizes`), for
    #: the families with terms in these readings; empty when the world was told.
    world_scales: dict[str, float] = field(default_factory=dict)

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

    def lead_patterns(self, rho: np.ndarray) -> np.ndarray:
        """(..., 3, K) the lead terms' carriage errors at ``rho`` (..., 3), mm per unit
        coefficient, in :attr:`lead_terms` order."""
        terms = dict(lead_terms(rho, self.readings.design, as_conditions(self.conditions),
                                self.node_spacing))
        shape = np.shape(rho)
        return (np.stack([terms[n] for n in self.lead_terms], axis=-1) if self.lead_terms
                else np.zeros((*shape, 0)))

    def lead_correction(self, rho: np.ndarray) -> np.ndarray:
        """The drives' error (mm) at ``rho`` (..., 3) that the fit found, which the
        controller compensates (0 without fitted lead terms)."""
        return self.lead_patterns(rho) @ self.lead_values if self.lead_terms else np.zeros(
            np.shape(rho))

    @property
    def fits_lead(self) -> bool:
        """Whether the fit found a lead error to compensate."""
        return bool(np.any(self.lead_values != 0))

    @property
    def pitch_table(self) -> PitchTable | None:
        """The fitted lead error as the controller's pitch-error tables, with each node's
        standard deviation; None unless the fit took the lead error as one."""
        fitted = [k for k, n in enumerate(self.lead_terms) if n.startswith(TABLE_TERM)]
        if self.node_spacing is None or not fitted:
            return None
        design = self.readings.design
        count, root = table_prior(design, as_conditions(self.conditions), self.node_spacing)
        values = np.zeros((3, count + 1))
        sigma = np.zeros((3, count + 1))
        n = len(ERROR_NAMES)
        for a, axis in enumerate(AXIS_NAMES):
            mine = [k for k in fitted if self.lead_terms[k].endswith(f"[{axis}]")]
            values[a, 1:] = root @ self.lead_values[mine]
            cov = self.lead_covariance[np.ix_([n + k for k in mine], [n + k for k in mine])]
            sigma[a, 1:] = np.sqrt(np.clip(np.diag(root @ cov @ root.T), 0.0, None))
        return PitchTable(design.rho_min, self.node_spacing, values, sigma)

    @property
    def backlash(self) -> dict[str, dict[str, float]] | None:
        """Each axis's fitted lost motion (mm) with its standard deviation, the controller's
        backlash value; None unless the fit fitted backlash."""
        names = [f"{WORLD_PREFIX}backlash.mean",
                 *(f"{WORLD_PREFIX}backlash.spread[{a}]" for a in AXIS_NAMES)]
        if not all(n in self.names for n in names):
            return None
        mean, spread = backlash_sizes(as_conditions(self.conditions))
        idx = [self.names.index(n) for n in names]
        theta = self.theta[[self.space.index(n) for n in names]]
        out = {}
        for a, axis in enumerate(AXIS_NAMES):
            gain = np.zeros(len(names))
            gain[0], gain[1 + a] = mean * 1e-3, spread * 1e-3
            variance = gain @ self.covariance[np.ix_(idx, idx)] @ gain
            out[axis] = {"value": float(gain @ theta), "sigma": float(np.sqrt(max(variance,
                                                                                    0.0)))}
        return out

    @property
    def residual_rms_mm(self) -> float:
        return float(np.sqrt(np.nanmean(self.residuals**2))) if self.residuals.size else 0.0

    @property
    def condition_number(self) -> float:
        sv = self.singular_values
        return float(sv[0] / sv[-1]) if sv.size and sv[-1] > 0 else float("inf")

    @property
    def chi2_rejected(self) -> bool | None:
        """Whether the chi-square test rejects the model on the readings at
        :data:`~calibrators.estimators.exact_fit.CHI2_LEVEL` (None: no test)."""
        if self.chi2 is None or not self.dof:
            return None
        from calibrators.estimators.exact_fit import chi2_rejects

        return bool(chi2_rejects(self.dof, self.chi2))

    @property
    def machine(self) -> MachineParams:
        """The estimated machine (every machine error the fit has), of the readings'
        design."""
        return MachineParams.from_vector(self.theta[: len(ERROR_NAMES)], self.readings.design)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready; the derived ``std``, ``residual_rms_mm`` and ``condition_number``
        are included for readers and ignored by :meth:`from_dict`."""
        data = {f.name: getattr(self, f.name) for f in fields(self)}
        for key, value in data.items():
            if isinstance(value, np.ndarray):
                data[key] = value.tolist()
        table = self.pitch_table
        data.update(readings=self.readings.to_dict(), std=self.std,
                    residual_rms_mm=self.residual_rms_mm, condition_number=self.condition_number,
                    pitch_table=None if table is None else table.to_dict(),
                    backlash_mm=self.backlash)
        if not self.world_scales:
            # A told world's estimate is written as before the scales existed.
            data.pop("world_scales")
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Estimate:
        kwargs = {f.name: data[f.name] for f in fields(cls) if f.name in data}
        for key in _ARRAY_FIELDS:
            if key in kwargs:
                # What :func:`strict` wrote as None is NaN again.
                kwargs[key] = np.array(leaves(kwargs[key], lambda v: np.nan if v is None else v),
                                       dtype=float)
        for key in ("covariance", "fisher", "information", "error_covariance",
                    "lead_covariance"):
            if key in kwargs and kwargs[key].size == 0:
                kwargs[key] = np.zeros((0, 0))  # an empty matrix comes back from JSON as []
        if "readings" in kwargs:
            kwargs["readings"] = Measurements.from_dict(kwargs["readings"])
        return cls(**kwargs)

    def to_json(self, path: str | Path) -> None:
        """Strict JSON (a NaN, such as a left-out reading's residual, as null)."""
        Path(path).write_text(json.dumps(strict(self.to_dict()), indent=2,
                                         allow_nan=False) + "\n")

    @classmethod
    def from_json(cls, path: str | Path) -> Estimate:
        return cls.from_dict(json.loads(Path(path).read_text()))


def leaves(value: Any, change: Callable[[Any], Any]) -> Any:
    """``value`` with ``change`` applied to every leaf, at any depth of dicts, lists and
    tuples (a tuple comes back as a list, as JSON writes it)."""
    if isinstance(value, dict):
        return {k: leaves(v, change) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [leaves(v, change) for v in value]
    return change(value)


def strict(value: Any) -> Any:
    """``value`` with every float that JSON cannot carry (NaN, infinities) as None."""
    return leaves(value, lambda v: None if isinstance(v, float) and not np.isfinite(v) else v)


def schema(values: list, space: list[str]) -> dict[str, Any]:
    """Per-parameter ``values`` (in the order of the names ``space``) in the machine-file
    schema; stand parameters go under ``"stands"`` keyed by mounting, fitted terms of the
    lab's world under ``"world"`` keyed by term."""
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
    world: dict[str, Any] = {}
    for name, value in zip(space[n:], values[n:], strict=True):
        if name.startswith(WORLD_PREFIX):
            world[name[len(WORLD_PREFIX):]] = value
            continue
        mounting = name.rsplit(".", 1)[0]
        stands.setdefault(mounting, []).append(value)
    if stands:
        out["stands"] = stands
    if world:
        out["world"] = world
    return out


_ARRAY_FIELDS: tuple[str, ...] = ("drho", "dL", "covariance", "residuals", "singular_values",
                                  "crlb", "fisher", "theta", "information", "scale",
                                  "error_covariance", "lead_values", "lead_covariance")


class Estimator:
    """Base class of estimators, in scikit-learn's shape: every choice is a keyword of
    ``__init__``, stored as an attribute of that name and checked there against the class's
    :attr:`_parameter_constraints` (:func:`~calibrators.estimators.constraints.validate_params`);
    :meth:`fit` turns readings into an :class:`Estimate`."""

    #: The registered name, written into every estimate's ``strategy``.
    name: ClassVar[str] = ""
    #: What the estimator is called in its messages.
    title: ClassVar[str] = ""
    #: Per parameter of ``__init__``, the kinds of value it takes (any one suffices).
    _parameter_constraints: ClassVar[dict[str, list[Constraint]]] = {}

    def _validate_params(self) -> None:
        validate_params(f"estimator '{self.name}'", self.get_params(),
                        self._parameter_constraints)

    @classmethod
    def parameter_names(cls) -> list[str]:
        """The parameters of ``__init__``, in its order."""
        return [p.name for p in inspect.signature(cls.__init__).parameters.values()
                if p.kind is inspect.Parameter.KEYWORD_ONLY]

    @classmethod
    def takes(cls, parameter: str) -> bool:
        """Whether the estimator has the parameter ``parameter``."""
        return parameter in cls.parameter_names()

    def get_params(self) -> dict[str, Any]:
        """The configuration, by parameter."""
        return {name: getattr(self, name) for name in self.parameter_names()}

    def clone(self, **config: Any) -> Estimator:
        """A new estimator of this class, configured as this one but for ``config``; a
        parameter the class does not take is refused (:meth:`refuse`)."""
        unknown = [key for key in config if not self.takes(key)]
        if unknown:
            raise self.refuse(unknown)
        return type(self)(**{**self.get_params(), **config})

    @classmethod
    def refuse(cls, unknown: list[str]) -> ValueError:
        """The error for the parameters ``unknown`` that the class does not take."""
        return InvalidParameterError(
            f"estimator '{cls.name}' takes no {', '.join(unknown)}; its parameters are "
            f"{', '.join(cls.parameter_names())}", unknown[0])

    def fit(self, data: Measurements) -> Estimate:
        """The estimate of the readings ``data``."""
        raise NotImplementedError

    def fit_many(self, datas: list[Measurements]) -> list[Estimate | Exception]:
        """:meth:`fit` of each experiment, a failure in place of its estimate; an estimator
        that can batch experiments overrides it, to the same results."""
        out: list[Estimate | Exception] = []
        for data in datas:
            try:
                out.append(self.fit(data))
            except (ValueError, RuntimeError, np.linalg.LinAlgError) as exc:
                out.append(exc)
        return out

    def estimate(self, data: Measurements, params: str = "paper6",
                 sigma: float = DEFAULT_SIGMA, **options: Any) -> Estimate:
        """The call-time form of earlier scripts: :meth:`fit` of this estimator configured
        with ``params``, ``sigma`` and ``options``."""
        return self.clone(params=params, sigma=sigma, **options).fit(data)

    def __repr__(self) -> str:
        changed = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({changed})"


#: The earlier name of :class:`Estimator`, kept for earlier scripts.
Calibrator = Estimator
STRATEGIES: Registry[Estimator] = Registry("strategy", "calibrators.estimators")
register = STRATEGIES.register
available = STRATEGIES.available
get_strategy = STRATEGIES.get


def check_params(params: str) -> tuple[int, ...]:
    if params not in PARAM_SETS:
        raise ValueError(f"unknown parameter set '{params}'; choose from {list(PARAM_SETS)}")
    return PARAM_SETS[params]

