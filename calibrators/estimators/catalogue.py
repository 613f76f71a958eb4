"""The named estimators that commands offer: configured instances, by name.

``compare --estimators`` and ``calibrate``/``fit --estimator`` take these names, and
:func:`get_estimator` hands out a new instance of one with any of its parameters changed
(``get_estimator("full", sigma=0.01, conditions="lab").fit(readings)``).  Adding a named
estimator is adding one line to :data:`CATALOGUE`.
"""

from __future__ import annotations

from typing import Any

from calibrators.estimators.base import Estimate, Estimator
from calibrators.estimators.gauss_newton import GaussNewtonCalibrator
from calibrators.estimators.paper_linear import PaperCalibrator
from calibrators.measurements import Measurements
from orthoglide_env.model.errors import DEFAULT_PRESET
from orthoglide_env.world.conditions import IDEAL, Conditions

#: The named estimators, each a configured instance (parameters not given are the
#: class's defaults).
CATALOGUE: dict[str, Estimator] = {
    # The paper's eq. (10), linear, on the paper's six parameters.
    "paper": PaperCalibrator(params="paper6"),
    # The paper's six parameters on the exact model.
    "paper6": GaussNewtonCalibrator(params="paper6", prior="none"),
    # Every machine error and stand parameter, with the realistic preset's prior.
    "extended": GaussNewtonCalibrator(params="extended", prior="auto"),
    # The same without a prior: base parameters, what the readings cannot see stays nominal.
    "extended-base": GaussNewtonCalibrator(params="extended", prior="none"),
    # ``extended`` fitting every term of the lab's conditions instead of considering them.
    "extended-world": GaussNewtonCalibrator(params="extended", prior="auto", fit_world=True),
    # ``extended`` with the lab's main terms, the lead error as a pitch-error table.
    "full": GaussNewtonCalibrator(params="full", prior="auto"),
}


#: What ``calibrate``, ``fit`` and :class:`calibrators.workflow.fit.Fit` fit unless told:
#: every error and, under a real lab's conditions, its terms, because a fit of fewer
#: parameters than the machine has can hand a user a wrong number with small error bars.
DEFAULT_ESTIMATOR = "full"


def exact_estimators() -> list[str]:
    """The catalogue's names whose fit is the exact model's, which reads any agent's
    readings (a tracker's, a world's): what a refusal of the paper's fit points to."""
    return [name for name, est in CATALOGUE.items()
            if isinstance(est, GaussNewtonCalibrator)]


def get_estimator(name: str, **config: Any) -> Estimator:
    """A new estimator configured as the catalogue's ``name``, but for ``config`` (any of
    its class's parameters, e.g. ``sigma``, ``conditions``, ``left_out``, ``verify``); an
    unknown name or parameter, or a bad value, is refused with a ``ValueError`` naming it
    and what is allowed."""
    if name not in CATALOGUE:
        raise ValueError(f"unknown estimator '{name}'; choose from {list(CATALOGUE)}")
    return CATALOGUE[name].clone(**config)


def for_readings(estimator: Estimator, sigma: float, conditions: Conditions | str = IDEAL
                 ) -> Estimator:
    """``estimator`` set for readings of noise ``sigma`` (mm, one reading's standard
    deviation) taken under ``conditions`` (or ``"auto"``: the fit estimates them from
    the readings); one that does not take the lab's conditions (the paper's linear fit)
    is refused for any but ideal ones, since it would read their effects as white
    noise."""
    given: dict[str, Any] = {"sigma": sigma}
    if getattr(conditions, "name", conditions) != IDEAL.name or estimator.takes("conditions"):
        given["conditions"] = conditions
    return estimator.clone(**given)


def for_study(name: str, sigma: float, conditions: Conditions | str = IDEAL,
              left_out: str = DEFAULT_PRESET, world_check: bool = False) -> Estimator:
    """The catalogue's ``name`` as a study runs it, on readings of noise ``sigma`` (mm)
    taken under ``conditions`` (or ``"auto"``) on a machine whose errors are of the
    preset ``left_out``'s size: without verification or the words on what the data
    determine (a study scores estimates and reads neither); ``world_check``: with the
    test that the readings show a worse world than told.  An estimator that does not take
    the lab's conditions (the paper's linear fit) reads the readings as the paper does,
    white noise only."""
    estimator = get_estimator(name, sigma=sigma, verify=False)
    lab = {"conditions": conditions, "left_out": left_out, "explain": False,
           **({"world_check": True} if world_check else {})}
    return estimator.clone(**{key: value for key, value in lab.items()
                              if estimator.takes(key)})


def estimate(data: Measurements, name: str, sigma: float, conditions: Conditions = IDEAL,
             left_out: str = DEFAULT_PRESET) -> Estimate:
    """The earlier call form: :func:`for_study`'s estimator fitted to ``data``."""
    return for_study(name, sigma, conditions, left_out).fit(data)


def estimate_many(datas: list[Measurements], name: str, sigma: float,
                  conditions: Conditions = IDEAL, left_out: str = DEFAULT_PRESET
                  ) -> list[Estimate | Exception]:
    """The earlier call form: :func:`for_study`'s estimator fitted to each of ``datas``
    (batched where it can), a failure in place of its estimate."""
    return for_study(name, sigma, conditions, left_out).fit_many(datas)
