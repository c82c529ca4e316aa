"""The whole loop on data this project did not write: record -> lerobot-train -> lerobot-eval -> offline check.

1. **record**: gymnasium's Reacher (``--env.type=reacher``, ``obs_type=state``) driven by ``--exploration``:
   ``random`` torques (each uniform in [-1, 1], held for 1-10 steps) or a noisy scripted ``teleop``erator
   (a PD controller towards 1-3 random points per episode, standing in for a person driving the arm to places),
   written with LeRobot's OWN recording API
   (``LeRobotDataset.create`` + ``add_frame`` + ``save_episode``, as a ``lerobot-record`` user's data is):
   ``observation.state`` (fingertip xy), ``observation.environment_state`` (joint cos, sin, velocities),
   ``action``; no reward, no goal column, no ground truth. Episodes hold T + 1 = 51 frames. The last
   ``--held_out`` episodes are never trained on.
2. **train**: ``lerobot-train --policy.type=indicator_ddpg`` on the training episodes, no method flags
   (goals: the episodes' own later frames; the recorded-goal stand-in: each episode's last frame).
3. **eval**: ``lerobot-eval`` in Reacher toward its goals (``goal_state``: the fingertip in the goal
   configuration), ``--eval.n_episodes`` goals the data never held (``lerobot-eval``'s seeds).
4. **oracle**: the reference the issue asks for beside it: ``lerobot-indicator-train`` online on the same env
   with the ground-truth reward (the paper's Oracle arm, ``benchmarks/experiments/presets.py``).
5. **check**: ``lerobot-indicator-offline-check`` on the held-out episodes (value ordering of goals by steps
   away, actor's action error toward near goals): what was learned, without a simulator.
6. **summary**: one JSON + PNG + the commands, in ``--results``.

    python -m benchmarks.experiments.own_data_loop [--exploration random|teleop]
        [--stages record train eval oracle check summary] [--episodes 400] [--held_out 20] [--train_steps 3000]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchmarks.records import command_line

BIN = Path(sys.executable).parent
EXPLORATION = {
    "random": "uniform random torques in [-1, 1], each held 1-10 steps",
    "teleop": "a noisy scripted teleoperator: per episode 1-3 points drawn like Reacher's goals (uniform in the "
    "0.2 m disk), switched at random steps; torque = clip(kp * joint error - kd * joint velocity + N(0, 0.3^2)), "
    "kp in [1.5, 5], kd in [0.1, 0.4] per episode",
}
STATE, ENV_STATE = "observation.state", "observation.environment_state"
HORIZON = 50  # Reacher's T (docs/envs.md)
# The lerobot-indicator-train runs beside lerobot-train's, and what each shows.
RUNS = {
    "oracle": "the paper's Oracle arm (ground-truth reward, 0.01 m), online in the same env",
    "online": "the method with its defaults (indicator reward, balance, filter), online in the same env",
    "fast": "the method with its defaults on the same goal-free training episodes, offline (in-memory buffer, "
    "no env episodes); the offline check logged with each evaluation (offline_*)",
}
STAGES = ("record", "train", "oracle", "online", "fast", "eval", "check", "summary")
# Runs that use the env and no recorded data: made once, in --env_only_work, and shown beside every dataset's.
ENV_ONLY = ("oracle", "online")


def environment() -> dict[str, str]:
    """One torch thread, glibc keeps freed memory (docs/policy.md, "Process settings"); no network."""
    return {
        **os.environ,
        "OMP_NUM_THREADS": "1",
        "MALLOC_MMAP_MAX_": "0",
        "MALLOC_TRIM_THRESHOLD_": "2147483647",
        "HF_HUB_OFFLINE": "1",
        "CUDA_VISIBLE_DEVICES": "",
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
    }


def exploratory_actions(rng: np.random.Generator, horizon: int, dim: int) -> np.ndarray:
    """Random torques, each uniform in [-1, 1] and held for 1-10 steps: the arm swings, coasts and brakes."""
    actions, t = np.empty((horizon, dim), np.float32), 0
    while t < horizon:
        hold = int(rng.integers(1, 11))
        actions[t : t + hold] = rng.uniform(-1.0, 1.0, dim)
        t += hold
    return actions


def repo_id(exploration: str) -> str:
    return f"local/reacher_{exploration}_no_goal"


def teleop_actions(
    env, rng: np.random.Generator, horizon: int
) -> tuple[Callable[[], np.ndarray], np.ndarray]:
    """A noisy scripted teleoperator for one episode (``EXPLORATION["teleop"]``): a function of nothing giving the
    next torque from the arm's joint state, driving it in turn to 1-3 random points of the reach disk, and those
    points (world xy, in the order visited)."""
    u = env.unwrapped
    n_points = int(rng.integers(1, 4))
    switches = np.sort(rng.choice(np.arange(5, horizon - 5), n_points - 1, replace=False))
    radius, angle = 0.2 * np.sqrt(rng.uniform(size=n_points)), rng.uniform(0, 2 * np.pi, n_points)
    points = np.stack([radius * np.cos(angle), radius * np.sin(angle)], 1)
    joints = [u.joints_reaching(p) for p in points]
    kp, kd = rng.uniform(1.5, 5.0), rng.uniform(0.1, 0.4)
    t = 0

    def act() -> np.ndarray:
        nonlocal t
        target = joints[int(np.searchsorted(switches, t, side="right"))]
        cos, sin, qd = np.split(u.environment_state(), 3)  # (cos, sin, velocity) of the two joints
        q = np.arctan2(sin, cos)
        error = np.array([(target[0] - q[0] + np.pi) % (2 * np.pi) - np.pi, target[1] - q[1]])
        t += 1
        return np.clip(kp * error - kd * qd + rng.normal(0.0, 0.3, 2), -1.0, 1.0).astype(np.float32)

    return act, points


def record(root: Path, n_episodes: int, seed: int, exploration: str) -> dict:
    """Episodes of Reacher under ``exploration``, with LeRobot's own recording API; no goal column."""
    import gymnasium as gym
    from lerobot.datasets import LeRobotDataset

    from lerobot_indicator.envs import REACHER_ID

    env = gym.make(REACHER_ID, obs_type="state")
    features = {
        STATE: {"dtype": "float32", "shape": (2,), "names": ["x", "y"]},
        ENV_STATE: {
            "dtype": "float32",
            "shape": (6,),
            "names": ["cos_joint0", "cos_joint1", "sin_joint0", "sin_joint1", "joint0_vel", "joint1_vel"],
        },
        "action": {"dtype": "float32", "shape": (2,), "names": ["joint0_torque", "joint1_torque"]},
    }
    t0 = time.perf_counter()
    ds = LeRobotDataset.create(
        repo_id(exploration), fps=50, features=features, root=root, robot_type="reacher", use_videos=False
    )
    rng = np.random.default_rng(seed)
    for ep in range(n_episodes):
        obs, _ = env.reset(seed=seed * 100_000 + ep)
        if exploration == "teleop":
            act, _ = teleop_actions(env, rng, HORIZON)
        else:
            actions = iter(exploratory_actions(rng, HORIZON, 2))
            act = actions.__next__
        for t in range(HORIZON + 1):
            # o_0..o_T; the last frame's action is never used (no o_{T+1}): zeros.
            action = act() if t < HORIZON else np.zeros(2, np.float32)
            ds.add_frame({STATE: obs["agent_pos"], ENV_STATE: obs["environment_state"], "action": action,
                          "task": "reach"})  # fmt: skip
            if t < HORIZON:
                obs, *_ = env.step(action)
        ds.save_episode()
    ds.finalize()
    env.close()
    return {"episodes": n_episodes, "frames": n_episodes * (HORIZON + 1), "seconds": time.perf_counter() - t0}


