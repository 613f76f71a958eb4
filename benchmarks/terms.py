"""Which of the lab's terms each instrument sees: the ``full`` estimator's posterior
against its prior, per family of terms, and what the drives' lead error left costs.

    python benchmarks/terms.py [--machines 5] [--agents paper,optimal,tracker]
                               [--conditions lab] [--seed 1] [--sigma 0.02]
                               [--resolution 0.01] [--instruments dial,interferometer]
                               [--budget 3600]

Per agent (each its experiment of ``--budget`` seconds under the conditions, the
``realistic`` preset), per family of terms
(:data:`calibrators.estimators.consider.TERM_FAMILIES`): the share of the prior's
variance the readings remove, ``1 - trace(posterior) / trace(prior)`` over the family's
coefficients (each has a unit prior), median over the machines.  Near 1 the instrument
identifies the family, near 0 nothing sees it; the dial family is considered, not fitted,
and so is the periodic one unless an interferometer read (a share of 0, or "-", by
construction).  The pitch table's coefficients whiten its prior, so that share weighs
a direction the prior allows a nanometre as much as one it allows microns; the column
``lead um2`` gives the share of the lead error's variance itself, over the table's
nodes: ``1 - trace(R C R^T) / trace(R R^T)`` with ``R`` the table's prior root and ``C``
the coefficients' posterior.  Then the predicted TCP error after rigid motion (um) with
and without the drives' part: the linearised cost of the lead error the fit leaves,
against the truth's error after compensation.  ``--instruments`` names what the lab owns
(an agent such as ``iso230-2`` needs the interferometer).
"""

from __future__ import annotations

import argparse
import sys

import gymnasium as gym
import numpy as np

from calibrators.agents import get_agent
from calibrators.estimators.base import Estimate
from calibrators.estimators.consider import (
    FULL_TERMS,
    TABLE_TERM,
    WORLD_PREFIX,
    table_prior,
    term_family,
)
from calibrators.estimators.gauss_newton import GaussNewtonCalibrator
from calibrators.estimators.prediction import predicted_tcp_error
from calibrators.study.episodes import machine_seed, run_episode
from calibrators.study.labs import lab_id, lab_kwargs
from orthoglide_env.instruments.catalogue import check_instruments
from orthoglide_env.instruments.dial import DEFAULT_RESOLUTION, DEFAULT_SIGMA
from orthoglide_env.lab.operations import DEFAULT_BUDGET_S
from orthoglide_env.model.errors import AXIS_NAMES
from orthoglide_env.scoring import score
from orthoglide_env.world.conditions import Conditions

UM = 1e3  # per mm


def lead_variance_share(est: Estimate) -> float:
    """The share of the lead error's prior variance over the pitch table's nodes that the
    fit removed (NaN without a fitted table)."""
    conditions = Conditions.from_dict(est.conditions) if est.conditions else None
    if conditions is None or est.node_spacing is None:
        return float("nan")
    _, root = table_prior(est.machine.design, conditions, est.node_spacing)
    removed, prior = 0.0, 0.0
    for axis in AXIS_NAMES:
        idx = [k for k, name in enumerate(est.names)
               if name.startswith(f"{WORLD_PREFIX}{TABLE_TERM}")
               and name.endswith(f"[{axis}]")]
        if len(idx) != root.shape[1]:
            return float("nan")
        posterior = est.covariance[np.ix_(idx, idx)]
        removed += float(np.trace(root @ posterior @ root.T))
        prior += float(np.trace(root @ root.T))
    return 1.0 - removed / prior


def shares(est: Estimate) -> dict[str, float]:
    """Per fitted family, the share of its prior variance the fit removed."""
    out: dict[str, list[float]] = {}
    for k, name in enumerate(est.names):
        if name.startswith(WORLD_PREFIX):
            family = term_family(name[len(WORLD_PREFIX):])
            out.setdefault(family, []).append(float(est.covariance[k, k]))
    return {f: 1.0 - float(np.mean(v)) for f, v in out.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, default=5)
    parser.add_argument("--agents", default="paper,optimal,tracker")
    parser.add_argument("--conditions", default="lab")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--sigma", type=float, default=DEFAULT_SIGMA,
                        help="the gauges' reading sigma (mm, default %(default)s)")
    parser.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION,
                        help="the dials' resolution (mm, default %(default)s)")
    parser.add_argument("--budget", type=float, default=DEFAULT_BUDGET_S,
                        help="each experiment's lab time (s, default %(default)s)")
    parser.add_argument("--instruments", default=None,
                        help="what the lab owns, comma-separated (default: the dial gauges "
                        "and the tracker for an agent that reads one)")
    args = parser.parse_args()
    if not args.sigma > 0:
        parser.error(f"--sigma must be positive (mm), got {args.sigma}")
    if not args.resolution >= 0:
        parser.error(f"--resolution must be 0 or more (mm), got {args.resolution}")
    try:
        owned = () if args.instruments is None else check_instruments(
            args.instruments.split(","))
        for name in args.agents.split(","):
            lab_kwargs(get_agent(name), owned)
    except ValueError as exc:
        parser.error(str(exc))
    fit = GaussNewtonCalibrator(params="full", verify=False, explain=False,
                                conditions=args.conditions)
    print(f"{args.conditions}, {args.machines} machines, seed {args.seed}, budget "
          f"{args.budget:g} s, instruments {args.instruments or 'dial'}, gauge sigma "
          f"{args.sigma} mm read to {args.resolution} mm: share of each "
          f"family's prior variance the full fit removes (median), predicted TCP rigid "
          f"(um) with / without the drives' part, and the true one")
    width = max(10, *(len(a) + 1 for a in args.agents.split(",")))
    families = (*FULL_TERMS, "periodic")
    print(f"{'agent':{width}}" + "".join(f"{f:>10}" for f in families)
          + f"{'lead um2':>10}{'pred':>8}{'geom':>8}{'true':>8}")
    for agent_name in args.agents.split(","):
        agent = get_agent(agent_name)
        rows: dict[str, list[float]] = {}
        predicted, geometric, true, physical = [], [], [], []
        kwargs = lab_kwargs(agent, owned, backend="exact", conditions=args.conditions,
                            errors="realistic", gauge_sigma=args.sigma, budget_s=args.budget,
                            gauge_resolution=args.resolution)
        for m in range(args.machines):
            env = gym.make(lab_id(kwargs), **kwargs)
            try:
                episode = run_episode(env, agent, machine_seed(args.seed, m))
            finally:
                env.close()
            est = fit.clone(sigma=episode.sigma).fit(episode.measurements)
            for family, value in shares(est).items():
                rows.setdefault(family, []).append(value)
            physical.append(lead_variance_share(est))
            predicted.append(predicted_tcp_error(est).rigid.rms * UM)
            geometry = Estimate.from_dict({**est.to_dict(), "lead_terms": []})
            geometric.append(predicted_tcp_error(geometry).rigid.rms * UM)
            true.append(score(est.machine, episode.truth, world=episode.world,
                              correction=est.lead_correction if est.fits_lead else None
                              ).tcp_after.rigid.rms * UM)
            print(f"  {agent_name} machine {m + 1}/{args.machines}", file=sys.stderr)
        print(f"{agent_name:{width}}" + "".join(
            f"{np.median(rows[f]):10.2f}" if f in rows else f"{'-':>10}" for f in families)
            + f"{np.median(physical):10.3f}"
            + f"{np.median(predicted):8.1f}{np.median(geometric):8.1f}{np.median(true):8.1f}")


if __name__ == "__main__":
    main()
