"""Machine parameter sets (geometric errors relative to a design) and error presets.

The nominal dimensions of a machine are its design
(:class:`~orthoglide_env.model.design.MachineDesign`, default the prototype); this module
holds the frames and the errors of one machine (or a batch) relative to it.  Units:
millimetres and radians.

Frames
------
World: origin at the intersection of the nominal actuator axes, x, y, z along them.
Each leg ``i`` has a *leg frame* ``R_LEG[i]`` (columns = leg-frame axes in world):

* local X: the actuator axis (x-leg: world x),
* local Z: the axis of the revolute joints R1/R2 (x-leg: world z),
* local Y = Z x X (x-leg: world y).

The y and z legs follow by the cyclic permutation x -> y -> z -> x.

Machine model (what a ``MachineParams`` describes)
-------------------------------------------------
For control coordinate ``rho_i`` (mm, 0 at the nominal isotropic posture) the centre of
the R1 joint of leg ``i`` is::

    A_i = o_i + (L + r + drho_i + rho_i) * u_i

with ``o_i = R_LEG[i] @ (0, axis_offset[i, 0], axis_offset[i, 1])`` the actuator axis
position error and ``u_i = R_LEG[i] @ normalize(1, tan(axis_tilt[i, 0]),
tan(axis_tilt[i, 1]))`` the actuator travel direction.  The carriage itself keeps its
nominal orientation (the error is in the guideway's direction, not in the R1 axis).
The centre of the R2 joint, on the platform, is ``C_i = P + r * e_i + attach[i]``
(the platform only translates).  The leg closes when ``|C_i - A_i| = L + dL_i``, which
with zero extended errors is the paper's equation (2) with ``q_i = L + rho_i + drho_i``.

Unequal bars within one parallelogram are *not* part of the model: they turn the
parallelogram's coupler, and because every leg locks two platform rotations (six
constraints on three rotations), the rigid machine then cannot be assembled.  A real
machine takes that up in joint clearance, which neither a rigid-body simulator nor an
exact model represents; a parameter that no simulator can reproduce honestly would only
fake fidelity.
"""

from __future__ import annotations

import json
import numbers
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from orthoglide_env.model.design import PROTOTYPE, DesignError, MachineDesign
from orthoglide_env.model.userfile import UserFileError, load_user_file, short_repr

LEG_NAMES: tuple[str, str, str] = ("x", "y", "z")
AXIS_NAMES: tuple[str, str, str] = ("x", "y", "z")

_E = np.eye(3)
#: Leg frames: R_LEG[i][:, 0] actuator axis, [:, 1] local Y, [:, 2] R-joint axis.
R_LEG: np.ndarray = np.stack(
    [np.column_stack([_E[i], _E[(i + 1) % 3], _E[(i + 2) % 3]]) for i in range(3)]
)


class MachineFileError(UserFileError):
    """A machine description (JSON file or dict) that does not describe a machine.

    ``key``: the machine key at fault, when there is one (a file reader turns it into a
    line number); ``occurrence``: which appearance of the key in the file (2 for the
    second of two duplicate keys).
    """


