"""What ``orthoglide pose`` and ``orthoglide render`` show: one posture of one machine."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from orthoglide_env.instruments.dial import (
    DEFAULT_RESOLUTION,
    DEFAULT_SIGMA,
    GaugeNoise,
    Status,
    readings_from_distances,
    status_of,
)
from orthoglide_env.instruments.slots import PAPER_LAYOUT
from orthoglide_env.instruments.stands import install, zero_gauges
from orthoglide_env.model.errors import AXIS_NAMES, LEG_NAMES, MachineParams, check_rho
from orthoglide_env.model.kinematics import direct
from orthoglide_env.sim.pybullet import OrthoglideMachine
from orthoglide_env.world.conditions import Conditions
from orthoglide_env.world.machine_file import machine_dict
from orthoglide_env.world.truth import World


def _machine_with_gauges(machine: MachineParams) -> OrthoglideMachine:
    """A simulated machine with the paper's gauges set up and zeroed at Zero on it."""
    sim = OrthoglideMachine(machine, install(PAPER_LAYOUT, machine))
    try:
        sim.set_gauges(zero_gauges(sim.gauges, sim.gauge_distances()))
    except BaseException:
        sim.close()
        raise
    return sim


def pose_report(
    machine: MachineParams,
    rho: np.ndarray,
    *,
    noise_free: bool = False,
    seed: int | None = None,
    sigma: float = DEFAULT_SIGMA,
    resolution: float = DEFAULT_RESOLUTION,
) -> dict:
    """Simulated TCP, exact-model TCP, loop residual and every gauge reading at ``rho``.

    Keys: ``tcp`` [3] (simulated, mm), ``tcp_model`` [3], ``loop_residual_mm``,
    ``platform_rotation_rad``, ``gauges``: list of ``{"leg", "axis", "reading", "valid",
    "status"}`` (reading in mm, ``None`` when not valid).
    """
    rho = check_rho(rho, design=machine.design)
    tcp_model = direct(machine, rho)
    sim = _machine_with_gauges(machine)
    try:
        sim.move(rho)
        t = sim.gauge_distances()
        tcp, residual = sim.tcp(), sim.loop_residual()
        rotation = sim.platform_orientation_error()
        gauges = sim.gauges
    finally:
        sim.close()
    readings = readings_from_distances(gauges, t)
    if not noise_free:
        readings = GaugeNoise(sigma, resolution).apply(readings, np.random.default_rng(seed))
    status = status_of(gauges, t)
    return {
        "tcp": tcp.tolist(),
        "tcp_model": tcp_model.tolist(),
        "loop_residual_mm": residual,
        "platform_rotation_rad": rotation,
        "gauges": [
            {
                "leg": LEG_NAMES[g.spec.leg],
                "axis": AXIS_NAMES[g.spec.axis],
                "reading": None if np.isnan(r) else float(r),
                "valid": bool(np.isfinite(r)),
                "status": Status(s).name.lower().replace("_", "-"),
            }
            for g, r, s in zip(gauges, readings, status, strict=True)
        ],
    }


def pose_in_world(machine: MachineParams, rho: np.ndarray, conditions: Conditions, *,
                  seed: int | None, sigma: float, resolution: float,
                  world: World | None = None) -> dict:
    """:func:`pose_report` in a world beyond the geometry: the paper's gauges mounted at
    Zero on the machine, which is then driven to ``rho``, in a lab of each backend (the
    ``world`` of a machine file, else one drawn from ``seed``).  The same keys, with the
    world's ``conditions`` and ``world``; the gauges' readings are the simulated lab's."""
    import gymnasium as gym

    from orthoglide_env import ENV_ID

    rho = check_rho(rho, design=machine.design)
    seed = int(np.random.SeedSequence().generate_state(1)[0]) if seed is None else seed
    out: dict = {}
    for backend in ("exact", "pybullet"):
        env = gym.make(ENV_ID, backend=backend, conditions=conditions,
                       gauge_sigma=sigma, gauge_resolution=resolution, errors="nominal",
                       design=machine.design)
        try:
            env.reset(seed=seed, options={"machine": machine_dict(machine, world)})
            obs, *_ = env.step(rho)
            lab = env.unwrapped
            out[backend] = (obs, lab.tcp(), lab.true_world, lab.true_gauges)
            if backend == "pybullet":
                sim = lab.simulated_machine
                out["residual"] = sim.loop_residual()
                out["rotation"] = sim.platform_orientation_error()
        finally:
            env.close()
    obs, tcp, world, gauges = out["pybullet"]
    return {
        "tcp": tcp.tolist(), "tcp_model": out["exact"][1].tolist(),
        "loop_residual_mm": out["residual"], "platform_rotation_rad": out["rotation"],
        "conditions": conditions.to_dict(), "world": world.to_dict(),
        "gauges": [{"leg": LEG_NAMES[g.spec.leg], "axis": AXIS_NAMES[g.spec.axis],
                    "reading": float(r) if v else None, "valid": bool(v),
                    "status": "valid" if v else "not-valid"}
                   for g, r, v in zip(gauges, obs["gauges"], obs["valid"], strict=True)],
    }


def render_png(
    machine: MachineParams, rho: np.ndarray, out_path: str | Path, *, width: int = 960,
    height: int = 720,
) -> Path:
    """Render the machine at ``rho`` with its gauges to a PNG file; returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import image

    rho = check_rho(rho, design=machine.design)
    out_path = Path(out_path)
    if out_path.suffix.lower() != ".png":
        raise ValueError(f"render output must be a .png file, got '{out_path}'")
    sim = _machine_with_gauges(machine)
    try:
        sim.move(rho)
        frame = sim.render(width, height)
    finally:
        sim.close()
    out_path.parent.mkdir(parents=True, exist_ok=True)
    image.imsave(out_path, frame)
    return out_path
