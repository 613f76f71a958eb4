"""Which effect families carry a misjudged world's excess of z^2, and can the readings see them.

    python benchmarks/world_excess.py --truth workshop --agent optimal --told lab
                                      [--machines 50] [--seed 1] [--sigma 0.02]
                                      [--budget 3600] [--episodes DIR] [--scale EFFECT=K]
                                      [--instruments LIST] [--effects LIST]
                                      [--zero LIST [--zero LIST ...]]

The experiments of ``misjudged_world.py`` (the same episodes, kept in ``--episodes``) are
fitted by ``full`` told ``--told`` with the world check on.  Beside the measured row it
prints, for each named world harsher than the told one, what the fit's blind-spot
analysis (:func:`calibrators.estimators.world_sizes.blind_spot`) weighed on the machines
where the world test was silent: the z-RMS it predicts there (the median over machines of
``sqrt(1 + sum of the families' excesses of z^2)``), and per family the mean excess of
``z^2``, the median factor and the world test's power against the family at that world's
size (median and largest).  The analysis predicts the excess over error bars that are
honest in the told world; what the fit shows told the truth is the other row to read
beside it.

``--scale EFFECT=K`` multiplies the second moments of one effect's table rows in the
fit's terms by K, ``--scale EFFECT.PARAMETER=K`` of one row (an experiment on the fit's
model of that effect, not an option of the tool): it asks how far the fit's own model of
the effect falls short of what acts.

``--effects LIST`` has only those effects of ``--truth`` act in the played world (as
``compare --effects``), the fit still told all of ``--told``'s: switched off one at a
time, they split the measured excess of z^2 by effect.  The agent still plans for all of
``--truth``'s effects (an experiment, not a lab: a planner told the world it plays in
would plan other operations), so every row reads the same operations and the rows are
paired.  ``--instruments`` names what the
lab owns (``misjudged_world.py --instruments``).

``--zero LIST`` (repeatable) plays each machine again with those effects' drawn values set
to zero (:data:`DRAWN`), every other draw as before: the same machine, the same other
effects and the same plan (its planner is told all of ``--truth``'s effects either way),
so each row pairs with the one where all of them act.  ``--effects`` cannot do that: an
effect switched off moves the stream every later one is drawn from.  Each row gives the
TCP error after rigid motion (median, RMS over machines), the fit's own predicted error
(RMS over machines), the z-RMS, and per machine its error over the one with every effect
(median with its 95 % interval, lower on how many).
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import numpy as np
from misjudged_world import owned, played, row

import calibrators.agents.active as active
import calibrators.agents.optimal as optimal
import calibrators.estimators.consider as consider
import calibrators.estimators.gauss_newton as gauss_newton
from calibrators.estimators.catalogue import for_study
from calibrators.estimators.consider import TERM_FAMILIES
from calibrators.study.compare import Config, agent_episodes, scored_trials
from calibrators.study.statistics import paired
from calibrators.study.trials import Trial
from orthoglide_env.world.conditions import CONDITION_NAMES, EFFECT_NAMES, Conditions
from orthoglide_env.world.table import EFFECTS
from orthoglide_env.world.truth import World

#: Each effect's values that a played world draws (:meth:`World.draw`, a re-mount's
#: :meth:`World.mounted`), which ``--zero`` sets to zero; the other effects' sizes are the
#: table's fixed values.
DRAWN: dict[str, tuple[str, ...]] = {
    "lead": ("lead_scale", "lead_a1", "lead_a2", "lead_periodic"),
    "backlash": ("backlash",),
    "warmup": ("warm_amplitude",),
    "room": ("offset", "rate", "walk"),
    "dial": ("dial_range", "dial_revolution", "retrace"),
    "stands": ("creep", "thermal"),
}


def scaled_effect(spec: str) -> tuple[str, str | None, float]:
    """``EFFECT=K`` or ``EFFECT.PARAMETER=K`` as (effect, parameter or None, K);
    ``argparse.ArgumentTypeError`` on anything else."""
    name, _, factor = spec.partition("=")
    effect, _, parameter = name.partition(".")
    try:
        k = float(factor)
    except ValueError:
        k = float("nan")
    if (effect not in EFFECT_NAMES or not k > 0
            or (parameter and parameter not in EFFECTS[effect])):
        raise argparse.ArgumentTypeError(f"--scale wants EFFECT=K or EFFECT.PARAMETER=K with "
                                         f"EFFECT one of {list(EFFECT_NAMES)}, a row of its "
                                         f"table and K > 0, got {spec!r}")
    return effect, parameter or None, k


def effect_list(text: str) -> tuple[str, ...]:
    """``--effects``: effect names, comma-separated; ``argparse.ArgumentTypeError`` naming
    an unknown one."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [n for n in names if n not in EFFECT_NAMES]
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown effect(s) {unknown}; effects are "
                                         f"{', '.join(EFFECT_NAMES)}")
    return names


