"""Side by side: Stable-Baselines3 DDPG + HER and our online trainer on a state-based goal task.

Tasks (``VS_TASKS``): the Sawyer reach (``reach_state``, T = 25) and gymnasium-robotics' FetchReach and
FetchPush (``fetch_reach_state``, ``fetch_push_state``, T = 50). Three learners, same simulator, same
hyper-parameters where both have them (3x256 tanh MLPs, batch 256, Adam lr 1e-3, gamma = 1 - 1/T, target smoothing 0.98 (SB3 tau 0.02), one env,
the same episodes and gradient steps per cycle, the same env-step budget):

* ``sb3_ddpg_her``: SB3 ``DDPG`` + ``HerReplayBuffer`` (``future``, 4 sampled goals) with the ground-truth
  sparse reward: on the Sawyer reach +1/-1 through ``GoalEnvAdapter.compute_reward``
  (``lerobot_indicator/envs/goal_env_adapter.py``); on FetchReach gymnasium-robotics' own ``FetchReach-v4``
  and its own ``compute_reward`` (0/-1, distance < 0.05 m);
* ``ours_oracle``: the ``oracle`` preset (``benchmarks.experiments.presets``: ground-truth reward, HER-style
  relabeling), on the task preset's env (``--env.type=fetch_reach --env.obs_type=state`` for FetchReach);
* ``ours_indicator``: the ``indicator_balance_filter`` preset (no ground truth).

Evaluation is the same for all: the deterministic actor on the N fixed eval episodes of our trainer
(``reset(seed=EVAL_SEED_OFFSET + i)``), success = ground-truth distance <= epsilon at the last step
(``FetchReach-v4``: its own ``is_success``, distance < 0.05 m, at the last step). Our
runs are timed through ``TrainerHooks``; wall-clock excludes evaluation. Update throughput is measured in
one process on equally filled buffers, blocks interleaved with the order of the arms rotating.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from benchmarks.experiments.presets import METHODS, TASKS
from benchmarks.records import REPO, cpu_model
from lerobot_indicator.keys import EVAL_SEED_OFFSET, GT_DISTANCE
from lerobot_indicator.training import atomic_dir
from lerobot_indicator.training.hooks import PhaseEnd, TrainerHooks
from lerobot_indicator.training.run_state import RESUME_DIR

# What differs between the SB3 and our learners beyond the shared hyper-parameters (each library's defaults).
COMMON_DIFFERENCES = [
    "exploration: SB3 Gaussian noise std 0.2; ours Gaussian 0.2 plus a uniform random action with p=0.3 "
    "(baselines' HER)",
    "losses: ours adds action_l2=1 on the actor output and clips TD targets to [R-/(1-gamma), R+/(1-gamma)], "
    "critic bias initialised at R-/(1-gamma); SB3 has neither",
    "relabeling: SB3 'future' with 4 sampled goals (80% relabeled); ours oracle HER-style p=0.9 uniform over "
    "{t+1..T}; ours indicator balanced 0.45 next / 0.45 future (t'>=t+2) / 0.1 recorded, plus filtering",
    "input normalisation: ours mean/std of the replay buffer's frames and goals, refreshed every cycle, "
    "clipped to +-5 (baselines' HER); SB3 none",
    "optimiser: SB3 one Adam per network (critic step then actor step); ours one Adam over both, one backward",
    "ours writes its resume state (weights, optimizer, new episodes) after every cycle; that time counts",
    "with --runs-dir SB3 writes its resume state (model, optimisers, the whole replay buffer) after every "
    "evaluation; that time counts too",
]
# Our learners: the package's method presets.
OURS = {"ours_oracle": "oracle", "ours_indicator": "indicator_balance_filter"}
LEARNERS = ("sb3_ddpg_her", *OURS)
# Asked for by name (``--methods``), not part of the default run. ``sb3_ddpg_her_norm``: with input normalisation
# (``VecNormalize`` of observation and goals, clipped to +-5, reward untouched), what rl-baselines3-zoo's HER
# configs set for the Fetch tasks (``normalize: true``) and what ours does. ``sb3_td3_her``: TD3 (twin critics,
# delayed actor, target smoothing) with the shared settings. ``sb3_sac_her_zoo``: SAC + HER with
# rl-baselines3-zoo's FetchReach hyper-parameters (SAC_ZOO), SB3's tuned reference on this task.
SB3_VARIANTS = ("sb3_ddpg_her_norm", "sb3_td3_her", "sb3_sac_her_zoo")
# rl-baselines3-zoo's SAC + HER settings for FetchReach (its hyperparams for FetchReach-v1: 20k env steps).
SAC_ZOO = {
    "gamma": 0.95,
    "learning_rate": 1e-3,
    "batch_size": 256,
    "learning_starts": 1000,
    "ent_coef": "auto",
}
SB3_LEARNERS = ("sb3_ddpg_her", *SB3_VARIANTS)
ALL_LEARNERS = (*LEARNERS, *SB3_VARIANTS)
SUCCESS_TARGET = 0.9
FETCH_REACH_ID = "FetchReach-v4"
FETCH_PUSH_ID = "FetchPush-v4"


@dataclass(frozen=True)
class VsTask:
    """One task of the comparison: our env (a ``TASKS`` preset's env flags) and SB3's env on the same simulator."""

    horizon: int
    title: str
    sb3_env_id: str | None  # None: our env through GoalEnvAdapter; else a gymnasium id with its own reward
    differences: list[str] = field(default_factory=list)


VS_TASKS = {
    "reach_state": VsTask(
        25,
        "Sawyer reach (state)",
        None,
        [
            "inputs: SB3 concatenates observation, achieved_goal (== observation) and desired_goal (9-d); ours "
            "observation and goal (6-d)",
            "reward: both ground truth +1/-1 within epsilon (SB3 through GoalEnvAdapter.compute_reward)",
        ],
    ),
    "fetch_reach_state": VsTask(
        50,
        "FetchReach (state)",
        FETCH_REACH_ID,
        [
            "env: SB3 runs gymnasium-robotics' FetchReach-v4 itself (its 4-d action, the gripper blocked); ours "
            "the same simulator through --env.type=fetch_reach (3-d action: the 4th is 0), whose start is redrawn "
            "when already within epsilon of the goal and whose goal is where the gripper settles when driven "
            "there (within a few mm of FetchReach-v4's sampled goal)",
            "inputs: SB3 FetchReach-v4's observation (10), achieved_goal (3), desired_goal (3), 16-d; ours the grip "
            "point (3, compared), its goal (3) and the wrapped observation as context (10), 16-d",
            "reward: SB3 FetchReach-v4's own compute_reward, 0 if distance < 0.05 m else -1; ours oracle +1/-1 "
            "(distance <= 0.05 m); ours indicator: +1 only when the grip point equals its goal bit for bit",
            "evaluation: the same seeds EVAL_SEED_OFFSET + i, but each env draws its own goals from them (the same "
            "distribution: FetchReach-v4's reset); success at the last step (SB3: FetchReach-v4's is_success)",
        ],
    ),
    "fetch_push_state": VsTask(
        50,
        "FetchPush (state)",
        FETCH_PUSH_ID,
        [
            "env: SB3 runs gymnasium-robotics' FetchPush-v4 itself; ours the same simulator through "
            "--env.type=fetch_push (the same 4-d action, the gripper blocked), whose start is redrawn when the block "
            "already lies within epsilon of the goal (FetchPush-v4 keeps them: 5.3% of 300 resets, so some of SB3's "
            "evaluation episodes are solved at reset) and whose goal puts the block at FetchPush-v4's sampled goal",
            "inputs: SB3 FetchPush-v4's observation (25), achieved_goal (3), desired_goal (3), 31-d; ours the block "
            "centre (3, compared), its goal (3) and the wrapped observation as context (25), 31-d",
            "reward: SB3 FetchPush-v4's own compute_reward, 0 if distance < 0.05 m else -1; ours oracle +1/-1 "
            "(distance <= 0.05 m); ours indicator: +1 only when the block centre equals its goal bit for bit",
            "evaluation: the same seeds EVAL_SEED_OFFSET + i, but each env draws its own starts and goals from them "
            "(the same distribution but for the redrawn solved starts); success at the last step",
        ],
    ),
}


@dataclass
class Settings:
    """What every learner and the update benchmark share."""

    env_steps: int = 5000  # env-step budget per run
    eval_every: int = 250  # env steps between evaluations
    eval_episodes: int = 20
    episodes_per_cycle: int = 2
    updates_per_cycle: int = 40
    batch_size: int = 256
    lr: float = 1e-3
    noise: float = 0.2  # Gaussian action noise std (both libraries)
    threads: int = 1  # torch threads in every process
    compile: bool = False  # ours with --policy.compile_model=true (training runs and an extra update arm)
    fill_episodes: int = 40  # update benchmark: episodes in the buffers
    updates_per_block: int = 50
    update_blocks: int = 6
    task: str = "reach_state"  # a key of VS_TASKS (and of presets.TASKS: our env flags)

    @property
    def horizon(self) -> int:
        return VS_TASKS[self.task].horizon

    def validate(self) -> None:
        if self.task not in VS_TASKS:
            raise ValueError(f"task {self.task!r}: choose from {list(VS_TASKS)}")
        cycle_steps = self.episodes_per_cycle * self.horizon
        if self.eval_every % cycle_steps or self.env_steps % cycle_steps:
            raise ValueError(
                f"eval_every ({self.eval_every}) and env_steps ({self.env_steps}) must be multiples of one "
                f"cycle ({cycle_steps} env steps)"
            )

    def steps(self) -> int:
        """Our optimisation steps for the env-step budget."""
        return self.env_steps * self.updates_per_cycle // (self.episodes_per_cycle * self.horizon)


# ----------------------------------------------------------------------------------------------------------
# SB3 side
# ----------------------------------------------------------------------------------------------------------
def make_sb3_env(s: Settings):
    """SB3's env: our state env as a GoalEnv (``GoalEnvAdapter``) or the task's gymnasium id, e.g.
    ``FetchReach-v4`` with its own ground-truth ``compute_reward``."""
    env_id = VS_TASKS[s.task].sb3_env_id
    if env_id is None:
        from lerobot_indicator.envs.goal_env_adapter import make_goal_env

        return make_goal_env()
    import gymnasium as gym
    import gymnasium_robotics

    gym.register_envs(gymnasium_robotics)
    env = gym.make(env_id)
    if env.spec.max_episode_steps != s.horizon:
        raise ValueError(
            f"{env_id}: {env.spec.max_episode_steps} steps per episode, the task's T is {s.horizon}"
        )
    return env


def make_sb3(seed: int, s: Settings, learning_starts: int = 0, learner: str = "sb3_ddpg_her"):
    """SB3 + HER for ``learner`` (SB3_LEARNERS). ``sb3_ddpg_her_norm`` goes through ``VecNormalize``
    (observation and goals, clipped to +-5; the replay buffer keeps raw observations, so HER's relabeled rewards
    use raw goals)."""
    from stable_baselines3 import DDPG, SAC, TD3, HerReplayBuffer
    from stable_baselines3.common.noise import NormalActionNoise
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
    from torch import nn

    env = make_sb3_env(s)
    n_actions = env.action_space.shape[0]
    her = {"replay_buffer_class": HerReplayBuffer,
           "replay_buffer_kwargs": {"n_sampled_goal": 4, "goal_selection_strategy": "future"}}  # fmt: skip
    if learner == "sb3_sac_her_zoo":
        zoo = {**SAC_ZOO, "learning_starts": max(SAC_ZOO["learning_starts"], learning_starts)}
        return SAC(
            "MultiInputPolicy", env, buffer_size=1_000_000, seed=seed, device="cpu", verbose=0, **zoo, **her
        )
    if learner == "sb3_ddpg_her_norm":
        env = VecNormalize(
            DummyVecEnv([lambda: env]),
            norm_obs=True,
            norm_reward=False,
            clip_obs=5.0,
            gamma=1 - 1 / s.horizon,
        )
    return (TD3 if learner == "sb3_td3_her" else DDPG)(
        "MultiInputPolicy",
        env,
        learning_rate=s.lr,
        buffer_size=1_000_000,
        learning_starts=learning_starts,
        batch_size=s.batch_size,
        tau=0.02,
        gamma=1 - 1 / s.horizon,
        train_freq=(s.episodes_per_cycle, "episode"),
        gradient_steps=s.updates_per_cycle,
        action_noise=NormalActionNoise(np.zeros(n_actions), s.noise * np.ones(n_actions)),
        **her,
        policy_kwargs={"net_arch": [256, 256, 256], "activation_fn": nn.Tanh},
        seed=seed,
        device="cpu",
        verbose=0,
    )


def evaluate_sb3(model, env, n_episodes: int, horizon: int) -> dict[str, float]:
    """Our trainer's evaluation protocol: seeds EVAL_SEED_OFFSET + i, deterministic actor, success at step T.
    The final distance is the env's ``gt_distance``, or (a gymnasium-robotics env) that of its achieved and
    desired goals."""
    normalizer = model.get_vec_normalize_env()  # frozen here: normalize_obs does not update its statistics

    def act(obs: dict) -> np.ndarray:
        return model.predict(
            obs if normalizer is None else normalizer.normalize_obs(obs), deterministic=True
        )[0]

    return evaluate_actions(act, env, n_episodes, horizon)


def evaluate_actions(act, env, n_episodes: int, horizon: int) -> dict[str, float]:
    """``evaluate_sb3``'s protocol for any ``act(obs) -> action``."""
    success, distance = [], []
    for i in range(n_episodes):
        obs, info = env.reset(seed=EVAL_SEED_OFFSET + i)
        for _ in range(horizon):
            obs, _, terminated, truncated, info = env.step(act(obs))
        if not truncated:
            raise RuntimeError("an eval episode did not end at the horizon")
        success.append(bool(info["is_success"]))
        if GT_DISTANCE in info:
            distance.append(float(info[GT_DISTANCE]))
        else:
            distance.append(float(np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"])))
    return {"eval_success_rate": float(np.mean(success)), "eval_final_distance": float(np.mean(distance))}


def zero_action_reference(s: Settings) -> dict[str, float]:
    """SB3's env under ``evaluate_sb3``'s protocol with the zero action at every step: what a learner scores
    that never acts (on FetchPush, the block stays where it starts)."""
    env = make_sb3_env(s)
    try:
        return evaluate_actions(lambda obs: np.zeros(env.action_space.shape), env, s.eval_episodes, s.horizon)
    finally:
        env.close()


SB3_CLASSES = {
    "sb3_ddpg_her": "DDPG",
    "sb3_ddpg_her_norm": "DDPG",
    "sb3_td3_her": "TD3",
    "sb3_sac_her_zoo": "SAC",
}


SB3_STATE = "ckpt"  # the SB3 resume state's directory inside a run's state_dir


def save_sb3_state(model, state_dir: Path, progress: dict) -> None:
    """The run's resume state (weights, optimisers, noise, replay buffer, ``VecNormalize`` statistics, curve and
    clocks) in ``state_dir/ckpt``, written beside the previous one and swapped in (``atomic_dir``)."""
    new = atomic_dir.staging(state_dir / SB3_STATE)
    model.save(new / "model.zip")
    model.save_replay_buffer(new / "replay_buffer.pkl")
    if (normalizer := model.get_vec_normalize_env()) is not None:
        normalizer.save(str(new / "vec_normalize.pkl"))
    (new / "progress.json").write_text(json.dumps(progress))
    atomic_dir.swap_in(new, state_dir / SB3_STATE)


def load_sb3_state(s: Settings, learner: str, state_dir: Path):
    """``(model, progress)`` from the newest complete state in ``state_dir``, or ``(None, None)``."""
    if (ckpt := atomic_dir.newest(state_dir / SB3_STATE)) is None:
        return None, None
    import stable_baselines3
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    env = make_sb3_env(s)
    if (ckpt / "vec_normalize.pkl").exists():
        env = VecNormalize.load(str(ckpt / "vec_normalize.pkl"), DummyVecEnv([lambda: env]))
    model = getattr(stable_baselines3, SB3_CLASSES[learner]).load(ckpt / "model.zip", env=env, device="cpu")
    model.load_replay_buffer(ckpt / "replay_buffer.pkl")
    return model, json.loads((ckpt / "progress.json").read_text())


def run_sb3(seed: int, s: Settings, learner: str, state_dir: Path | None = None) -> dict:
    """One SB3 run. With ``state_dir`` it writes its resume state after every evaluation and, started again,
    continues from the last one (the env restarts at an episode boundary, as the state was written between
    cycles; the random streams are not restored)."""
    from stable_baselines3.common.callbacks import BaseCallback

    model, progress = load_sb3_state(s, learner, state_dir) if state_dir else (None, None)
    model = model or make_sb3(seed, s, learner=learner)
    progress = progress or {"curve": [], "eval_s": 0.0, "collect_s": 0.0, "elapsed_s": 0.0}
    eval_env = make_sb3_env(s)
    curve: list[dict] = progress["curve"]
    # "start" is when the run would have started had it never stopped: elapsed time continues across resumes.
    clock = {"eval": progress["eval_s"], "collect": progress["collect_s"], "rollout_t0": 0.0}
    clock["start"] = time.perf_counter() - progress["elapsed_s"]

    def do_eval() -> None:
        t0 = time.perf_counter()
        train_wall = t0 - clock["start"] - clock["eval"]
        result = evaluate_sb3(model, eval_env, s.eval_episodes, s.horizon)
        clock["eval"] += time.perf_counter() - t0
        curve.append(
            {
                "env_steps": int(model.num_timesteps),
                "updates": int(model._n_updates),
                "train_wall_s": train_wall,
                **result,
            }
        )
        if state_dir:
            elapsed = time.perf_counter() - clock["start"]
            save_sb3_state(
                model,
                state_dir,
                {
                    "curve": curve,
                    "eval_s": clock["eval"],
                    "collect_s": clock["collect"],
                    "elapsed_s": elapsed,
                },
            )

    class Timer(BaseCallback):
        """Rollout start = the previous cycle's gradient steps are done: evaluate there (as ours does)."""

        def _on_rollout_start(self) -> None:
            n = self.model.num_timesteps
            if n > 0 and n % s.eval_every == 0 and (not curve or curve[-1]["env_steps"] != n):
                do_eval()
            clock["rollout_t0"] = time.perf_counter()

        def _on_rollout_end(self) -> None:
            clock["collect"] += time.perf_counter() - clock["rollout_t0"]

        def _on_step(self) -> bool:
            return True

    remaining = s.env_steps - int(model.num_timesteps)
    if remaining > 0:
        model.learn(total_timesteps=remaining, callback=Timer(), reset_num_timesteps=not curve)
    if not curve or curve[-1]["env_steps"] != model.num_timesteps:
        do_eval()  # after the last cycle's gradient steps
    return {"curve": curve, "collect_wall_s": clock["collect"], "updates": int(model._n_updates)}


# ----------------------------------------------------------------------------------------------------------
# our side
# ----------------------------------------------------------------------------------------------------------
def ours_cli(learner: str, seed: int, s: Settings, steps: int) -> list[str]:
    """``lerobot-indicator-train`` flags of one of our learners (without ``--output_dir``)."""
    return [
        *TASKS[s.task].env_args,
        "--policy.type=indicator_ddpg",
        "--policy.device=cpu",
        "--policy.push_to_hub=false",
        f"--cpu_threads={s.threads}",
        f"--policy.learning_rate={s.lr}",
        f"--policy.noise_eps={s.noise}",
        *METHODS[OURS[learner]],
        "--online.n_envs=1",
        "--online.use_async_envs=false",
        f"--online.episodes_per_cycle={s.episodes_per_cycle}",
        f"--online.updates_per_cycle={s.updates_per_cycle}",
        f"--online.batch_size={s.batch_size}",
        f"--online.eval_episodes={s.eval_episodes}",
        f"--steps={steps}",
        f"--policy.compile_model={str(s.compile).lower()}",
        f"--env_eval_freq={s.eval_every * s.updates_per_cycle // (s.episodes_per_cycle * s.horizon)}",
        "--save_checkpoint=false",
        f"--seed={seed}",
    ]


def ours_config(learner: str, seed: int, s: Settings, output_dir: Path, steps: int, resume: bool = False):
    import draccus

    from lerobot_indicator.training.config import OnlineTrainConfig

    args = [
        *ours_cli(learner, seed, s, steps),
        f"--output_dir={output_dir}",
        f"--resume={str(resume).lower()}",
    ]
    cfg = draccus.parse(OnlineTrainConfig, args=args)
    cfg.validate()
    return cfg


class EvalCurve:
    """Trainer hooks that record the eval curve against the training wall-clock (evaluation excluded) and the
    time spent collecting and optimising. With ``state``, a JSON file, they continue from it and write it at
    every cycle start (just after the trainer wrote its own resume state) and evaluation."""

    def __init__(self, state: Path | None = None) -> None:
        saved = json.loads(state.read_text()) if state and state.exists() else {}
        self.state = state
        self.curve: list[dict] = saved.get("curve", [])
        self.start: float | None = None
        self.elapsed = saved.get("elapsed_s", 0.0)
        self.eval_s, self.collect_s, self.optimise_s = (
            saved.get(k, 0.0) for k in ("eval_s", "collect_s", "optimise_s")
        )

    def hooks(self) -> TrainerHooks:
        return TrainerHooks(
            on_cycle_start=self._cycle_start,
            on_collect_end=self._collect_end,
            on_update_end=self._update_end,
            on_eval_end=self._eval_end,
        )

    def _cycle_start(self, cycle: int) -> None:
        if self.start is None:
            self.start = time.perf_counter() - self.elapsed
        self._save()

    def _save(self) -> None:
        if self.state:
            saved = {"curve": self.curve, "elapsed_s": time.perf_counter() - self.start}
            saved |= {"eval_s": self.eval_s, "collect_s": self.collect_s, "optimise_s": self.optimise_s}
            tmp = self.state.with_suffix(".tmp")
            tmp.write_text(json.dumps(saved))
            tmp.replace(self.state)

    def _collect_end(self, phase: PhaseEnd, rollouts: object) -> None:
        self.collect_s += phase.seconds

    def _update_end(self, phase: PhaseEnd, stats: dict[str, float]) -> None:
        self.optimise_s += phase.seconds

    def _eval_end(self, phase: PhaseEnd, metrics: dict[str, float]) -> None:
        train_wall = time.perf_counter() - phase.seconds - self.start - self.eval_s
        self.eval_s += phase.seconds
        # A cycle redone after an interruption evaluates again: its new result replaces the saved one.
        self.curve = [c for c in self.curve if c["env_steps"] < phase.env_steps]
        self.curve.append(
            {"env_steps": phase.env_steps, "updates": phase.step, "train_wall_s": train_wall, **metrics}
        )
        self._save()


def run_ours(learner: str, seed: int, s: Settings, state_dir: Path | None = None) -> dict:
    """One of our runs. With ``state_dir`` the trainer keeps its resume state there and, started again,
    continues from it (``--resume=true``), the curve and clocks with it."""
    from lerobot_indicator.training.online import OnlineTrainer, apply_process_settings

    with tempfile.TemporaryDirectory() as tmp:
        root = state_dir or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        timing = EvalCurve(root / "timing.json" if state_dir else None)
        resume = atomic_dir.newest(root / "run" / RESUME_DIR) is not None
        cfg = ours_config(learner, seed, s, root / "run", s.steps(), resume)
        trainer = OnlineTrainer(cfg, timing.hooks())
        apply_process_settings(trainer.cfg)  # as lerobot-indicator-train does
        try:
            trainer.train()
        finally:
            trainer.close()
    return {
        "curve": timing.curve,
        "collect_wall_s": timing.collect_s,
        "optimise_wall_s": timing.optimise_s,
        "updates": trainer.progress.step,
        "cli": "lerobot-indicator-train " + " ".join(ours_cli(learner, seed, s, s.steps())),
    }


def run_learner(learner: str, seed: int, s: Settings, state_dir: Path | None = None) -> dict:
    torch.set_num_threads(s.threads)
    t0 = time.perf_counter()
    run = (run_sb3 if learner in SB3_LEARNERS else run_ours)(
        learner=learner, seed=seed, s=s, state_dir=state_dir
    )
    run["process_wall_s"] = time.perf_counter() - t0
    return run


def run_state_dir(runs_dir: Path, s: Settings, learner: str, seed: int, claim: bool = False) -> Path:
    """``runs_dir/<task>/<learner>/seed_<seed>``, checked against ``s`` through its ``settings.json``, which
    ``claim`` writes for a new run: a run never continues, nor is it gathered, under other settings."""
    state_dir = runs_dir / s.task / learner / f"seed_{seed}"
    recorded = state_dir / "settings.json"
    if recorded.exists() and json.loads(recorded.read_text()) != asdict(s):
        raise ValueError(
            f"{recorded}: the run was made with other settings than these; use another --runs-dir"
        )
    if claim and not recorded.exists():
        state_dir.mkdir(parents=True, exist_ok=True)
        recorded.write_text(json.dumps(asdict(s)))
    return state_dir


def run_in_subprocess(learner: str, seed: int, s: Settings, runs_dir: Path | None = None) -> dict:
    """One training run in a fresh process (``python -m benchmarks.experiments.vs_sb3``). With ``runs_dir`` the
    run keeps its resume state in ``run_state_dir`` and its result in ``run.json`` there: a finished run is read
    back, an interrupted one continues."""
    state_dir = run_state_dir(runs_dir, s, learner, seed, claim=True) if runs_dir else None
    if state_dir and (state_dir / "run.json").exists():
        return json.loads((state_dir / "run.json").read_text())
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.json"
        request = {"learner": learner, "seed": seed, "settings": asdict(s), "out": str(out)}
        request["state_dir"] = str(state_dir) if state_dir else None
        subprocess.run([sys.executable, "-m", __name__, json.dumps(request)], check=True, cwd=REPO)
        run = json.loads(out.read_text())
    if state_dir:
        (state_dir / "run.json").write_text(json.dumps(run))
    return run


# ----------------------------------------------------------------------------------------------------------
# update throughput, one process, interleaved
# ----------------------------------------------------------------------------------------------------------
def time_update_arms(learner: str, sb3, s: Settings) -> tuple[dict[str, list[float]], dict[str, float]]:
    """Seconds per block of ``updates_per_block`` gradient steps for each arm: ours (eager), ours with
    ``--policy.compile_model=true`` when ``compile`` is set, and SB3; and the matmul FLOPs per update."""
    from lerobot_indicator.training.online import OnlineTrainer, apply_process_settings, cycle_episode_seeds

    n = s.updates_per_block
    variants = {"ours": False, **({"ours_compiled": True} if s.compile else {})}
    arms, trainers = {}, []
    with tempfile.TemporaryDirectory() as tmp:
        for name, compiled in variants.items():
            cfg = ours_config(learner, 0, s, Path(tmp) / name, steps=max(n, s.updates_per_cycle))
            cfg.online.updates_per_cycle = n
            cfg.policy.compile_model = compiled
            trainer = OnlineTrainer(cfg)
            apply_process_settings(cfg)
            g = torch.Generator().manual_seed(0)
            for cycle in range(s.fill_episodes // s.episodes_per_cycle):
                seeds = cycle_episode_seeds(cfg.seed, cycle, s.episodes_per_cycle)
                for r in trainer.collect_episodes(seeds, True, g, random_eps=1.0):
                    for episode in r.episodes():
                        trainer.buffer.add_episode(*episode)
            rng = np.random.default_rng(0)
            arms[name] = lambda trainer=trainer, rng=rng, g=g: trainer.optimise(rng, g)
            trainers.append(trainer)

        def sb3_train() -> None:
            sb3.train(gradient_steps=n, batch_size=s.batch_size)

        arms["sb3"] = sb3_train
        names = list(arms)
        flops = {}
        for name in names:  # warm-up (and compilation); matmul FLOPs counted on the eager arms
            if name in ("ours", "sb3"):
                with FlopCounterMode(display=False) as counter:
                    arms[name]()
                flops[name] = counter.get_total_flops() / n
            else:
                arms[name]()
        times: dict[str, list[float]] = {name: [] for name in names}
        for block in range(s.update_blocks):
            k = block % len(names)
            for name in names[k:] + names[:k]:
                t0 = time.perf_counter()
                arms[name]()
                times[name].append(time.perf_counter() - t0)
        for trainer in trainers:
            trainer.close()
    return times, flops


def sgemm_gflops(size: int = 256, repeats: int = 400) -> float:
    """This core's float32 matmul throughput at the update's layer size: the roofline for both libraries."""
    a, b = torch.randn(size, size), torch.randn(size, size)
    for _ in range(20):
        a @ b
    t0 = time.perf_counter()
    for _ in range(repeats):
        a @ b
    return 2 * size**3 * repeats / (time.perf_counter() - t0) / 1e9


def bench_updates(s: Settings) -> dict:
    """Gradient updates/s at batch 256 incl. replay sampling (what each library's train step does), both
    buffers filled with the same number of random-action episodes; blocks interleaved, the order of the arms
    rotating every block. Also each library's matmul FLOPs per update (``torch.utils.flop_counter``; the
    compiled arm does the same math as ``ours``) and the share of the core's measured sgemm throughput they
    reach: the headroom left once the matmuls dominate."""
    n = s.updates_per_block
    sb3 = make_sb3(0, s, learning_starts=10**9)
    sb3.learn(total_timesteps=s.fill_episodes * s.horizon)  # random actions, no training
    results = {}
    for learner in ("ours_indicator", "ours_oracle"):
        times, flops = time_update_arms(learner, sb3, s)
        r = {f"{name}_updates_per_s": n * len(t) / sum(t) for name, t in times.items()}
        flops["ours_compiled"] = flops["ours"]
        for name in times:
            r[f"{name}_matmul_gflop_per_update"] = flops[name] / 1e9
            r[f"{name}_matmul_gflops"] = flops[name] * r[f"{name}_updates_per_s"] / 1e9
        r |= {f"per_block_{name}": [n / x for x in t] for name, t in times.items()}
        for name in (x for x in times if x != "sb3"):
            ratios = [b / a for b, a in zip(times["sb3"], times[name], strict=True)]
            r[f"{name}_over_sb3"] = r[f"{name}_updates_per_s"] / r["sb3_updates_per_s"]
            r[f"{name}_over_sb3_median_of_blocks"] = float(np.median(ratios))
        results[learner] = r
        print(
            f"updates/s {learner}: "
            + ", ".join(f"{name} {r[f'{name}_updates_per_s']:.1f}" for name in times)
            + "".join(
                f", {name}/SB3 {r[f'{name}_over_sb3']:.2f} (median of blocks {r[f'{name}_over_sb3_median_of_blocks']:.2f})"
                for name in times
                if name != "sb3"
            )
            + "; matmul GFLOP/s "
            + ", ".join(f"{name} {r[f'{name}_matmul_gflops']:.1f}" for name in times),
            flush=True,
        )
    peak = sgemm_gflops()
    for r in results.values():
        for name in [k.removesuffix("_matmul_gflops") for k in r if k.endswith("_matmul_gflops")]:
            r[f"{name}_share_of_sgemm_peak"] = r[f"{name}_matmul_gflops"] / peak
    print(f"sgemm 256x256x256 on this core: {peak:.1f} GFLOP/s", flush=True)
    return {
        "sgemm_gflops_256": peak,
        "batch_size": s.batch_size,
        "filled_episodes": s.fill_episodes,
        "updates_per_block": n,
        "blocks": s.update_blocks,
        **results,
    }


# ----------------------------------------------------------------------------------------------------------
# summary
# ----------------------------------------------------------------------------------------------------------
def summarise_run(run: dict) -> dict:
    curve = run["curve"]
    hit = next((c for c in curve if c["eval_success_rate"] >= SUCCESS_TARGET), None)
    final = curve[-1]
    train_wall = final["train_wall_s"]
    return {
        "env_steps_to_90": hit["env_steps"] if hit else None,
        "train_wall_s_to_90": hit["train_wall_s"] if hit else None,
        "final_success_rate": final["eval_success_rate"],
        "final_distance_m": final["eval_final_distance"],
        "train_wall_s": train_wall,
        "env_steps_per_s_training": final["env_steps"] / train_wall,
        "env_steps_per_s_collecting": final["env_steps"] / run["collect_wall_s"],
    }


def aggregate(runs: list[dict]) -> dict:
    s = [r["summary"] for r in runs]

    def stat(key: str) -> dict:
        vals = [x[key] for x in s if x[key] is not None]
        return {
            "mean": float(np.mean(vals)) if vals else None,
            "median": float(np.median(vals)) if vals else None,
            "n_reached": len(vals),
        }

    keys = ("env_steps_to_90", "train_wall_s_to_90", "final_success_rate", "final_distance_m")
    keys += ("train_wall_s", "env_steps_per_s_training", "env_steps_per_s_collecting")
    return {k: stat(k) for k in keys}


def first_mean_hit(runs: list[dict]) -> int | None:
    """The first env steps at which the success rate averaged over ``runs`` (seeds) reaches ``SUCCESS_TARGET``
    (on the evaluations all runs share): the experiments table's "first env steps with mean success >= 0.9"."""
    n = min(len(r["curve"]) for r in runs)
    steps = [c["env_steps"] for c in runs[0]["curve"][:n]]
    for r in runs:
        if [c["env_steps"] for c in r["curve"][:n]] != steps:
            raise ValueError(
                f"{r['method']} seed {r['seed']}: evaluated at other env steps than seed {runs[0]['seed']}"
            )
    mean = np.mean([[c["eval_success_rate"] for c in r["curve"][:n]] for r in runs], axis=0)
    return next((x for x, m in zip(steps, mean, strict=True) if m >= SUCCESS_TARGET), None)


def ratios(runs: list[dict], learners: list[str]) -> dict:
    """Env steps to ``SUCCESS_TARGET`` of each of our learners over each SB3 learner's (``<ours>_over_sb3`` for
    ``sb3_ddpg_her``, ``<ours>_over_<sb3 learner>`` for a variant): from the mean-over-seeds curves, as the mean
    of the seeds' first hits (None unless every seed of both reached it) and seed by seed."""
    by = {m: sorted((r for r in runs if r["method"] == m), key=lambda r: r["seed"]) for m in learners}
    by = {m: rs for m, rs in by.items() if rs}
    hits = {m: first_mean_hit(rs) for m, rs in by.items()}
    out: dict = {"env_steps_to_90_mean_curve": hits}

    def per_seed(rs: list[dict]) -> dict[int, int | None]:
        return {r["seed"]: r["summary"]["env_steps_to_90"] for r in rs}

    def mean_all(hits: dict[int, int | None]) -> float | None:
        return float(np.mean(list(hits.values()))) if None not in hits.values() else None

    for ref in (m for m in SB3_LEARNERS if m in by):
        base, base_mean = per_seed(by[ref]), mean_all(per_seed(by[ref]))
        suffix = "sb3" if ref == "sb3_ddpg_her" else ref
        for m in (m for m in OURS if m in by):
            mine = per_seed(by[m])
            mean = mean_all(mine)
            out[f"{m}_over_{suffix}"] = {
                "mean_curve": hits[m] / hits[ref] if hits[m] and hits[ref] else None,
                "mean_of_seeds": mean / base_mean if mean and base_mean else None,
                "per_seed": {
                    seed: (x / base[seed] if x and base.get(seed) else None) for seed, x in mine.items()
                },
                "env_steps_to_90_per_seed": {"ours": mine, "sb3": base},
            }
    return out


def runs_so_far(seeds: list[int], learners: list[str], s: Settings, runs_dir: Path) -> list[dict]:
    """Every run of ``runs_dir`` as far as it got, without training: a finished run's ``run.json``, else the
    curve and clocks of its last resume state (``finished: false``); runs never started are left out."""
    runs = []
    for seed in seeds:
        for learner in learners:
            state_dir = run_state_dir(runs_dir, s, learner, seed)
            if (state_dir / "run.json").exists():
                run = json.loads((state_dir / "run.json").read_text()) | {"finished": True}
            else:
                sb3_state = atomic_dir.newest(state_dir / SB3_STATE)
                saved = [state_dir / "timing.json", *([sb3_state / "progress.json"] if sb3_state else [])]
                state = next((json.loads(f.read_text()) for f in saved if f.exists()), None)
                if state is None or not state["curve"]:
                    continue
                run = {"curve": state["curve"], "collect_wall_s": state["collect_s"], "finished": False}
                run["updates"] = state["curve"][-1]["updates"]
            run |= {"method": learner, "seed": seed, "summary": summarise_run(run)}
            runs.append(run)
    return runs


def training_runs(
    seeds: list[int], learners: list[str], s: Settings, runs_dir: Path | None = None
) -> list[dict]:
    """Every (seed, learner) run in its own process, interleaved seed by seed so machine noise hits all
    learners alike; with ``runs_dir`` each one resumes (``run_in_subprocess``)."""
    runs = []
    for seed in seeds:
        for learner in learners:
            run = run_in_subprocess(learner, seed, s, runs_dir)
            run |= {"method": learner, "seed": seed, "summary": summarise_run(run)}
            runs.append(run)
            print(f"{learner} seed {seed}: {json.dumps(run['summary'])}", flush=True)
    return runs


def plot_updates(ax, upd: dict, colors: dict[str, str]) -> None:
    """The update-throughput bars: SB3 and our two learners."""
    names = ["SB3 DDPG+HER", "ours oracle", "ours indicator"]
    vals = [
        upd["ours_indicator"]["sb3_updates_per_s"],
        upd["ours_oracle"]["ours_updates_per_s"],
        upd["ours_indicator"]["ours_updates_per_s"],
    ]
    ax.bar(names, vals, color=[colors[m] for m in LEARNERS])
    ax.set_ylabel("gradient updates/s")
    ax.set_title(f"batch {upd['batch_size']}, CPU, incl. replay sampling", fontsize=9)
    for i, v in enumerate(vals):
        ax.text(i, v, f"{v:.1f}", ha="center", va="bottom")


def plot(record: dict, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(21, 4.4))
    colors = {
        "sb3_ddpg_her": "tab:gray",
        "sb3_ddpg_her_norm": "black",
        "sb3_td3_her": "tab:brown",
        "sb3_sac_her_zoo": "tab:green",
        "ours_oracle": "tab:blue",
        "ours_indicator": "tab:red",
    }
    labels = {
        "sb3_ddpg_her": "SB3 DDPG+HER (GT reward)",
        "sb3_ddpg_her_norm": "SB3 DDPG+HER, normalised inputs (GT reward)",
        "sb3_td3_her": "SB3 TD3+HER (GT reward)",
        "sb3_sac_her_zoo": "SB3 SAC+HER, rl-zoo settings (GT reward)",
        "ours_oracle": "ours, oracle (GT reward)",
        "ours_indicator": "ours, indicator+balance+filter",
    }
    for learner in ALL_LEARNERS:
        runs = [r for r in record["runs"] if r["method"] == learner]
        if not runs:
            continue
        for i, r in enumerate(runs):
            steps = [c["env_steps"] for c in r["curve"]]
            wall = [c["train_wall_s"] for c in r["curve"]]
            succ = [c["eval_success_rate"] for c in r["curve"]]
            label = labels[learner] if i == 0 else None
            axes[0].plot(steps, succ, color=colors[learner], alpha=0.35, lw=1)
            axes[1].plot(wall, succ, color=colors[learner], alpha=0.8, lw=1.2, label=label)
        n = min(len(r["curve"]) for r in runs)
        steps = [c["env_steps"] for c in runs[0]["curve"][:n]]
        mean = np.mean([[c["eval_success_rate"] for c in r["curve"][:n]] for r in runs], axis=0)
        axes[0].plot(steps, mean, color=colors[learner], lw=2.2, label=f"{labels[learner]} (mean)")
    for ax, xlabel in zip(axes[:2], ("env steps", "training wall-clock (s, eval excluded)"), strict=True):
        ax.axhline(SUCCESS_TARGET, color="k", ls=":", lw=0.8)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("eval success rate")
        ax.set_ylim(-0.02, 1.02)
        ax.legend(fontsize=7)
    if record["update_throughput"] is None:  # --so-far: runs gathered, no update benchmark
        axes[2].text(0.5, 0.5, "update throughput not measured (--so-far)", ha="center", va="center")
        axes[2].set_axis_off()
    else:
        plot_updates(axes[2], record["update_throughput"], colors)
    # Env steps to 90% success: each seed's first hit (x at the budget: never), the mean curve's first hit.
    ax, budget = axes[3], record["env_steps_budget"]
    hits = record.get("ratios", {}).get("env_steps_to_90_mean_curve", {})
    drawn = [m for m in ALL_LEARNERS if any(r["method"] == m for r in record["runs"])]
    for i, learner in enumerate(drawn):
        mine = [r for r in record["runs"] if r["method"] == learner]
        reached = [
            r["summary"]["env_steps_to_90"] for r in mine if r["summary"]["env_steps_to_90"] is not None
        ]
        missed = [r for r in mine if r["summary"]["env_steps_to_90"] is None]
        never = [budget for r in missed if r.get("finished", True)]
        # An unfinished run that has not reached it yet: a triangle at the env steps it got to.
        so_far = [r["curve"][-1]["env_steps"] for r in missed if not r.get("finished", True)]
        if hits.get(learner) is not None:
            ax.bar(i, hits[learner], color=colors[learner], alpha=0.6)
            ax.text(i, hits[learner], f"{hits[learner]}", ha="center", va="bottom")
        ax.scatter([i] * len(reached), reached, color="k", s=14, zorder=3)
        ax.scatter([i] * len(never), never, marker="x", color="k")
        ax.scatter([i] * len(so_far), so_far, marker="^", facecolors="none", edgecolors="k")
    ax.set_xticks(range(len(drawn)), [labels[m].split(" (")[0] for m in drawn], fontsize=7)
    ax.set_ylabel(f"env steps to {SUCCESS_TARGET:.0%} success")
    ratio = record.get("ratios", {}).get("ours_indicator_over_sb3", {})
    fmt = lambda x: "-" if x is None else f"{x:.2f}"  # noqa: E731
    ax.set_title(
        f"bar: mean-over-seeds curve, dots: seeds (x: never, triangle: not yet, unfinished)\nours indicator / SB3: {fmt(ratio.get('mean_curve'))} "
        f"(mean curve), {fmt(ratio.get('mean_of_seeds'))} (mean of seeds)",
        fontsize=9,
    )
    fig.suptitle(
        f"{VS_TASKS[record.get('task', 'reach_state')].title}: SB3 {record['versions']['stable_baselines3']} vs lerobot-indicator, "
        f"seeds {record['seeds']}, {record['env_steps_budget']} env steps, "
        f"torch threads {record['torch_threads']}"
        + "".join(
            f"\n{r['method']} seed {r['seed']} unfinished: {r['curve'][-1]['env_steps']} env steps so far"
            for r in record["runs"]
            if r.get("finished") is False
        )
    )
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def run_benchmark(
    seeds: list[int],
    learners: list[str],
    s: Settings,
    out_dir: Path,
    command: str,
    skip_training: bool,
    runs_dir: Path | None = None,
    so_far: bool = False,
) -> dict:
    """Every training run (unless ``skip_training``), then the update benchmark; writes ``vs_sb3.json`` and
    ``vs_sb3.png``, or ``vs_sb3_updates.json`` for the update benchmark alone (never replacing a full run). With
    ``so_far``: neither, only the runs of ``runs_dir`` as far as they got, in ``vs_sb3_so_far.json`` / ``.png``."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        sb3_version = version("stable-baselines3")
    except PackageNotFoundError:
        if not so_far:  # gathering finished curves needs no SB3
            raise
        sb3_version = None
    s.validate()
    load_start = os.getloadavg()
    t_start = time.perf_counter()
    torch.set_num_threads(s.threads)
    if so_far:
        if runs_dir is None:
            raise ValueError("--so-far reads the runs of --runs-dir: name it")
        update_throughput, runs = None, runs_so_far(seeds, learners, s, runs_dir)
        if not runs:
            raise ValueError(f"--so-far: no run of {learners}, seeds {seeds} in {runs_dir / s.task}")
    else:
        # Training first: an interrupted invocation then never pays for the update benchmark, only the one that
        # finishes every run does.
        runs = [] if skip_training else training_runs(seeds, learners, s, runs_dir)
        update_throughput = bench_updates(s)
    record = {
        "command": command,
        "machine": {"cpus": os.cpu_count(), "cpu": cpu_model()},
        "load_average_1_5_15_min": {"start": load_start, "end": os.getloadavg()},
        "bench_wall_s": time.perf_counter() - t_start,
        "torch_threads": s.threads,
        "versions": {
            "stable_baselines3": sb3_version,
            "torch": torch.__version__,
            "numpy": np.__version__,
            "python": platform.python_version(),
        },
        "seeds": seeds,
        "env_steps_budget": s.env_steps,
        "settings": asdict(s)
        | {
            "gamma": 1 - 1 / s.horizon,
            "target_smoothing": 0.98,
            "hidden": [256, 256, 256],
            "activation": "tanh",
        },
        "presets": {learner: METHODS[OURS[learner]] for learner in OURS},
        "task": s.task,
        "sb3_env": VS_TASKS[s.task].sb3_env_id or "lerobot_indicator GoalEnvAdapter(" + s.task + ")",
        "protocol_differences": VS_TASKS[s.task].differences + COMMON_DIFFERENCES,
        "update_throughput": update_throughput,
        "sb3_env_zero_action": zero_action_reference(s),
        "summary": {m: aggregate(rs) for m in learners if (rs := [r for r in runs if r["method"] == m])},
        "runs": runs,
    }
    if runs:
        sb3 = record["summary"].get("sb3_ddpg_her", {}).get("env_steps_to_90", {}).get("mean")
        ind = record["summary"].get("ours_indicator", {}).get("env_steps_to_90", {}).get("mean")
        record["ratio_env_steps_to_90_indicator_over_sb3"] = ind / sb3 if sb3 and ind else None
        record["ratios"] = ratios(runs, learners)
    out_dir.mkdir(parents=True, exist_ok=True)
    name = "vs_sb3_so_far" if so_far else "vs_sb3" if runs else "vs_sb3_updates"
    (out_dir / f"{name}.json").write_text(json.dumps(record, indent=2) + "\n")
    if runs:
        plot(record, out_dir / f"{name}.png")
    return record


def main() -> None:
    """A single training run, as ``run_in_subprocess`` asks for it (one JSON argument)."""
    request = json.loads(sys.argv[1])
    state_dir = Path(request["state_dir"]) if request.get("state_dir") else None
    run = run_learner(request["learner"], request["seed"], Settings(**request["settings"]), state_dir)
    Path(request["out"]).write_text(json.dumps(run))


if __name__ == "__main__":
    main()
