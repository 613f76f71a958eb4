"""Estimators on the paper's experiment: what each makes of the same readings.

    python benchmarks/estimators.py [--machines 50] [--seed 0] [--write-docs]

Realistic machines (27 errors), gauges with sigma 0.01 mm and a 0.01 mm dial, installed
with the preset's stand errors; the paper's experiment (the ``paper`` agent: 7 postures, 6
mid-leg gauges, 3 repetitions) in the lab on the exact backend.  Four estimators read the
same readings:

* ``paper eq. 10``: the paper's linear fit of drho and dL;
* ``paper6 exact``: the exact model, drho and dL (Gauss-Newton);
* ``extended, base``: every machine error and gauge stand, no prior: the combinations the
  readings determine better than their a-priori scale are fitted, the others stay nominal;
* ``extended, prior``: the same with the realistic preset's sigmas as a prior (MAP).

Columns: the TCP error over the workspace grid after calibration, median over machines of
the RMS in the three frames (raw world frame, after the best-fit translation, after the
best-fit rigid motion: the headline, what a user who touches off the workpiece sees), the
rigid p95; ``z-RMS``: (estimate - truth) / reported std along the combinations the readings
identify (1 for an honest estimator; the paper's fit: per parameter, its own std); the
share of machines whose chi-square test rejects the model; the ratio of the predicted
rigid TCP error (from the covariance) to the real one, its median over machines and the
ratio of the root-mean-squares (a one-machine error is one draw, dominated by a few
combinations, so even an exact prediction has a median ratio above 1); fit time per
machine.
"""

from __future__ import annotations

import argparse
import re
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import orthoglide_env
from calibrators.agents import get_agent
from calibrators.estimators.base import Estimator
from calibrators.estimators.exact_fit import z_scores
from calibrators.estimators.gauss_newton import GaussNewtonCalibrator, layout_and_values
from calibrators.estimators.paper_linear import PaperCalibrator
from calibrators.estimators.prediction import predicted_tcp_error
from calibrators.study.episodes import run_episode
from orthoglide_env.reading_model import parameters_of
from orthoglide_env.scoring import FRAMES, score

ESTIMATORS: dict[str, Estimator] = {
    "paper eq. 10": PaperCalibrator(params="paper6", verify=False),
    "paper6 exact": GaussNewtonCalibrator(params="paper6", prior="none", verify=False),
    "extended, base": GaussNewtonCalibrator(params="extended", prior="none", verify=False),
    "extended, prior": GaussNewtonCalibrator(params="extended", prior="realistic",
                                             verify=False),
}
MARK = "<!-- estimators table -->"


def run(machines: int, seed: int) -> dict[str, dict[str, list[float]]]:
    env = gym.make(orthoglide_env.LAB_ENV_ID, errors="realistic", gauge_sigma=0.01,
                   conditions="ideal", gauge_resolution=0.01, backend="exact")
    results: dict[str, dict[str, list[float]]] = {name: {} for name in ESTIMATORS}
    for k in range(machines):
        episode = run_episode(env, get_agent("paper"), seed * 100_003 + k)
        data, truth_machine, sigma = episode.measurements, episode.truth, episode.sigma
        design, _ = layout_and_values(data)
        truth = parameters_of(design, truth_machine, env.unwrapped.true_gauges)
        for name, estimator in ESTIMATORS.items():
            start = time.perf_counter()
            est = estimator.clone(sigma=sigma).fit(data)
            seconds = time.perf_counter() - start
            scored = score(est.machine, truth_machine).tcp_after
            free = [est.space.index(n) for n in est.names]
            if est.information.size:
                z = z_scores(est.theta[free], truth[free], est.covariance, est.information,
                             est.scale)
            else:
                z = (est.theta[free] - truth[free]) / np.sqrt(np.diag(est.covariance))
            row = results[name]
            for frame in FRAMES:
                row.setdefault(frame, []).append(getattr(scored, frame).rms)
            row.setdefault("z2", []).extend(np.square(z))
            row.setdefault("misfit", []).append(np.nan if est.chi2 is None
                                                else est.covariance_scale > 1)
            row.setdefault("predicted", []).append(predicted_tcp_error(est).rigid.rms)
            row.setdefault("seconds", []).append(seconds)
        print(f"\rmachine {k + 1}/{machines}", end="", flush=True)
    print()
    env.close()
    return results


def table(results: dict[str, dict[str, list[float]]], machines: int) -> str:
    lines = [
        f"| estimator ({machines} realistic machines, sigma 0.01 mm) | TCP after, rigid "
        "(headline) | raw | translation | rigid p95 | z-RMS | chi-square rejects | "
        "predicted / real (rigid): median, RMS | fit time |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, row in results.items():
        predicted, real = np.array(row["predicted"]), np.array(row["rigid"])
        rejects = "no test" if np.isnan(row["misfit"]).all() else f"{np.mean(row['misfit']):.0%}"
        lines.append(
            f"| {name} | {np.median(row['rigid']):.4f} mm | {np.median(row['raw']):.3f} mm | "
            f"{np.median(row['translation']):.3f} mm | {np.percentile(row['rigid'], 95):.4f} mm"
            f" | {np.sqrt(np.mean(row['z2'])):.2f} | {rejects} | "
            f"{np.median(predicted / real):.2f}, "
            f"{np.sqrt(np.mean(predicted**2) / np.mean(real**2)):.2f} | "
            f"{1e3 * np.median(row['seconds']):.0f} ms |")
    return "\n".join(lines)


def write_page(text: str, page: Path) -> None:
    """Replace the table between the two markers of the measured results' page."""
    content = page.read_text()
    pattern = re.compile(f"{re.escape(MARK)}.*?{re.escape(MARK)}", re.S)
    if not pattern.search(content):
        raise SystemExit(f"{page} has no pair of '{MARK}' markers")
    page.write_text(pattern.sub(lambda _: f"{MARK}\n{text}\n{MARK}", content))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--write-docs", action="store_true",
                        help="put the table into docs/benchmarks.md between its markers")
    args = parser.parse_args()
    start = time.perf_counter()
    results = run(args.machines, args.seed)
    text = table(results, args.machines)
    print(text)
    print(f"{time.perf_counter() - start:.0f} s")
    if args.write_docs:
        write_page(text, Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md")


if __name__ == "__main__":
    main()
