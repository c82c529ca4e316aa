"""Config of the online trainer, shaped like ``lerobot-train``'s (``--policy.*``, ``--env.type``,
``--dataset.*``, ``--output_dir``, ``--seed``, ``--steps``, ``--env_eval_freq``, ``--save_freq``,
``--resume``) plus the online loop's own knobs under ``--online.*`` and ``--record.*``."""

import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path

import draccus
from lerobot import envs
from lerobot.configs import parser
from lerobot.configs.default import DatasetConfig, WandBConfig
from lerobot.configs.policies import PreTrainedConfig
from lerobot.utils.hub import HubMixin

from lerobot_indicator.io_errors import ConfigError
from lerobot_indicator.training import atomic_dir
from lerobot_indicator.training.offline_check import OfflineCheckConfig

TRAIN_CONFIG_NAME = "train_config.json"
INPUT_STATS = ("running", "first_cycle")
BACKENDS = ("local", "ray")


@dataclass
class OnlineConfig:
    """Paper Algorithm 1: each cycle collects episodes, then runs optimisation steps."""

    # Parallel env processes (gymnasium AsyncVectorEnv when > 1 and use_async_envs).
    n_envs: int = 2
    use_async_envs: bool = True
    # Episodes collected per cycle (rounded up to a multiple of n_envs; 0 with --dataset.*: train on the
    # dataset alone, from the in-memory buffer) and gradient steps per cycle.
    episodes_per_cycle: int = 4
    updates_per_cycle: int = 40
    # Batch size; None = the paper's (256 for state inputs, 128 for images).
    batch_size: int | None = None
    # Replay capacity in transitions; None = the paper's (1e6 state, 5e3 visual).
    buffer_capacity: int | None = None
    # Random-action episodes before the first update (exploration warm-up).
    warmup_episodes: int = 0
    # Evaluation episodes (deterministic actor) every env_eval_freq steps.
    eval_episodes: int = 20
    # Of those, how many each evaluation writes as MP4 (<output_dir>/eval/videos_step_<step>/): the RGB
    # observation beside its goal, upscaled to >= 256 px (policies comparing RGB images only).
    eval_videos: int = 1
    # Input normalisation of a policy trained from scratch: "running" = mean/std of every episode in the
    # replay buffer (frames and goals), refreshed each cycle, as baselines' HER; "first_cycle" = frozen
    # after the first cycle (a few episodes' narrow stats clip goals outside their range, so the networks
    # cannot tell those goals apart: docs/results/README.md). A --policy.path policy keeps its own stats.
    input_stats: str = "running"
    # Where training episodes are collected: "local" = this process's vector env; "ray" = num_workers Ray
    # actors, each with its own n_envs sub-envs and a CPU copy of the actor (docs/scaling.md; needs the
    # [distributed] extra). ray_address: an existing cluster ("auto", "host:6379", "ray://host:10001");
    # None = a new local Ray instance on this machine. Evaluation episodes run on the learner.
    backend: str = "local"
    num_workers: int = 2
    ray_address: str | None = None


@dataclass
class OnlineRecordConfig:
    """``--record.*``: write every collected (behaviour-policy) episode to a LeRobotDataset, in the format of
    ``lerobot_indicator.data.recorder`` (docs/dataset_format.md, lossless images). None repo_id = don't.
    The trainer builds the recorder's own ``RecordConfig`` from these fields."""

    repo_id: str | None = None
    root: str | None = None
    push_to_hub: bool = False


