"""The pictures of a comparison: accuracy against lab time, and the spread per strategy."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calibrators.study.compare import Config, Trial

#: One line style per agent, so curves stay apart in grey print too.
STYLES: tuple[str, ...] = ("o-", "s--", "^-.", "D:", "v-", "P--", "X-.")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    return plt


def _save(plt, fig, ax, note: str, path: Path, **text) -> Path:
    """Finish a figure of TCP errors (log scale) with ``note`` below it, write ``path``."""
    ax.set_yscale("log")
    ax.set_ylabel("TCP error RMS after rigid motion (mm)")
    fig.text(0.01, 0.01, note, fontsize=7, **text)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def accuracy_vs_time(trials: list[Trial], config: Config, out: Path) -> Path:
    """Median TCP error after rigid motion against the lab time an agent had spent, one
    curve per agent (``config.curve_estimator``, re-estimated at quarters of its episode)."""
    plt = _pyplot()
    name = config.curve_estimator
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    for k, agent in enumerate(config.agents):
        curves = [t.curve for t in trials if t.agent == agent and t.estimator == name
                  and not t.failed and t.curve]
        if not curves:
            continue
        points = np.array(curves)  # (machines, points, 2)
        ax.plot(np.median(points[:, :, 0], axis=0) / 60, np.median(points[:, :, 1], axis=0),
                STYLES[k % len(STYLES)], label=agent)
    ax.set_xlabel("lab time spent (min)")
    ax.set_title(f"Accuracy against lab time ({name} estimator)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    return _save(plt, fig, ax, f"Median over {len({t.machine for t in trials})} machines "
                 f"({config.world}). Each point re-estimates from the readings taken so far.",
                 out / "accuracy_vs_time.png", wrap=True)


def boxes(trials: list[Trial], config: Config, out: Path) -> Path:
    """TCP error after rigid motion per agent x estimator, with the uncalibrated machines."""
    plt = _pyplot()
    before = [t.tcp_before["rigid"] for t in trials if not t.failed
              and t.agent == config.agents[0]]
    data, labels = [before], ["uncalibrated"]
    for agent in config.agents:
        for name in config.estimators:
            values = [t.tcp_after["rigid"] for t in trials
                      if t.agent == agent and t.estimator == name and not t.failed]
            if values:
                data.append(values)
                labels.append(f"{agent}\n{name}")
    fig, ax = plt.subplots(figsize=(max(6.0, 1.1 * len(data)), 4.8))
    ax.boxplot(data, tick_labels=labels)
    ax.set_title("Accuracy per agent x estimator")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    return _save(plt, fig, ax, f"{len({t.machine for t in trials})} machines "
                 f"({config.world}). Boxes: quartiles over machines, whiskers 1.5 IQR. Failed "
                 "estimates (an estimator that cannot read an agent's instrument) are left out.",
                 out / "boxes.png", wrap=True)
