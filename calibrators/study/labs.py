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
from orthoglide_env.lab.spec import LAB
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.errors import MachineParams
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.machine_file import machine_dict


def lab_kwargs(agent: Agent, instruments: tuple[str, ...] = (), **settings: Any
               ) -> dict[str, Any]:
    """The lab env's arguments: ``settings`` (budget, design, conditions, noise, ...) and
    the instruments ``agent`` needs beyond the gauges (``tracker``, ``reference``).
    ``instruments``: what the lab owns (names of :data:`~orthoglide_env.instruments.
    catalogue.INSTRUMENT_NAMES`; empty: today's lab, the dial gauges and the tracker
    for an agent that reads one); ``ValueError`` in one line when ``agent`` needs one the
    lab does not own, or when the budget (``settings``' ``budget_s``, else the lab's
    default) cannot hold the agent's procedure (:meth:`~calibrators.agents.base.Agent.
    check_budget`).  The tracker is read only by an agent that needs it."""
    owned = tuple(instruments) or ("dial", *(("tracker",) if agent.needs_tracker else ()))
    needs = (*(("tracker",) if agent.needs_tracker else ()), *agent.needs_instruments)
    missing = [n for n in needs if n not in owned]
    if missing:
        raise ValueError(f"agent '{agent.name}' needs the {missing[0]}, which the lab does "
                         f"not own (instruments {','.join(owned)})")
    agent.check_budget(settings.get("budget_s", LAB["budget_s"].default),
                       settings.get("design") or PROTOTYPE,
                       settings.get("stands", LAB["stands"].default))
    kwargs = {**settings, "tracker": agent.needs_tracker, "reference": agent.needs_reference}
    if instruments:
        kwargs["instruments"] = [n for n in owned if n != "tracker"]
    return kwargs


def lab_id(kwargs: dict[str, Any]) -> str:
    """The lab env that takes ``kwargs``: ``OrthoglideLab-v4`` for a lab with the
    interferometer (its moves choose whether to read it), ``OrthoglideLab-v3`` for one with
    the step gauge, ``OrthoglideLab-v2`` for one with the ballbar, else
    ``OrthoglideLab-v0``."""
    owned = kwargs.get("instruments", ())
    if "interferometer" in owned:
        return orthoglide_env.LAB_V4_ENV_ID
    if "step-gauge" in owned:
        return orthoglide_env.LAB_V3_ENV_ID
    return orthoglide_env.LAB_V2_ENV_ID if "ballbar" in owned else orthoglide_env.LAB_ENV_ID


def make_lab(agent: Agent, **settings: Any) -> gym.Env:
    """A lone lab (:func:`lab_id`'s) of :func:`lab_kwargs` for ``agent``."""
    kwargs = lab_kwargs(agent, **settings)
    return gym.make(lab_id(kwargs), **kwargs)


def nominal_lab(agent: Agent, design: MachineDesign, conditions: Conditions,
                budget_s: float, *, sigma: float, resolution: float,
                instruments: tuple[str, ...] = ()) -> gym.Env:
    """The exact-model lab of the nominal machine of ``design`` for ``agent`` (reset it
    with :func:`nominal_options`), gauges of noise ``sigma`` and dial ``resolution`` (mm),
    owning ``instruments`` (:func:`lab_kwargs`).  The gauges are the ones the real lab
    reads, never a default: a planned agent designs its experiment for the noise the lab
    shows it, so a lab of other gauges plays another plan."""
    return make_lab(agent, backend="exact", errors="nominal", gauge_sigma=sigma,
                    gauge_resolution=resolution, budget_s=budget_s, design=design,
                    conditions=conditions, instruments=instruments)


def nominal_options(design: MachineDesign) -> dict[str, Any]:
    """The reset options that put the nominal machine of ``design`` into a lab."""
    return {"machine": machine_dict(MachineParams(design=design), None)}