def _validated(values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A machine's fields ``values`` checked (each field's shape after its batch axes,
    finite numbers, a batch shape they share) and broadcast to that batch shape."""
    for key, value in values.items():
        shape = _SHAPES[key]
        if value.shape[value.ndim - len(shape):] != shape or value.ndim < len(shape):
            raise MachineFileError(f"machine key '{key}' must have shape {list(shape)}, got "
                                   f"{list(value.shape)}")
        if not np.all(np.isfinite(value)):
            raise MachineFileError(f"machine key '{key}' holds a non-finite number")
    try:
        batch = np.broadcast_shapes(*(v.shape[: v.ndim - len(_SHAPES[k])]
                                      for k, v in values.items()))
    except ValueError:
        raise MachineFileError("machine keys have different batch shapes") from None
    return {key: value if value.shape == (*batch, *_SHAPES[key])
            else np.broadcast_to(value, (*batch, *_SHAPES[key])).copy()
            for key, value in values.items()}


@dataclass
class MachineParams:
    """Geometric errors of one Orthoglide, relative to the nominal prototype.

    All fields default to zero (the nominal machine).  JSON schema (every key optional,
    unknown keys rejected, lengths in mm, angles in rad)::

        {
          "drho":        [3]     encoder offsets (paper)
          "dL":          [3]     leg length deviations (paper)
          "axis_tilt":   [3][2]  actuator direction, tilt toward local Y and local Z
          "axis_offset": [3][2]  actuator axis position along local Y and local Z
          "attach":      [3][3]  R2 centre on the platform, world-frame offset
          "design":      {...} or "FILE"  the machine's nominal design (see
                         :class:`~orthoglide_env.model.design.MachineDesign`): an object of
                         design keys, or the path of a design file (relative to the
                         machine file's folder); left out: the prototype
        }

    The errors are relative to the machine's ``design`` (default: the prototype), whose
    validity range bounds them.  A batch of machines shares one design.
    """

    drho: np.ndarray = field(default_factory=lambda: np.zeros((3,)))
    dL: np.ndarray = field(default_factory=lambda: np.zeros((3,)))
    axis_tilt: np.ndarray = field(default_factory=lambda: np.zeros((3, 2)))
    axis_offset: np.ndarray = field(default_factory=lambda: np.zeros((3, 2)))
    attach: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    design: MachineDesign = PROTOTYPE

    def __post_init__(self) -> None:
        values = {key: np.array(getattr(self, key), dtype=float) for key in _SHAPES}
        # One machine with every field in shape, by far the common case (the kinematics'
        # callers build them by the thousand), needs only its numbers checked.
        single = all(values[key].shape == shape for key, shape in _SHAPES.items())
        if not (single and np.isfinite(np.concatenate([v.ravel() for v in values.values()])
                                       ).all()):
            values = _validated(values)
        for key, value in values.items():
            setattr(self, key, value)
        if not isinstance(self.design, MachineDesign):
            raise MachineFileError(f"a machine's design must be a MachineDesign, got "
                                   f"{type(self.design).__name__}", key="design")
        if np.any(self.design.L + self.dL <= self.design.d / 2):
            raise MachineFileError(f"leg length L + dL must exceed {self.design.d / 2} mm")

    # -- batches of machines ----------------------------------------------------------------
    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading shape of a batch of machines; ``()`` for one machine.

        Every field may carry leading batch dimensions (``drho`` of shape ``(B, 3)`` holds B
        machines); the kinematics broadcast over them, so a single machine is a batch of
        shape ``()`` and there is one code path."""
        return self.drho.shape[:-1]

    def __getitem__(self, index: Any) -> MachineParams:
        """One machine (or a sub-batch) of a batch."""
        if not self.batch_shape:
            raise IndexError("a single machine has no batch axis to index")
        fields = {key: np.array(getattr(self, key)[index]) for key in _SHAPES}
        if isinstance(index, tuple):  # it may reach into the fields' own axes: check
            return MachineParams(**fields, design=self.design)
        # Rows of a checked batch need no checks again (a lab takes rows of its batch
        # every step, and the checks cost 3 % of a lone env's step).
        part = object.__new__(MachineParams)
        part.__dict__.update(fields, design=self.design)
        return part

    @classmethod
    def stack(cls, machines: list[MachineParams]) -> MachineParams:
        """A batch of shape ``(len(machines),)`` from single machines of one design."""
        if not machines:
            raise ValueError("cannot stack an empty list of machines")
        design = machines[0].design
        if any(m.design is not design and m.design != design for m in machines):
            raise ValueError("a batch of machines shares one design")
        return cls(**{key: np.stack([getattr(m, key) for m in machines]) for key in _SHAPES},
                   design=design)

    def to_vector(self) -> np.ndarray:
        """The 27 errors as one vector in :data:`ERROR_NAMES` order, shape ``(*batch, 27)``."""
        return np.concatenate([getattr(self, key).reshape(*self.batch_shape, -1)
                               for key in _SHAPES], axis=-1)

    @classmethod
    def from_vector(cls, vector: np.ndarray, design: MachineDesign) -> MachineParams:
        """Inverse of :meth:`to_vector` (leading dimensions are batch dimensions), machines of
        ``design``."""
        vector = np.asarray(vector, dtype=float)
        if vector.shape[-1:] != (len(ERROR_NAMES),):
            raise ValueError(f"a machine vector has {len(ERROR_NAMES)} entries, "
                             f"got shape {list(vector.shape)}")
        # Slices, the views ``np.split`` makes at a tenth of its cost (a sweep makes a
        # machine from each estimate).
        return cls(**{key: vector[..., start:end].reshape(*vector.shape[:-1], *shape)
                      for (key, shape), start, end in zip(
                          _SHAPES.items(), [0, *_SPLITS], [*_SPLITS, len(ERROR_NAMES)],
                          strict=True)}, design=design)

    # -- derived geometry, used by the kinematics and the URDF writer ------------------
    @property
    def leg_lengths(self) -> np.ndarray:
        """True leg lengths L + dL, shape (3,)."""
        return self.design.L + self.dL

    @property
    def axis_directions(self) -> np.ndarray:
        """Unit actuator travel directions u_i in world, shape (*batch, 3, 3) (row i = leg i),
        read-only."""
        return _axis_directions(self.axis_tilt)

    @property
    def axis_origins(self) -> np.ndarray:
        """Points o_i of the actuator axes in world, shape (*batch, 3, 3), read-only."""
        return _axis_origins(self.axis_offset)

    @property
    def attach_points(self) -> np.ndarray:
        """R2 centres C_i relative to the TCP, in world, shape (*batch, 3, 3)."""
        return self.design.r * np.eye(3) + self.attach

    @property
    def is_paper_model(self) -> bool:
        """True when only the paper's six parameters are non-zero (in every machine)."""
        return not (self.axis_tilt.any() or self.axis_offset.any() or self.attach.any())

    def __eq__(self, other: object) -> bool:
        """Equal when of one design and every field holds the same numbers in the same shape
        (the generated dataclass comparison would ask numpy for the truth value of an
        array)."""
        if not isinstance(other, MachineParams):
            return NotImplemented
        return self.design == other.design and all(
            np.array_equal(getattr(self, key), getattr(other, key)) for key in _SHAPES)

    # -- (de)serialisation ---------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The machine as a JSON-ready dict; its ``design`` (every key) only when it is not
        the prototype."""
        out: dict[str, Any] = {key: getattr(self, key).tolist() for key in _SHAPES}
        if self.design != PROTOTYPE:
            out["design"] = self.design.to_dict()
        return out

    @classmethod
    def from_dict(cls, data: Any, design: MachineDesign | None = None,
                  folder: Path | None = None) -> MachineParams:
        """Build from a JSON-like dict; missing keys are zero, unknown keys an error.

        Values are (nested) lists of numbers: booleans, strings and integers no float can
        hold are refused, and the machine must lie inside its design's validity range.  The
        design is the dict's ``design`` (an object of design keys, or a design file's path
        relative to ``folder``, default the working directory; refused when ``design`` is
        given and differs), else ``design``, else the prototype.
        """
        if not isinstance(data, dict):
            raise MachineFileError("a machine must be a JSON object")
        unknown = [key for key in data if key not in (*_SHAPES, "design")]
        if unknown:
            raise MachineFileError(f"unknown machine key(s) {sorted(map(str, unknown))}; "
                                   f"allowed: {[*sorted(_SHAPES), 'design']}", key=str(unknown[0]))
        if "design" in data:
            named = _design_of(data["design"], folder)
            if design is not None and named != design:
                raise MachineFileError("machine key 'design' names another design than the "
                                       "one given (a command's --design, an env's design)",
                                       key="design")
            design = named
        design = PROTOTYPE if design is None else design
        kwargs = {key: _numbers(key, value) for key, value in data.items() if key != "design"}
        for key, value in kwargs.items():
            # The dataclass checks every field; building with one key at a time tells which
            # key (and so which line of a file) breaks its rules.
            try:
                cls(**{key: value}, design=design)
            except MachineFileError as exc:
                raise MachineFileError(str(exc), key=key) from None
        return check_validity(cls(**kwargs, design=design))

    def to_json(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def from_json(cls, path: str | Path, design: MachineDesign | None = None) -> MachineParams:
        """Read a machine file (a JSON object, see :meth:`from_dict`; a key given twice is
        an error); ``design``: the machine's design when the file names none (a file that
        names another is refused).  Errors name the file, and the line of the key at
        fault."""
        return load_user_file(path, "machine", MachineFileError,
                              lambda data: cls.from_dict(data, design, Path(path).parent))

    def with_paper_params(self, drho: np.ndarray, dL: np.ndarray) -> MachineParams:
        """A copy whose paper parameters are replaced (extended errors kept)."""
        data = {key: getattr(self, key).tolist() for key in _SHAPES}
        data["drho"], data["dL"] = np.asarray(drho).tolist(), np.asarray(dL).tolist()
        return MachineParams.from_dict(data, design=self.design)


_SHAPES: dict[str, tuple[int, ...]] = {
    "drho": (3,),
    "dL": (3,),
    "axis_tilt": (3, 2),
    "axis_offset": (3, 2),
    "attach": (3, 3),
}
#: Where each group's errors end in a machine's vector (but the last).
_SPLITS: list[int] = np.cumsum([np.prod(shape) for shape in _SHAPES.values()])[:-1].tolist()

def _by_value(function: Callable[[np.ndarray], np.ndarray]
              ) -> Callable[[np.ndarray], np.ndarray]:
    """``function`` of one array, remembered for the last few arrays by their contents (a
    fit asks the same machines for their geometry a dozen times per step); the results are
    read-only, so no caller can change what the next one gets."""
    cache: OrderedDict[tuple, np.ndarray] = OrderedDict()

    def remembered(value: np.ndarray) -> np.ndarray:
        key = (value.shape, value.tobytes())
        out = cache.get(key)
        if out is None:
            out = function(value)
            out.setflags(write=False)
            cache[key] = out
            if len(cache) > 16:
                cache.popitem(last=False)
        return out

    return remembered


@_by_value
def _axis_directions(axis_tilt: np.ndarray) -> np.ndarray:
    tilt = np.tan(axis_tilt)
    local = np.concatenate([np.ones((*tilt.shape[:-1], 1)), tilt], axis=-1)
    local /= np.linalg.norm(local, axis=-1, keepdims=True)
    return np.einsum("ijk,...ik->...ij", R_LEG, local)


@_by_value
def _axis_origins(axis_offset: np.ndarray) -> np.ndarray:
    local = np.concatenate([np.zeros((*axis_offset.shape[:-1], 1)), axis_offset], axis=-1)
    return np.einsum("ijk,...ik->...ij", R_LEG, local)


#: Error groups of a machine file, in schema order.
ERROR_GROUPS: tuple[str, ...] = tuple(_SHAPES)


def _element_names(key: str) -> list[str]:
    """Names of one group's elements.  Tilts and offsets are named by the leg and the world
    axis they point to (``axis_tilt_y.z``: the y actuator tilted toward z), attachment
    errors by the leg and the world component (``attach_x.y``)."""
    if key in ("drho", "dL"):
        return [f"{key}_{leg}" for leg in LEG_NAMES]
    if key == "attach":
        return [f"{key}_{leg}.{ax}" for leg in LEG_NAMES for ax in AXIS_NAMES]
    return [f"{key}_{LEG_NAMES[i]}.{AXIS_NAMES[(i + k) % 3]}" for i in range(3) for k in (1, 2)]


#: The 27 errors of a machine, in :meth:`MachineParams.to_vector` order.
ERROR_NAMES: tuple[str, ...] = tuple(n for key in ERROR_GROUPS for n in _element_names(key))


def error_group(name: str) -> str:
    """The machine-file key an error name belongs to (``attach_x.y`` -> ``attach``)."""
    return name.split("_", 1)[0] if not name.startswith("axis_") else "_".join(
        name.split("_")[:2])


def check_validity(machine: MachineParams) -> MachineParams:
    """``machine`` itself when every error lies inside its design's validity range (see
    :attr:`MachineDesign.validity_range`), otherwise ``MachineFileError`` naming the key, the
    element, its value and the range."""
    for key, (limit, unit) in machine.design.validity_range.items():
        values = getattr(machine, key)
        outside = np.argwhere(np.abs(values) > limit)
        if len(outside):
            index = tuple(int(i) for i in outside[0])
            raise MachineFileError(
                f"machine key '{key}' element {list(index)} = {values[index]:g} {unit} is "
                f"outside the validity range [-{limit:g}, {limit:g}] {unit} (where the "
                "simulator and the exact model agree)", key=key)
    return machine


def valid_vectors(vectors: np.ndarray, design: MachineDesign) -> np.ndarray:
    """(M,) for machine vectors ``vectors`` (M, 27) of ``design``: True where
    :meth:`MachineParams.from_vector` and :func:`check_validity` take the machine (finite
    errors, legs longer than half the parallelogram's width, each error inside its
    validity range), False where either would raise: for many estimates at once, the
    same comparisons without a machine each."""
    vectors = np.asarray(vectors, dtype=float)
    valid = np.isfinite(vectors).all(axis=-1)
    parts = dict(zip(_SHAPES, np.split(vectors, _SPLITS, axis=-1), strict=True))
    with np.errstate(invalid="ignore"):
        valid &= ~np.any(design.L + parts["dL"] <= design.d / 2, axis=-1)
        for key, (limit, _) in design.validity_range.items():
            valid &= ~np.any(np.abs(parts[key]) > limit, axis=-1)
    return valid


def _design_of(value: Any, folder: Path | None) -> MachineDesign:
    """The design under a machine's ``design`` key: a design object, or a design file's path
    (relative to ``folder``)."""
    try:
        if isinstance(value, str):
            return MachineDesign.from_file((folder or Path()) / value)
        if isinstance(value, MachineDesign):
            return value
        return MachineDesign.from_dict(value)
    except DesignError as exc:
        key = "design" if isinstance(value, str) or exc.key is None else exc.key
        raise MachineFileError(str(exc), key=key) from None


def _numbers(key: str, value: Any) -> np.ndarray:
    """The numbers under a machine key, as floats.  numpy alone would read ``true`` and
    ``"1.5"`` as numbers and overflow on an integer of hundreds of digits: each element
    must be an int or a float that a float can hold."""
    depth = len(_SHAPES[key])
    pending = [(value, 0)]
    while pending:
        item, level = pending.pop()
        if level < depth and (isinstance(item, list | tuple)
                              or (isinstance(item, np.ndarray) and item.ndim > 0)):
            pending.extend((element, level + 1) for element in item)
            continue
        if isinstance(item, bool | np.bool_) or not isinstance(item, numbers.Real):
            raise MachineFileError(f"machine key '{key}' must hold numbers, got "
                                   f"{short_repr(item)} ({type(item).__name__})", key=key)
        try:
            float(item)
        except OverflowError:
            raise MachineFileError(f"machine key '{key}' holds an integer beyond the range "
                                   f"of a float (+-{np.finfo(float).max:.1e})",
                                   key=key) from None
    try:
        return np.array(value, dtype=float)
    except ValueError:
        raise MachineFileError(f"machine key '{key}' must have shape {list(_SHAPES[key])}, "
                               f"got rows of different lengths", key=key) from None


@dataclass(frozen=True)
class ErrorPreset:
    """Standard deviations of zero-mean normal errors of a random machine and its gauges.

    ``gauge_position`` and ``gauge_tilt`` are installation errors of each gauge's stand
    (position in mm per axis, tilt of the measuring axis in rad per transverse axis).
    """

    name: str
    drho: float = 0.0
    dL: float = 0.0
    axis_tilt: float = 0.0
    axis_offset: float = 0.0
    attach: float = 0.0
    gauge_position: float = 0.0
    gauge_tilt: float = 0.0
    description: str = ""

    def sigmas(self) -> np.ndarray:
        """Standard deviation of each of the 27 errors, in :data:`ERROR_NAMES` order."""
        return np.array([getattr(self, error_group(n)) for n in ERROR_NAMES], dtype=float)

    def sample(self, rng: np.random.Generator, design: MachineDesign) -> MachineParams:
        """Draw one machine of ``design`` (the gauge installation errors are drawn by the
        gauges)."""
        return MachineParams(**{key: rng.normal(0.0, getattr(self, key), shape)
                                for key, shape in _SHAPES.items()}, design=design)


#: Named error presets.  ``realistic`` sizes the extended errors so that the paper's
#: six-parameter model is left with gauge residuals of the order the paper reports
#: (about 0.1 mm, Table 1); ``benchmarks/realistic.py`` measures that.
PRESETS: dict[str, ErrorPreset] = {p.name: p for p in (
    ErrorPreset("nominal", description="no error at all"),
    ErrorPreset("paper", drho=2.0, dL=2.0,
                description="only the paper's six parameters: drho, dL ~ N(0, 2 mm)"),
    ErrorPreset("realistic", drho=2.0, dL=2.0, axis_tilt=2e-3, axis_offset=0.5, attach=0.3,
                gauge_position=0.5, gauge_tilt=5e-3,
                description="paper errors N(0, 2 mm) plus actuator tilt N(0, 2 mrad), axis "
                "offset N(0, 0.5 mm), platform attachment N(0, 0.3 mm), gauge stand position "
                "N(0, 0.5 mm) and tilt N(0, 5 mrad)"),
)}
DEFAULT_PRESET = "realistic"


def get_preset(name: str) -> ErrorPreset:
    """Look up an error preset by name, with a clear error listing the valid ones."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown error preset '{name}'; choose from {sorted(PRESETS)}") from None