def plan_as_told(world: Conditions) -> None:
    """From here on, ``optimal`` and ``active`` plan as told ``world`` whatever lab they
    play in (an experiment, not a lab): rows whose played worlds differ then read the
    same operations."""
    setup = optimal.lab_setup

    def planned(*given):  # type: ignore[no-untyped-def]
        return (*setup(*given)[:-1], world)

    optimal.lab_setup = active.lab_setup = planned


def z_rms(trials: list[Trial]) -> float:
    """The pooled z-RMS of the trials whose fit did not fail."""
    return float(np.sqrt(np.mean(np.concatenate([t.z for t in trials if not t.failed])**2)))


def drawn_list(text: str) -> tuple[str, ...]:
    """``--zero``: effects whose drawn values are set to zero, comma-separated;
    ``argparse.ArgumentTypeError`` naming one that draws nothing."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    wrong = [n for n in names if n not in DRAWN]
    if not names or wrong:
        raise argparse.ArgumentTypeError(f"--zero takes effects of {', '.join(DRAWN)}, "
                                         f"got {text!r}")
    return names


@contextmanager
def zeroed(effects: tuple[str, ...]) -> Iterator[None]:
    """Within it, every world drawn has ``effects``' values at zero (the streams drawn as
    with them, so every other value is the same)."""
    draw, mounted = vars(World)["draw"], vars(World)["mounted"]

    def without(world: World) -> World:
        return world.replace(**{f: np.zeros_like(np.asarray(getattr(world, f)))
                                for e in effects for f in DRAWN[e]})

    World.draw = classmethod(lambda cls, *a, **k: without(draw.__func__(cls, *a, **k)))
    World.mounted = lambda self, *a, **k: without(mounted(self, *a, **k))
    try:
        yield
    finally:
        World.draw, World.mounted = draw, mounted


def zeroed_rows(config: Config, agent: str, machines: int, told: str,
                variants: list[tuple[str, ...]]) -> None:
    """Print the agent's row with every effect of ``config`` and with each of
    ``variants``' effects zeroed (:func:`zeroed`), fitted by ``full`` told ``told``, each
    paired per machine with the first."""
    def trials(effects: tuple[str, ...]) -> list[Trial]:
        with zeroed(effects):
            episodes = agent_episodes(config, agent, list(range(machines)))
        fit = for_study("full", episodes[0].run.sigma, Conditions(told), "realistic")
        named = agent + "".join(f" -{e}" for e in effects)
        return [replace(t, agent=named) for t in scored_trials(
            episodes, "full", fit.fit_many([e.run.measurements for e in episodes]))]

    first = trials(())
    for effects in [(), *variants]:
        rows = first if not effects else trials(effects)
        ok = [t for t in rows if not t.failed]
        rigid = np.array([t.tcp_after["rigid"] for t in rows]) * 1e3
        predicted = np.array([t.predicted_rigid_mm for t in ok]) * 1e3
        line = (f"{rows[0].agent}: {np.median(rigid):.3f} um, RMS {np.sqrt(np.mean(rigid**2)):.3f}"
                f", predicted RMS {np.sqrt(np.mean(predicted**2)):.3f}, z-RMS "
                f"{z_rms(rows):.2f}, failed {len(rows) - len(ok)}")
        if effects:
            pair = paired(rows + first)[0]
            low, high = pair["ratio_ci95"] or (np.nan, np.nan)
            line += (f"; per machine {pair['ratio_median']:.3f} [{low:.3f}, {high:.3f}], "
                     f"lower on {pair['win_rate']:.0%} of {pair['machines']}")
        print(line, flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--truth", choices=CONDITION_NAMES, default="workshop")
    parser.add_argument("--agent", default="optimal")
    parser.add_argument("--told", choices=CONDITION_NAMES, default="lab")
    parser.add_argument("--machines", type=int, default=50)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--sigma", type=float, default=0.02)
    parser.add_argument("--budget", type=float, default=3600.0)
    parser.add_argument("--episodes", type=Path, default=None,
                        help="the folder where misjudged_world.py keeps its episodes")
    parser.add_argument("--scale", type=scaled_effect, default=None,
                        help="EFFECT=K or EFFECT.PARAMETER=K: those second moments "
                        "times K in the fit")
    parser.add_argument("--instruments", type=owned, default=(),
                        help="what the lab owns, comma-separated (default: the dial gauges)")
    parser.add_argument("--effects", type=effect_list, default=None,
                        help="only these effects of --truth act in the played world")
    parser.add_argument("--zero", type=drawn_list, action="append", default=[],
                        help="these effects' drawn values at zero, every other draw the "
                        "same (repeatable: one paired row each)")
    args = parser.parse_args()
    if args.zero:
        if args.effects is not None or args.scale is not None:
            parser.error("--zero takes neither --effects nor --scale")
        zeroed_rows(Config(agents=(args.agent,), estimators=("full",),
                           conditions=Conditions(args.truth), seed=args.seed,
                           sigma=args.sigma, budget_s=args.budget,
                           instruments=args.instruments),
                    args.agent, args.machines, args.told, args.zero)
        return
    truth = Conditions(args.truth, effects=args.effects)
    if args.effects is not None:
        plan_as_told(Conditions(args.truth))
    config = Config(agents=(args.agent,), estimators=("full",), conditions=truth,
                    seed=args.seed, sigma=args.sigma, budget_s=args.budget,
                    instruments=args.instruments)
    episodes = played(config, args.agent, args.machines, args.episodes)
    if args.scale is not None:
        effect, parameter, k = args.scale
        moment = consider.second_moment
        consider.second_moment = (lambda e, p, c: moment(e, p, c) * (
            k if e == effect and parameter in (None, p) else 1.0))
    weighed: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    words = gauss_newton.blind_spot

    def recorded(told: str, harsher: str, families: tuple[str, ...], factors: np.ndarray,
                 power: np.ndarray) -> str | None:
        weighed.setdefault(harsher, []).append((factors.copy(), power.copy()))
        return words(told, harsher, families, factors, power)

    gauss_newton.blind_spot = recorded
    # The world test sizes the gauges' terms only: with other instruments it is left out,
    # and the measured row is all there is to read.
    r = row(args.truth, args.agent, args.told, episodes, episodes[0].run.sigma,
            world_check=set(args.instruments) <= {"dial"})
    low, high = r["z_ci95"]
    scale = "" if args.scale is None else (
        f", {'.'.join(n for n in args.scale[:2] if n)} second moments x{args.scale[2]:g}")
    print(f"truth {truth.label}, {args.agent}, told {args.told}{scale}, {r['machines']} "
          f"machines: z-RMS {r['z_rms']:.2f} [{low:.2f}, {high:.2f}], world test flags "
          f"{r['warned'] - r['blind']:.2f}, blind spot {r['blind']:.2f}")
    for harsher, rows in weighed.items():
        factors = np.array([f for f, _ in rows])
        power = np.array([p for _, p in rows])
        predicted = np.sqrt(1.0 + np.sum(factors**2 - 1.0, axis=1))
        print(f"  against {harsher}, {len(rows)} machines the test left silent: predicted "
              f"z-RMS {np.median(predicted):.2f}")
        for f, family in enumerate(TERM_FAMILIES):
            print(f"    {family:9} excess of z^2 {np.mean(factors[:, f]**2 - 1):6.3f}  factor "
                  f"{np.median(factors[:, f]):.3f}  power {np.median(power[:, f]):.3f} "
                  f"(largest {power[:, f].max():.3f})")


if __name__ == "__main__":
    main()
