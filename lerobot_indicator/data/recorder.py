"""Record goal-conditioned episodes from a sim task into a LeRobotDataset (v3.0), optionally push to the Hub.

Frame ``t`` of an episode holds ``o_t`` (observation, goal observation, ground truth), ``a_t``, and
``next.reward``/``next.done`` of the transition ``o_t -a_t-> o_{t+1}``; LeRobot's usual layout, so
``lerobot-train`` reads ``o_{t+1}`` as the next frame. An episode of T steps has **T + 1 frames**: the
last one holds only the final observation ``o_T`` (zero action, reward 0, done), so that every one of
the T transitions has its ``o_{t+1}`` (for rope push, T = 3, dropping it would lose a third of the
data). ``indicator_ddpg`` never samples that frame as ``o_t`` (``drop_n_last_frames=1``). ``next.reward`` is the *indicator* reward:
R+ only if ``o_{t+1}`` equals the episode's goal observation bit for bit on the compared keys.
See docs/dataset_format.md.
"""

import contextlib
import json
import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import draccus
import numpy as np
import torch
from lerobot.configs import parser
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, HF_LEROBOT_HOME, OBS_IMAGES
from lerobot.utils.utils import init_logging
from tqdm import tqdm

import lerobot_indicator.envs  # noqa: F401  (registers the task EnvConfigs with draccus)
from lerobot_indicator.data.action_sources import make_action_source
from lerobot_indicator.data.checkpoint import clear_checkpoint, restore_checkpoint, write_checkpoint
from lerobot_indicator.data.features import (
    DONE,
    REWARD,
    batch,
    dataset_features,
    observation_frame,
    unbatch,
)
from lerobot_indicator.keys import goal_key, is_goal_key, is_ground_truth_key
from lerobot_indicator.policy.indicator_core import indicator_reward


@dataclass
class RecordConfig:
    env: EnvConfig
    # Dataset id on the Hub ("user/name") and local directory (default $HF_LEROBOT_HOME/<repo_id>).
    repo_id: str | None = None
    root: Path | None = None
    # random | scripted | noisy_scripted | path of a pretrained policy directory.
    policy: str = "scripted"
    num_episodes: int = 10
    # Continue an existing dataset at root (required if it exists; nothing is ever overwritten).
    resume: bool = False
    # False: lossless PNG/TIFF frames (exact indicator comparisons). True: MP4 (lossy, small).
    use_videos: bool = False
    seed: int = 0
    # Gaussian action noise (action units) of noisy_scripted.
    noise_std: float = 0.3
    # Observation keys the indicator reward compares; default: the cameras if any, else the state.
    reward_keys: list[str] | None = None
    r_pos: float = 1.0
    r_neg: float = -1.0
    # Finalize + journal at most this often (seconds; 0 = after every episode). A *killed* recorder
    # loses at most the episodes since the last checkpoint; Ctrl-C and exceptions lose none.
    checkpoint_every_s: float = 30.0
    # Threads writing PNG/TIFF frames in the background (LeRobot's AsyncImageWriter; 0 = inline).
    image_writer_threads: int = 4
    push_to_hub: bool = False
    private: bool = False
    tags: list[str] = field(default_factory=list)
    license: str = "apache-2.0"
    device: str = "cpu"

    def __post_init__(self):
        if not self.repo_id:
            raise ValueError("repo_id is required, e.g. --repo_id=<user>/sawyer_reach_scripted")
        if self.num_episodes <= 0:
            raise ValueError(f"num_episodes must be > 0, got {self.num_episodes}")
        if self.image_writer_threads < 0:
            raise ValueError(f"image_writer_threads must be >= 0, got {self.image_writer_threads}")
        if self.checkpoint_every_s < 0:
            raise ValueError(f"checkpoint_every_s must be >= 0, got {self.checkpoint_every_s}")
        if self.r_pos <= self.r_neg:
            raise ValueError(f"r_pos ({self.r_pos}) must be > r_neg ({self.r_neg})")
        self.root = Path(self.root) if self.root else HF_LEROBOT_HOME / self.repo_id


