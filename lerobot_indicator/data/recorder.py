"""Record goal-conditioned episodes from a sim task into a LeRobotDataset (v3.0), optionally push to the Hub.

Frame ``t`` of an episode holds ``o_t`` (observation, goal observation, ground truth), ``a_t``, and
``next.reward``/``next.done`` of the transition ``o_t -a_t-> o_{t+1}``; LeRobot's usual layout, so
``lerobot-train`` reads ``o_{t+1}`` as the next frame. An episode of T steps has **T + 1 frames**: the
last one holds only the final observation ``o_T`` (reward 0, done; no action follows ``o_T``, so its
action repeats ``a_{T-1}``, LeRobot's own padding, and ``complementary_info.action_is_pad`` marks it), so
that every one of the T transitions has its ``o_{t+1}`` (for rope push, T = 3, dropping it would lose a
third of the data). ``indicator_ddpg`` never samples that frame as ``o_t`` (``drop_n_last_frames=1``). ``next.reward`` is the *indicator* reward:
R+ only if ``o_{t+1}`` equals the episode's goal observation bit for bit on the compared keys.
See docs/dataset_format.md.

Every saved episode is committed to ``--root`` before the next one starts (data/checkpoint.py, also
behind the online trainer's ``--record.*``): the dataset there is complete and readable by
``LeRobotDataset`` at every instant, so an interruption of any kind (Ctrl-C, SIGTERM, SIGKILL, a crash)
loses at most the episode in flight, and ``--resume=true`` never removes a saved episode.
"""

import contextlib
import json
import logging
import re
import shlex
import signal
import sys
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import draccus
import numpy as np
import pyarrow.parquet as pq
import torch
import yaml
from lerobot.configs import parser
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.datasets.utils import create_lerobot_dataset_card
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, HF_LEROBOT_HOME, OBS_IMAGES
from lerobot.utils.utils import init_logging
from tqdm import tqdm

import lerobot_indicator.envs  # noqa: F401  (registers the task EnvConfigs with draccus)
from lerobot_indicator.data.action_sources import episode_seed, make_action_source
from lerobot_indicator.data.checkpoint import (
    INFO,
    JOURNAL_DIR,
    CorruptFrameError,
    StagedRecording,
    committed_counts,
    discard_stage,
    recover_recording,
    write_atomic,
)
from lerobot_indicator.data.features import (
    DONE,
    REWARD,
    batch,
    dataset_features,
    env_feature_names,
    env_robot_type,
    observation_frame,
    unbatch,
)
from lerobot_indicator.data.storage import check_depth_range
from lerobot_indicator.io_errors import report_line
from lerobot_indicator.keys import ACTION_IS_PAD, goal_key, is_goal_key, is_ground_truth_key
from lerobot_indicator.policy.indicator_core import indicator_reward
from lerobot_indicator.stop_signals import Interrupted, exit_code

# A Hub dataset id: namespace/name, each of letters, digits, '-', '_', '.' (not at either end, no '..' or
# '--'), so $HF_LEROBOT_HOME/<repo_id> stays a directory two levels inside $HF_LEROBOT_HOME.
_REPO_PART = r"[A-Za-z0-9](?:[A-Za-z0-9._-]{0,94}[A-Za-z0-9])?"
REPO_ID = re.compile(rf"{_REPO_PART}/{_REPO_PART}")


def check_repo_id(repo_id: str, flag: str = "repo_id") -> None:
    """``repo_id`` is a Hub dataset id ``namespace/name`` (``flag``: the option named in the error)."""
    if not REPO_ID.fullmatch(repo_id) or ".." in repo_id or "--" in repo_id:
        raise ValueError(
            f"{flag}={repo_id!r} is not a Hub dataset id 'namespace/name' (letters, digits, '-', '_', '.'; "
            "e.g. <user>/sawyer_reach_scripted)"
        )


