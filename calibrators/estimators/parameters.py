"""Parameters of a fit: which errors are estimated, which are fixed, and their priors.

The parameter vector of a fit is the machine's 27 errors in
:data:`~orthoglide_env.model.errors.ERROR_NAMES` order, then four stand parameters per gauge
mounting (:data:`~orthoglide_env.instruments.stands.STAND_PARAMS`: shift and tilt across the
measuring axis).  A *selection* names the free ones, by comma-separated tokens:

==============  ==============================================================
token           frees
==============  ==============================================================
``paper6``      drho and dL (the paper's model)
``extended``    every machine error and every stand parameter
``machine``     every machine error
``stands``      every stand parameter (``stand_shift``, ``stand_tilt``: half)
a group         ``drho``, ``dL``, ``axis_tilt``, ``axis_offset``, ``attach``
a name          ``drho_x``, ``attach_y.z``, ``x-leg/y@0.5.tilt_z``, ...
==============  ==============================================================

A *prior* is a zero-mean normal on a free parameter, given as a preset name (every group
gets the preset's sigma; stands get its installation tolerances) and/or
``GROUP=SIGMA`` / ``NAME=SIGMA`` overrides; ``none`` gives no prior.  ``auto`` (the
default) puts the realistic preset's prior on a selection that frees more than the
paper's parameters, and none on the paper's model.
"""

from __future__ import annotations

import numpy as np

from orthoglide_env.model.errors import (
    DEFAULT_PRESET,
    ERROR_GROUPS,
    ERROR_NAMES,
    PRESETS,
)
from orthoglide_env.reading_model import ParameterSpace, default_scales, preset_sigmas

#: Selections by alias: ``full`` is the extended selection (with the lab's terms, which
#: the exact-model fit adds: :data:`calibrators.estimators.consider.FULL_TERMS`).
ALIASES: dict[str, str] = {"full": "extended"}
#: The selections that free a run of the parameter vector.
SPANS: dict[str, slice] = {"paper6": slice(6), "extended": slice(None),
                           "machine": slice(len(ERROR_NAMES)),
                           "stands": slice(len(ERROR_NAMES), None)}


def select(selection: str, space: ParameterSpace) -> np.ndarray:
    """Boolean mask of the free parameters named by ``selection`` (see the module doc)."""
    names, groups = space.names, space.groups
    free = np.zeros(len(names), dtype=bool)
    tokens = [t.strip() for t in str(selection).split(",") if t.strip()]
    if not tokens:
        raise ValueError("the parameter selection is empty")
    for token in tokens:
        token = ALIASES.get(token, token)
        if token in SPANS:
            free[SPANS[token]] = True
        elif token in groups:
            free |= np.array([g == token for g in groups])
        elif token in names:
            free[names.index(token)] = True
        else:
            raise ValueError(
                f"unknown parameter '{token}': use paper6, extended, machine, stands, a group "
                f"({', '.join((*ERROR_GROUPS, 'stand_shift', 'stand_tilt'))}) or a name such "
                f"as drho_x, attach_y.z or {names[-1] if len(names) > 27 else 'x-leg/y.tilt_x'}"
            )
    # A tracker's frame and a ballbar's pivot are an instrument's unknowns, like a gauge's
    # zero: always estimated.
    free |= np.array([g in ("tracker_rotation", "ballbar_centre") for g in groups], dtype=bool)
    return free


def parse_assignments(items: list[str] | str | None, what: str) -> dict[str, float]:
    """``NAME=VALUE`` pairs (a list, or one comma-separated string) as a dict."""
    if not items:
        return {}
    if isinstance(items, str):
        items = items.split(",")
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = float("nan")
        if not sep or not name.strip() or not np.isfinite(number):
            raise ValueError(f"{what} '{item}' must be NAME=NUMBER with a finite number")
        out[name.strip()] = number
    return out


def fixed_values(fix: dict[str, float], space: ParameterSpace) -> np.ndarray:
    """The parameter vector holding the ``fix`` values (zero elsewhere)."""
    values = np.zeros(len(space))
    names = space.names
    for name, value in fix.items():
        if name not in names:
            raise ValueError(f"cannot fix unknown parameter '{name}'")
        values[names.index(name)] = value
    return values


def _preset_sigmas(preset_name: str, space: ParameterSpace) -> np.ndarray:
    if preset_name not in PRESETS:
        raise ValueError(f"unknown prior '{preset_name}': use none, a preset "
                         f"({', '.join(sorted(PRESETS))}) or GROUP=SIGMA")
    return preset_sigmas(PRESETS[preset_name], space)


