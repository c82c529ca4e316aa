"""``lerobot-indicator-train``: online training of ``indicator_ddpg`` from its own rollouts.

Paper Algorithm 1: each *cycle* collects episodes with the behaviour policy into an episode replay
buffer, then runs optimisation steps whose relabeling, indicator reward, filtering and DDPG losses
come from the same learning core as ``lerobot-train`` (``IndicatorDDPGPolicy.forward``).

Crash safety (``run_state``): after every cycle the run's resume state (weights, optimizer, counters) is
rewritten atomically and the cycle's new episodes are appended to ``replay/``, so a run killed mid-cycle loses
at most that cycle, and ``--resume=true`` continues bit for bit on CPU (every cycle's randomness is
seeded from ``(seed, cycle)``). LeRobot-layout checkpoints (``checkpoints/<step>/pretrained_model``,
loadable by ``lerobot-eval --policy.path``) are written every ``save_freq`` steps and at the end.
Benchmarks and loggers time the phases through ``TrainerHooks`` (``hooks``).
"""

import dataclasses
import functools
import logging
import math
import shutil
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from lerobot.common.train_utils import get_step_checkpoint_dir, save_checkpoint, update_last_checkpoint
from lerobot.configs import parser
from lerobot.envs import close_envs, make_env, make_env_pre_post_processors
from lerobot.envs.utils import env_to_policy_features
from lerobot.policies import make_policy, make_pre_post_processors
from lerobot.utils.constants import CHECKPOINTS_DIR, LAST_CHECKPOINT_LINK, PRETRAINED_MODEL_DIR
from lerobot.utils.import_utils import register_third_party_plugins
from lerobot.utils.random_utils import set_seed
from lerobot.utils.utils import init_logging
from tqdm import tqdm

from lerobot_indicator import process
from lerobot_indicator.data.errors import one_line, one_line_errors
from lerobot_indicator.envs.base import OBS_TYPES
from lerobot_indicator.finite import NonFiniteError, check_module
from lerobot_indicator.io_errors import ConfigError, DiskFullError, is_disk_full, report_line
from lerobot_indicator.keys import EVAL_SEED_OFFSET
from lerobot_indicator.policy.input_checks import PolicyInputError, check_policy_inputs, input_problems
from lerobot_indicator.stop_signals import exit_code, raise_interrupted
from lerobot_indicator.training.batches import to_transition_batch
from lerobot_indicator.training.config import OnlineTrainConfig
from lerobot_indicator.training.dataset_seed import seed_buffer
from lerobot_indicator.training.eval_videos import write_eval_videos
from lerobot_indicator.training.hooks import PhaseEnd, TrainerHooks
from lerobot_indicator.training.hub_push import PolicyPushError, push_policy
from lerobot_indicator.training.offline_check import check_policy, trainer_check_episodes, trainer_metrics
from lerobot_indicator.training.plots import plot_learning_curve
from lerobot_indicator.training.recording import RolloutRecorder
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer
from lerobot_indicator.training.rollout import EpisodeBatch, Processors, Rollouts, run_episodes, stored_keys
from lerobot_indicator.training.run_state import METRICS_FILE, Progress, RunPersistence, kept_state

# A cycle's mean std of Q over the batch below this: the critic ignores its inputs. Runs measured 0.01-0.2 in
# their first cycle (rope and reach from pixels) and 7e-7 for a saturated critic (critic_saturation.json).
CONSTANT_Q_STD = 1e-3


def cycle_seed(seed: int, cycle: int) -> int:
    return (seed * 1_000_003 + cycle) % (2**63)


def cycle_episode_seeds(seed: int, cycle: int, n_episodes: int) -> list[int]:
    """Reset seeds of a cycle's training episodes: from (seed, cycle), so a resumed run replays them."""
    base = cycle_seed(seed, cycle) % 10**8 * 64
    return [base + i for i in range(n_episodes)]


