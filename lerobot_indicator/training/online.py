"""``lerobot-indicator-train``: online training of ``indicator_ddpg`` from its own rollouts.

Paper Algorithm 1: each *cycle* collects episodes with the behaviour policy into an episode replay
buffer, then runs optimisation steps whose relabeling, indicator reward, filtering and DDPG losses
come from the same learning core as ``lerobot-train`` (``IndicatorDDPGPolicy.forward``).

Crash safety: after every cycle the run's resume state (weights, optimizer, counters) is rewritten
atomically and the cycle's new episodes are appended to ``replay/``, so a run killed mid-cycle loses
at most that cycle, and ``--resume=true`` continues bit for bit on CPU (every cycle's randomness is
seeded from ``(seed, cycle)``). LeRobot-layout checkpoints (``checkpoints/<step>/pretrained_model``,
loadable by ``lerobot-eval --policy.path``) are written every ``save_freq`` steps and at the end.
"""

import json
import logging
import math
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from lerobot.common.train_utils import get_step_checkpoint_dir, save_checkpoint, update_last_checkpoint
from lerobot.configs import parser
from lerobot.envs import close_envs, make_env, make_env_pre_post_processors
from lerobot.optim import load_optimizer_state, save_optimizer_state
from lerobot.policies import make_policy, make_pre_post_processors
from lerobot.utils.import_utils import register_third_party_plugins
from lerobot.utils.random_utils import set_seed
from lerobot.utils.utils import init_logging
from safetensors.torch import load_model, save_model
from tqdm import tqdm

from lerobot_indicator.data.checkpoint import clear_checkpoint, write_checkpoint
from lerobot_indicator.finite import NonFiniteError, check_module
from lerobot_indicator.keys import EVAL_SEED_OFFSET, goal_key
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.networks_indicator_ddpg import as_float
from lerobot_indicator.training.config import OnlineTrainConfig
from lerobot_indicator.training.dataset_seed import seed_buffer
from lerobot_indicator.training.plots import plot_learning_curve
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer
from lerobot_indicator.training.rollout import Processors, Rollouts, run_episodes, stored_keys

METRICS_FILE = "metrics.jsonl"
RESUME_DIR = "resume"
REPLAY_DIR = "replay"


@dataclass
class Progress:
    """Counters saved with the resume state."""

    cycle: int = 0
    step: int = 0
    env_steps: int = 0
    episodes: int = 0
    wall_time_s: float = 0.0
    seeded_episodes: int = 0  # from --dataset, before any rollout
    recorded_episodes: int = 0  # in the --record dataset's last checkpoint when this state was saved
    # False when training a --policy.path policy, which keeps its own input normalisation (a resumed run
    # also loads a checkpoint as pretrained_path, so this is decided once, at the start, and saved).
    own_input_stats: bool = True
    # (file name, global index of its first episode) of the episode chunks still needed to rebuild the buffer
    replay_files: list[tuple[str, int]] = field(default_factory=list)


def cycle_seed(seed: int, cycle: int) -> int:
    return (seed * 1_000_003 + cycle) % (2**63)