def baselines(n_episodes: int, seed: int) -> dict:
    """Success at any step and at the final step (0.01 m) of policies that never look at the goal, on the
    online trainer's evaluation goals: uniform random torques each step, the recording's exploration, and
    no torque. A swinging arm passes within 0.01 m of some goals by chance: the floor of "any step"."""
    import gymnasium as gym

    from lerobot_indicator.envs import REACHER_ID
    from lerobot_indicator.keys import EVAL_SEED_OFFSET

    env = gym.make(REACHER_ID, obs_type="state")
    rng = np.random.default_rng(seed)
    policies = {
        "uniform_random": lambda: rng.uniform(-1, 1, (HORIZON, 2)).astype(np.float32),
        "exploration_of_the_data": lambda: exploratory_actions(rng, HORIZON, 2),
        "zero_torque": lambda: np.zeros((HORIZON, 2), np.float32),
    }
    out = {}
    for name, actions_of in policies.items():
        any_step, final, distance = [], [], []
        for i in range(n_episodes):
            env.reset(seed=EVAL_SEED_OFFSET + i)
            hits = []
            for a in actions_of():
                _, _, _, _, info = env.step(a)
                hits.append(bool(info["is_success"]))
            any_step.append(any(hits))
            final.append(hits[-1])
            distance.append(float(info["gt_distance"]))
        out[name] = {"success_any_step": float(np.mean(any_step)), "success_final_step": float(np.mean(final)),
                     "final_distance_mean_m": float(np.mean(distance))}  # fmt: skip
    env.close()
    return out


