"""The settings of a lab engine, made from an env's checked arguments, and the env's spaces.

:class:`LabSettings` holds everything the engine's rules depend on.  Both envs are faces
of the same engine: ``OrthoglideLab-v0`` (:func:`lab_settings`) and
``OrthoglideCalibration-v0`` (:func:`calibration_settings`: stands at the layout's
slots, all engaged; every action a move; an overtravel that lasts only while the bar
presses; a move the machine cannot assemble refused with ``ValueError``; no tracker
station and no notebook: its readings are its observations).  Each builder takes the
arguments its env's table in :mod:`orthoglide_env.lab.spec` checked and adds the checks
that tie arguments together.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from gymnasium import spaces

from orthoglide_env.instruments import ballbar, step_gauge
from orthoglide_env.instruments.catalogue import check_instruments
from orthoglide_env.instruments.dial import GaugeNoise, check_noise
from orthoglide_env.instruments.slots import PAPER_LAYOUT, GaugeSpec
from orthoglide_env.lab.notebook import Estimator
from orthoglide_env.lab.operations import (
    TIME,
    TRACKER_SIGMA,
    V0_OPS,
    V1_OPS,
    V2_OPS,
    Op,
    slot_catalogue,
    slot_index,
)
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.errors import ErrorPreset, get_preset
from orthoglide_env.sim.display import display_problem, require_display
from orthoglide_env.world.conditions import IDEAL, Conditions
from orthoglide_env.world.faults import NO_FAULTS, Faults
from orthoglide_env.world.table import BALLBAR_LENGTHS_MM

#: Encoders may read a hair outside the control limits after settling (solver residue
#: ~1e-9 mm); the observation box leaves this margin so an observation is always inside.
ENCODER_MARGIN: float = 1.0


@dataclass(frozen=True)
class LabSettings:
    """What a lab engine's rules depend on (see the envs' docstrings)."""

    preset: ErrorPreset
    noise: GaugeNoise
    backend: str
    stands: int
    layout: tuple[GaugeSpec, ...]  # mounted on stands 0, 1, ... at every reset
    travel: float
    design: MachineDesign  # the machines' design: control limits, validity, slots
    tracker: bool = False  # the tracker is read at every move
    tracker_sigma: float = TRACKER_SIGMA
    thermometer: bool = False  # a room thermometer is read with every reading
    station: bool = True  # a tracker station stands in the lab (its frame drawn at reset)
    budget_s: float = np.inf
    max_steps: int | None = None
    reward: str = "time"
    estimator: Estimator | None = None
    time_weight: float = 1.0
    success_mm: float = 0.01
    #: A ``fault`` puts the gauge out of service until it is re-mounted; a ``momentary``
    #: overtravel lasts while the bar presses it (and is charged on entering only).
    overtravel: str = "fault"
    strict_moves: bool = False  # a move the machine cannot assemble raises ValueError
    notebook: bool = True  # every reading is written into the episode's notebook
    motion: str = "quasi-static"
    render_mode: str | None = None
    conditions: Conditions = IDEAL  # the world's effects beyond the geometry
    reference: bool = False  # the lab has the gauge block: its catalogue the reference slots
    instruments: tuple[str, ...] = ("dial",)  # what the lab owns (catalogue.INSTRUMENT_NAMES)
    version: int = 0  # the env's version: v1's spaces carry the interferometer, v2's ballbar,
    # v3's step gauge, v4's the moves' choice to read the laser
    faults: Faults = NO_FAULTS  # what can go wrong in the session (orthoglide_env.lab.faults)

    @property
    def interferometer(self) -> bool:
        """Whether the lab owns a laser interferometer (``align`` sets it up)."""
        return "interferometer" in self.instruments

    @property
    def ballbar(self) -> bool:
        """Whether the lab owns a ballbar (``pivot`` sets it up)."""
        return "ballbar" in self.instruments

    @property
    def step_gauge(self) -> bool:
        """Whether the lab owns a step gauge (``place`` sets it up)."""
        return "step-gauge" in self.instruments

    @cached_property
    def slots(self) -> tuple[GaugeSpec, ...]:
        """The lab's slot catalogue: its design's (:func:`~orthoglide_env.lab.operations.
        slot_catalogue`, with the reference slots when the lab has the gauge block), whose
        indices the ``slot`` action and observation use."""
        return slot_catalogue(self.design, self.reference)

    def longest_step(self) -> float:
        """The most one operation can cost (a re-mount from the far corner, the tracker, and
        every stand pushed past its travel): the clock never passes budget + this."""
        far = TIME.move(np.full(3, self.design.rho_min), np.full(3, self.design.rho_max))
        block = TIME.reference_s if self.reference else 0.0
        longest = (far + TIME.remount_s + block + TIME.tracker_point_s
                   + TIME.overtravel_s * self.stands)
        if self.ballbar:
            longest = max(longest, far + TIME.ballbar_setup_s + TIME.overtravel_s * self.stands)
        if self.step_gauge:
            longest = max(longest, far + TIME.step_gauge_setup_s + TIME.step_gauge_face_s
                          + TIME.tracker_point_s + TIME.overtravel_s * self.stands)
        if not self.interferometer:
            return longest
        setup = (far + TIME.interferometer_setup_s + TIME.interferometer_soak_s
                 + TIME.overtravel_s * self.stands)
        return max(longest, setup)


def _picture(backend: str, render_mode: str | None) -> None:
    """Refuse a picture the backend cannot draw, and a window where none can open."""
    if backend == "exact" and render_mode is not None:
        raise ValueError("the exact backend has no picture: use backend='pybullet' to render")
    if render_mode == "human":
        require_display("render_mode='human'", "render_mode='rgb_array'")


def render_modes(backend: str) -> list[str]:
    """The render modes an instance on ``backend`` can produce here."""
    if backend == "exact":
        return []
    return ["rgb_array"] + (["human"] if display_problem() is None else [])


def _shared(args: dict[str, Any], design: MachineDesign) -> dict[str, Any]:
    """The settings of the arguments both envs take (:data:`orthoglide_env.lab.spec.
    CALIBRATION`, :data:`~orthoglide_env.lab.spec.LAB`), for machines of ``design``."""
    render_mode = args.get("render_mode")  # a lab vector env draws no picture
    _picture(args["backend"], render_mode)
    travel = design.gauge_travel if args["travel"] is None else args["travel"]
    return {"preset": get_preset(args["errors"]), "backend": args["backend"],
            "noise": check_noise(args["gauge_sigma"], args["gauge_resolution"], travel),
            "travel": travel, "render_mode": render_mode, "design": design,
            "conditions": args["conditions"]}


def lab_settings(args: dict[str, Any], version: int = 0) -> LabSettings:
    """The settings of ``OrthoglideLab-v<version>`` from its checked arguments
    (:data:`orthoglide_env.lab.spec.LAB`)."""
    if args["reward"] == "accuracy" and args["estimator"] is None:
        raise ValueError("reward 'accuracy' needs an estimator: records -> machine, e.g. "
                         "calibrators.study.episodes.make_estimator()")
    design = args["design"] or PROTOTYPE
    slots = slot_catalogue(design)
    stands = args["stands"]
    if stands > len(slots):
        raise ValueError(f"stands must be an integer in [1, {len(slots)}] (the design's slot "
                         f"count), got {stands!r}")
    mid = PAPER_LAYOUT[0].at  # the paper's gauges are all at mid-leg
    if mid not in design.slot_positions:
        # The lab has no layout argument: every episode opens on the paper's stands.
        raise ValueError(f"the lab mounts its stands at the paper's mid-leg slots (e.g. "
                         f"'{PAPER_LAYOUT[0].slot}') at every reset: the design's "
                         f"slot_positions {list(design.slot_positions)} must include {mid}")
    instruments = args["instruments"] or ("dial",)
    # ``tracker=True`` and an instrument list naming the tracker say the same.
    tracker = args["tracker"] or "tracker" in instruments
    if tracker and "tracker" not in instruments:
        instruments = check_instruments((*instruments, "tracker"))
    if "interferometer" in instruments and version < 1:
        raise ValueError("instruments: the interferometer needs OrthoglideLab-v1 (its action "
                         "has the align operation and an axis, its observation the "
                         "interferometer's reading)")
    if "ballbar" in instruments and version < 2:
        raise ValueError("instruments: the ballbar needs OrthoglideLab-v2 (its action has the "
                         "pivot operation and a bar, its observation the ballbar's reading)")
    if "step-gauge" in instruments and version < 3:
        raise ValueError("instruments: the step gauge needs OrthoglideLab-v3 (its action has "
                         "the place operation, its observation the step gauge's reading)")
    faults = args["faults"]
    if "thermal-step" in faults.kinds and "room" not in args["conditions"]:
        raise ValueError("faults: 'thermal-step' steps the room's temperature: it needs "
                         "conditions 'lab' or 'workshop' with the room effect")
    return LabSettings(
        **_shared(args, design), stands=stands, faults=faults,
        layout=tuple(slots[slot_index(spec, design=design)] for spec in PAPER_LAYOUT[:stands]),
        instruments=instruments, version=version,
        tracker=tracker, tracker_sigma=args["tracker_sigma"],
        thermometer=args["thermometer"],
        budget_s=args["budget_s"], reward=args["reward"], estimator=args["estimator"],
        time_weight=args["time_weight"], success_mm=args["success_mm"],
        reference=args["reference"])


def calibration_settings(args: dict[str, Any]) -> LabSettings:
    """The settings of ``OrthoglideCalibration-v0`` from its checked arguments
    (:data:`orthoglide_env.lab.spec.CALIBRATION`)."""
    layout = args["gauges"] or PAPER_LAYOUT
    return LabSettings(
        **_shared(args, args["design"] or PROTOTYPE), stands=len(layout), layout=layout,
        station=False, max_steps=args["max_episode_steps"], overtravel="momentary",
        strict_moves=True, notebook=False, motion=args["motion"])


def lab_spaces(settings: LabSettings) -> tuple[spaces.Dict, spaces.Dict]:
    """``OrthoglideLab-v0``'s action and observation spaces."""
    n, design = settings.stands, settings.design
    v1, v2, v3 = settings.version >= 1, settings.version >= 2, settings.version >= 3
    action_space = spaces.Dict({
        "op": spaces.Discrete(len(Op) if v3 else V2_OPS if v2 else V1_OPS if v1 else V0_OPS),
        "rho": spaces.Box(design.rho_min, design.rho_max, shape=(3,), dtype=np.float64),
        "stand": spaces.Discrete(n),
        "slot": spaces.Discrete(len(settings.slots)),
        **({"axis": spaces.Discrete(3)} if v1 else {}),
        **({"bar": spaces.Discrete(len(BALLBAR_LENGTHS_MM))} if v2 else {}),
        **({"laser": spaces.Discrete(2)} if settings.version >= 4 else {}),
    })
    observation_space = spaces.Dict({
        # A valid reading lies within +-travel/2 of its zero; the box leaves another
        # travel/2 (>= 25 sigma, see MAX_NOISE_FRACTION) for the noise.
        "gauges": spaces.Box(-settings.travel, settings.travel, shape=(n,), dtype=np.float64),
        "valid": spaces.MultiBinary(n),
        "engaged": spaces.MultiBinary(n),
        "faulted": spaces.MultiBinary(n),
        "slot": spaces.MultiDiscrete([len(settings.slots) + 1] * n),
        "mounting": spaces.Box(0.0, 1e6, shape=(n,), dtype=np.float64),
        "joints": spaces.Box(design.rho_min - ENCODER_MARGIN, design.rho_max + ENCODER_MARGIN,
                             shape=(3,), dtype=np.float64),
        "tracker": spaces.Box(-1e5, 1e5, shape=(3,), dtype=np.float64),
        "tracker_valid": spaces.MultiBinary(1),
        "time": spaces.Box(0.0, settings.budget_s + settings.longest_step(), shape=(1,),
                           dtype=np.float64),
        # The carriage's deviation from its command along the set-up drive: tens of um.
        **({"interferometer": spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float64),
            "interferometer_valid": spaces.MultiBinary(1),
            "interferometer_axis": spaces.Discrete(4)} if v1 else {}),
        # The bar's distance less its length: within its travel, and a little noise.
        **({"ballbar": spaces.Box(-2 * ballbar.travel_mm(), 2 * ballbar.travel_mm(),
                                  shape=(1,), dtype=np.float64),
            "ballbar_valid": spaces.MultiBinary(1),
            "ballbar_in": spaces.MultiBinary(1)} if v2 else {}),
        # The TCP's positioning error along the gauge: tens of um, within the probe's range.
        **({"step_gauge": spaces.Box(-2 * step_gauge.probe_range_mm(),
                                     2 * step_gauge.probe_range_mm(), shape=(1,),
                                     dtype=np.float64),
            "step_gauge_valid": spaces.MultiBinary(1),
            "step_gauge_in": spaces.MultiBinary(1)} if v3 else {}),
    })
    return action_space, observation_space


def calibration_spaces(settings: LabSettings) -> tuple[spaces.Box, spaces.Dict]:
    """``OrthoglideCalibration-v0``'s action and observation spaces: the lab's joint
    targets, and its gauges, valid flags and joints."""
    actions, observations = lab_spaces(settings)
    return actions["rho"], spaces.Dict({key: observations[key]
                                        for key in ("gauges", "valid", "joints")})
