"""The lab env an agent works in: its arguments, and the nominal machine's lab.

Every caller that makes a lab for an agent (``compare``, ``calibrate``, the workflow's
plan and session) takes its arguments from :func:`lab_kwargs`, which adds the instruments
the agent needs beyond the dial gauges (a laser tracker, a gauge block).  The workflow
plays an experiment on the nominal machine of a design, in the exact-model lab
(:func:`nominal_lab`, reset with :func:`nominal_options`), to learn its steps, their
timing and which readings each takes.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

import orthoglide_env
from calibrators.agents import Agent
from orthoglide_env.model.design import MachineDesign
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.machine_file import machine_dict


def lab_kwargs(agent: Agent, **settings: Any) -> dict[str, Any]:
    """The lab env's arguments: ``settings`` (budget, design, conditions, noise, ...) and
    the instruments ``agent`` needs beyond the gauges (``tracker``, ``reference``)."""
    return {**settings, "tracker": agent.needs_tracker, "reference": agent.needs_reference}


def make_lab(agent: Agent, **settings: Any) -> gym.Env:
    """A lone lab (``OrthoglideLab-v0``) of :func:`lab_kwargs` for ``agent``."""
    return gym.make(orthoglide_env.LAB_ENV_ID, **lab_kwargs(agent, **settings))


def nominal_lab(agent: Agent, design: MachineDesign, conditions: Conditions,
                budget_s: float, *, sigma: float = 0.0, resolution: float = 0.0) -> gym.Env:
    """The exact-model lab of the nominal machine of ``design`` for ``agent`` (reset it
    with :func:`nominal_options`), gauges of noise ``sigma`` and dial ``resolution``."""
    return make_lab(agent, backend="exact", errors="nominal", gauge_sigma=sigma,
                    gauge_resolution=resolution, budget_s=budget_s, design=design,
                    conditions=conditions)


def nominal_options(design: MachineDesign) -> dict[str, Any]:
    """The reset options that put the nominal machine of ``design`` into a lab."""
    return {"machine": machine_dict(MachineParams(design=design), None)}