def run(cmd: list[str], log: Path) -> float:
    """Run ``cmd`` at the lowest priority, its output to ``log``; seconds taken (fails loudly)."""
    log.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    print("$", " ".join(cmd), flush=True)
    with open(log, "w") as f:
        proc = subprocess.run(
            ["nice", "-n", "19", *cmd], stdout=f, stderr=subprocess.STDOUT, env=environment()
        )
    if proc.returncode != 0:
        raise SystemExit(f"{cmd[0]} failed ({proc.returncode}); see {log}")
    return time.perf_counter() - t0


def train_command(args, root: Path, out: Path) -> list[str]:
    train_eps = ",".join(map(str, range(args.episodes - args.held_out)))
    return [
        str(BIN / "lerobot-train"), "--policy.type=indicator_ddpg", f"--dataset.repo_id={repo_id(args.exploration)}",
        f"--dataset.root={root}", f"--dataset.episodes=[{train_eps}]",
        "--policy.push_to_hub=false", "--policy.device=cpu", f"--batch_size={args.batch_size}",
        f"--steps={args.train_steps}", f"--num_workers={args.num_workers}", f"--save_freq={args.save_freq}",
        "--log_freq=100", "--wandb.enable=false", f"--seed={args.seed}", f"--output_dir={out}",
    ]  # fmt: skip


def eval_command(args, policy: Path, out: Path) -> list[str]:
    return [
        str(BIN / "lerobot-eval"), f"--policy.path={policy}", "--env.type=reacher", "--env.obs_type=state",
        f"--eval.n_episodes={args.eval_episodes}", "--eval.batch_size=10", "--policy.device=cpu",
        f"--seed={args.seed}", f"--output_dir={out}",
    ]  # fmt: skip


def oracle_command(args, out: Path) -> list[str]:
    """The paper's Oracle arm (ground-truth reward), online in the same env: the reference beside the result."""
    from benchmarks.experiments.presets import METHODS

    return [
        str(BIN / "lerobot-indicator-train"), "--env.type=reacher", "--env.obs_type=state",
        "--policy.type=indicator_ddpg", "--policy.push_to_hub=false", "--policy.device=cpu", *METHODS["oracle"],
        f"--steps={args.oracle_steps}", f"--online.eval_episodes={args.eval_episodes}",
        f"--env_eval_freq={args.oracle_steps // 6}", f"--save_freq={args.oracle_steps}", f"--seed={args.seed}",
        f"--output_dir={out}",
    ]  # fmt: skip


def online_command(args, out: Path) -> list[str]:
    """The method itself (defaults: indicator reward, balance, filter) online in the same env, from its own
    rollouts: separates what the method needs from what offline random data gives."""
    return [
        str(BIN / "lerobot-indicator-train"), "--env.type=reacher", "--env.obs_type=state",
        "--policy.type=indicator_ddpg", "--policy.push_to_hub=false", "--policy.device=cpu",
        f"--steps={args.oracle_steps}", f"--online.eval_episodes={args.eval_episodes}",
        f"--env_eval_freq={args.oracle_steps // 6}", f"--save_freq={args.oracle_steps}", f"--seed={args.seed}",
        f"--output_dir={out}",
    ]  # fmt: skip


def fast_command(args, root: Path, out: Path) -> list[str]:
    """The same goal-free training episodes and default method, from lerobot-indicator-train's in-memory buffer
    (no env episodes collected): what more updates give than lerobot-train's data loader allows here. Logs
    the offline check (offline_* in metrics.jsonl) on the held-out episodes with each evaluation."""
    train_eps = ",".join(map(str, range(args.episodes - args.held_out)))
    return [
        str(BIN / "lerobot-indicator-train"), "--env.type=reacher", "--env.obs_type=state",
        "--policy.type=indicator_ddpg", "--policy.push_to_hub=false", "--policy.device=cpu",
        f"--dataset.repo_id={repo_id(args.exploration)}", f"--dataset.root={root}",
        f"--dataset.episodes=[{train_eps}]",
        "--online.episodes_per_cycle=0", f"--steps={args.fast_steps}", f"--online.eval_episodes={args.eval_episodes}",
        f"--env_eval_freq={args.fast_steps // 6}", f"--save_freq={args.fast_steps}", f"--seed={args.seed}",
        f"--output_dir={out}",
    ]  # fmt: skip