def check_prior(prior: str) -> None:
    """``ValueError`` saying what is wrong with the form of ``prior`` (which names and groups
    exist depends on the readings' mountings, and is checked when they are fitted)."""
    for token in (t.strip() for t in str(prior).split(",") if t.strip()):
        if token in ("none", "auto"):
            continue
        if "=" not in token:
            if token not in PRESETS:
                raise ValueError(f"unknown prior '{token}': use none, auto, a preset "
                                 f"({', '.join(sorted(PRESETS))}) or GROUP=SIGMA")
            continue
        (key, value), = parse_assignments([token], "prior").items()
        if value <= 0:
            raise ValueError(f"prior sigma of '{key}' must be > 0, got {value:g}")


def prior_sigmas(prior: str, space: ParameterSpace, free: np.ndarray) -> np.ndarray:
    """Prior sigma of every parameter (``inf``: no prior).  ``prior``: ``none``, ``auto``,
    a preset name and/or ``GROUP=SIGMA`` / ``NAME=SIGMA`` overrides, comma-separated."""
    sigma = np.full(len(space), np.inf)
    names, groups = space.names, space.groups
    tokens = [t.strip() for t in str(prior).split(",") if t.strip()]
    for token in tokens or ["none"]:
        if token == "none":
            continue
        if token == "auto":
            beyond = [g not in ("drho", "dL", "tracker_rotation", "ballbar_centre")
                      for g in groups]
            if free[beyond].any():
                sigma = _preset_sigmas(DEFAULT_PRESET, space)
            continue
        if "=" not in token:
            sigma = _preset_sigmas(token, space)
            continue
        (key, value), = parse_assignments([token], "prior").items()
        if value <= 0:
            raise ValueError(f"prior sigma of '{key}' must be > 0, got {value:g}")
        if key in groups:
            sigma[[g == key for g in groups]] = value
        elif key in names:
            sigma[names.index(key)] = value
        else:
            raise ValueError(f"prior for unknown parameter or group '{key}'")
    # A zero sigma in a preset means "this error does not exist": no prior rather than an
    # infinitely tight one (the parameter is then better left fixed).
    return np.where(sigma > 0, sigma, np.inf)


def scales(space: ParameterSpace, prior: np.ndarray) -> np.ndarray:
    """Typical size of every parameter: its prior sigma, else its default scale
    (:func:`orthoglide_env.reading_model.default_scales`)."""
    return np.where(np.isfinite(prior), prior, default_scales(space))


def describe(direction: np.ndarray, names: tuple[str, ...] | list[str],
             tolerance: float = 0.2) -> str:
    """A combination of parameters in words: its largest components (``+0.71 drho_x
    -0.70 attach_x.x``), those above ``tolerance`` of the largest."""
    direction = np.asarray(direction, dtype=float)
    order = np.argsort(-np.abs(direction))
    big = [k for k in order if abs(direction[k]) >= tolerance * abs(direction[order[0]])]
    sign = np.sign(direction[order[0]]) or 1.0
    return " ".join(f"{sign * direction[k]:+.2f} {names[k]}" for k in big[:6]) + (
        f" (+{len(big) - 6} more)" if len(big) > 6 else "")


def sparse_basis(vectors: np.ndarray, iterations: int = 100) -> np.ndarray:
    """A rotation of the rows of ``vectors`` (an orthonormal basis of a subspace) whose
    rows are as sparse as the subspace allows (varimax): the eigenvectors of a degenerate
    subspace mix every parameter in it, while ``drho_x - attach_x.x`` is what a reader can
    act on."""
    basis = np.asarray(vectors, dtype=float).T  # (params, k)
    k = basis.shape[1]
    if k < 2:
        return basis.T
    rotation = np.eye(k)
    previous = 0.0
    for _ in range(iterations):
        rotated = basis @ rotation
        target = rotated**3 - rotated @ np.diag(np.sum(rotated**2, axis=0)) / len(basis)
        u, singular, vt = np.linalg.svd(basis.T @ target)
        rotation = u @ vt
        if singular.sum() < previous * (1 + 1e-9):
            break
        previous = singular.sum()
    return (basis @ rotation).T


def act_together(direction: np.ndarray, names: tuple[str, ...] | list[str]) -> str:
    """An unseen combination in words: ``drho_x and attach_x.x act together (+0.71 drho_x
    -0.71 attach_x.x is not seen)``, or the largest components when more are involved."""
    text = describe(direction, names)
    parts = [p for p in text.split() if not p.startswith(("+", "-", "("))]
    if len(parts) == 1:
        return f"{parts[0]} is not seen"
    if len(parts) <= 3 and "more" not in text:
        return f"{' and '.join(parts)} act together ({text} is not seen)"
    return f"not seen: {text}"