def make_single_env(env_cfg: EnvConfig):
    """One env behind LeRobot's own ``create_envs`` (so task EnvConfig overrides are honoured)."""
    envs = env_cfg.create_envs(n_envs=1, use_async_envs=False)
    return next(iter(next(iter(envs.values())).values()))


def default_reward_keys(features: dict) -> list[str]:
    """The compared keys: every non-goal camera if the env renders any, else every non-goal vector."""
    observed = [k for k in features if k.startswith("observation.") and not is_ground_truth_key(k)]
    compared = [k for k in observed if not is_goal_key(k) and goal_key(k) in features]
    cameras = [k for k in compared if k.startswith(f"{OBS_IMAGES}.")]
    return cameras or compared


def _comparable(features: dict) -> dict:
    return {k: (v["dtype"], tuple(v["shape"])) for k, v in features.items()}


def _task_description(vec_env, env_cfg: EnvConfig) -> str:
    with contextlib.suppress(AttributeError, NotImplementedError):
        return str(vec_env.call("task_description")[0])
    return env_cfg.task or env_cfg.type


def _episode_length(vec_env, env_cfg: EnvConfig) -> int:
    """Horizon T: the env's time limit (as lerobot-eval reads it), else ``env.episode_length``."""
    with contextlib.suppress(AttributeError):
        limit = vec_env.call("_max_episode_steps")[0]
        if limit:
            return int(limit)
    limit = getattr(env_cfg, "episode_length", None)
    if not limit or limit <= 0:
        raise ValueError(f"env {env_cfg.type!r} has no time limit (max_episode_steps or episode_length)")
    return int(limit)


def _check_root(cfg: RecordConfig) -> None:
    """Fail before building anything: never overwrite, never resume nothing."""
    if not cfg.resume and cfg.root.exists():
        raise FileExistsError(
            f"{cfg.root} already exists: pass --resume=true to add episodes to it, or choose another "
            "--root/--repo_id (nothing was overwritten)"
        )
    if cfg.resume and not (cfg.root / "meta" / "info.json").exists():
        raise FileNotFoundError(f"--resume=true but there is no dataset at {cfg.root}")


def _resume(cfg: RecordConfig) -> LeRobotDataset:
    return LeRobotDataset.resume(
        cfg.repo_id, root=cfg.root, video_backend="pyav", image_writer_threads=cfg.image_writer_threads
    )


def checkpoint_dataset(cfg: RecordConfig, dataset: LeRobotDataset) -> LeRobotDataset:
    """Finalize, journal that consistent state (a later kill rolls back to it), reopen for more episodes."""
    dataset.finalize()
    write_checkpoint(cfg.root, dataset.meta.total_episodes)
    return _resume(cfg)


def open_dataset(cfg: RecordConfig, features: dict) -> LeRobotDataset:
    root = cfg.root
    _check_root(cfg)
    if not cfg.resume:
        return LeRobotDataset.create(
            cfg.repo_id,
            fps=cfg.env.fps,
            features=features,
            root=root,
            use_videos=cfg.use_videos,
            video_backend="pyav",
            image_writer_threads=cfg.image_writer_threads,
        )
    restore_checkpoint(root)  # no-op unless the last recording was killed
    dataset = _resume(cfg)
    existing = {k: v for k, v in dataset.meta.features.items() if k in features}
    if _comparable(existing) != _comparable(features) or set(features) - set(dataset.meta.features):
        dataset.finalize()
        raise ValueError(
            f"the dataset at {root} was recorded with other features than --env gives now "
            f"({sorted(set(_comparable(existing).items()) ^ set(_comparable(features).items()))})"
        )
    if dataset.meta.video_keys and not cfg.use_videos or (cfg.use_videos and not dataset.meta.video_keys):
        dataset.finalize()
        raise ValueError(f"--use_videos={cfg.use_videos} does not match the dataset at {root}")
    return dataset