def goals_command(args, policy: Path, out: Path) -> list[str]:
    """Final-step success and distance on the online trainer's evaluation goals (the Oracle's own eval goals)."""
    return [
        sys.executable, "-m", "benchmarks.probes.run_eval_goals", "--env.type=reacher", "--env.obs_type=state",
        f"--policy_path={policy}", f"--episodes={args.eval_episodes}", f"--out={out}",
    ]  # fmt: skip


def check_command(args, root: Path, policy: Path, out: Path) -> list[str]:
    held = ",".join(map(str, range(args.episodes - args.held_out, args.episodes)))
    return [
        str(BIN / "lerobot-indicator-offline-check"), f"--policy.path={policy}",
        f"--dataset.repo_id={repo_id(args.exploration)}",
        f"--dataset.root={root}", f"--episodes=[{held}]", f"--output_dir={out}",
    ]  # fmt: skip


def work_of(args, name: str) -> Path:
    """The directory of run ``name``: ``--env_only_work`` for the runs without data, else ``--work``."""
    return args.env_only_work if name in ENV_ONLY else args.work


def checkpoints(args) -> dict[str, Path]:
    """Every policy the run made: lerobot-train's saved steps, the Oracle's and the fast run's last."""
    found = {}
    train = args.work / "train" / "checkpoints"
    for step in sorted(p.name for p in train.glob("[0-9]*")) if train.is_dir() else []:
        found[f"lerobot_train_{int(step)}"] = train / step / "pretrained_model"
    for name in ("oracle", "online", "fast"):
        last = work_of(args, name) / name / "checkpoints" / "last" / "pretrained_model"
        if last.exists():
            found[name] = last
    return found


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--exploration", default="random", choices=sorted(EXPLORATION), help="how the data is driven"
    )
    p.add_argument("--stages", nargs="+", default=list(STAGES), choices=STAGES)
    p.add_argument("--episodes", type=int, default=400, help="recorded episodes, held-out ones included")
    p.add_argument("--held_out", type=int, default=20, help="the last episodes, never trained on")
    p.add_argument("--train_steps", type=int, default=3000)
    p.add_argument("--batch_size", type=int, default=128)
    p.add_argument("--save_freq", type=int, default=1000)
    p.add_argument("--num_workers", type=int, default=1)
    p.add_argument("--oracle_steps", type=int, default=12000)
    p.add_argument("--fast_steps", type=int, default=12000)
    p.add_argument("--eval_episodes", type=int, default=50)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--work", type=Path, help="default: outputs/own_data/<exploration>")
    p.add_argument("--results", type=Path, help="default: docs/results/own_data/<exploration>")
    p.add_argument(
        "--env_only_work", type=Path, help="the Oracle's and online runs; default: outputs/own_data/random"
    )
    args = p.parse_args()
    args.work = args.work or Path("outputs/own_data") / args.exploration
    args.results = args.results or Path("docs/results/own_data") / args.exploration
    args.env_only_work = args.env_only_work or Path("outputs/own_data/random")
    root, state_file = args.work / "dataset", args.work / "stages.json"
    done = read_stages(args.work)
    done.setdefault("commands", []).append(command_line())
    logs = args.work / "logs"
    for stage in args.stages:
        t0 = time.perf_counter()
        if stage == "record":
            done["record"] = record(root, args.episodes, args.seed, args.exploration)
        elif stage == "train":
            cmd = train_command(args, root, args.work / "train")
            done["train"] = {"command": cmd, "seconds": run(cmd, logs / "train.log")}
        elif stage in ("oracle", "online", "fast"):
            make = {"oracle": oracle_command, "online": online_command}.get(stage)
            make = make or (lambda a, out: fast_command(a, root, out))
            cmd = make(args, work_of(args, stage) / stage)
            done[stage] = {"command": cmd, "seconds": run(cmd, logs / f"{stage}.log")}
        elif stage == "eval":
            done["baselines"] = baselines(args.eval_episodes, args.seed)
            # lerobot-eval (success at any step, LeRobot's pc_success) and the final-step success on the Oracle's
            # evaluation goals, for every checkpoint.
            for name, policy in checkpoints(args).items():
                for kind, make in (("lerobot_eval", eval_command), ("goals", goals_command)):
                    key = f"{kind}/{name}"
                    if key in done or key in read_stages(work_of(args, name)):
                        continue
                    out = work_of(args, name) / kind / name
                    if kind == "goals":
                        out = out / "eval_goals.json"
                    cmd = make(args, policy, out)
                    done[key] = {"command": cmd, "seconds": run(cmd, logs / f"{kind}_{name}.log")}
        elif stage == "check":
            for name, policy in checkpoints(args).items():
                cmd = check_command(args, root, policy, args.work / "check" / name)  # on this data's episodes
                done[f"check/{name}"] = {"command": cmd, "seconds": run(cmd, logs / f"check_{name}.log")}
        elif stage == "summary":
            summarize(args, done)
        print(f"{stage}: {time.perf_counter() - t0:.0f} s", flush=True)
        state_file.parent.mkdir(parents=True, exist_ok=True)
        state_file.write_text(json.dumps(done, indent=1, default=str))