@dataclass
class OnlineTrainConfig(HubMixin):
    env: envs.EnvConfig
    policy: PreTrainedConfig | None = None
    # Optional offline data: seeds the replay buffer before online collection.
    dataset: DatasetConfig | None = None
    online: OnlineConfig = field(default_factory=OnlineConfig)
    record: OnlineRecordConfig = field(default_factory=OnlineRecordConfig)
    # With --dataset.*: the offline check (training/offline_check.py) on held-out episodes, at each evaluation.
    offline_check: OfflineCheckConfig = field(default_factory=OfflineCheckConfig)
    output_dir: Path | None = None
    job_name: str | None = None
    resume: bool = False
    seed: int = 1000
    # Total optimisation steps (gradient updates), as in lerobot-train; the last cycle runs only what is left.
    steps: int = 2000
    # In optimisation steps, checked at cycle ends (0 disables). Eval also runs after the last cycle.
    env_eval_freq: int = 400
    save_freq: int = 1000
    save_checkpoint: bool = True
    # LeRobot's Weights & Biases logging (--wandb.enable=true --wandb.project=...; --wandb.mode=offline works
    # without a network): every cycle's metrics, the learning-curve figure and the checkpoints.
    wandb: WandBConfig = field(default_factory=WandBConfig)
    # Process settings, applied by the CLI (lerobot_indicator/process.py; docs/policy.md, "Process settings").
    # torch intra-op threads while the policy trains on CPU; None = torch's default (one per core).
    cpu_threads: int | None = 1
    # glibc keeps freed memory for reuse instead of page-faulting large tensors in again on every update.
    keep_freed_memory: bool = True
    # Threads of each video decoder this process (and its forked workers) opens; None = FFmpeg's choice.
    video_decoder_threads: int | None = 1
    # LeRobot's training-config field; unused: --resume=true continues from the run's resume/ state alone.
    checkpoint_path: Path | None = field(init=False, default=None)

    def validate(self) -> None:
        policy_path = parser.get_path_arg("policy")
        if policy_path:
            overrides = parser.get_cli_overrides("policy")
            self.policy = PreTrainedConfig.from_pretrained(policy_path, cli_overrides=overrides)
            self.policy.pretrained_path = Path(policy_path)
        if self.policy is None:
            raise ValueError(
                "No policy configured: pass --policy.type=indicator_ddpg (or --policy.path=...)."
            )
        if self.policy.type != "indicator_ddpg":
            raise ValueError(
                f"the online trainer trains indicator_ddpg policies, got --policy.type={self.policy.type}"
            )
        o = self.online
        for name in ("n_envs", "updates_per_cycle", "eval_episodes"):
            if getattr(o, name) < 1:
                raise ValueError(f"--online.{name} must be >= 1, got {getattr(o, name)}")
        if o.eval_videos < 0:
            raise ValueError(f"--online.eval_videos must be >= 0, got {o.eval_videos}")
        if o.episodes_per_cycle < 0 or (o.episodes_per_cycle == 0 and self.dataset is None):
            raise ValueError(
                f"--online.episodes_per_cycle must be >= 1, or 0 with a --dataset.* to train on offline only, "
                f"got {o.episodes_per_cycle}"
            )
        if o.backend not in BACKENDS:
            raise ValueError(f"--online.backend must be one of {BACKENDS}, got {o.backend!r}")
        if o.num_workers < 1:
            raise ValueError(f"--online.num_workers must be >= 1, got {o.num_workers}")
        if o.input_stats not in INPUT_STATS:
            raise ValueError(f"--online.input_stats must be one of {INPUT_STATS}, got {o.input_stats!r}")
        for name in ("cpu_threads", "video_decoder_threads"):
            if getattr(self, name) is not None and getattr(self, name) < 1:
                raise ValueError(
                    f"--{name} must be null (the library's choice) or >= 1, got {getattr(self, name)}"
                )
        if self.steps < 1:
            raise ValueError(f"--steps must be >= 1, got {self.steps}")
        if self.record.repo_id is not None:
            from lerobot_indicator.data.recorder import check_repo_id

            check_repo_id(self.record.repo_id, "--record.repo_id")
        if not self.job_name:
            self.job_name = f"{self.env.type}_{self.policy.type}_online"
        if self.output_dir is None:
            now = dt.datetime.now()
            self.output_dir = Path("outputs/train") / f"{now:%Y-%m-%d}/{now:%H-%M-%S}_{self.job_name}"
        self.output_dir = Path(self.output_dir)
        if self.resume:
            # The per-cycle resume state (resume/: weights, optimizer, counters) is all a run continues from, so a
            # missing or corrupt checkpoints/last never blocks a resume; the same command gives the same policy.
            from lerobot_indicator.training.run_state import RESUME_DIR  # run_state imports this module

            if atomic_dir.newest(self.output_dir / RESUME_DIR) is None:
                held = sorted(p.name for p in self.output_dir.iterdir()) if self.output_dir.is_dir() else []
                raise FileNotFoundError(
                    f"--resume=true but {self.output_dir} has no resume state (resume/); it holds {held or 'nothing'}"
                )
        elif self.output_dir.is_dir() and any(self.output_dir.iterdir()):
            held = sorted(p.name for p in self.output_dir.iterdir())
            raise FileExistsError(
                f"Output directory {self.output_dir} already exists (it holds {held}) and --resume=false. "
                "Pass --resume=true to continue it, or choose another --output_dir."
            )
        if self.policy.push_to_hub and not self.policy.repo_id:
            raise ValueError(
                "--policy.push_to_hub=true needs --policy.repo_id (or pass --policy.push_to_hub=false)"
            )

    # What LeRobot's WandBLogger reads of a training config besides its fields.
    is_reward_model_training = False

    def to_dict(self) -> dict:
        return draccus.encode(self)

    @property
    def peft(self) -> None:
        """LeRobot's ``save_checkpoint`` reads ``cfg.peft``; PEFT adapters don't apply to this policy."""
        return None

    @classmethod
    def __get_path_fields__(cls) -> list[str]:
        return ["policy"]

    @classmethod
    def from_pretrained(
        cls, pretrained_name_or_path: str | Path, *, cli_args: list[str] | None = None, **kwargs
    ) -> "OnlineTrainConfig":
        """``--config_path``: a training config file (YAML or JSON, e.g. a run's ``train_config.json``; an
        ``env_configs/*.yaml`` holds only ``env``, the rest comes from the command line) or a directory holding
        ``train_config.json`` (a checkpoint's ``pretrained_model``); command-line options override it."""
        path = Path(pretrained_name_or_path)
        if path.is_dir():
            path = path / TRAIN_CONFIG_NAME
        if not path.is_file():
            raise ConfigError(
                f"--config_path={pretrained_name_or_path}: no such file; pass a training config (YAML or JSON) "
                f"or a directory holding {TRAIN_CONFIG_NAME}"
            )
        with draccus.config_type("json" if path.suffix == ".json" else "yaml"):
            return draccus.parse(cls, config_path=str(path), args=list(cli_args or []))

    def _save_pretrained(self, save_directory: Path) -> None:
        with open(Path(save_directory) / TRAIN_CONFIG_NAME, "w") as f, draccus.config_type("json"):
            draccus.dump(self, f, indent=4)