class OnlineTrainer:
    """Owns the env, policy, optimizer, replay buffer and run persistence of one online training run."""

    def __init__(self, cfg: OnlineTrainConfig, hooks: TrainerHooks | None = None):
        self.cfg = cfg
        self.hooks = hooks or TrainerHooks()
        try:
            check_env_inputs(cfg)
        except PolicyInputError as err:
            raise ConfigError(one_line(err)) from err
        o = cfg.online
        logging.info(
            "building %d %s env(s)%s, the %s indicator_ddpg policy and its replay buffer; then each cycle "
            "collects %d episode(s) and makes %d updates (%d steps in all)",
            o.n_envs,
            cfg.env.type,
            f" (obs_type={cfg.env.obs_type})" if hasattr(cfg.env, "obs_type") else "",
            f"pretrained ({cfg.policy.pretrained_path})" if cfg.policy.pretrained_path else "new",
            o.episodes_per_cycle,
            o.updates_per_cycle,
            cfg.steps,
        )
        self.out = Path(cfg.output_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        set_seed(cfg.seed)
        self.vec_env = make_env(cfg.env, n_envs=o.n_envs, use_async_envs=o.use_async_envs)[cfg.env.type][0]
        env_pre, env_post = make_env_pre_post_processors(cfg.env, cfg.policy)
        self.horizon = int(self.vec_env.call("_max_episode_steps")[0])
        cfg.policy.set_horizon(self.horizon, source=f"env {cfg.env.type}")
        epsilon = getattr(cfg.env, "epsilon", None)
        if epsilon is not None and cfg.policy.oracle_epsilon != epsilon:
            logging.info(
                "policy.oracle_epsilon %g -> %g (the env's success threshold)",
                cfg.policy.oracle_epsilon,
                epsilon,
            )
            cfg.policy.oracle_epsilon = float(epsilon)
        self.policy = make_policy(cfg.policy, env_cfg=cfg.env)
        self.device = next(self.policy.parameters()).device
        pre, post = make_pre_post_processors(cfg.policy, pretrained_path=cfg.policy.pretrained_path)
        self.processors = Processors(env_pre=env_pre, env_post=env_post, pre=pre, post=post)
        self.optimizer = cfg.policy.get_optimizer_preset().build(self.policy.get_optim_params())
        self.keys = cfg.policy.observation_keys
        self.context_keys = cfg.policy.context_keys
        visual = any(
            ft.type.name == "VISUAL" for k, ft in cfg.policy.input_features.items() if k in self.keys
        )
        if visual and cfg.policy.n_step == 1 and cfg.policy.inverse_dynamics == 0:
            # Chosen with --policy.preset=paper or these flags (the default gives images n_step=3): say what it costs.
            logging.info(
                "indicator_ddpg from images with the paper's one-step target and no inverse dynamics: on RGB-D "
                "reach it did not learn in 10,000 env steps where the default (--policy.preset=auto: n_step=3, "
                "inverse_dynamics=1.0) did (docs/results/experiments_rgbd/)"
            )
        self.batch_size = o.batch_size or (128 if visual else 256)
        capacity = o.buffer_capacity or (5_000 if visual else 1_000_000)
        self.buffer = EpisodeReplayBuffer(capacity, self.horizon)
        self.progress = Progress()
        # The last cycle runs only the updates left, so a run makes exactly --steps updates.
        self.n_cycles = math.ceil(cfg.steps / o.updates_per_cycle)
        self.episodes_per_cycle = math.ceil(o.episodes_per_cycle / o.n_envs) * o.n_envs
        recorder = RolloutRecorder(cfg, self.vec_env, self.keys) if cfg.record.repo_id else None
        self.persistence = RunPersistence(self.out, recorder)
        self.ray_rollouts = None
        if o.backend == "ray":
            from lerobot_indicator.training.ray_rollouts import RayRollouts

            self.ray_rollouts = RayRollouts(cfg, o.num_workers, o.ray_address)
        self.wandb = None
        if cfg.wandb.enable and cfg.wandb.project:
            from lerobot.common.wandb_utils import WandBLogger

            self.wandb = WandBLogger(cfg)

    def train(self) -> dict[str, float]:
        """Paper Algorithm 1, one cycle per iteration."""
        self._start()
        o, p = self.cfg.online, self.progress
        if p.step < self.cfg.steps:  # the first cycle's collection is what the first seconds are spent on
            warmup = " warm-up (uniformly random actions)" if p.episodes < o.warmup_episodes else ""
            logging.info(
                "cycle %d: collecting %d%s episode(s) of %d steps with %d env(s), then %d updates of batch %d",
                p.cycle, self.episodes_per_cycle, warmup, self.horizon, o.n_envs,
                min(o.updates_per_cycle, self.cfg.steps - p.step), self.batch_size,
            )  # fmt: skip
        bar = tqdm(
            total=self.cfg.steps, initial=self.progress.step, desc="indicator_ddpg online", unit="step"
        )
        try:
            while self.progress.step < self.cfg.steps:
                cycle, t0 = self.progress.cycle, time.perf_counter()
                n_updates = min(self.cfg.online.updates_per_cycle, self.cfg.steps - self.progress.step)
                rng, generator = self._cycle_randomness(cycle)
                if self.hooks.on_cycle_start is not None:
                    self.hooks.on_cycle_start(cycle)
                # Behaviour-policy episodes (random actions during the warm-up).
                rollouts = self.collect(cycle)
                # Into the replay buffer, its on-disk chunks and the --record dataset; input statistics.
                self.store(rollouts)
                # Relabel -> indicator reward -> filter -> DDPG update, by the learning core.
                stats = self.optimise(rng, generator, n_updates)
                # Evaluate, log, checkpoint and save the resume state, each when due.
                record = self.end_cycle(cycle, rollouts, stats, t0, n_updates)
                bar.update(n_updates)
                bar.set_postfix(
                    env_steps=self.progress.env_steps,
                    success=f"{record.get('eval_success_rate', record['train_success_rate']):.2f}",
                    q=f"{stats.get('q_mean', float('nan')):.2f}",
                )
        finally:
            bar.close()  # before any error message, so that message is the last line
        return self._finish()

    # ---------------- the phases of a cycle ----------------
    def collect_episodes(
        self,
        seeds: Sequence[int],
        explore: bool,
        generator: torch.Generator | None = None,
        random_eps: float | None = None,
    ) -> list[Rollouts]:
        """One episode per reset seed with the current policy, ``n_envs`` at a time (``explore``: the behaviour
        policy, else the deterministic actor): every episode the trainer runs comes from here."""
        n = self.cfg.online.n_envs
        if len(seeds) % n:
            raise ValueError(f"collect_episodes: {len(seeds)} seeds is not a multiple of n_envs={n}")
        keep_frames = explore and self.persistence.keeps_dataset_frames
        return [
            run_episodes(
                self.vec_env, self.policy, self.processors, stored_keys(self.keys, self.context_keys), self.horizon,
                seeds=list(seeds[i : i + n]), explore=explore, generator=generator, random_eps=random_eps,
                keep_dataset_frames=keep_frames,
            )
            for i in range(0, len(seeds), n)
        ]  # fmt: skip

    def collect(self, cycle: int) -> list[Rollouts]:
        """The cycle's behaviour-policy episodes, from seeds of (seed, cycle), so a resumed run replays them;
        each batch of ``n_envs`` explores with a generator of its own (``EpisodeBatch``), so the Ray backend
        (``--online.backend=ray``) collects the same episodes as the local one."""
        t0 = time.perf_counter()
        warmup = self.progress.episodes < self.cfg.online.warmup_episodes
        seeds, n = cycle_episode_seeds(self.cfg.seed, cycle, self.episodes_per_cycle), self.cfg.online.n_envs
        batches = [
            EpisodeBatch(
                seeds=tuple(seeds[i : i + n]), explore=True, generator_seed=cycle_seed(seeds[i], 1),
                random_eps=1.0 if warmup else None, keep_dataset_frames=self.persistence.keeps_dataset_frames,
            )
            for i in range(0, len(seeds), n)
        ]  # fmt: skip
        if self.ray_rollouts is not None:
            rollouts = self.ray_rollouts.collect(batches, self.policy)
        else:
            keys = stored_keys(self.keys, self.context_keys)
            rollouts = [
                b.run(self.vec_env, self.policy, self.processors, keys, self.horizon) for b in batches
            ]
        self._phase_end(self.hooks.on_collect_end, t0, rollouts)
        return rollouts

    def store(self, rollouts: list[Rollouts]) -> None:
        """New episodes into the replay buffer and the run's persistence; input statistics."""
        for r in rollouts:
            for episode in r.episodes():
                self.buffer.add_episode(*episode)
        self.persistence.store(rollouts, self.buffer, self.progress)
        o = self.cfg.online
        if (
            rollouts
            and self.progress.own_input_stats
            and (self.progress.cycle == 0 or o.input_stats == "running")
        ):
            # No dataset statistics online: normalise inputs with those of the buffer's episodes
            # (saved with the weights, so a resumed or evaluated policy uses the same ones).
            self.policy.set_observation_stats(self.buffer.observation_stats())
        n_episodes = sum(r.actions.shape[0] for r in rollouts)
        self.progress.episodes += n_episodes
        self.progress.env_steps += n_episodes * self.horizon

    def optimise(
        self, rng: np.random.Generator, generator: torch.Generator, n_updates: int | None = None
    ) -> dict[str, float]:
        """``n_updates`` (default ``updates_per_cycle``) learning-core updates on replay batches; their mean
        statistics."""
        n_updates = self.cfg.online.updates_per_cycle if n_updates is None else n_updates
        t0 = time.perf_counter()
        self.policy.train()
        sums: dict[str, float] = {}
        n_step = self.policy.config.n_step
        data_s = update_s = (
            0.0  # wall time of the cycle sampling the buffer / updating (lerobot-train's split)
        )
        for _ in range(n_updates):
            t_data = time.perf_counter()
            sample = self.buffer.sample(self.batch_size, rng, packed=True, n_step=n_step)
            batch = to_transition_batch(sample, self.keys, self.horizon, self.device, self.context_keys)
            t_update = time.perf_counter()
            loss, stats = self.policy.forward(batch, generator=generator)
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            self.optimizer.step()
            self.policy.update()
            self.progress.step += 1
            for k, v in stats.items():
                sums[k] = sums.get(k, 0.0) + v
            data_s, update_s = data_s + t_update - t_data, update_s + time.perf_counter() - t_update
        means = {k: v / n_updates for k, v in sums.items()}
        means |= {"data_s": data_s, "update_s": update_s}
        self._phase_end(self.hooks.on_update_end, t0, means)
        return means

    def evaluate(self) -> dict[str, float]:
        """Deterministic actor on a fixed set of goals (the same at every evaluation)."""
        t0 = time.perf_counter()
        n, n_eval = self.cfg.online.n_envs, self.cfg.online.eval_episodes
        seeds = [EVAL_SEED_OFFSET + i for i in range(math.ceil(n_eval / n) * n)]
        results = self.collect_episodes(seeds, explore=False)
        success = np.concatenate([r.success for r in results])[:n_eval]
        dist = np.concatenate([r.final_distance for r in results])[:n_eval]
        metrics = {"eval_success_rate": float(success.mean()), "eval_final_distance": float(np.nanmean(dist))}
        if self.cfg.online.eval_videos:
            videos = self.out / "eval" / f"videos_step_{self.progress.step}"
            fps = int(getattr(self.cfg.env, "fps", None) or 20)
            write_eval_videos(results, self.keys, videos, self.cfg.online.eval_videos, fps)
        self._phase_end(self.hooks.on_eval_end, t0, metrics)
        return metrics

    def end_cycle(
        self,
        cycle: int,
        rollouts: list[Rollouts],
        stats: dict[str, float],
        t0: float,
        n_updates: int | None = None,
    ) -> dict:
        """Evaluate, log, checkpoint and save the resume state as due (the cycle made ``n_updates``, default
        ``updates_per_cycle``); returns the cycle's metrics."""
        cfg = self.cfg
        prev_step = self.progress.step - (cfg.online.updates_per_cycle if n_updates is None else n_updates)
        is_last = self.progress.step >= cfg.steps

        def due(freq: int) -> bool:
            return is_last or (freq > 0 and self.progress.step // freq > prev_step // freq)

        record = {"cycle": cycle, "step": self.progress.step, "env_steps": self.progress.env_steps,
                  "episodes": self.progress.episodes, **train_metrics(rollouts), **stats}  # fmt: skip
        if due(cfg.env_eval_freq):
            self._last_eval = self.evaluate()
            record.update(self._last_eval)
            if self._offline_check is not None:  # --dataset.*: what was learned, on held-out episodes
                episodes, held_out = self._offline_check
                o = cfg.offline_check
                result = check_policy(self.policy, episodes, offsets=o.offsets, near_offsets=o.near_offsets)
                record.update(trainer_metrics(result, held_out))
        self.progress.cycle += 1
        self.progress.wall_time_s += time.perf_counter() - t0
        record["wall_time_s"] = self.progress.wall_time_s
        self.persistence.run_dir.append_metrics(record)
        self._log(record)
        self._warn_if_critic_is_constant(stats)
        if cfg.save_checkpoint and due(cfg.save_freq):
            checkpoint = self.save_checkpoint()
            if self.wandb is not None:
                self.wandb.log_policy(checkpoint)
        self.persistence.save_if_due(self.policy, self.optimizer, self.progress, is_last)
        if self.hooks.on_cycle_end is not None:
            self.hooks.on_cycle_end(self._phase(time.perf_counter() - t0, cycle), record)
        return record

    # ---------------- bookkeeping ----------------
    def _start(self) -> None:
        cfg = self.cfg
        seed = None
        if cfg.dataset is not None:
            stored = stored_keys(self.keys, self.context_keys)
            seed = functools.partial(seed_buffer, self.buffer, cfg.dataset, stored)
        if cfg.resume:
            self.optimizer, self.progress = self.persistence.resume(
                self.policy, self.optimizer, self.buffer, seed
            )
        else:
            self.progress.own_input_stats = cfg.policy.pretrained_path is None
            if seed is not None:
                self.progress.seeded_episodes = self.progress.episodes = seed()
                if self.progress.own_input_stats:
                    self.policy.set_observation_stats(self.buffer.observation_stats())
        self._offline_check = None
        if cfg.dataset is not None and cfg.offline_check.enable:
            inputs = [*self.keys, *(self.context_keys or [])]
            self._offline_check = trainer_check_episodes(cfg.dataset, cfg.offline_check, inputs)
        self.persistence.start(self.progress)
        self._last_eval: dict[str, float] = {}
        self._warned_constant_critic = False

    def _cycle_randomness(self, cycle: int) -> tuple[np.random.Generator, torch.Generator]:
        """Everything random in a cycle comes from (seed, cycle), so a resumed run replays it exactly."""
        torch.manual_seed(cycle_seed(self.cfg.seed, cycle))  # image augmentation draws from the global RNG
        generator = torch.Generator().manual_seed(cycle_seed(self.cfg.seed, cycle))
        return np.random.default_rng([self.cfg.seed, cycle]), generator

    def _phase(self, seconds: float, cycle: int | None = None) -> PhaseEnd:
        p = self.progress
        return PhaseEnd(p.cycle if cycle is None else cycle, p.step, p.env_steps, seconds)

    def _phase_end(self, hook, t0: float, result) -> None:
        if hook is not None:
            hook(self._phase(time.perf_counter() - t0), result)

    def _warn_if_critic_is_constant(self, stats: dict[str, float]) -> None:
        """Once per run: a critic whose Q no longer varies over the batch has stopped learning."""
        q_std = stats.get("q_std")
        if self._warned_constant_critic or q_std is None or q_std >= CONSTANT_Q_STD:
            return
        self._warned_constant_critic = True
        if self.policy.config.critic_output_scale == "return":
            remedy = "the critic output is already return-scaled: try another seed or a lower learning rate"
        else:
            remedy = "rerun with --policy.critic_output_scale=return (docs/policy.md)"
        logging.warning(
            "the critic gives the same Q (%.3g, std %.2g over the batch) for every input at step %d: its last "
            "tanh layer has saturated and gets no gradient, so this run will not learn; %s",
            stats.get("q_mean", float("nan")),
            q_std,
            self.progress.step,
            remedy,
        )

    def _log(self, record: dict) -> None:
        if self.wandb is not None:
            evals = {k: v for k, v in record.items() if k.startswith("eval_")}
            self.wandb.log_dict({k: v for k, v in record.items() if k not in evals}, self.progress.step)
            if evals:
                self.wandb.log_dict(evals, self.progress.step, mode="eval")

    def save_checkpoint(self) -> Path:
        """LeRobot-train layout, loadable by ``lerobot-eval --policy.path=<dir>/pretrained_model``."""
        check_module(self.policy, "checkpoint")
        ckpt = get_step_checkpoint_dir(self.out, self.cfg.steps, self.progress.step)
        try:
            save_checkpoint(
                ckpt,
                self.progress.step,
                self.cfg,
                self.policy,
                self.optimizer,
                None,
                self.processors.pre,
                self.processors.post,
            )
        except Exception:
            # A part-written checkpoint (e.g. the disk filled up) goes, unless checkpoints/last points at it.
            last = self.out / "checkpoints" / "last"
            if not (last.exists() and last.resolve() == ckpt.resolve()):
                shutil.rmtree(ckpt, ignore_errors=True)
            raise
        update_last_checkpoint(ckpt)
        return ckpt

    def _finish(self) -> dict[str, float]:
        cfg = self.cfg
        curve = self.out / "learning_curve.png"
        plot_learning_curve(self.out / METRICS_FILE, curve, title=cfg.job_name)
        if self.wandb is not None:
            import wandb

            wandb.log({"train/learning_curve": wandb.Image(str(curve))}, step=self.progress.step)
        tags = ["lerobot-indicator", "indicator-rewards", cfg.env.type]
        self.persistence.finish(tags if cfg.record.push_to_hub else None)
        if cfg.policy.push_to_hub:
            push_policy(self.policy, self.processors, cfg, self.batch_size, self._kept_policy)
        return {**self._last_eval, "env_steps": self.progress.env_steps, "steps": self.progress.step}

    def _kept_policy(self) -> Path:
        """The trained policy on disk: the last checkpoint (saved after the last cycle), or one saved now."""
        last = self.out / CHECKPOINTS_DIR / LAST_CHECKPOINT_LINK
        checkpoint = last if self.cfg.save_checkpoint and last.exists() else self.save_checkpoint()
        return checkpoint.resolve() / PRETRAINED_MODEL_DIR

    def close(self) -> None:
        """Also on a crash: finalize the recorded dataset so every saved episode stays readable."""
        self.persistence.close()
        if self.wandb is not None:
            import wandb

            wandb.finish()
        close_envs({self.cfg.env.type: {0: self.vec_env}})
        if self.ray_rollouts is not None:
            self.ray_rollouts.close()


def train_metrics(rollouts: list[Rollouts]) -> dict[str, float]:
    """Ground-truth success and final distance of the cycle's behaviour-policy episodes (NaN without any)."""
    success = np.concatenate([r.success for r in rollouts]) if rollouts else np.full(1, np.nan)
    distance = np.concatenate([r.final_distance for r in rollouts]) if rollouts else np.full(1, np.nan)
    finite = np.isfinite(distance).any()
    return {
        "train_success_rate": float(np.mean(success)),
        "train_final_distance": float(np.nanmean(distance)) if finite else float("nan"),
    }


def env_input_fix(env_cfg, policy_cfg) -> str:
    """The ``--env.*`` options under which the env gives the policy's inputs in their shapes, as a hint."""
    if not hasattr(env_cfg, "obs_type"):
        return ""
    for obs_type in OBS_TYPES:
        try:
            alt = dataclasses.replace(env_cfg, obs_type=obs_type)
        except (ValueError, TypeError):
            continue
        missing, shapes = input_problems(policy_cfg, env_to_policy_features(alt))
        if missing:
            continue
        fixes = [] if obs_type == env_cfg.obs_type else [f"--env.obs_type={obs_type}"]
        for policy_shape, _ in shapes.values():
            if len(policy_shape) == 3:  # (C, H, W): the camera size
                fixes.append(f"--env.camera.height={policy_shape[1]} --env.camera.width={policy_shape[2]}")
        if fixes:
            return "use " + " ".join(dict.fromkeys(fixes))
    return ""


def check_env_inputs(cfg: OnlineTrainConfig) -> None:
    """Before anything is built: the env gives every input the policy reads (``--policy.observation_keys``, or a
    pretrained policy's keys) in the shape it was made for; else one line with the fix."""
    features = env_to_policy_features(cfg.env)
    obs_type = getattr(cfg.env, "obs_type", None)
    source = f"env {cfg.env.type}" + (f" (obs_type={obs_type})" if obs_type else "")
    if input_problems(cfg.policy, features) != ([], {}):
        check_policy_inputs(cfg.policy, features, source, env_input_fix(cfg.env, cfg.policy))


def check_config_path(args: list[str]) -> None:
    """``--config_path`` names a file or a directory (LeRobot's parser would open a missing one with a
    traceback)."""
    path = parser.parse_arg("config_path", args)
    if path and not Path(path).exists():
        raise ConfigError(
            f"--config_path={path}: no such file; pass a training config (YAML or JSON) or a directory holding "
            "train_config.json"
        )


def apply_process_settings(cfg: OnlineTrainConfig) -> None:
    """``--cpu_threads`` (when the policy trains on CPU), ``--keep_freed_memory``, ``--video_decoder_threads``."""
    on_cpu = torch.device(cfg.policy.device or "cpu").type == "cpu"
    process.apply(cfg.cpu_threads if on_cpu else None, cfg.keep_freed_memory, cfg.video_decoder_threads)


@parser.wrap()
def train(cfg: OnlineTrainConfig) -> dict[str, float]:
    try:
        cfg.validate()
    except (ValueError, FileNotFoundError, FileExistsError) as err:
        raise ConfigError(one_line(err)) from err
    trainer = OnlineTrainer(cfg)
    # Once the trainer is built, so the env worker processes it started keep the libraries' defaults.
    apply_process_settings(cfg)
    try:
        try:
            return trainer.train()
        finally:
            trainer.close()
    except Exception as err:
        if not is_disk_full(err):
            raise
        raise DiskFullError(
            f"stopped: the disk holding {trainer.out} is full ({one_line(err)}). Kept: {kept_state(trainer.out)}. "
            "Free some space, then run the same command with --resume=true"
        ) from err


def main() -> None:
    init_logging()
    register_third_party_plugins()
    signal.signal(signal.SIGTERM, raise_interrupted)  # stop as on Ctrl-C: workers, dataset, wandb closed
    try:
        check_config_path(sys.argv[1:])
        with one_line_errors():  # bad dataset content: one line naming the file, key, episode, frame
            train()
    except PolicyPushError as e:
        logging.error("%s", e)
        raise SystemExit(1) from None
    except NonFiniteError as e:
        logging.error(
            "stopped: %s. Nothing non-finite was saved; the last checkpoint and resume state are kept.", e
        )
        raise SystemExit(1) from None
    except KeyboardInterrupt as exc:
        logging.error(
            "interrupted: the run continues from its resume/ state (the last completed cycle; with --record, the "
            "last dataset checkpoint) with the same command and --resume=true"
        )
        raise SystemExit(exit_code(exc)) from None
    except Exception as exc:
        # A config error, a corrupt file read or a full disk: one line (io_errors), any other error its traceback.
        line = report_line(exc)
        if line is None:
            raise
        print(line, file=sys.stderr, flush=True)
        raise SystemExit(1) from None


if __name__ == "__main__":
    main()
