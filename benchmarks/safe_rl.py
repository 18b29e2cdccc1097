"""Safe RL: what a lidar safety shield saves and costs while PPO learns GoToGoal.

Trains stable-baselines3 PPO on ``safenav/GoToGoal-v0`` twice per seed, with the same seed,
budget and hyper-parameters: once unshielded, once behind ``SafetyShield(env, "cbf")``. The
agent acts in ``[-1, 1]^2`` (``RescaleAction`` maps it onto the robot's ``(v, omega)`` limits, in
front of the shield) and sees the flattened observation (``FlattenObservation``). It reports

* collisions during training (total, and per 10k steps) and how many training episodes
  reached the goal;
* the final policy evaluated without exploration noise (``deterministic=True``) on the same
  held-out episodes (seeds 100000 + i), both with and without the shield: success rate, mean
  return (the environment's reward, without any shield penalty), collisions;
* wall time of every training run;

and draws cumulative collisions and the training success rate against steps
(``--plot``, by default ``docs/images/safe_rl.png``). Needs the ``rl`` extra
(``pip install "safenav[rl]"``: gymnasium, stable-baselines3 and torch); not part of CI.

Run (the numbers in BENCHMARKS.md; four training runs of 850-1800 s each on the shared 2-core machine)::

    nice python -m benchmarks.safe_rl --steps 200000 --seeds 0 1 --json safe_rl.json
    python benchmarks/safe_rl.py --quick          # a 4k-step smoke run
    python benchmarks/safe_rl.py --env-picture docs/images/safe_rl_env.png   # the picture of the environment
    python benchmarks/safe_rl.py --from-json safe_rl.json                   # table and plot of a saved run
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

if __package__ in (None, ""):  # run as `python benchmarks/safe_rl.py`: import this checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from benchmarks.common import markdown_table, write_json
from safenav._checks import argument_type, integer
from safenav._optional import require
from safenav.robot import PRESET_NAMES

positive_int = argument_type(integer, low=1)

ENV_ID = "safenav/GoToGoal-v0"
EVAL_SEED = 100_000
"""Evaluation episodes use seeds EVAL_SEED + i, never seen in training."""
BIN_STEPS = 10_000
"""Width of the bins of the per-10k-steps rates [steps]."""


@dataclass
class TrainingLog:
    """What happened in the training episodes of one run, episode by episode."""

    end_steps: list[int] = field(default_factory=list)
    collided: list[bool] = field(default_factory=list)
    succeeded: list[bool] = field(default_factory=list)
    intervened_steps: int = 0
    safety_change: float = 0.0
    steps: int = 0


def make_env(robot: str, shielded: bool, info_scan: bool = False) -> Any:
    """GoToGoal for ``robot``, optionally shielded by the CBF, with actions in ``[-1, 1]^2`` and a flat observation."""
    gymnasium = require("gymnasium", extra="rl", purpose="the safe-RL benchmark")
    import safenav.gym

    env = gymnasium.make(ENV_ID, robot=robot, info_scan=info_scan)
    if shielded:
        env = safenav.gym.SafetyShield(env, "cbf")
    unit = np.ones(2, dtype=np.float32)
    env = gymnasium.wrappers.RescaleAction(env, -unit, unit)
    return gymnasium.wrappers.FlattenObservation(env)


def _callback(log: TrainingLog) -> Any:
    callbacks = require("stable_baselines3.common.callbacks", extra="rl", purpose="the safe-RL benchmark",
                        package="stable-baselines3")

    class Recorder(callbacks.BaseCallback):
        def _on_step(self) -> bool:
            for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
                log.steps += 1
                change = info["shield"]["safety_change"] if "shield" in info else 0.0
                log.intervened_steps += change > 1e-6
                log.safety_change += change
                if done:
                    log.end_steps.append(self.num_timesteps)
                    log.collided.append(bool(info["collision"]))
                    log.succeeded.append(bool(info.get("is_success", False)))
            return True

    return Recorder()


def train(robot: str, shielded: bool, seed: int, steps: int, n_envs: int) -> tuple[Any, TrainingLog, float]:
    """PPO on GoToGoal; returns the model, the training log and the wall time [s]."""
    torch = require("torch", extra="rl", purpose="the safe-RL benchmark")
    sb3 = require("stable_baselines3", extra="rl", purpose="the safe-RL benchmark", package="stable-baselines3")
    from stable_baselines3.common.vec_env import DummyVecEnv

    torch.set_num_threads(1)
    vector = DummyVecEnv([lambda: make_env(robot, shielded)] * n_envs)
    vector.seed(seed)
    model = sb3.PPO("MlpPolicy", vector, n_steps=2048 // n_envs, batch_size=256, seed=seed, device="cpu", verbose=0)
    log = TrainingLog()
    start = time.perf_counter()
    model.learn(total_timesteps=steps, callback=_callback(log))
    wall = time.perf_counter() - start
    vector.close()
    return model, log, wall


def evaluate(model: Any, robot: str, shielded: bool, episodes: int) -> dict[str, float]:
    """The deterministic policy on episodes EVAL_SEED + i: success rate, mean return, collisions."""
    env = make_env(robot, shielded)
    successes = collisions = 0
    returns = []
    for episode in range(episodes):
        observation, _ = env.reset(seed=EVAL_SEED + episode)
        total, done = 0.0, False
        while not done:
            action, _ = model.predict(observation, deterministic=True)
            observation, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            done = terminated or truncated
        successes += bool(info.get("is_success", False))
        collisions += bool(info["collision"])
        returns.append(total)
    env.close()
    return {"success_rate": successes / episodes, "mean_return": float(np.mean(returns)), "collisions": collisions,
            "episodes": episodes}


def _binned(log: TrainingLog, steps: int) -> dict[str, list[float]]:
    """Collisions, episodes and successes per BIN_STEPS bin of training steps."""
    edges = np.arange(0, steps + BIN_STEPS, BIN_STEPS)
    index = np.clip(np.searchsorted(edges, np.asarray(log.end_steps), side="left") - 1, 0, len(edges) - 2)
    counts = np.bincount(index, minlength=len(edges) - 1)
    collided = np.bincount(index, weights=np.asarray(log.collided, dtype=float), minlength=len(edges) - 1)
    succeeded = np.bincount(index, weights=np.asarray(log.succeeded, dtype=float), minlength=len(edges) - 1)
    return {"bin_end_steps": edges[1:].tolist(), "episodes": counts.tolist(), "collisions": collided.tolist(),
            "successes": succeeded.tolist()}


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Train and evaluate every seed and condition; the report (and plot) are saved after every run."""
    report = {"env": ENV_ID, "robot": args.robot, "steps_per_run": args.steps, "seeds": list(args.seeds),
              "n_envs": args.n_envs, "eval_episodes": args.eval_episodes, "algorithm": "stable-baselines3 PPO",
              "runs": []}
    runs = report["runs"]
    for seed in args.seeds:
        for shielded in (False, True):
            name = "shielded" if shielded else "unshielded"
            print(f"training {name}, seed {seed}, {args.steps} steps ...", flush=True)
            model, log, wall = train(args.robot, shielded, seed, args.steps, args.n_envs)
            evaluation = {f"eval_{'shielded' if at_eval else 'unshielded'}":
                          evaluate(model, args.robot, at_eval, args.eval_episodes) for at_eval in (False, True)}
            runs.append({
                "condition": name, "seed": seed, "steps": log.steps, "wall_time_s": wall,
                "training_episodes": len(log.end_steps), "training_collisions": int(sum(log.collided)),
                "training_successes": int(sum(log.succeeded)),
                "shield_intervened_fraction": log.intervened_steps / max(log.steps, 1),
                "shield_mean_safety_change": log.safety_change / max(log.steps, 1),
                "episode_end_steps": log.end_steps, "episode_collided": log.collided,
                "episode_succeeded": log.succeeded, "binned": _binned(log, args.steps), **evaluation,
            })
            last = runs[-1]
            print(f"  {last['training_collisions']} collisions in {last['training_episodes']} episodes, "
                  f"{wall:.0f} s; eval success {last['eval_unshielded']['success_rate']:.2f} unshielded / "
                  f"{last['eval_shielded']['success_rate']:.2f} shielded", flush=True)
            write_json(args.json, report)
            plot(report, args.plot)
    return report