@dataclass
class RecordConfig:
    env: EnvConfig
    # Dataset id on the Hub ("user/name") and local directory (default $HF_LEROBOT_HOME/<repo_id>).
    repo_id: str | None = None
    root: Path | None = None
    # random | scripted | noisy_scripted | path of a pretrained policy directory.
    policy: str = "scripted"
    num_episodes: int = 10  # to record in this run (with resume: to add)
    # Continue an existing dataset at root (required if it exists; nothing is ever overwritten).
    resume: bool = False
    # False: PNG/TIFF frames inside the parquet rows. True: lossless HEVC video (data/storage.py), the same
    # decoded frames; lerobot-train then decodes no image columns in its row reads (docs/dataset_format.md).
    use_videos: bool = False
    seed: int = 0  # episode e resets the env with seed + e
    # Gaussian action noise (action units) of noisy_scripted.
    noise_std: float = 0.3
    # Observation keys the indicator reward compares; default: the cameras if any, else the state.
    reward_keys: list[str] | None = None
    r_pos: float = 1.0
    r_neg: float = -1.0
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
        check_repo_id(self.repo_id)
        if self.num_episodes <= 0:
            raise ValueError(f"num_episodes must be > 0, got {self.num_episodes}")
        if self.image_writer_threads < 0:
            raise ValueError(f"image_writer_threads must be >= 0, got {self.image_writer_threads}")
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


# The recorder settings a dataset is recorded with (env config and reward definition), checked on --resume.
SETTINGS_FILE = "meta/recording.json"
# EnvConfig fields about how envs are run, not what they produce.
_RUNNER_FIELDS = ("features", "features_map", "max_parallel_tasks", "disable_env_checker")


class RecordingError(Exception):
    """An error the CLI reports as one line (no traceback)."""


class SettingsMismatchError(RecordingError, ValueError):
    """``--resume`` with settings other than those the dataset was recorded with."""


class RecordingInterrupted(Interrupted):
    """Recording stopped by SIGINT/SIGTERM (or Ctrl-C); every committed episode is kept."""

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signum)
        self.target_episodes: int | None = None  # the episode count the run was asked to reach
        self.dropped_episode: int | None = None  # the episode being stepped, if any


class _StopSignals:
    """SIGINT/SIGTERM while recording. Outside :meth:`deferred` they interrupt at once (the episode in
    flight is dropped); inside it (saving and committing an episode, finishing) they are held until the
    block is done, so a signal never costs a complete episode; a second signal interrupts at once."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.pending: int | None = None
        self._deferring = False
        self._previous: dict = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():  # signal handlers live in the main thread
            self._previous = {sig: signal.signal(sig, self._handle) for sig in self.SIGNALS}
        return self

    def __exit__(self, *exc):
        for sig, handler in self._previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)

    def _handle(self, signum, frame):
        if self._deferring and self.pending is None:
            self.pending = signum
            return
        raise RecordingInterrupted(signum)

    @contextlib.contextmanager
    def deferred(self):
        self._deferring = True
        try:
            yield
        except Exception as err:  # e.g. video encoder workers killed by the same Ctrl-C
            if self.pending is not None:
                raise RecordingInterrupted(self.pending) from err
            raise
        finally:
            self._deferring = False

    def check(self) -> None:
        if self.pending is not None:
            raise RecordingInterrupted(self.pending)


def env_settings(env: EnvConfig) -> dict:
    """The env config as plain JSON/YAML values, without the fields about how envs are run."""
    fields = {k: v for k, v in draccus.encode(env).items() if k not in _RUNNER_FIELDS}
    return json.loads(json.dumps({"type": env.type, **fields}, default=str))


def recording_settings(cfg: RecordConfig) -> dict:
    """What a dataset's episodes depend on besides the policy and seed: the env config and the reward."""
    settings = {
        "env": env_settings(cfg.env),
        "reward_keys": sorted(cfg.reward_keys or []),
        "r_pos": cfg.r_pos,
        "r_neg": cfg.r_neg,
    }
    return json.loads(json.dumps(settings, default=str))


def _write_settings(cfg: RecordConfig) -> None:
    write_atomic(cfg.root / SETTINGS_FILE, json.dumps(recording_settings(cfg), indent=2) + "\n")


