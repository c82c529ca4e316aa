"""Rope push's ceiling: how close a planner with the true simulator gets to the evaluation goals in 3 pushes.

For each of the online trainer's evaluation goals (reset seeds ``keys.EVAL_SEED_OFFSET + i``, the goals
``benchmarks.experiments.start_distance`` scores), the cross-entropy method (CEM) searches the whole 3-push
action sequence (12 numbers in [-1, 1]) open loop: every candidate is simulated from the exact start state
(``RopeSim.set_qpos``; the state is a function of qpos alone, so it restores bit for bit) and scored by the
ground-truth final distance the env reports (``gt_distance``). The simulator is deterministic, so
replanning after each push would see exactly the predicted state; open loop loses nothing.

CEM: iteration 0 is half uniform random action sequences, half the env's own random pushes (the authors'
push across a random link, which also makes the goals); then ``iterations - 1`` Gaussian rounds refitted to
the ``elites`` best seen so far (the elites carry over; replays are exact, so they are not rerun).
Beside it, on the same goals: not moving (distance at reset), the iteration-0 samples as random baselines
(uniform actions; the env's random push), and replaying the hidden goal pushes (the goal is that many
random pushes from the start, so this is a plan that reaches it; read from ground truth, never a policy's).

Goal sets: ``cache:N[:SEED]`` the pairs an N-pair cache (``scripts/generate_rope_cache.py --n N --seed
SEED``, env defaults) holds at the indices the evaluation seeds pick, rebuilt from their per-index random
streams without generating the whole file; ``file:PATH`` a cache file through the env's reset;
``fly`` goals generated at reset (no cache).

    nice -n 10 env OMP_NUM_THREADS=1 MUJOCO_GL=egl python -m benchmarks.experiments.rope_ceiling \\
        --goal_sets='[cache:4000,cache:10000]' --scratch=/work/runs/rope_ceiling --out=docs/results/rope_ceiling
    # twice the iterations on the first 10 goals: its first 12 iterations are the run above's, replayed
    ... --goal_sets='[cache:4000]' --episodes=10 --cem.iterations=24 --out=docs/results/rope_ceiling/longer_search

Plots read their reference lines with :func:`ceiling_lines`.
"""

import hashlib
import json
import time
from contextlib import closing
from dataclasses import asdict, dataclass, field
from pathlib import Path

import draccus
import numpy as np
from gymnasium.utils.seeding import np_random

from benchmarks.records import command_line, git_commit, machine_record, write_json
from lerobot_indicator.envs.rope_cache import generate_pair, sample_rng
from lerobot_indicator.envs.rope_push import RopePushEnv
from lerobot_indicator.envs.rope_sim import RopeSim
from lerobot_indicator.keys import EVAL_SEED_OFFSET, GT_DESIRED_GOAL

PUSHES = 3  # the env's episode length
EPSILONS = (0.1, 0.05)  # success thresholds: the paper's table, the authors' code


@dataclass
class CemConfig:
    population: int = 64  # candidate plans simulated per iteration
    iterations: int = 12  # iteration 0 is the random samples
    elites: int = 8  # best plans seen so far that the Gaussian is fitted to
    uniform_share: float = 0.5  # of iteration 0: uniform random actions; the rest the env's random pushes
    momentum: float = 0.1  # weight of the previous mean/std in each refit
    min_std: float = 0.02  # std floor (action units), so the search never freezes


@dataclass
class Goal:
    goal_set: str
    seed: int  # the reset seed of the evaluation episode
    cache_index: int | None
    start_qpos: np.ndarray
    goal_xy: np.ndarray  # the 30 link xy numbers at the goal (the env's gt_desired_goal)
    start_distance: float
    goal_actions: np.ndarray  # hidden pushes that made the goal (ground truth; the replay line only)


# ----- goals ---------------------------------------------------------------------------------------
def cache_index(seed: int, n: int) -> int:
    """The cached pair ``env.reset(seed=seed)`` picks from an n-pair cache: gymnasium seeds the env's
    ``np_random`` from the reset seed and the env draws one integer from it."""
    return int(np_random(seed)[0].integers(n))