def print_table(report: dict[str, Any]) -> None:
    rows = []
    for condition in ("unshielded", "shielded"):
        runs = [run for run in report["runs"] if run["condition"] == condition]
        if not runs:
            continue
        steps = sum(run["steps"] for run in runs)
        collisions = sum(run["training_collisions"] for run in runs)
        episodes = sum(run["training_episodes"] for run in runs)

        def evaluation(key: str, metric: str, runs: list[dict[str, Any]] = runs) -> float:
            return float(np.mean([run[key][metric] for run in runs]))

        rows.append([
            f"trained {condition}", collisions, f"{1e4 * collisions / max(steps, 1):.2f}",
            f"{sum(run['training_successes'] for run in runs)} / {episodes}",
            f"{evaluation('eval_unshielded', 'success_rate'):.2f}",
            f"{evaluation('eval_unshielded', 'mean_return'):.2f}",
            sum(run["eval_unshielded"]["collisions"] for run in runs),
            f"{evaluation('eval_shielded', 'success_rate'):.2f}", f"{evaluation('eval_shielded', 'mean_return'):.2f}",
            sum(run["eval_shielded"]["collisions"] for run in runs),
            f"{100 * np.mean([run['shield_intervened_fraction'] for run in runs]):.1f}" if condition == "shielded"
            else "–",
            f"{np.mean([run['wall_time_s'] for run in runs]):.0f}",
        ])
    episodes = report["eval_episodes"] * len(report["seeds"])
    print(f"\nPPO on {report['env']} ({report['robot']}), {report['steps_per_run']} steps per run, seeds "
          f"{report['seeds']}; evaluation: {episodes} episodes per cell, deterministic policy")
    print(markdown_table(
        ["", "training collisions", "per 10k steps", "training goals / episodes",
         "eval success (no shield)", "eval return (no shield)", "eval collisions (no shield)",
         "eval success (shield)", "eval return (shield)", "eval collisions (shield)",
         "training steps the shield changed [%]", "wall time per run [s]"],
        rows))