def _dataset_card(cfg: RecordConfig) -> str:
    env_yaml = draccus.dump(cfg.env)
    return (
        f"Goal-conditioned episodes of the **{cfg.env.type}** task recorded with lerobot-indicator's "
        f"`scripts/record.py` (policy: `{cfg.policy}`, seed {cfg.seed}) for *Reinforcement Learning "
        "without Ground-Truth State* (Lin, Baweja, Held, CoRL 2019). `next.reward` is the indicator "
        f"reward ({cfg.r_pos} iff the next observation equals the goal observation bit for bit on "
        f"{cfg.reward_keys}, else {cfg.r_neg}); `observation.gt_*` are ground truth for evaluation only.\n\n"
        f"Env config:\n\n```yaml\n{env_yaml}```\n"
    )


def record(cfg: RecordConfig) -> LeRobotDataset:
    """Record ``cfg.num_episodes`` episodes; returns the finalized dataset."""
    _check_root(cfg)
    vec_env = make_single_env(cfg.env)
    try:
        obs, info = vec_env.reset(seed=cfg.seed)
        features = dataset_features(
            vec_env.single_observation_space, vec_env.single_action_space, unbatch(info), cfg.use_videos
        )
        cfg.reward_keys = cfg.reward_keys or default_reward_keys(features)
        unknown = [k for k in cfg.reward_keys if k not in features or goal_key(k) not in features]
        if unknown:
            raise ValueError(
                f"reward_keys {unknown} are not observation keys with a goal in {sorted(features)}"
            )
        actions = make_action_source(cfg.policy, cfg.env, vec_env, cfg.seed, cfg.noise_std, cfg.device)
        # One dry call, so a policy that cannot drive this env fails before the dataset exists.
        actions.reset()
        dry = np.asarray(actions(obs, info))
        if dry.size != int(np.prod(vec_env.action_space.shape)):
            raise ValueError(
                f"policy {cfg.policy!r} gives actions of shape {dry.shape}, env expects {vec_env.action_space.shape}"
            )
        dataset = open_dataset(cfg, features)
        dataset = _record_episodes(cfg, vec_env, actions, dataset)
    finally:
        vec_env.close()
    if cfg.push_to_hub:
        dataset.push_to_hub(
            tags=["lerobot-indicator", "indicator-rewards", cfg.env.type, *cfg.tags],
            license=cfg.license,
            private=cfg.private,
            dataset_description=_dataset_card(cfg),
        )
    return dataset


def _record_episodes(cfg: RecordConfig, vec_env, actions, dataset: LeRobotDataset) -> LeRobotDataset:
    task = _task_description(vec_env, cfg.env)
    stepper = EpisodeStepper(vec_env)
    first = dataset.meta.total_episodes
    write_checkpoint(cfg.root, first)
    saving, last_checkpoint, frames, t0 = False, time.monotonic(), 0, time.monotonic()
    bar = tqdm(range(first, first + cfg.num_episodes), desc=f"recording {cfg.repo_id}", unit="episode")
    try:
        for episode in bar:
            frames += _record_episode(cfg, stepper, actions, dataset, task, seed=cfg.seed + episode)
            saving = True
            dataset.save_episode()
            saving = False
            bar.set_postfix(frames=frames, fps=f"{frames / (time.monotonic() - t0):.1f}")
            if (
                time.monotonic() - last_checkpoint >= cfg.checkpoint_every_s
                and episode + 1 < first + cfg.num_episodes
            ):
                dataset = checkpoint_dataset(cfg, dataset)
                last_checkpoint = time.monotonic()
    except BaseException:
        if not saving and dataset.has_pending_frames():
            dataset.clear_episode_buffer()  # the interrupted episode is dropped, saved ones are kept
        raise
    finally:
        bar.close()
        dataset.finalize()
        if not saving:  # consistent now: the journal is only needed after a kill or a failed save
            clear_checkpoint(cfg.root)
    logging.info(
        "recorded %d frames in %.1f s (%.1f frames/s)",
        frames,
        time.monotonic() - t0,
        frames / (time.monotonic() - t0),
    )
    return dataset