def xy_distance(sim: RopeSim, goal_xy: np.ndarray) -> float:
    """The env's ``gt_distance`` (which ``info`` rounds to float32): plain L2 over the 30 link xy numbers."""
    return float(np.linalg.norm(sim.link_positions()[:, :2].reshape(-1) - goal_xy))


def env_for(goal_set: str) -> RopePushEnv:
    cache_path = goal_set.removeprefix("file:") if goal_set.startswith("file:") else None
    return RopePushEnv(obs_type="state", cache_path=cache_path)


def eval_goals(env: RopePushEnv, goal_set: str, episodes: int, cache_epsilon: float = 0.1) -> list[Goal]:
    """The first ``episodes`` evaluation goals of ``goal_set`` (see module docstring); ``env`` from
    :func:`env_for`. ``cache_epsilon``: the epsilon the cache was generated with (its never-start-solved
    check)."""
    goals = []
    for i in range(episodes):
        seed = EVAL_SEED_OFFSET + i
        if goal_set.startswith("cache:"):
            n, _, cache_seed = goal_set.removeprefix("cache:").partition(":")
            index = cache_index(seed, int(n))
            pair = generate_pair(env.sim, sample_rng(int(cache_seed or 0), index), cache_epsilon)
            env.sim.set_qpos(pair["goal_qpos"])
            goal_xy = env.sim.link_positions()[:, :2].reshape(-1)
            env.sim.set_qpos(pair["start_qpos"])
            start, actions = pair["start_qpos"], pair["goal_actions"]
            distance = xy_distance(env.sim, goal_xy)
        elif goal_set == "fly" or goal_set.startswith("file:"):
            _, info = env.reset(seed=seed)
            start, actions = env.sim.data.qpos.copy(), env.goal_push_actions
            # The goal in float64 (``info`` holds it in float32): the hidden pushes replay it exactly.
            for action in actions:
                env.sim.push(action)
            goal_xy = env.sim.link_positions()[:, :2].reshape(-1)
            if np.abs(goal_xy - info[GT_DESIRED_GOAL]).max() > 1e-6:
                raise RuntimeError(f"seed {seed}: replaying the hidden goal pushes missed the goal")
            env.sim.set_qpos(start)
            distance = xy_distance(env.sim, goal_xy)  # info's gt_distance, in float64
            index = None if goal_set == "fly" else cache_index(seed, len(env.cache["start_qpos"]))
        else:
            raise ValueError(f"goal set {goal_set!r}: expected cache:N[:SEED], file:PATH or fly")
        goals.append(Goal(goal_set, seed, index, start.copy(), goal_xy.copy(), distance, actions.copy()))
    return goals


# ----- simulating plans ----------------------------------------------------------------------------
def as_policy_actions(plan: np.ndarray) -> np.ndarray:
    """Plans are float32-representable, as a policy's actions are, so the env replays them bit for bit."""
    return np.clip(np.asarray(plan, np.float64), -1.0, 1.0).astype(np.float32).astype(np.float64)


def rollout(sim: RopeSim, goal: Goal, plan: np.ndarray) -> float:
    """Final distance after the pushes of ``plan`` (PUSHES x 4 numbers) from the goal's exact start."""
    sim.set_qpos(goal.start_qpos)
    for action in np.asarray(plan, np.float64).reshape(-1, 4):
        sim.push(action)
    return xy_distance(sim, goal.goal_xy)