def plot(report: dict[str, Any], path: str) -> None:
    """Cumulative training collisions and the training success rate per 10k steps, per condition and seed."""
    figure = Figure(figsize=(10.0, 4.0), dpi=100)
    FigureCanvasAgg(figure)
    collisions_ax, success_ax = figure.subplots(1, 2)
    colors = {"unshielded": "#d62728", "shielded": "#2ca02c"}
    styles = ["-", "--", ":", "-."]
    for run in report["runs"]:
        color = colors[run["condition"]]
        style = styles[report["seeds"].index(run["seed"]) % len(styles)]
        label = f"{run['condition']}, seed {run['seed']}"
        ends = np.asarray(run["episode_end_steps"])
        collisions_ax.step(np.concatenate(([0], ends)), np.concatenate(([0], np.cumsum(run["episode_collided"]))),
                           where="post", color=color, linestyle=style, alpha=0.8, label=label)
        binned = run["binned"]
        episodes = np.asarray(binned["episodes"], dtype=float)
        rate = np.divide(binned["successes"], episodes, out=np.full(episodes.shape, np.nan), where=episodes > 0)
        success_ax.plot(binned["bin_end_steps"], rate, color=color, linestyle=style, alpha=0.8, marker=".",
                        label=label)
    collisions_ax.set(xlabel="training steps", ylabel="collisions (cumulative)", title="collisions while learning")
    success_ax.set(xlabel="training steps", ylabel="goal reached, training episodes", ylim=(-0.02, 1.02),
                   title=f"success per {BIN_STEPS // 1000}k steps")
    for ax in (collisions_ax, success_ax):
        ax.grid(True, linewidth=0.3, alpha=0.5)
        ax.legend(fontsize="small")
    figure.suptitle(f"PPO on {report['env']} ({report['robot']}), with and without the CBF shield")
    figure.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)
    print(f"wrote {path}")


