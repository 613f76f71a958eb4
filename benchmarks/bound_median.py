"""The bound's median beside its RMS: what a median over machines is to be held against.

    python benchmarks/bound_median.py [--conditions lab] [--budget 3600]
                                      [--instruments dial,ballbar] [--warm-bins 0]

The bound (:mod:`calibrators.planning.bound`) is an expectation: its square is the
predicted mean-square TCP error after rigid motion, ``trace(W C)``, over machines drawn
from the prior, so it is an RMS over machines.  A row's median over machines is not:
on the linearised model a machine's squared error is ``z' L z`` with ``z`` standard normal
and ``L`` the eigenvalues of ``F' C F``, a weighted chi-square whose median is below its
mean.  This prints, for the bound's best design (and with ``--warm-bins K`` the design of
the bound with the timed terms unknown, :mod:`calibrators.planning.warm_bound`) and for
``optimal``'s kept plan (:func:`calibrators.agents.optimal.fixed_plan`, its readings
counted on the bound's model), the RMS, the median and 95th percentile over 200,000
machines of the model, and the median over the RMS: the bound's own median is the bound
times its design's.  The prototype, dial sigma 0.02
mm, resolution 0.01 mm, the paper's stands; no lab episodes.
"""

from __future__ import annotations

import argparse

import numpy as np
from plan_gap import lab_arguments, lab_options
from scipy.linalg import cho_factor, cho_solve

from calibrators.agents.optimal import fixed_plan
from calibrators.planning.bound import BoundModel, best_design, lab_model, plan_counts
from calibrators.planning.instruments import step_actions
from calibrators.planning.warm_bound import warm_design
from orthoglide_env.instruments.dial import GaugeNoise, weighting_sigma
from orthoglide_env.lab.operations import PAPER_SLOTS
from orthoglide_env.model.design import PROTOTYPE

UM = 1e3  # per mm
#: Machines drawn from the model per design: the median's sampling error is then about
#: 0.3 % of it (its standard error is sqrt(p (1 - p) / n) over the density there).
MACHINES: int = 200_000


def spread(models: list[BoundModel], counts: np.ndarray) -> tuple[float, float, float]:
    """The RMS, median and 95th percentile (mm) of the TCP error after rigid motion over
    machines of the model fitted with ``counts`` (K, N) readings of ``models``' candidates
    (one model per bin of time)."""
    information = sum(m.information(c) for m, c in zip(models, counts, strict=True))
    factor = models[0].factor
    covariance_f = cho_solve(cho_factor(np.eye(len(information)) + information), factor)
    weights = np.clip(np.linalg.eigvalsh(factor.T @ covariance_f), 0.0, None)
    draws = np.random.default_rng(1).standard_normal((MACHINES, len(weights)))
    errors = np.sqrt((draws**2) @ weights)
    return (float(np.sqrt(weights.sum())), float(np.median(errors)),
            float(np.quantile(errors, 0.95)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    lab_arguments(parser)
    args = parser.parse_args()
    owned, conditions = lab_options(parser, args)
    sigma = float(weighting_sigma(GaugeNoise(0.02, 0.01).effective_sigma))
    found = best_design(PROTOTYPE, conditions, sigma, args.budget, owned)
    model = lab_model(PROTOTYPE, conditions, sigma, args.budget, owned, len(PAPER_SLOTS))
    rows = [("the bound", found.bound.bound_mm, [model], found.counts[None])]
    if args.warm_bins:
        held, warm = warm_design(PROTOTYPE, conditions, sigma, args.budget, owned,
                                 bins=args.warm_bins)
        rows.append((f"with the warm-up unknown ({args.warm_bins} bins)", held.bound.bound_mm,
                     list(warm.models), held.counts))
    slots, engaged = tuple(PAPER_SLOTS), (True,) * len(PAPER_SLOTS)
    steps, _ = fixed_plan(slots, engaged, sigma, args.budget, PROTOTYPE, conditions,
                          instruments=tuple(n for n in owned if n != "dial"), warm_judged=True)
    rows.append(("`optimal`'s kept plan", np.nan, [model],
                 plan_counts(model, PROTOTYPE, slots, engaged, step_actions(steps))[None]))
    print("| bound or plan | certified µm | its design: RMS, median, p95 µm | median / RMS |")
    print("|---|---|---|---|")
    for name, certified, models, counts in rows:
        rms, median, p95 = spread(models, counts)
        bound = f"{UM * certified:.3f}" if np.isfinite(certified) else "-"
        print(f"| {name} | {bound} | {UM * rms:.3f}, {UM * median:.3f}, "
              f"{UM * p95:.3f} | {median / rms:.3f} |", flush=True)


if __name__ == "__main__":
    main()