def random_push_rollout(sim: RopeSim, goal: Goal, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """The env's random push (across a random link of the current rope) PUSHES times: (plan, distance)."""
    sim.set_qpos(goal.start_qpos)
    plan = []
    for _ in range(PUSHES):
        plan.append(sim.random_push_action(rng))
        sim.push(plan[-1])
    return np.concatenate(plan), xy_distance(sim, goal.goal_xy)


def goal_push_replay(sim: RopeSim, goal: Goal) -> float:
    """The hidden goal pushes, then no-op pushes (a zero-length push is skipped)."""
    plan = np.zeros((PUSHES, 4))
    plan[: len(goal.goal_actions)] = goal.goal_actions[:PUSHES]
    return rollout(sim, goal, plan)


def cem_plan(sim: RopeSim, goal: Goal, cfg: CemConfig, rng: np.random.Generator) -> dict:
    """CEM over the whole PUSHES-push sequence (module docstring). Returns the best plan, its distance, the
    best distance after each iteration (``history``) and the iteration-0 random samples' distances."""
    dim = 4 * PUSHES
    n_uniform = round(cfg.population * cfg.uniform_share)
    uniform = as_policy_actions(rng.uniform(-1.0, 1.0, (n_uniform, dim)))
    d_uniform = np.array([rollout(sim, goal, p) for p in uniform])
    pushes = [random_push_rollout(sim, goal, rng) for _ in range(cfg.population - n_uniform)]
    d_push = np.array([d for _, d in pushes])
    pool = np.concatenate([uniform, np.array([p for p, _ in pushes]).reshape(-1, dim)])
    pool_d = np.concatenate([d_uniform, d_push])
    order = np.argsort(pool_d, kind="stable")[: cfg.elites]
    elites, elite_d = pool[order], pool_d[order]
    mean, std = elites.mean(0), np.maximum(elites.std(0), cfg.min_std)
    history, elite_means = [float(elite_d[0])], [float(elite_d.mean())]
    for _ in range(1, cfg.iterations):
        samples = as_policy_actions(mean + std * rng.standard_normal((cfg.population, dim)))
        d = np.array([rollout(sim, goal, p) for p in samples])
        pool, pool_d = np.concatenate([elites, samples]), np.concatenate([elite_d, d])
        order = np.argsort(pool_d, kind="stable")[: cfg.elites]
        elites, elite_d = pool[order], pool_d[order]
        m = cfg.momentum
        mean = m * mean + (1 - m) * elites.mean(0)
        std = np.maximum(m * std + (1 - m) * elites.std(0), cfg.min_std)
        history.append(float(elite_d[0]))
        elite_means.append(float(elite_d.mean()))
    return {
        "plan": elites[0].tolist(),
        "distance": float(elite_d[0]),
        "history": history,
        "elite_mean_history": elite_means,
        "uniform_distances": d_uniform.tolist(),
        "random_push_distances": d_push.tolist(),
    }


def solve_goal(sim: RopeSim, goal: Goal, cfg: CemConfig, seed: int) -> dict:
    """Everything measured on one goal (a JSON-able record)."""
    t0, c0 = time.perf_counter(), time.process_time()
    result = cem_plan(sim, goal, cfg, np.random.default_rng([seed, goal.seed]))
    return {
        "seed": goal.seed,
        "cache_index": goal.cache_index,
        "start_distance": goal.start_distance,
        "goal_push_replay_distance": goal_push_replay(sim, goal),
        **result,
        "seconds": time.perf_counter() - t0,
        "cpu_seconds": time.process_time() - c0,
    }


# ----- aggregation ---------------------------------------------------------------------------------
def success(distances, eps: float) -> float:
    return float(np.mean(np.asarray(distances) <= eps))


def summarise(goals: list[dict], epsilons=EPSILONS) -> dict:
    """Means over goals; random baselines: the mean over all samples (a random policy's expected score)
    and the mean of each goal's best sample."""
    final = [g["distance"] for g in goals]
    start = [g["start_distance"] for g in goals]
    replay = [g["goal_push_replay_distance"] for g in goals]
    out = {
        "goals": len(goals),
        "ceiling": {
            "final_distance": float(np.mean(final)),
            "final_distance_median": float(np.median(final)),
        },
        "not_moving": {"final_distance": float(np.mean(start))},
        "goal_push_replay": {"final_distance": float(np.mean(replay))},
    }
    for eps in epsilons:
        out["ceiling"][f"success_{eps}"] = success(final, eps)
        out["not_moving"][f"success_{eps}"] = success(start, eps)
        out["goal_push_replay"][f"success_{eps}"] = success(replay, eps)
    for name, key in (("random_uniform", "uniform_distances"), ("random_push", "random_push_distances")):
        samples = np.concatenate([g[key] for g in goals])
        best = [min(g[key]) for g in goals]
        out[name] = {
            "samples_per_goal": len(goals[0][key]),
            "final_distance": float(samples.mean()),
            "best_of_samples_final_distance": float(np.mean(best)),
        }
        for eps in epsilons:
            out[name][f"success_{eps}"] = success(samples, eps)
            out[name][f"best_of_samples_success_{eps}"] = success(best, eps)
    history = np.array([g["history"] for g in goals])
    out["convergence"] = {
        "rollouts_after_iteration": [],  # filled by the caller, which knows the population
        "final_distance": history.mean(0).tolist(),
        **{f"success_{eps}": (history <= eps).mean(0).tolist() for eps in epsilons},
    }
    return out


def ceiling_lines(
    path: str | Path, goal_set: str | None = None, episodes: int | None = None, metric: str = "final_distance"
) -> dict[str, float]:
    """Reference lines for a rope plot from a ``ceiling.json``: {"ceiling", "random", "random_push",
    "not_moving"} over the first ``episodes`` goals (all when None) of ``goal_set`` (the file's first when
    None). ``metric``: "final_distance" or "success_<eps>" (e.g. "success_0.1"). "random" is a uniformly
    random policy's expected score, "random_push" the env's random push's; the ceiling is CEM's best plan."""
    record = json.loads(Path(path).read_text())
    sets = record["goal_sets"]
    goals = sets[goal_set or next(iter(sets))]["per_goal"][:episodes]
    eps = float(metric.removeprefix("success_")) if metric.startswith("success_") else None
    s = summarise(goals, (eps,) if eps is not None else ())
    pick = "final_distance" if eps is None else f"success_{eps}"
    return {
        "ceiling": s["ceiling"][pick],
        "random": s["random_uniform"][pick],
        "random_push": s["random_push"][pick],
        "not_moving": s["not_moving"][pick],
    }


# ----- CLI -----------------------------------------------------------------------------------------
@dataclass
class CeilingConfig:
    goal_sets: list[str] = field(default_factory=lambda: ["cache:4000", "cache:10000"])
    episodes: int = 20  # evaluation goals per set (the state comparison's eval_episodes)
    cem: CemConfig = field(default_factory=CemConfig)
    cache_epsilon: float = 0.1  # the epsilon the rebuilt caches were generated with
    seed: int = 0  # the planner's randomness
    scratch: Path | None = None  # per-goal results (resumable); None: kept in memory only
    out: Path | None = None  # folder for ceiling.json and ceiling.png
    plot_only: bool = False  # redraw ceiling.png from the ceiling.json in ``out``; plan nothing


def _settings_key(cfg: CeilingConfig, goal_set: str) -> str:
    blob = json.dumps([asdict(cfg.cem), cfg.cache_epsilon, cfg.seed, goal_set], sort_keys=True)
    return hashlib.sha1(blob.encode()).hexdigest()[:12]


def run_goal_set(cfg: CeilingConfig, goal_set: str) -> list[dict]:
    scratch = None
    if cfg.scratch is not None:
        name = goal_set.replace(":", "_").replace("/", "_")
        scratch = cfg.scratch / f"{name}_{_settings_key(cfg, goal_set)}"
        scratch.mkdir(parents=True, exist_ok=True)
    results = []
    with closing(env_for(goal_set)) as env:
        for goal in eval_goals(env, goal_set, cfg.episodes, cfg.cache_epsilon):
            done = scratch / f"goal_{goal.seed}.json" if scratch is not None else None
            if done is not None and done.exists():
                results.append(json.loads(done.read_text()))
                continue
            record = solve_goal(env.sim, goal, cfg.cem, cfg.seed)
            write_json(done, record)
            results.append(record)
            print(
                f"{goal_set} seed {goal.seed}: start {record['start_distance']:.3f} -> CEM {record['distance']:.3f} "
                f"(random best {min(record['uniform_distances'] + record['random_push_distances']):.3f}), "
                f"{record['seconds']:.0f} s",
                flush=True,
            )
    return results


def plot(record: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sets = record["goal_sets"]
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.5))
    ax = axes[0]
    for k, (name, s) in enumerate(sets.items()):
        colour = f"C{k}"
        conv = s["summary"]["convergence"]
        x = conv["rollouts_after_iteration"]
        for g in s["per_goal"]:
            ax.plot(x, g["history"], color=colour, alpha=0.15, lw=0.8)
        ax.plot(x, conv["final_distance"], color=colour, lw=2, marker="o", label=f"{name}: CEM best (mean)")
        ax.axhline(s["summary"]["random_uniform"]["final_distance"], color=colour, ls=":", lw=1)
        ax.axhline(s["summary"]["not_moving"]["final_distance"], color=colour, ls="--", lw=1)
    for eps in EPSILONS:
        ax.axhline(eps, color="k", lw=0.6)
    ax.set(xlabel="rollouts per goal", ylabel="final distance (m)", yscale="log",
           title="CEM convergence (thin: goals; -- not moving; : uniform random)")  # fmt: skip
    ax.legend(fontsize=7)
    ax = axes[1]
    for k, (name, s) in enumerate(sets.items()):
        conv = s["summary"]["convergence"]
        for eps, ls in zip(EPSILONS, ("-", "--"), strict=True):
            ax.plot(conv["rollouts_after_iteration"], conv[f"success_{eps}"], color=f"C{k}", ls=ls,
                    marker="o", label=f"{name}, eps {eps}")  # fmt: skip
    ax.set(xlabel="rollouts per goal", ylabel="success rate", ylim=(-0.03, 1.03), title="CEM success")
    ax.legend(fontsize=7)
    ax = axes[2]
    name, s = next(iter(sets.items()))
    goals = s["per_goal"]
    x = np.arange(len(goals))
    bars = {
        "not moving": [g["start_distance"] for g in goals],
        "uniform random (mean)": [np.mean(g["uniform_distances"]) for g in goals],
        "random push (mean)": [np.mean(g["random_push_distances"]) for g in goals],
        "random (best sample)": [min(g["uniform_distances"] + g["random_push_distances"]) for g in goals],
        "CEM": [g["distance"] for g in goals],
    }
    w = 0.8 / len(bars)
    for k, (label, values) in enumerate(bars.items()):
        ax.bar(x + (k - len(bars) / 2 + 0.5) * w, values, w, label=label)
    for eps in EPSILONS:
        ax.axhline(eps, color="k", lw=0.6)
    ax.set(xlabel="evaluation goal", ylabel="final distance (m)", title=f"per goal, {name}")
    ax.set_xticks(x, [str(g["seed"] - EVAL_SEED_OFFSET) for g in goals])
    ax.set_ylim(0, 1.3 * max(max(v) for v in bars.values()))
    ax.legend(fontsize=7, ncol=3, loc="upper center")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(cfg: CeilingConfig) -> dict:
    """Plan on every goal set, write ``ceiling.json`` and ``ceiling.png`` into ``cfg.out``; the record."""
    t0 = time.perf_counter()
    record = {"command": command_line(), "commit": git_commit(), "machine": machine_record(),
              "config": asdict(cfg) | {"scratch": str(cfg.scratch), "out": str(cfg.out)},
              "planner": "CEM over the whole 3-push sequence, open loop (module docstring)",
              "goal_sets": {}}  # fmt: skip
    for goal_set in cfg.goal_sets:
        per_goal = run_goal_set(cfg, goal_set)
        summary = summarise(per_goal)
        p = cfg.cem.population
        summary["convergence"]["rollouts_after_iteration"] = [p * (i + 1) for i in range(cfg.cem.iterations)]
        record["goal_sets"][goal_set] = {"summary": summary, "per_goal": per_goal}
        print(goal_set, json.dumps({k: v for k, v in summary.items() if k != "convergence"}, indent=1))
    record["wall_s"] = time.perf_counter() - t0  # this invocation (goals read from scratch cost nothing)
    per_goal = [g for s in record["goal_sets"].values() for g in s["per_goal"]]
    record["planning_wall_s"] = sum(g["seconds"] for g in per_goal)  # including goals read from scratch
    record["planning_cpu_s"] = sum(g["cpu_seconds"] for g in per_goal)
    if cfg.out is not None:
        write_json(cfg.out / "ceiling.json", record)
        plot(record, cfg.out / "ceiling.png")
    return record


@draccus.wrap()
def main(cfg: CeilingConfig) -> dict:
    if cfg.plot_only:
        record = json.loads((cfg.out / "ceiling.json").read_text())
        plot(record, cfg.out / "ceiling.png")
        return record
    return run(cfg)


if __name__ == "__main__":
    import lerobot_indicator  # noqa: F401  (registers the env types)

    main()