def random_machine(seed: int | np.random.Generator | None, preset: str = DEFAULT_PRESET, *,
                   design: MachineDesign) -> MachineParams:
    """A seeded random machine of ``design`` drawn from a named preset."""
    return get_preset(preset).sample(np.random.default_rng(seed), design)


def check_rho(rho: np.ndarray, *, design: MachineDesign, margin: float = 0.0) -> np.ndarray:
    """Validate control coordinates (shape (..., 3), finite, within ``design``'s control
    limits)."""
    rho = np.asarray(rho, dtype=float)
    if rho.shape[-1:] != (3,):
        raise ValueError(f"joint targets must have 3 components, got shape {list(rho.shape)}")
    if not np.all(np.isfinite(rho)):
        raise ValueError("joint targets must be finite numbers")
    bad = ~within_limits(rho, design, margin)
    if np.any(bad):
        lo, hi = design.rho_min - margin, design.rho_max + margin
        raise ValueError(f"joint target {rho[bad].flat[0]:g} mm is outside the joint limits "
                         f"[{lo:g}, {hi:g}] mm")
    return rho


def within_limits(rho: np.ndarray, design: MachineDesign, margin: float = 0.0) -> np.ndarray:
    """Which coordinates of the commands ``rho`` (..., 3) lie within ``design``'s control
    limits, widened by ``margin`` (mm); NaN lies outside.  Every check of the limits asks
    this."""
    return (rho >= design.rho_min - margin) & (rho <= design.rho_max + margin)
