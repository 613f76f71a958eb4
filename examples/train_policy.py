"""Train stable-baselines3's PPO on the lab, off the shelf.

    pip install -e '.[rl]'
    python examples/ppo_lab.py [--steps 2000] [--reward information] [--out policy.zip]

``OrthoglideLabFlat-v0`` is the lab env with one Box of actions and one of observations,
so ``PPO("MlpPolicy", env)`` trains on it without custom code.  This script only shows
that it runs and how fast; a policy worth comparing with the designed agents needs far
more steps (the agents issue).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym

import orthoglide_env


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--reward", default="information",
                        choices=["time", "information"])
    parser.add_argument("--budget", type=float, default=1800.0, help="lab seconds per episode")
    parser.add_argument("--out", default=None, help="save the trained policy here")
    args = parser.parse_args()
    from stable_baselines3 import PPO

    env = gym.make(orthoglide_env.FLAT_LAB_ENV_ID, reward=args.reward, budget_s=args.budget,
                   gauge_sigma=0.01)
    model = PPO("MlpPolicy", env, n_steps=256, batch_size=64, seed=0, verbose=0)
    start = time.perf_counter()
    model.learn(total_timesteps=args.steps)
    seconds = time.perf_counter() - start
    print(f"PPO: {args.steps} steps of {orthoglide_env.FLAT_LAB_ENV_ID} ({args.reward} reward) "
          f"in {seconds:.1f} s ({args.steps / seconds:.0f} steps/s)")
    if args.out:
        model.save(args.out)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