def _flatten(settings: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in settings.items():
        if isinstance(value, dict) and value:
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def _leftover_only(root: Path) -> bool:
    """``root`` holds nothing but the stage of a recording killed before it published anything."""
    return root.is_dir() and not (root / INFO).exists() and {p.name for p in root.iterdir()} <= {JOURNAL_DIR}


def check_root(cfg: RecordConfig) -> None:
    """Fail before building anything: never overwrite, never resume nothing."""
    if _leftover_only(cfg.root):  # nothing was saved there: as if it did not exist
        discard_stage(cfg.root)
        if not any(cfg.root.iterdir()):
            cfg.root.rmdir()
    if not cfg.resume and cfg.root.exists():
        raise FileExistsError(
            f"{cfg.root} already exists: pass --resume=true to add episodes to it, or choose another "
            "--root/--repo_id (nothing was overwritten)"
        )
    if cfg.resume and not (cfg.root / INFO).exists():
        raise FileNotFoundError(f"--resume=true but there is no dataset at {cfg.root}")


def _last_episode_length(root: Path) -> int | None:
    files = sorted((root / "meta" / "episodes").glob("*/*.parquet"))
    if not files:
        return None
    lengths = pq.read_table(files[-1], columns=["length"]).column("length").to_pylist()
    return int(lengths[-1]) if lengths else None


def _check_resume(cfg: RecordConfig, features: dict, horizon: int | None) -> None:
    """Refuse to add episodes that differ in kind from the dataset's: other features, storage, env
    settings or reward definition. Nothing is written on refusal."""
    root = cfg.root
    info = json.loads((root / INFO).read_text())
    stored = info["features"]
    if ACTION_IS_PAD not in stored:  # a dataset without the final-frame marker goes on without it
        features = {k: v for k, v in features.items() if k != ACTION_IS_PAD}
    existing = {k: v for k, v in stored.items() if k in features}
    if _comparable(existing) != _comparable(features) or set(features) - set(stored):
        raise SettingsMismatchError(
            f"the dataset at {root} was recorded with other features than --env gives now "
            f"({sorted(set(_comparable(existing).items()) ^ set(_comparable(features).items()))})"
        )
    has_videos = any(v["dtype"] == "video" for v in stored.values())
    if has_videos != cfg.use_videos:
        raise SettingsMismatchError(
            f"--use_videos={cfg.use_videos} does not match the dataset at {root} (use_videos={has_videos})"
        )
    given = _flatten(recording_settings(cfg))
    settings_path = root / SETTINGS_FILE
    if settings_path.exists():
        recorded = _flatten(json.loads(settings_path.read_text()))
    else:  # recorded without a settings file: fps and horizon are what the dataset itself tells
        recorded = {"env.fps": info["fps"]}
        length = _last_episode_length(root)
        if horizon is not None and length is not None:
            recorded["env.episode_length"] = length - 1
            given = {**given, "env.episode_length": horizon}
        given = {k: given[k] for k in recorded}
    unset = "<unset>"
    diffs = [
        f"{key}: dataset {json.dumps(recorded.get(key, unset))}, given {json.dumps(given.get(key, unset))}"
        for key in sorted(set(recorded) | set(given))
        if recorded.get(key, unset) != given.get(key, unset)
    ]
    if diffs:
        raise SettingsMismatchError(
            f"--resume: the dataset at {root} was recorded with other settings ({'; '.join(diffs)}); "
            "record into another --root to use other settings"
        )
    if not settings_path.exists():
        if info["total_episodes"] == 0:
            _write_settings(cfg)  # nothing recorded yet: this run's settings become the dataset's
        else:
            logging.warning("%s has no %s: only fps and the horizon were checked", root, SETTINGS_FILE)


def open_recording(
    cfg: RecordConfig, features: dict, horizon: int | None, robot_type: str | None = None
) -> StagedRecording:
    """The dataset at ``cfg.root`` behind data/checkpoint.py's per-episode commits: created (``robot_type``
    into its ``meta/info.json``), or with ``cfg.resume`` recovered from any interruption, checked against
    this run's settings and reopened. Used by :func:`record` and the online trainer's ``--record.*``."""
    check_root(cfg)
    if not cfg.resume:
        session = StagedRecording.create(
            cfg.root, cfg.repo_id, cfg.env.fps, features, cfg.use_videos, cfg.image_writer_threads,
            robot_type=robot_type,
        )  # fmt: skip
        _write_settings(cfg)
        return session
    recover_recording(cfg.root)  # finish a commit cut short, drop the episode that was being saved
    _check_resume(cfg, features, horizon)
    return StagedRecording.resume(cfg.root, cfg.repo_id, cfg.image_writer_threads)


PAPER = "https://arxiv.org/abs/1905.07866"
CITATION_BIBTEX = """@inproceedings{lin2019reinforcement,
  title     = {Reinforcement Learning without Ground-Truth State},
  author    = {Lin, Xingyu and Baweja, Harjatin Singh and Held, David},
  booktitle = {Conference on Robot Learning (CoRL)},
  year      = {2019},
  eprint    = {1905.07866},
  archivePrefix = {arXiv}
}"""
# What simulates each robot the tasks use (meta/info.json's robot_type).
SIMULATORS = {
    "sawyer": "MuJoCo, in a scene composed from robosuite's Sawyer, gripper and table models",
    "fetch": "MuJoCo, through gymnasium-robotics' Fetch environment",
    "reacher": "MuJoCo, through gymnasium's Reacher-v5 environment",
}
# RecordConfig fields that do not change what is recorded (left out of the card's command).
_NOT_IN_COMMAND = (
    "env", "repo_id", "root", "resume", "num_episodes", "image_writer_threads", "push_to_hub", "private", "tags",
    "license", "device",
)  # fmt: skip


def _arg(name: str, value) -> str:
    text = json.dumps(value) if isinstance(value, list | bool) or value is None else str(value)
    return shlex.quote(f"--{name}={text}")


def env_args(env: EnvConfig) -> list[str]:
    """``--env.type`` and every ``--env.*`` field that differs from the default of its config."""
    settings, defaults = _flatten(env_settings(env)), _flatten(env_settings(type(env)()))
    args = [_arg("env.type", settings.pop("type"))]
    return args + [_arg(f"env.{k}", v) for k, v in settings.items() if v != defaults.get(k, object())]


def record_command(cfg: RecordConfig, num_episodes: int) -> str:
    """The ``lerobot-indicator-record`` command that records such a dataset in one run: every env field
    and recorder setting that differs from its default."""
    args = env_args(cfg.env)
    given, default = asdict(cfg), asdict(RecordConfig(env=cfg.env, repo_id=cfg.repo_id))
    args += [_arg(k, v) for k, v in given.items() if k not in _NOT_IN_COMMAND and v != default[k]]
    args += [_arg("num_episodes", num_episodes), _arg("repo_id", cfg.repo_id)]
    return "lerobot-indicator-record " + " ".join(args)


def _sensors(features: dict, env: dict) -> list[str]:
    """One line per recorded observation (not the goal copies): what kind of sensor and its size."""
    lines = []
    camera = env.get("camera") or {}
    depth_range = (
        f", valid {camera['depth_min_m']}-{camera['depth_max_m']} m, 0 = no reading"
        if "depth_min_m" in camera
        else ""
    )
    for key, ft in features.items():
        if not key.startswith("observation.") or is_goal_key(key):
            continue
        shape = "x".join(str(n) for n in ft["shape"])
        if ft["dtype"] in ("image", "video") and (ft.get("info") or {}).get("is_depth_map", False):
            kind = f"simulated depth camera, {shape} uint16 millimetres{depth_range}"
        elif ft["dtype"] in ("image", "video"):
            kind = f"simulated RGB camera, {shape} uint8"
        elif is_ground_truth_key(key):
            kind = f"ground truth from the simulator ({shape}), for evaluation only, never a policy input"
        else:
            names = ft.get("names") or []
            shown = ", ".join(names[:6]) + (", ..." if len(names) > 6 else "")
            kind = f"float32 vector ({shape}: {shown})"
        lines.append(f"- `{key}`: {kind}")
    return lines


def dataset_card(dataset: LeRobotDataset, cfg: RecordConfig, command: str) -> dict[str, str]:
    """LeRobot's dataset card fields (``push_to_hub``'s card keywords): description, paper, citation."""
    env = recording_settings(cfg)["env"]
    robot = dataset.meta.robot_type
    simulator = SIMULATORS.get(robot, "MuJoCo")
    goal_keys = [k for k in dataset.meta.features if is_goal_key(k)]
    final_frame = (
        f"its action repeats the previous one (LeRobot's padding) and `{ACTION_IS_PAD}` is true on it alone"
        if ACTION_IS_PAD in dataset.meta.features
        else "its action is padding (zeros or a repeat of the previous action), with no marker"
    )
    description = "\n".join(
        [
            f"Goal-conditioned episodes of the **{cfg.env.type}** task (robot: {robot}), **simulated** with "
            f"{simulator}, for *Reinforcement Learning without Ground-Truth State* (Lin, Baweja, Held, CoRL "
            "2019). Every frame also holds the episode's goal observation "
            f"({', '.join(f'`{k}`' for k in goal_keys)}), rendered in the goal configuration.",
            "",
            f"Recorded with (policy: `{cfg.policy}`, seed {cfg.seed}):",
            "",
            f"```bash\n{command}\n```",
            "",
            "Sensors (per frame):",
            "",
            *_sensors(dataset.meta.features, env),
            "",
            f"`next.reward` is the indicator reward ({cfg.r_pos} iff the next observation equals the goal "
            f"observation bit for bit on {cfg.reward_keys}, else {cfg.r_neg}). An episode of T steps has T + 1 "
            f"frames: the last holds the final observation o_T, which no action follows; {final_frame}.",
            "",
            "Limitations: the data is **synthetic** (rendered by a simulator, not a real robot's cameras): no sensor "
            "noise, latency or calibration error, so a policy trained on it alone is not ready for a real robot.",
            "",
            "Env config:",
            "",
            f"```yaml\n{yaml.safe_dump(env, sort_keys=False)}```",
        ]
    )
    return {"dataset_description": description, "paper": PAPER, "citation_bibtex": CITATION_BIBTEX}


def card_tags(cfg: RecordConfig, extra: list[str] | None = None) -> list[str]:
    return list(
        dict.fromkeys(["lerobot-indicator", "indicator-rewards", cfg.env.type, *cfg.tags, *(extra or [])])
    )


def write_card(
    dataset: LeRobotDataset, cfg: RecordConfig, command: str, extra_tags: list[str] | None = None
) -> None:
    """The dataset card ``push_dataset`` puts on the Hub, also as the local ``README.md`` (written atomically),
    so a dataset that is never pushed still says what it holds."""
    card = create_lerobot_dataset_card(
        tags=card_tags(cfg, extra_tags), dataset_info=dataset.meta.info, license=cfg.license, repo_id=cfg.repo_id,
        **dataset_card(dataset, cfg, command),
    )  # fmt: skip
    write_atomic(Path(dataset.root) / "README.md", str(card))


def push_dataset(
    dataset: LeRobotDataset, cfg: RecordConfig, command: str, extra_tags: list[str] | None = None
) -> None:
    """``LeRobotDataset.push_to_hub`` with this project's tags and dataset card."""
    dataset.push_to_hub(
        tags=card_tags(cfg, extra_tags),
        license=cfg.license,
        private=cfg.private,
        **dataset_card(dataset, cfg, command),
    )


def record(cfg: RecordConfig) -> LeRobotDataset:
    """Record ``cfg.num_episodes`` episodes; returns the finalized dataset at ``cfg.root``.

    Raises :class:`RecordingInterrupted` (a ``KeyboardInterrupt``) on SIGINT/SIGTERM, after the episode
    being saved (if any) is committed; the episode being stepped is dropped.
    """
    check_root(cfg)
    vec_env = make_single_env(cfg.env)
    target, session = None, None
    try:
        with _StopSignals() as stop:
            obs, info = vec_env.reset(seed=cfg.seed)
            features = dataset_features(
                vec_env.single_observation_space, vec_env.single_action_space, unbatch(info), cfg.use_videos,
                env_feature_names(vec_env),
            )  # fmt: skip
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
            session = open_recording(
                cfg, features, _episode_length(vec_env, cfg.env), env_robot_type(vec_env)
            )
            target = session.total_episodes + cfg.num_episodes
            clean = False
            try:
                _record_episodes(cfg, vec_env, actions, session, stop)
                clean = True
            finally:
                with stop.deferred():
                    session.close(clean)
            stop.check()
    except KeyboardInterrupt as exc:
        interrupted = exc if isinstance(exc, RecordingInterrupted) else RecordingInterrupted()
        interrupted.target_episodes = target
        interrupted.dropped_episode = getattr(exc, "dropped_episode", None)
        if interrupted is exc:
            raise
        raise interrupted from exc
    finally:
        vec_env.close()
    dataset = session.committed_dataset()
    command = record_command(cfg, dataset.meta.total_episodes)
    write_card(dataset, cfg, command)
    if cfg.push_to_hub:
        push_dataset(dataset, cfg, command)
    return dataset


def _record_episodes(
    cfg: RecordConfig, vec_env, actions, session: StagedRecording, stop: _StopSignals
) -> None:
    task = _task_description(vec_env, cfg.env)
    stepper = EpisodeStepper(vec_env)
    first = session.total_episodes
    frames, t0 = 0, time.monotonic()
    bar = tqdm(range(first, first + cfg.num_episodes), desc=f"recording {cfg.repo_id}", unit="episode")
    try:
        for episode in bar:
            try:
                frames += _record_episode(cfg, stepper, actions, session.dataset, task, episode)
            except KeyboardInterrupt as exc:
                exc.dropped_episode = episode  # for the CLI's last line
                raise
            with stop.deferred():
                session.save_episode()
            stop.check()
            bar.set_postfix(frames=frames, fps=f"{frames / (time.monotonic() - t0):.1f}")
    finally:
        bar.close()
    logging.info(
        "recorded %d frames in %.1f s (%.1f frames/s)",
        frames,
        time.monotonic() - t0,
        frames / (time.monotonic() - t0),
    )


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
    video_depth = [k for k in dataset.meta.depth_keys if k in dataset.meta.video_keys]
    for frame in frames:
        for key in video_depth:
            check_depth_range(key, frame[key])
    # np.require copies only arrays torch will not wrap: read-only ones (frames from Ray's object store).
    goal = {
        k: torch.from_numpy(np.require(frames[0][goal_key(k)], requirements="CW"))[None] for k in reward_keys
    }
    horizon = len(actions)
    marked = ACTION_IS_PAD in dataset.features  # a dataset without the marker is continued without it

    def pad(value: bool) -> dict[str, np.ndarray]:
        return {ACTION_IS_PAD: np.array([value])} if marked else {}

    for t, action in enumerate(actions):
        reached = {
            k: torch.from_numpy(np.require(frames[t + 1][k], requirements="CW"))[None] for k in reward_keys
        }
        reward = float(indicator_reward(reached, goal, r_pos, r_neg)[0])
        dataset.add_frame(
            {
                **frames[t],
                ACTION: np.asarray(action, dtype=np.float32),
                REWARD: np.array([reward], dtype=np.float32),
                DONE: np.array([t == horizon - 1], dtype=bool),
                "task": task,
                **pad(False),
            }
        )
    # The final observation o_T as its own frame (see the module docstring).
    dataset.add_frame(
        {
            **frames[-1],
            ACTION: np.asarray(actions[-1], dtype=np.float32),
            REWARD: np.zeros(1, dtype=np.float32),
            DONE: np.ones(1, dtype=bool),
            "task": task,
            **pad(True),
        }
    )
    return horizon + 1


def _record_episode(
    cfg: RecordConfig, stepper: EpisodeStepper, actions, dataset: LeRobotDataset, task: str, episode: int
) -> int:
    """Step episode ``episode`` (env reset with ``seed + episode``, action noise seeded from
    ``(seed, episode)``) into the dataset's episode buffer; returns its frame count."""
    obs, info = stepper.reset(cfg.seed + episode)
    actions.reset(seed=episode_seed(cfg.seed, episode))
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


def interrupted_message(cfg: RecordConfig, exc: KeyboardInterrupt) -> str:
    """The one line the CLI ends with after SIGINT/SIGTERM: what is saved, how to continue."""
    name = signal.Signals(getattr(exc, "signum", signal.SIGINT)).name
    if not (cfg.root / INFO).exists():
        return f"{name}: recording stopped before anything was saved (nothing at {cfg.root})"
    episodes, frames = committed_counts(cfg.root)
    target = getattr(exc, "target_episodes", None)
    dropped = getattr(exc, "dropped_episode", None)
    missing = target - episodes if target is not None else cfg.num_episodes
    saved = (
        f"{name}: recording stopped. {episodes} complete episodes ({frames} frames) are saved in "
        f"{cfg.root} and readable as they are"
    )
    if dropped is not None:
        saved += f"; episode {dropped}, being recorded, was dropped"
    if missing <= 0:
        return f"{saved}. All {target} requested episodes are there."
    return f"{saved}. To record the {missing} missing ones: the same command with --resume=true --num_episodes={missing}"


@parser.wrap()
def record_main(cfg: RecordConfig) -> None:
    init_logging()
    logging.info("record config:\n%s", json.dumps(asdict(cfg), default=str, indent=2))
    try:
        dataset = record(cfg)
    except KeyboardInterrupt as exc:
        print(interrupted_message(cfg, exc), file=sys.stderr, flush=True)
        raise SystemExit(exit_code(exc)) from None
    except (RecordingError, CorruptFrameError) as exc:
        print(f"error: {exc}", file=sys.stderr, flush=True)
        raise SystemExit(1) from None
    logging.info(
        "dataset at %s: %d episodes, %d frames",
        dataset.root,
        dataset.meta.total_episodes,
        dataset.meta.total_frames,
    )


def main() -> None:
    """``lerobot-indicator-record``. A bad option or config file is one line: draccus turns a config
    dataclass's ValueError into "Couldn't instantiate class ..." with tracebacks (io_errors.config_error_line)."""
    try:
        record_main()
    except Exception as exc:
        line = report_line(exc)
        if line is None:
            raise
        print(line, file=sys.stderr, flush=True)
        raise SystemExit(1) from None


if __name__ == "__main__":
    main()