def read_stages(work: Path) -> dict:
    """What the stages run in ``work`` recorded (their commands and times)."""
    state_file = work / "stages.json"
    return json.loads(state_file.read_text()) if state_file.exists() else {}


def read_jsonl(path: Path) -> list[dict]:
    return (
        [json.loads(line) for line in path.read_text().splitlines() if line.strip()] if path.exists() else []
    )


def last_train_log(log: Path) -> dict[str, float]:
    """The last ``step:...`` line of a lerobot-train log as numbers (its throughput and loss statistics)."""
    import re

    lines = [line for line in log.read_text().replace("\r", "\n").splitlines() if " step:" in line]
    if not lines:
        return {}
    fields = dict(re.findall(r"(\w+):([-\d.eK+]+)", lines[-1].split(" step:", 1)[1].join(["step:", ""])))
    out = {}
    for k, v in fields.items():
        try:
            out[k] = float(v[:-1]) * 1000 if v.endswith("K") else float(v)
        except ValueError:
            continue
    return out


def summarize(args, done: dict) -> None:
    """``own_data_loop.json`` (every number, with its command), ``own_data_loop.png`` and the offline check's
    figure of the last lerobot-train checkpoint, in ``--results``."""
    import shutil

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from benchmarks.records import machine_record

    env_only_done = read_stages(args.env_only_work)

    def command(key: str) -> str:
        stages = done if key in done else env_only_done
        return " ".join(stages[key]["command"]) if key in stages else ""

    policies = {}
    for name in checkpoints(args):
        entry: dict = {}
        info = work_of(args, name) / "lerobot_eval" / name / "eval_info.json"
        if info.exists():
            agg = json.loads(info.read_text())["overall"]
            entry["lerobot_eval"] = {"pc_success_any_step": agg["pc_success"], "avg_sum_reward": agg["avg_sum_reward"],
                                     "command": command(f"lerobot_eval/{name}")}  # fmt: skip
        goals = work_of(args, name) / "goals" / name / "eval_goals.json"
        if goals.exists():
            g = json.loads(goals.read_text())
            entry["final_step_eval"] = {
                "success_rate": g["success_rate"], "final_distance_mean_m": g["final_distance_mean"],
                "start_distance_mean_m": float(np.mean([e["start_distance"] for e in g["episodes"]])),
                "final_distances_m": [round(e["final_distance"], 4) for e in g["episodes"]],
                "command": command(f"goals/{name}"),
            }  # fmt: skip
        check = args.work / "check" / name / "offline_check.json"
        if check.exists():
            c = json.loads(check.read_text())
            keep = ("q_rank_corr", "q_rank_undefined_frac", "q_by_offset", "offsets", "action_error",
                    "action_error_mean_action", "action_error_zero", "action_error_random", "action_error_by_offset",
                    "near_offsets", "episodes")  # fmt: skip
            entry["offline_check"] = {k: c[k] for k in keep} | {"command": command(f"check/{name}")}
        policies[name] = entry
    train_log = last_train_log(args.work / "logs" / "train.log")
    logged = ("step", "env_steps", "eval_success_rate", "eval_final_distance", "q_mean", "frac_filtered",
              "offline_q_rank_corr", "offline_action_error", "offline_action_error_mean_action", "wall_time_s")  # fmt: skip
    runs = {
        name: {
            "what": RUNS[name],
            "command": command(name),
            "wall_s": (done if name in done else env_only_done).get(name, {}).get("seconds"),
            "evaluations": [
                {k: r[k] for k in logged if k in r}
                for r in read_jsonl(work_of(args, name) / name / "metrics.jsonl")
                if "eval_success_rate" in r
            ],
        }
        for name in RUNS
        if name in done or name in env_only_done
    }
    held = list(range(args.episodes - args.held_out, args.episodes))
    record = {
        "what": f"Reacher (gymnasium Reacher-v5, state observations): goal-free {args.exploration} data recorded with "
        "LeRobot's own API -> lerobot-train --policy.type=indicator_ddpg -> lerobot-eval on 50 goals -> offline check "
        "on held-out episodes; the Oracle (ground-truth reward) trained online beside it",
        "command": done.get("commands", [])[-1:],
        "machine": machine_record(),
        "dataset": {
            **done.get("record", {}),
            "repo_id": repo_id(args.exploration),
            "features": [STATE, ENV_STATE, "action"],
            "goal_columns": False,
            "exploration": EXPLORATION[args.exploration],
            "train_episodes": args.episodes - args.held_out,
            "held_out_episodes": held,
        },  # fmt: skip
        "lerobot_train": {
            "command": command("train"),
            "wall_s": done.get("train", {}).get("seconds"),
            "steps": args.train_steps,
            "batch_size": args.batch_size,
            "last_log": train_log,
        },  # fmt: skip
        "lerobot_indicator_train_runs": runs,
        "goal_blind_baselines": done.get("baselines"),
        "policies": policies,
    }
    args.results.mkdir(parents=True, exist_ok=True)
    (args.results / "own_data_loop.json").write_text(json.dumps(record, indent=1) + "\n")
    last_train = [n for n in policies if n.startswith("lerobot_train_")]
    if last_train and (args.work / "check" / last_train[-1] / "offline_check.png").exists():
        shutil.copy(
            args.work / "check" / last_train[-1] / "offline_check.png", args.results / "offline_check.png"
        )

    fig, axes = plt.subplots(1, 3, figsize=(15, 3.8))
    names = [n for n in policies if "final_step_eval" in policies[n]]
    starts = [policies[n]["final_step_eval"]["start_distance_mean_m"] for n in names]
    for n in names:
        axes[0].hist(
            policies[n]["final_step_eval"]["final_distances_m"],
            bins=np.linspace(0, 0.45, 31),
            histtype="step",
            lw=1.5,
            label=n,
        )
    axes[0].axvline(0.01, color="k", ls=":", label="success (0.01 m)")
    axes[0].set(
        xlabel="final fingertip distance to the goal (m)",
        ylabel="goals",
        title=f"{args.eval_episodes} eval goals; mean start {np.mean(starts) if starts else float('nan'):.3f} m",
    )
    axes[0].legend(fontsize=7)
    x = np.arange(len(names))
    axes[1].bar(
        x - 0.2, [policies[n]["final_step_eval"]["success_rate"] for n in names], 0.4, label="final step"
    )
    axes[1].bar(
        x + 0.2,
        [policies[n].get("lerobot_eval", {}).get("pc_success_any_step", float("nan")) / 100 for n in names],
        0.4,
        label="any step (lerobot-eval)",
    )
    axes[1].set_xticks(x, names, rotation=20, fontsize=7)
    axes[1].set(ylim=(0, 1), ylabel="success rate (0.01 m)", title="success")
    axes[1].legend(fontsize=7)
    checked = [n for n in policies if "offline_check" in policies[n]]
    for n in checked:
        c = policies[n]["offline_check"]
        axes[2].plot(c["offsets"], c["q_by_offset"], "o-", label=f"{n}: rho={c['q_rank_corr']:.2f}")
    axes[2].set(
        xscale="log",
        xlabel="goal offset k on held-out episodes",
        ylabel="mean Q(o_t, o_{t+k}, a_t)",
        title="offline check",
    )
    axes[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(args.results / "own_data_loop.png", dpi=70)
    plt.close(fig)
    print(
        json.dumps(
            {
                n: {k: v for k, v in e.items() if k != "final_step_eval"}
                | {"final_step_success": e.get("final_step_eval", {}).get("success_rate")}
                for n, e in policies.items()
            },
            indent=1,
            default=str,
        )[:4000]
    )


if __name__ == "__main__":
    main()