def to_transition_batch(
    sample: dict, keys: list[str], horizon: int, device: torch.device
) -> dict[str, torch.Tensor]:
    """Replay-buffer sample -> the learning core's transition batch (``indicator_core`` docstring).

    ``future.count`` = |{t+2..T}| lets the unbalanced (HER-style) mode pick o_{t+1} with the right
    probability, so its future goal is uniform over {t+1..T}."""

    def t(x: np.ndarray) -> torch.Tensor:
        x = torch.from_numpy(np.ascontiguousarray(x)).to(device)
        # uint8 frames stay uint8 (the networks convert them); torch has few uint16 kernels, so packed depth
        # becomes its float32 value here.
        return x.float() if x.dtype == torch.uint16 else x

    batch = {
        core.ACTION: t(sample["action"]),
        core.HAS_FUTURE: t(sample["has_future"]),
        core.FUTURE_COUNT: t(np.maximum(horizon - sample["t"] - 1, 0)),
    }
    for k in keys:
        batch[k] = t(sample["obs"][k])
        batch[core.NEXT + k] = t(sample["next_obs"][k])
        batch[core.FUTURE + k] = t(sample["future_obs"][k])
    for k in (k for k in sample["obs"] if k not in batch):
        batch[k] = t(sample["obs"][k])  # the recorded goals
    for k in keys:
        # The buffer packs an observation key and its goal key separately: where one was widened to float32
        # and the other is still uint8, compare and encode both as their float32 values.
        group = [k, core.NEXT + k, core.FUTURE + k, goal_key(k)]
        if len({batch[g].dtype for g in group}) > 1:
            batch.update({g: as_float(batch[g]) for g in group})
    if "gt_next_achieved" in sample:
        batch[core.GT_NEXT_ACHIEVED] = t(sample["gt_next_achieved"])
        batch[core.GT_FUTURE_ACHIEVED] = t(sample["gt_future_achieved"])
        batch[core.GT_DESIRED] = t(sample["gt_desired"])
    return batch


def add_replay_chunk(buffer: EpisodeReplayBuffer, chunk: dict[str, np.ndarray]) -> None:
    """Add the episodes of one ``replay/cycle_*.npz`` chunk (written by ``OnlineTrainer._append_replay``)."""
    obs = {k[4:]: v for k, v in chunk.items() if k.startswith("obs/")}
    for i in range(chunk["actions"].shape[0]):
        gt = None
        if "gt_achieved" in chunk:
            gt = {"gt_achieved_goal": chunk["gt_achieved"][i], "gt_desired_goal": chunk["gt_desired"][i]}
        buffer.add_episode({k: v[i] for k, v in obs.items()}, chunk["actions"][i], gt)