class EpisodeStepper:
    """Steps the one env of a ``SyncVectorEnv`` directly, keeping the vector env's batch axis.

    A vector env auto-resets after the last step (for rope push: simulating three random pushes) only
    to have the recorder reset it again with the next episode's seed; stepping the env itself avoids
    that wasted reset. Other vector envs are stepped as such, the final observation taken from
    ``info["final_obs"]``.
    """

    def __init__(self, vec_env):
        envs = getattr(vec_env, "envs", None)
        self.vec_env = vec_env
        self.env = envs[0] if envs is not None and len(envs) == 1 else None

    def reset(self, seed: int) -> tuple[dict, dict]:
        if self.env is None:
            return self.vec_env.reset(seed=seed)
        obs, info = self.env.reset(seed=seed)
        return batch(obs), batch(info)

    def step(self, action: np.ndarray) -> tuple[dict, dict, bool]:
        """Batched ``(observation, info, done)`` after ``action`` (shape (1, action_dim))."""
        if self.env is None:
            obs, _, terminated, truncated, info = self.vec_env.step(action)
            done = bool(terminated[0] or truncated[0])
            if done and "final_obs" in info:
                return info["final_obs"], info["final_info"], done
            return obs, info, done
        obs, _, terminated, truncated, info = self.env.step(action[0])
        return batch(obs), batch(info), bool(terminated or truncated)


def write_episode(
    dataset: LeRobotDataset,
    frames: list[dict[str, np.ndarray]],
    actions: list[np.ndarray],
    reward_keys: list[str],
    task: str,
    r_pos: float = 1.0,
    r_neg: float = -1.0,
) -> int:
    """Add one episode (``T + 1`` observation frames ``o_0..o_T``, ``T`` actions) to ``dataset``'s
    episode buffer (the caller saves it); returns the number of frames added. ``next.reward`` is the indicator reward of the
    recorded goal. Shared by this recorder and the online trainer's ``--record.*``."""
    if len(frames) != len(actions) + 1:
        raise ValueError(
            f"an episode needs T + 1 observations for T actions, got {len(frames)} and {len(actions)}"
        )
    goal = {k: torch.from_numpy(np.ascontiguousarray(frames[0][goal_key(k)]))[None] for k in reward_keys}
    horizon = len(actions)
    for t, action in enumerate(actions):
        reached = {k: torch.from_numpy(np.ascontiguousarray(frames[t + 1][k]))[None] for k in reward_keys}
        reward = float(indicator_reward(reached, goal, r_pos, r_neg)[0])
        dataset.add_frame(
            {
                **frames[t],
                ACTION: np.asarray(action, dtype=np.float32),
                REWARD: np.array([reward], dtype=np.float32),
                DONE: np.array([t == horizon - 1], dtype=bool),
                "task": task,
            }
        )
    # The final observation o_T as its own frame (see the module docstring).
    final_action = np.zeros_like(np.asarray(actions[0], dtype=np.float32))
    dataset.add_frame(
        {
            **frames[-1],
            ACTION: final_action,
            REWARD: np.zeros(1, dtype=np.float32),
            DONE: np.ones(1, dtype=bool),
            "task": task,
        }
    )
    return horizon + 1


def _record_episode(
    cfg: RecordConfig, stepper: EpisodeStepper, actions, dataset: LeRobotDataset, task: str, seed: int
) -> int:
    obs, info = stepper.reset(seed)
    actions.reset()
    frames = [observation_frame(unbatch(obs), unbatch(info))]
    taken = []
    max_steps = _episode_length(stepper.vec_env, cfg.env)
    done = False
    while not done:
        action = np.asarray(actions(obs, info), dtype=np.float32).reshape(stepper.vec_env.action_space.shape)
        obs, info, done = stepper.step(action)
        done = done or len(taken) + 1 >= max_steps
        frames.append(observation_frame(unbatch(obs), unbatch(info)))
        taken.append(action[0])
    return write_episode(dataset, frames, taken, cfg.reward_keys, task, cfg.r_pos, cfg.r_neg)


@parser.wrap()
def main(cfg: RecordConfig) -> None:
    init_logging()
    logging.info("record config:\n%s", json.dumps(asdict(cfg), default=str, indent=2))
    dataset = record(cfg)
    logging.info(
        "dataset at %s: %d episodes, %d frames",
        dataset.root,
        dataset.meta.total_episodes,
        dataset.meta.total_frames,
    )


if __name__ == "__main__":
    main()
