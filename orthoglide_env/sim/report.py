"""What ``orthoglide pose`` and ``orthoglide render`` show: one posture of one machine."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from orthoglide_env.instruments.dial import (
    DEFAULT_RESOLUTION,
    DEFAULT_SIGMA,
    GaugeNoise,
    Status,
    readings_from_distances,
    status_of,
)
from orthoglide_env.instruments.gauges import Gauge
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


def pose_report(machine: MachineParams, rho: np.ndarray, *, noise_free: bool = False,
                seed: int | None = None, sigma: float = DEFAULT_SIGMA,
                resolution: float = DEFAULT_RESOLUTION) -> dict:
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
    status = [Status(s).name.lower().replace("_", "-") for s in status_of(gauges, t)]
    return {"tcp": tcp.tolist(), "tcp_model": tcp_model.tolist(), "loop_residual_mm": residual,
            "platform_rotation_rad": rotation, "gauges": _gauges(gauges, readings, status)}


def _gauges(gauges: list[Gauge], readings: np.ndarray, status: list[str]) -> list[dict]:
    """The report's ``gauges``: each gauge's leg, axis, reading (mm, None when not valid),
    validity and status."""
    return [{"leg": LEG_NAMES[g.spec.leg], "axis": AXIS_NAMES[g.spec.axis],
             "reading": None if np.isnan(r) else float(r), "valid": bool(np.isfinite(r)),
             "status": s} for g, r, s in zip(gauges, readings, status, strict=True)]


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
    return {"tcp": tcp.tolist(), "tcp_model": out["exact"][1].tolist(),
            "loop_residual_mm": out["residual"], "platform_rotation_rad": out["rotation"],
            "conditions": conditions.to_dict(), "world": world.to_dict(),
            "gauges": _gauges(gauges, np.where(obs["valid"], obs["gauges"], np.nan),
                              ["valid" if v else "not-valid" for v in obs["valid"]])}


def render_png(machine: MachineParams, rho: np.ndarray, out_path: str | Path, *, width: int = 960,
               height: int = 720) -> Path:
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


def project(points: np.ndarray, eye: np.ndarray, target: np.ndarray, fov: float,
            width: int, height: int) -> np.ndarray:
    """Pixel coordinates (column, row) of world ``points`` (..., 3) (mm) in the image of a
    camera at ``eye`` aimed at ``target``, world z up, vertical field of view ``fov``
    (deg): the pinhole model of :meth:`OrthoglideMachine.render`."""
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = np.asarray(points, dtype=float) - eye
    depth = d @ forward
    scale = np.tan(np.radians(fov) / 2) * depth
    x = (d @ right) / (scale * width / height)
    y = (d @ up) / scale
    return np.stack([(x + 1) / 2 * width, (1 - y) / 2 * height], axis=-1)


def draw_world_axes(axes: Any, eye: np.ndarray, target: np.ndarray, fov: float,
                    width: int, height: int) -> None:
    """The world axes as a triad in the lower left corner of ``axes``, an image of the
    camera at ``eye`` aimed at ``target`` (:func:`project`'s): a sheet's signs are along
    them."""
    ends = project(np.vstack([np.zeros(3), 100 * np.eye(3)]), eye, target, fov, width,
                   height)
    corner = np.array([70.0, height - 70.0])
    for k, name in enumerate(AXIS_NAMES):
        tip = corner + (ends[k + 1] - ends[0]) / np.linalg.norm(ends[k + 1] - ends[0]) * 50
        axes.annotate("", tip, xytext=corner, arrowprops={"arrowstyle": "->", "lw": 2})
        axes.text(*(corner + (tip - corner) * 1.3), f"+{name}", fontsize=12, ha="center",
                  va="center")


def render_stands_png(machine: MachineParams, specs: list, labels: list[str],
                      out_path: str | Path, *, highlight: int | None = None,
                      title: str = "", width: int = 960, height: int = 720) -> Path:
    """A PNG picture of ``machine`` at Zero with gauge stands at ``specs``, each tip
    marked and labelled with ``labels`` (the stand ``highlight`` in red, larger): what a
    technician looks at to find where a stand goes."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    from orthoglide_env.sim.pybullet import square_on_camera

    sim = OrthoglideMachine(machine, install(list(specs), machine))
    try:
        sim.move(np.zeros(3))
        frame = sim.render(width, height)
        tips = np.array([g.origin + t * g.direction
                         for g, t in zip(sim.gauges, sim.gauge_distances(), strict=True)])
    finally:
        sim.close()
    eye, target, fov = square_on_camera(width / height, machine.design)
    pixels = project(tips, eye, target, fov, width, height)
    figure = plt.figure(figsize=(width / 100, height / 100), dpi=100)
    try:
        axes = figure.add_axes((0, 0, 1, 1))
        axes.imshow(frame)
        axes.set_axis_off()
        centre = np.array([width / 2, height / 2])
        for k, ((u, v), label) in enumerate(zip(pixels, labels, strict=True)):
            mine = k == highlight
            # Labels sit outward from the image's centre, away from the machine's middle.
            away = np.array([u, v]) - centre
            away = away / max(np.linalg.norm(away), 1.0) * (90 if mine else 60)
            axes.annotate(label, (u, v), xytext=(u + away[0], v + away[1]),
                          color="red" if mine else "navy", fontsize=14 if mine else 10,
                          fontweight="bold" if mine else "normal", ha="center",
                          bbox={"boxstyle": "round", "fc": "white", "alpha": 0.85},
                          arrowprops={"arrowstyle": "->", "lw": 2.5 if mine else 1.2,
                                      "color": "red" if mine else "navy"})
        draw_world_axes(axes, eye, target, fov, width, height)
        if title:
            axes.text(10, 24, title, fontsize=13, color="black",
                      bbox={"fc": "white", "alpha": 0.85})
        out_path = Path(out_path)
        out_path.parent.mkdir(parents=True, exist_ok=True)
        figure.savefig(out_path, dpi=100)
    finally:
        plt.close(figure)
    return out_path