def draw_env_picture(path: str, seed: int = 0, hold: int = 40) -> None:
    """GoToGoal drawn after the same random agent ran once unshielded and once behind the CBF shield."""
    gymnasium = require("gymnasium", extra="gym", purpose="the safe-RL benchmark")
    import safenav.gym

    figure = Figure(figsize=(12.0, 5.4), dpi=100)
    FigureCanvasAgg(figure)
    for ax, shielded in zip(figure.subplots(1, 2), (False, True), strict=True):
        env = gymnasium.make(ENV_ID, render_mode="rgb_array")
        env = safenav.gym.SafetyShield(env, "cbf") if shielded else env
        _, info = env.reset(seed=seed)
        closest = info["clearance"]
        for step in range(round(env.unwrapped.task.duration / env.unwrapped.control_dt)):
            if step % hold == 0:
                action = env.action_space.sample()    # seeded by reset(seed=...)
            _, _, terminated, truncated, info = env.step(action)
            closest = min(closest, info["clearance"])
            if terminated or truncated:
                break
        ax.imshow(env.render())
        ax.set_axis_off()
        ax.set_title(f'SafetyShield(env, "cbf"): {info["time"]:.0f} s, closest {closest:.2f} m, no collision'
                     if shielded else f"no shield: collision after {info['time']:.1f} s" if info["collision"]
                     else f"no shield: {info['time']:.0f} s, closest {closest:.2f} m", fontsize=11)
        env.close()
    figure.suptitle(f"{ENV_ID}, reset(seed={seed}), the same random agent (each action held {hold} steps)")
    figure.tight_layout(rect=(0.0, 0.0, 1.0, 0.95))
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)
    print(f"wrote {path}")


def build_parser(prog: str = "safe_rl") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=positive_int, default=200_000, help="training steps per run (default: 200000)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1], help="training seeds (default: 0 1)")
    parser.add_argument("--robot", choices=PRESET_NAMES, default="rosbot", help="robot preset (default: rosbot)")
    parser.add_argument("--n-envs", type=positive_int, default=4,
                        help="environments stepped in turn in one process (default: 4)")
    parser.add_argument("--eval-episodes", type=positive_int, default=20,
                        help="evaluation episodes per policy and shield setting (default: 20)")
    parser.add_argument("--quick", action="store_true", help="a smoke run: 4096 steps, one seed, 3 evaluation episodes")
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON to PATH")
    parser.add_argument("--from-json", metavar="PATH",
                        help="train nothing: print the table and draw the plot of a report written by --json")
    parser.add_argument("--env-picture", metavar="PATH",
                        help="only draw the environment with a random agent, unshielded and shielded, to PATH "
                             "(docs/images/safe_rl_env.png), and train nothing")
    parser.add_argument("--plot", metavar="PATH", default="docs/images/safe_rl.png",
                        help="where to draw the learning curves (default: docs/images/safe_rl.png)")
    return parser


def main(argv: Sequence[str] | None = None, prog: str = "safe_rl") -> int:
    args = build_parser(prog).parse_args(argv)
    if args.env_picture:
        draw_env_picture(args.env_picture)
        return 0
    if args.from_json:
        report = json.loads(Path(args.from_json).read_text())
        print_table(report)
        plot(report, args.plot)
        return 0
    if args.quick:
        args.steps, args.seeds, args.eval_episodes = 4096, args.seeds[:1], 3
    report = run(args)
    print_table(report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