class OnlineTrainer:
    """Owns the env, policy, optimizer, buffer and the run directory of one online training run."""

    def __init__(self, cfg: OnlineTrainConfig):
        self.cfg = cfg
        self.out = Path(cfg.output_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        set_seed(cfg.seed)
        o = cfg.online
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
        visual = any(
            ft.type.name == "VISUAL" for k, ft in cfg.policy.input_features.items() if k in self.keys
        )
        self.batch_size = o.batch_size or (128 if visual else 256)
        capacity = o.buffer_capacity or (5_000 if visual else 1_000_000)
        self.buffer = EpisodeReplayBuffer(capacity, self.horizon)
        self.progress = Progress()
        self.n_cycles = math.ceil(cfg.steps / o.updates_per_cycle)
        self.rounds_per_cycle = math.ceil(o.episodes_per_cycle / o.n_envs)
        self.dataset = self._open_record_dataset() if cfg.record.repo_id else None
        self.wandb = None
        if cfg.wandb.enable and cfg.wandb.project:
            from lerobot.common.wandb_utils import WandBLogger

            self.wandb = WandBLogger(cfg)

    # ---------------- --record.*: rollouts as a LeRobotDataset ----------------
    def _open_record_dataset(self):
        from lerobot_indicator.data.features import dataset_features, unbatch
        from lerobot_indicator.data.recorder import RecordConfig, open_dataset

        r = self.cfg.record
        self.record_cfg = RecordConfig(
            env=self.cfg.env,
            repo_id=r.repo_id,
            root=r.root,
            policy=f"indicator_ddpg online ({self.cfg.output_dir})",
            seed=self.cfg.seed,
            reward_keys=list(self.keys),
        )
        self.record_cfg.resume = self.cfg.resume and self.record_cfg.root.exists()
        _, info = self.vec_env.reset(seed=self.cfg.seed)
        features = dataset_features(
            self.vec_env.single_observation_space, self.vec_env.single_action_space, unbatch(info), False
        )
        self.task = str(self.vec_env.call("task_description")[0])
        dataset = open_dataset(self.record_cfg, features)  # rolls back to the last checkpoint if killed
        write_checkpoint(self.record_cfg.root, dataset.meta.total_episodes)
        return dataset

    def _record(self, rollouts: list[Rollouts]) -> None:
        """Write this cycle's episodes, but not those a replayed cycle already recorded before a kill."""
        from lerobot_indicator.data.recorder import write_episode

        episodes = [e for r in rollouts for e in zip(r.dataset_frames, r.actions, strict=True)]
        skip = min(self._record_skip, len(episodes))
        self._record_skip -= skip
        for frames, actions in episodes[skip:]:
            write_episode(self.dataset, frames, list(actions), self.keys, self.task)
            self.dataset.save_episode()

    def _save_state_if_due(self, is_last: bool) -> None:
        """The resume state, every cycle; with --record only at a dataset checkpoint, taken just before it.

        A kill between the two leaves the dataset ahead of the state: ``_record`` then skips the replayed
        episodes it already holds (rollouts replay exactly)."""
        if self.dataset is not None:
            due = time.monotonic() - self._record_checkpoint_t >= self.cfg.record.checkpoint_every_s
            if not (due or is_last):
                return
            from lerobot_indicator.data.recorder import checkpoint_dataset

            self.dataset = checkpoint_dataset(self.record_cfg, self.dataset)
            self.progress.recorded_episodes = self.dataset.meta.total_episodes
            self._record_checkpoint_t = time.monotonic()
        self._save_resume_state()

    def _episodes_recorded_ahead(self) -> int:
        """Episodes the dataset holds beyond the resume state: recorded by cycles about to be replayed."""
        ahead = self.dataset.meta.total_episodes - self.progress.recorded_episodes
        if ahead < 0:
            raise ValueError(
                f"the --record dataset at {self.record_cfg.root} has {self.dataset.meta.total_episodes} "
                f"episodes but this run's resume state expects {self.progress.recorded_episodes}: it was "
                "changed outside this run"
            )
        return ahead

    # ---------------- resume state ----------------
    def _save_resume_state(self) -> None:
        """Atomic: write resume.tmp/, then swap it in; a crash leaves the previous state intact."""
        tmp, final, old = (self.out / f"{RESUME_DIR}{s}" for s in (".tmp", "", ".old"))
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        check_module(self.policy, "resume state")
        save_model(self.policy, str(tmp / "model.safetensors"))  # handles the shared encoder
        save_optimizer_state(self.optimizer, tmp)
        (tmp / "progress.json").write_text(json.dumps(self.progress.__dict__))
        if final.exists():
            final.rename(old)
        tmp.rename(final)
        shutil.rmtree(old, ignore_errors=True)

    def _load_resume_state(self) -> None:
        state = self.out / RESUME_DIR
        if not state.exists() and (self.out / f"{RESUME_DIR}.old").exists():
            state = self.out / f"{RESUME_DIR}.old"  # crashed between the two renames
        if not state.exists():
            raise FileNotFoundError(f"--resume=true but {self.out} has no resume state ({RESUME_DIR}/)")
        load_model(self.policy, str(state / "model.safetensors"))
        self.optimizer = load_optimizer_state(self.optimizer, state)
        self.progress = Progress(**json.loads((state / "progress.json").read_text()))
        files = self.progress.replay_files
        if files and files[0][1] > self.progress.seeded_episodes:
            # Older chunks (and any dataset seed) were evicted by the FIFO: start the buffer where the first
            # kept chunk started, so every episode lands in the same slot as before the interruption.
            first = files[0][1]
            self.buffer.total_episodes_added = first
            self.buffer.next_slot = first % self.buffer.capacity
            self.buffer.num_episodes = min(first, self.buffer.capacity)
        elif self.cfg.dataset is not None:
            seed_buffer(self.buffer, self.cfg.dataset, stored_keys(self.keys))
        for name, _ in files:
            with np.load(self.out / REPLAY_DIR / name) as chunk:
                add_replay_chunk(self.buffer, dict(chunk))
        metrics = self.out / METRICS_FILE
        if metrics.exists():  # drop lines written after the state we resume from
            lines = [
                ln for ln in metrics.read_text().splitlines() if json.loads(ln)["cycle"] < self.progress.cycle
            ]
            metrics.write_text("".join(f"{ln}\n" for ln in lines))
        logging.info("resumed at cycle %d, step %d", self.progress.cycle, self.progress.step)

    def _append_replay(self, rollouts: list[Rollouts]) -> None:
        """Persist this cycle's episodes (one small file per cycle); files whose episodes the FIFO has
        already evicted are deleted, so disk use stays bounded by the buffer capacity."""
        chunk = {
            f"obs/{k}": np.concatenate([r.observations[k] for r in rollouts])
            for k in rollouts[0].observations
        }
        chunk["actions"] = np.concatenate([r.actions for r in rollouts])
        if rollouts[0].gt_achieved is not None:
            chunk["gt_achieved"] = np.concatenate([r.gt_achieved for r in rollouts])
            chunk["gt_desired"] = np.concatenate([r.gt_desired for r in rollouts])
        (self.out / REPLAY_DIR).mkdir(exist_ok=True)
        name = f"cycle_{self.progress.cycle:07d}.npz"
        np.savez(self.out / REPLAY_DIR / name, **chunk)
        first_index = self.buffer.total_episodes_added - chunk["actions"].shape[0]
        self.progress.replay_files.append((name, first_index))
        # A chunk is no longer needed once every one of its episodes has been evicted.
        oldest_kept = self.buffer.total_episodes_added - self.buffer.capacity
        while len(self.progress.replay_files) > 1 and self.progress.replay_files[1][1] <= oldest_kept:
            (self.out / REPLAY_DIR / self.progress.replay_files.pop(0)[0]).unlink(missing_ok=True)

    # ---------------- the loop ----------------
    def _episodes(self, seeds: list[int], explore: bool, **kwargs) -> Rollouts:
        return run_episodes(
            self.vec_env, self.policy, self.processors, stored_keys(self.keys), self.horizon,
            seeds=seeds, explore=explore, **kwargs,
        )  # fmt: skip

    def collect(self, cycle: int, generator: torch.Generator, warmup: bool) -> list[Rollouts]:
        """Behaviour-policy episodes; seeds from (seed, cycle), so a resumed run replays them exactly."""
        n = self.cfg.online.n_envs
        rollouts = []
        for r in range(self.rounds_per_cycle):
            base = cycle_seed(self.cfg.seed, cycle) % 10**8 * 64 + r * n
            seeds = [base + i for i in range(n)]
            random_eps = 1.0 if warmup else None
            rollouts.append(
                self._episodes(
                    seeds, True, generator=generator, random_eps=random_eps,
                    keep_dataset_frames=self.dataset is not None,
                )
            )  # fmt: skip
        return rollouts

    def evaluate(self) -> dict[str, float]:
        """Deterministic actor on a fixed set of goals (the same at every evaluation)."""
        n, n_eval = self.cfg.online.n_envs, self.cfg.online.eval_episodes
        seeds = range(0, n_eval, n)
        results = [self._episodes([EVAL_SEED_OFFSET + s + i for i in range(n)], False) for s in seeds]
        success = np.concatenate([r.success for r in results])[:n_eval]
        dist = np.concatenate([r.final_distance for r in results])[:n_eval]
        return {"eval_success_rate": float(success.mean()), "eval_final_distance": float(np.nanmean(dist))}

    def optimise(self, rng: np.random.Generator, generator: torch.Generator) -> dict[str, float]:
        self.policy.train()
        sums: dict[str, float] = {}
        data_s = update_s = (
            0.0  # wall time of the cycle sampling the buffer / updating (lerobot-train's split)
        )
        for _ in range(self.cfg.online.updates_per_cycle):
            t0 = time.perf_counter()
            batch = to_transition_batch(
                self.buffer.sample(self.batch_size, rng, packed=True), self.keys, self.horizon, self.device
            )
            t1 = time.perf_counter()
            loss, stats = self.policy.forward(batch, generator=generator)
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            self.optimizer.step()
            self.policy.update()
            self.progress.step += 1
            for k, v in stats.items():
                sums[k] = sums.get(k, 0.0) + v
            data_s, update_s = data_s + t1 - t0, update_s + time.perf_counter() - t1
        means = {k: v / self.cfg.online.updates_per_cycle for k, v in sums.items()}
        return {**means, "data_s": data_s, "update_s": update_s}

    def save_checkpoint(self) -> Path:
        """LeRobot-train layout, loadable by ``lerobot-eval --policy.path=<dir>/pretrained_model``."""
        check_module(self.policy, "checkpoint")
        ckpt = get_step_checkpoint_dir(self.out, self.cfg.steps, self.progress.step)
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
        update_last_checkpoint(ckpt)
        return ckpt

    def train(self) -> dict[str, float]:
        """Paper Algorithm 1: per cycle, collect episodes, store them, run the learning core's updates."""
        self._start()
        bar = tqdm(
            total=self.cfg.steps, initial=self.progress.step, desc="indicator_ddpg online", unit="step"
        )
        try:
            while self.progress.cycle < self.n_cycles:
                t0, cycle = time.perf_counter(), self.progress.cycle
                rng, generator = self._cycle_randomness(cycle)
                rollouts = self.collect(
                    cycle, generator, warmup=self.progress.episodes < self.cfg.online.warmup_episodes
                )
                self.store(rollouts)
                stats = self.optimise(rng, generator)  # relabel -> indicator reward -> filter -> DDPG update
                record = self._end_cycle(cycle, rollouts, stats, t0)
                bar.update(self.cfg.online.updates_per_cycle)
                bar.set_postfix(
                    env_steps=self.progress.env_steps,
                    success=f"{record.get('eval_success_rate', record['train_success_rate']):.2f}",
                    q=f"{stats.get('q_mean', float('nan')):.2f}",
                )
        finally:
            bar.close()  # before any error message, so that message is the last line
        return self._finish()

    def _start(self) -> None:
        cfg = self.cfg
        if cfg.resume:
            self._load_resume_state()
        else:
            self.progress.own_input_stats = cfg.policy.pretrained_path is None
        if not cfg.resume and cfg.dataset is not None:
            self.progress.seeded_episodes = seed_buffer(self.buffer, cfg.dataset, stored_keys(self.keys))
            self.progress.episodes = self.progress.seeded_episodes
            if self.progress.own_input_stats:
                self.policy.set_observation_stats(self.buffer.observation_stats())
        self._record_skip = self._episodes_recorded_ahead() if self.dataset is not None else 0
        self._record_checkpoint_t = -math.inf  # the first cycle always leaves a resume state
        self._last_eval: dict[str, float] = {}

    def _cycle_randomness(self, cycle: int) -> tuple[np.random.Generator, torch.Generator]:
        """Everything random in a cycle comes from (seed, cycle), so a resumed run replays it exactly."""
        torch.manual_seed(cycle_seed(self.cfg.seed, cycle))  # image augmentation draws from the global RNG
        generator = torch.Generator().manual_seed(cycle_seed(self.cfg.seed, cycle))
        return np.random.default_rng([self.cfg.seed, cycle]), generator

    def store(self, rollouts: list[Rollouts]) -> None:
        """New episodes into the replay buffer, its on-disk chunks and the --record dataset; input stats."""
        for r in rollouts:
            for episode in r.episodes():
                self.buffer.add_episode(*episode)
        if rollouts:
            self._append_replay(rollouts)
        if self.dataset is not None:
            self._record(rollouts)
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

    def _end_cycle(self, cycle: int, rollouts: list[Rollouts], stats: dict[str, float], t0: float) -> dict:
        """Evaluate, log, checkpoint and save the resume state as due; returns the cycle's metrics."""
        cfg = self.cfg
        prev_step = self.progress.step - cfg.online.updates_per_cycle
        is_last = cycle == self.n_cycles - 1

        def due(freq: int) -> bool:
            return is_last or (freq > 0 and self.progress.step // freq > prev_step // freq)

        success = np.concatenate([r.success for r in rollouts]) if rollouts else np.full(1, np.nan)
        distance = np.concatenate([r.final_distance for r in rollouts]) if rollouts else np.full(1, np.nan)
        record = {
            "cycle": cycle,
            "step": self.progress.step,
            "env_steps": self.progress.env_steps,
            "episodes": self.progress.episodes,
            "train_success_rate": float(np.mean(success)),
            "train_final_distance": float(np.nanmean(distance))
            if np.isfinite(distance).any()
            else float("nan"),
            **stats,
        }
        if due(cfg.env_eval_freq):
            self._last_eval = self.evaluate()
            record.update(self._last_eval)
        self.progress.cycle += 1
        self.progress.wall_time_s += time.perf_counter() - t0
        record["wall_time_s"] = self.progress.wall_time_s
        with open(self.out / METRICS_FILE, "a") as f:
            f.write(json.dumps(record) + "\n")
        if self.wandb is not None:
            evals = {k: v for k, v in record.items() if k.startswith("eval_")}
            self.wandb.log_dict({k: v for k, v in record.items() if k not in evals}, self.progress.step)
            if evals:
                self.wandb.log_dict(evals, self.progress.step, mode="eval")
        if cfg.save_checkpoint and due(cfg.save_freq):
            checkpoint = self.save_checkpoint()
            if self.wandb is not None:
                self.wandb.log_policy(checkpoint)
        self._save_state_if_due(is_last)
        return record

    def _finish(self) -> dict[str, float]:
        cfg = self.cfg
        curve = self.out / "learning_curve.png"
        plot_learning_curve(self.out / METRICS_FILE, curve, title=cfg.job_name)
        if self.wandb is not None:
            import wandb

            wandb.log({"train/learning_curve": wandb.Image(str(curve))}, step=self.progress.step)
        if self.dataset is not None:
            self.dataset.finalize()
            clear_checkpoint(self.record_cfg.root)  # complete and consistent: nothing to roll back to
            if cfg.record.push_to_hub:
                self.dataset.push_to_hub(tags=["lerobot-indicator", "indicator-rewards", cfg.env.type])
        if cfg.policy.push_to_hub:
            self.policy.push_model_to_hub(cfg)
            self.processors.pre.push_to_hub(cfg.policy.repo_id)
            self.processors.post.push_to_hub(cfg.policy.repo_id)
        return {**self._last_eval, "env_steps": self.progress.env_steps, "steps": self.progress.step}

    def close(self) -> None:
        """Also on a crash: finalize the recorded dataset so every saved episode stays readable (its
        checkpoint journal stays, so ``--resume=true`` rolls it back to the resume state)."""
        if self.dataset is not None:
            self.dataset.finalize()
        if self.wandb is not None:
            import wandb

            wandb.finish()
        close_envs({self.cfg.env.type: {0: self.vec_env}})


@parser.wrap()
def train(cfg: OnlineTrainConfig) -> dict[str, float]:
    cfg.validate()
    trainer = OnlineTrainer(cfg)
    try:
        return trainer.train()
    finally:
        trainer.close()


def main() -> None:
    init_logging()
    register_third_party_plugins()
    try:
        train()
    except NonFiniteError as e:
        logging.error(
            "stopped: %s. Nothing non-finite was saved; the last checkpoint and resume state are kept.", e
        )
        raise SystemExit(1) from None
    except KeyboardInterrupt:
        logging.error(
            "interrupted: the run continues from its resume/ state (the last completed cycle; with --record, the "
            "last dataset checkpoint) with the same command and --resume=true"
        )
        raise SystemExit(130) from None


if __name__ == "__main__":
    main()
