"""Configuration of the ``indicator_ddpg`` policy (Lin, Baweja, Held, CoRL 2019, section 5 and appendix).

One line per field here; why each default is what it is, and the measurements behind it: docs/policy.md,
"Config fields".
"""

import logging
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import draccus
from draccus.parsers.encoding import encode_choice, encode_dataclass
from draccus.utils import is_choice_type
from lerobot.configs import FeatureType, NormalizationMode, PolicyFeature, PreTrainedConfig
from lerobot.optim import AdamConfig, OptimizerConfig
from lerobot.utils.constants import ACTION, OBS_STATE

from lerobot_indicator.keys import OBS_PREFIX, goal_key, is_goal_key, is_ground_truth_key

# "ae" / "vae": the paper's learned-reward baselines (policy/learned_reward.py).
LEARNED_REWARDS = ("ae", "vae")
REWARD_MODES = ("indicator", "oracle", *LEARNED_REWARDS)
FILTER_Q_SOURCES = ("online", "target")
FILTER_STARTS = ("always", "calibrated")
BALANCE_FALLBACKS = ("recorded", "next")
# Per image encoder: the values of the conv and augmentation fields left at None (docs/policy.md, "Networks").
ENCODER_PRESETS = {
    "paper": {
        "conv_channels": [16, 32, 64, 64],
        "conv_kernel_size": 2,
        "conv_strides": [2, 2, 2, 2],
        "augment_pad": 0,
    },
    "drq": {
        "conv_channels": [16, 16, 32, 32],
        "conv_kernel_size": 3,
        "conv_strides": [2, 2, 1, 1],
        "augment_pad": 4,
    },
}
IMAGE_ENCODERS = tuple(ENCODER_PRESETS)
CONV_PRECISIONS = ("auto", "float32", "bfloat16")
CRITIC_OUTPUT_SCALES = ("paper", "return")
# Per preset: the values of n_step, inverse_dynamics and critic_output_scale left at None (docs/policy.md,
# "Presets"). "paper": the paper's one-step target, no inverse-dynamics loss, Q straight from the MLP. "auto": the
# settings measured to learn, filled in once the inputs are known (validate_features): the paper's on state
# (the return-scaled output regresses state reach, docs/results/experiments/return_scale/), AUTO_IMAGES with
# an image among the compared keys (docs/results/experiments_rgbd/defaults/).
PRESETS = {
    "auto": {"n_step": 1, "inverse_dynamics": 0.0, "critic_output_scale": "paper"},
    "paper": {"n_step": 1, "inverse_dynamics": 0.0, "critic_output_scale": "paper"},
}
# "auto" with an image among the compared keys: a 3-step target, the return-scaled critic output (no seed's
# critic saturates) and, with the shared "drq" encoder, the inverse-dynamics loss. lerobot-train keeps
# n_step=1: its samples hold no frames between o_{t+1} and the future.
AUTO_IMAGES = {"n_step": 3, "inverse_dynamics": 1.0, "critic_output_scale": "return"}
PRESET_FIELDS = tuple(PRESETS["paper"])
# A delta index past any episode's end: LeRobot clamps it to the episode's last frame.
EPISODE_END_OFFSET = 1_000_000
# The allowed values of each choice field, checked in this order.
CHOICES = {
    "preset": tuple(PRESETS),
    "reward": REWARD_MODES,
    "filter_q": FILTER_Q_SOURCES,
    "filter_start": FILTER_STARTS,
    "critic_output_scale": CRITIC_OUTPUT_SCALES,
    "balance_fallback": BALANCE_FALLBACKS,
    "image_encoder": IMAGE_ENCODERS,
    "conv_precision": CONV_PRECISIONS,
}
# Keys that checkpoints saved by earlier versions hold and this config ignores: process settings, which the
# CLIs own (lerobot_indicator/process.py). Loading accepts them; saving never writes them (_encode).
IGNORED_KEYS = ("cpu_threads", "keep_freed_memory", "video_decoder_threads")


class IndicatorDDPGConfigError(Exception):
    """A bad ``--policy.*`` value. Not a ValueError on purpose: draccus replaces a ValueError raised while it
    builds a config by "Couldn't instantiate class ...", while other exceptions keep their message, which
    names the field and the value."""


@OptimizerConfig.register_subclass("fused_adam")
@dataclass
class FusedAdamConfig(AdamConfig):
    """LeRobot's ``adam`` with torch's fused kernel (``fused=False`` gives plain ``adam``); ``AdamConfig.build``
    passes every field to ``torch.optim.Adam``."""

    fused: bool = True


@PreTrainedConfig.register_subclass("indicator_ddpg")
@dataclass
class IndicatorDDPGConfig(PreTrainedConfig):
    """Goal-conditioned DDPG trained with indicator rewards, hindsight relabeling, balancing and filtering.

    ``observation_keys`` are the *compared* keys: the reward is R+ only when every one of them equals its goal
    (``keys.goal_key``) bit for bit. The networks see these keys, their goals and the ``context_keys``: states
    of o_t (and of the frame a TD target bootstraps from) that are never compared, relabeled or in a goal.
    """

    # Defaults of n_step, inverse_dynamics and critic_output_scale: "auto" (what learned) or "paper" (PRESETS).
    preset: str = "auto"

    # Inputs and horizon
    # Compared keys (goals: goal_key(k)); None = the data's camera keys with a goal, else its state keys.
    observation_keys: list[str] | None = None
    # Uncompared state inputs (no goal, never relabeled); None = goal-less states if no image is compared.
    context_keys: list[str] | None = None
    # Episode horizon T (gamma = (T-1)/T, q0 follow); None = the dataset's or env's episode length.
    horizon: int | None = None
    # lerobot-train fetches o_{t+k} for each of these offsets k (all >= 2) as candidate future goals.
    future_offsets: list[int] = field(default_factory=lambda: [2, 4, 8, 16])
    # Inputs normalised with their key's mean/std (observation and goal alike) are clipped to +-this.
    input_clip: float = 5.0
    # lerobot-train's sampler skips each episode's last frame, which has no o_{t+1}.
    drop_n_last_frames: int = 1
    # lerobot-train fetches each episode's last frame, the stand-in goal of data without goals; None = auto.
    episode_end_goal: bool | None = None
    # Deployment: a directory holding one goal per compared key (save_goal), added to observations without one.
    goal_path: str | None = None

    # Reward
    # "indicator" (the paper's), "oracle" (ground-truth distance <= oracle_epsilon), or learned "ae" / "vae".
    reward: str = "indicator"
    # Success distance of the oracle reward and of the logged ground-truth statistics.
    oracle_epsilon: float = 0.1
    # R+, the reward when o_{t+1} equals the goal.
    positive_reward: float = 1.0
    # R-, the reward otherwise.
    negative_reward: float = -1.0
    # reward="oracle" only: probability that a true R+ is given as R- (the paper's section-4 p_FN study).
    reward_false_negative_rate: float = 0.0
    # reward="oracle" only: probability that a true R- is given as R+ (the paper's section-4 p_FP study).
    reward_false_positive_rate: float = 0.0

    # Relabeling (Algorithm 1)
    # Balanced relabeling: goal o_{t+1} with p_next, a future frame t' >= t+2 with p_future, else the recorded.
    balance: bool = True
    # balance=true: probability that the goal is o_{t+1}.
    p_next: float = 0.45
    # balance=true: probability that the goal is a future frame o_{t'}, t' >= t+2.
    p_future: float = 0.45
    # balance=false (the paper's "Indicator"): probability of a future goal over {t+1..T}.
    p_future_unbalanced: float = 0.9
    # Balanced future goal when no t' >= t+2 exists: "next" (o_{t+1}) or "recorded" (the recorded goal).
    balance_fallback: str = "next"

    # Reward filtering (section 5.3)
    # Drop R- transitions whose Q(o_t, o_g, a_t) exceeds q0.
    filter: bool = True
    # The filter's Q: "online" (the critic being trained, the paper's) or "target" (the target critic).
    filter_q: str = "online"
    # "always" (the paper's) or "calibrated": only in batches whose R+ have Q > q0 often enough.
    filter_start: str = "always"
    # filter_start=calibrated: the share of a batch's R+ transitions that must have Q above q0.
    filter_calibration: float = 0.9

    # Critic output
    # Initial Q (the critic's output bias); None = R-/(1-gamma), the lowest return.
    q_init: float | None = None
    # "paper" (the MLP outputs Q) or "return" ((1-gamma) Q, scaled by 1/(1-gamma)); None = the preset's.
    critic_output_scale: str | None = None

    # Networks (paper appendix)
    # Hidden layers of the actor's and critic's MLPs (tanh).
    hidden_dims: list[int] = field(default_factory=lambda: [256, 256, 256])
    # "drq" (one shared, augmented encoder, DrQ-v2's design) or "paper" (the appendix's CNN per network).
    image_encoder: str = "drq"
    # Filters per conv layer; None = the image encoder's preset (ENCODER_PRESETS).
    conv_channels: list[int] | None = None
    # Conv kernel size; None = the preset.
    conv_kernel_size: int | None = None
    # One stride per conv layer; None = the preset.
    conv_strides: list[int] | None = None
    # "drq": width of the linear projection after the convs (DrQ-v2's feature_dim).
    feature_dim: int = 50
    # Random-shift augmentation of training frames, in pixels (0 = off); None = the preset.
    augment_pad: int | None = None
    # Conv precision: "float32", "bfloat16", or "auto" (bfloat16 where the device computes it natively).
    conv_precision: str = "auto"
    # "drq": weight of the self-supervised inverse-dynamics loss on the encoder (0 = off); None = the preset's.
    inverse_dynamics: float | None = None
    # "drq": the target critic keeps its own EMA copy of the encoder (SAC-AE / CURL) instead of sharing it.
    target_encoder: bool = False
    # A spatial softmax (LeRobot's SpatialSoftmax) after the convs (RopePush).
    spatial_softmax: bool = False
    # Keypoints of the spatial softmax.
    spatial_softmax_keypoints: int = 32

    # Learned-reward baselines ("ae", "vae")
    # Filters of the reward model's 3x3 conv + 2x2 max-pool layers (the decoder mirrors them).
    reward_conv_channels: list[int] = field(default_factory=lambda: [16, 32, 64, 64])
    # Size of the latent code.
    reward_latent_dim: int = 32
    # Weight of the VAE's KL term.
    vae_beta: float = 5.0
    # A learned reward >= this counts as positive in the logged rates; None = 0.9 ("ae") or -1.0 ("vae").
    learned_reward_positive: float | None = None

    # DDPG
    # n-step TD target (1 = the paper's one-step target; online trainer only); None = the preset's.
    n_step: int | None = None
    # Target networks: target <- tau * target + (1 - tau) * online.
    tau: float = 0.98
    # Weight of the penalty on the squared actor output (baselines' HER).
    action_l2: float = 1.0
    # Adam's learning rate (fused_adam, no gradient clipping).
    learning_rate: float = 1e-3
    # torch.compile the loss (relabel -> reward -> filter -> DDPG losses) into one graph.
    compile_model: bool = False
    # torch.compile's mode (as LeRobot's pi0 config).
    compile_mode: str = "default"

    # Exploration (online trainer only, never select_action)
    # Std of the Gaussian noise added to the actor's action.
    noise_eps: float = 0.2
    # Probability of a uniform random action instead.
    random_eps: float = 0.3

    # Observations are normalised inside the networks (observation and goal alike), so the processors are
    # identity: the indicator comparison and relabeling see raw values; actions are the env's [-1, 1].
    normalization_mapping: dict[str, NormalizationMode] = field(
        default_factory=lambda: {
            "VISUAL": NormalizationMode.IDENTITY,
            "STATE": NormalizationMode.IDENTITY,
            "ENV": NormalizationMode.IDENTITY,
            "ACTION": NormalizationMode.IDENTITY,
        }
    )

    # IGNORED_KEYS: accepted when a checkpoint holds them, never used, never saved, not command-line flags.
    cpu_threads: Any = field(default=None, init=False, repr=False, compare=False)
    keep_freed_memory: Any = field(default=None, init=False, repr=False, compare=False)
    video_decoder_threads: Any = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        super().__post_init__()
        try:
            self._check_fields()
        except ValueError as e:
            raise IndicatorDDPGConfigError(f"indicator_ddpg config: {e}") from None

    def _check_fields(self) -> None:
        if self.observation_keys is not None and not self.observation_keys:
            raise ValueError("observation_keys must name at least one compared observation key")
        for key in self.observation_keys or []:
            if is_ground_truth_key(key):
                raise ValueError(
                    f"observation_keys: {key!r} is a ground-truth key: it is for evaluation and the oracle baseline only and "
                    "can never be a policy input (see docs/conventions.md)"
                )
            if is_goal_key(key):
                raise ValueError(
                    f"observation_keys: {key!r} is a goal key; list the observation key it is the goal of instead"
                )
            goal_key(key)  # raises on keys outside observation.*
        self._check_context_keys()
        if self.horizon is not None:
            self.set_horizon(self.horizon)
        if self.preset == "paper":  # "auto" waits for the inputs
            self._fill_from_preset(PRESET_FIELDS)
        for name, choices in CHOICES.items():
            if getattr(self, name) is not None and getattr(self, name) not in choices:
                raise ValueError(f"{name} must be one of {choices}, got {getattr(self, name)!r}")
        for name, value in ENCODER_PRESETS[self.image_encoder].items():
            if getattr(self, name) is None:
                setattr(self, name, value)
        offsets = self.future_offsets
        for name, ok, requirement in (
            ("future_offsets", bool(offsets) and min(offsets) >= 2, "non-empty and all >= 2 (t' >= t+2)"),
            ("p_future_unbalanced", 0 <= self.p_future_unbalanced <= 1, "in [0, 1]"),
            ("filter_calibration", 0 < self.filter_calibration <= 1, "in (0, 1]"),
            ("hidden_dims", len(self.hidden_dims) > 0, "non-empty"),
            ("conv_channels", len(self.conv_channels) > 0, "non-empty"),
            ("augment_pad", self.augment_pad >= 0, ">= 0 pixels"),
            (
                "inverse_dynamics",
                self.inverse_dynamics is None or self.inverse_dynamics >= 0,
                ">= 0 (0 = off)",
            ),
            ("reward_conv_channels", len(self.reward_conv_channels) > 0, "non-empty"),
            ("reward_latent_dim", self.reward_latent_dim >= 1, ">= 1"),
            ("n_step", self.n_step is None or self.n_step >= 1, ">= 1 (1 = the paper's one-step TD target)"),
            ("tau", 0 <= self.tau <= 1, "in [0, 1]"),
        ):
            if not ok:
                raise ValueError(f"{name} must be {requirement}, got {getattr(self, name)}")
        if not self.positive_reward > self.negative_reward:
            raise ValueError("positive_reward must be larger than negative_reward")
        if min(self.p_next, self.p_future) < 0 or self.p_next + self.p_future > 1:
            raise ValueError(
                f"p_next={self.p_next}, p_future={self.p_future} are not probabilities summing <= 1"
            )
        for name in ("reward_false_negative_rate", "reward_false_positive_rate"):
            rate = getattr(self, name)
            if not 0 <= rate <= 1:
                raise ValueError(f"{name} must be in [0, 1], got {rate}")
            if rate > 0 and self.reward != "oracle":
                raise ValueError(f"{name}={rate} flips the ground-truth reward: it needs reward='oracle'")
        if self.reward in LEARNED_REWARDS and self.filter:
            raise ValueError(
                f"filter=True drops R- transitions, but reward={self.reward!r} gives a continuous reward with no "
                "R-: pass --policy.filter=false"
            )
        if (self.inverse_dynamics or 0) > 0 and self.image_encoder != "drq":
            raise ValueError(
                f"inverse_dynamics={self.inverse_dynamics} trains the shared image encoder, which "
                f"image_encoder={self.image_encoder!r} does not have: use image_encoder=drq or inverse_dynamics=0"
            )
        if len(self.conv_strides) != len(self.conv_channels):
            raise ValueError(
                f"conv_strides has {len(self.conv_strides)} entries but conv_channels has "
                f"{len(self.conv_channels)}: give one stride per conv layer"
            )

    def _check_context_keys(self) -> None:
        """Context keys: observation keys, never ground truth or goals, each named once, never compared."""
        seen: set[str] = set()
        for key in self.context_keys or []:
            if is_ground_truth_key(key):
                raise ValueError(
                    f"context_keys: {key!r} is a ground-truth key: it is for evaluation and the oracle "
                    "baseline only and can never be a policy input (see docs/conventions.md)"
                )
            if is_goal_key(key):
                raise ValueError(
                    f"context_keys: {key!r} is a goal key; a goal never carries context: list observation keys"
                )
            goal_key(key)  # raises on keys outside observation.*
            if key in (self.observation_keys or []):
                raise ValueError(
                    f"context_keys: {key!r} is also in observation_keys; a key is either compared or context"
                )
            if key in seen:
                raise ValueError(f"context_keys: {key!r} is listed twice")
            seen.add(key)

    def _fill_from_preset(self, names: Iterable[str], images: bool = False) -> None:
        """Set each of ``names`` left at None to ``preset``'s value for these inputs; a given value stays."""
        values = preset_values(self.preset, images, self.image_encoder, self.trains_on_dataset_samples)
        for name in names:
            if getattr(self, name) is None:
                setattr(self, name, values[name])

    def set_dataset_feature_metadata(self, dataset_features: dict[str, Any]) -> None:
        """Called by LeRobot's ``make_policy`` when it makes the policy for a dataset, as ``lerobot-train``
        does: the policy then trains on ``lerobot-train`` samples, which allow no n-step target."""
        self._dataset_samples = True

    @property
    def trains_on_dataset_samples(self) -> bool:
        """Whether the policy was made for a dataset's ``lerobot-train`` samples (not an attribute draccus saves)."""
        return getattr(self, "_dataset_samples", False)

    def set_horizon(self, horizon: int, source: str | None = None) -> None:
        """Set T from the data (``source`` names where it comes from); a different given value is an error."""
        if source is not None and self.horizon is not None and self.horizon != horizon:
            raise ValueError(
                f"--policy.horizon={self.horizon} but the episodes of the {source} have T = {horizon} steps: "
                "leave horizon unset to take it from the data, or use data of that horizon"
            )
        if horizon < 2:
            raise ValueError(f"horizon must be >= 2 (gamma = (T-1)/T), got {horizon}")
        self.horizon = int(horizon)
        if self.q_init is None:
            return
        if self.reward in LEARNED_REWARDS and not self.q_min <= self.q_init <= self.q_max:
            raise ValueError(
                f"q_init must be in the {self.reward!r} reward's return range [{self.q_min}, {self.q_max}], "
                f"got {self.q_init}"
            )
        if self.reward not in LEARNED_REWARDS and not self.q_min <= self.q_init < self.q0:
            raise ValueError(
                f"q_init must be in [R-/(1-gamma), q0) = [{self.q_min}, {self.q0}), got {self.q_init}"
            )

    # Paper quantities derived from the horizon.
    @property
    def gamma(self) -> float:
        if self.horizon is None:
            raise ValueError(
                "the horizon T is not known yet: it comes from the dataset or env the policy is made for, "
                "or from --policy.horizon"
            )
        return (self.horizon - 1) / self.horizon

    @property
    def reward_range(self) -> tuple[float, float]:
        """(lowest, highest) reward: R-, R+ for the indicator and oracle; [0, 1] for the AE's clipped cosine,
        (-inf, 0] for the VAE's negative latent distance."""
        if self.reward == "ae":
            return 0.0, 1.0
        if self.reward == "vae":
            return float("-inf"), 0.0
        return self.negative_reward, self.positive_reward

    @property
    def reward_positive_threshold(self) -> float:
        """Rewards >= this count as positive in the logged rates: R+, or ``learned_reward_positive``."""
        if self.reward not in LEARNED_REWARDS:
            return self.positive_reward
        if self.learned_reward_positive is not None:
            return self.learned_reward_positive
        return 0.9 if self.reward == "ae" else -1.0

    @property
    def q_min(self) -> float:
        return self.reward_range[0] * self.discounted_steps

    @property
    def discounted_steps(self) -> float:
        """1 / (1 - gamma) = T exactly (computing it from gamma rounds: R-/(1-gamma) was -24.999999999999982)."""
        _ = self.gamma  # raises while T is unknown
        return float(self.horizon)

    @property
    def initial_q(self) -> float:
        """q_init, else the lowest return (0 for the VAE, whose return is unbounded below)."""
        if self.q_init is not None:
            return self.q_init
        return self.q_min if self.q_min > float("-inf") else 0.0

    @property
    def q_output_scale(self) -> float:
        """What the critic's MLP output is multiplied by (``critic_output_scale``): 1, or 1/(1-gamma) = T."""
        return self.discounted_steps if self.critic_output_scale == "return" else 1.0

    @property
    def q_max(self) -> float:
        return self.reward_range[1] * self.discounted_steps

    @property
    def q0(self) -> float:
        """Filter threshold 0.5 [R- + gamma R+/(1-gamma) + R+/(1-gamma)] (appendix table)."""
        r_pos, r_neg, n = self.positive_reward, self.negative_reward, self.discounted_steps
        return 0.5 * (r_neg + self.gamma * r_pos * n + r_pos * n)

    @property
    def goal_keys(self) -> list[str]:
        return [goal_key(k) for k in self.observation_keys]

    def validate_features(self) -> None:
        """Choose (when not given) and check the compared keys and their goals against ``input_features``,
        then keep only those as inputs.

        ``make_policy`` fills ``input_features`` with every ``observation.*`` feature of the dataset (ground
        truth included); the networks use exactly the compared keys, their goals and the context keys.
        """
        features = self.input_features or {}
        if not any(is_goal_key(k) for k in features):
            features = self._episode_end_goal_features(features)
        elif self.episode_end_goal is None:
            self.episode_end_goal = False  # saved: a resumed lerobot-train fetches the same frames
        cameras = default_observation_keys(features, FeatureType.VISUAL)
        if self.observation_keys is None:
            self.observation_keys = cameras or default_observation_keys(features, None)
            if not self.observation_keys:
                raise ValueError(
                    f"no observation key with a goal ({goal_key('observation.x')!r} form) among the input "
                    f"features {sorted(features)}: pass --policy.observation_keys"
                )
            logging.info("indicator_ddpg compares and conditions on %s", self.observation_keys)
        elif cameras and not any(
            features.get(k) and features[k].type is FeatureType.VISUAL for k in self.observation_keys
        ):
            logging.warning(
                "indicator_ddpg trains on %s although the data has the camera keys %s: the reward and the "
                "inputs use no image (as asked by --policy.observation_keys)",
                self.observation_keys,
                cameras,
            )
        for key in self.observation_keys:
            gkey = goal_key(key)
            if key not in features and gkey in features:
                raise ValueError(f"goal key {gkey!r} has no observation {key!r} in the input features")
            if key not in features:
                raise ValueError(
                    f"observation key {key!r} is missing from the input features {sorted(features)}"
                )
            if gkey not in features:
                raise ValueError(f"observation key {key!r} has no goal {gkey!r} in the input features")
            if tuple(features[key].shape) != tuple(features[gkey].shape):
                raise ValueError(
                    f"{key!r} has shape {tuple(features[key].shape)} but its goal {gkey!r} has shape "
                    f"{tuple(features[gkey].shape)}: they must be identical to be compared"
                )
            if features[key].type is FeatureType.VISUAL and len(features[key].shape) != 3:
                raise ValueError(f"image key {key!r} must have shape (C, H, W), got {features[key].shape}")
        visual = [k for k in self.observation_keys if features[k].type is FeatureType.VISUAL]
        sizes = {tuple(features[k].shape[1:]) for k in visual}
        if len(sizes) > 1:
            raise ValueError(
                f"image keys {visual} must share one (H, W) to be stacked as channels, got {sizes}"
            )
        if not self.output_features or ACTION not in self.output_features:
            raise ValueError(
                f"output features must contain {ACTION!r}, got {list(self.output_features or {})}"
            )
        self._fill_from_preset(PRESET_FIELDS, images=bool(visual))
        logging.info("%s", self.preset_summary(bool(visual)))
        if self.inverse_dynamics > 0 and not visual:
            raise ValueError(
                f"inverse_dynamics={self.inverse_dynamics} trains the shared image encoder, and the observation "
                f"keys {self.observation_keys} hold no image: use inverse_dynamics=0"
            )
        self._validate_context_features(features, visual)
        keep = self.observation_keys + self.goal_keys + self.context_keys
        self.input_features = {k: features[k] for k in keep}

    def _episode_end_goal_features(self, features: dict[str, PolicyFeature]) -> dict[str, PolicyFeature]:
        """Data without goal columns: choose the compared keys (the cameras; without one, ``observation.state``
        if the data has it, else every state key) and give each a goal feature of its own shape. The states not
        compared become context inputs. Every relabeled goal is a later frame of the same episode; where the
        method keeps the recorded goal, the episode's last frame stands in for it."""
        observed = [k for k in features if k.startswith(OBS_PREFIX) and not is_ground_truth_key(k)]
        if self.observation_keys is None:
            cameras = [k for k in observed if features[k].type is FeatureType.VISUAL]
            states = [k for k in observed if features[k].type is not FeatureType.VISUAL]
            self.observation_keys = cameras or ([OBS_STATE] if OBS_STATE in states else states)
            if not self.observation_keys:
                raise ValueError(
                    f"no observation key among the input features {sorted(features)}: nothing to compare"
                )
        if self.episode_end_goal is False:
            raise ValueError(
                f"the data has no goal column ({goal_key(self.observation_keys[0])!r} form) and "
                "episode_end_goal=false: pass --policy.episode_end_goal=true (the episode's last frame stands in "
                "for the recorded goal)"
            )
        self.episode_end_goal = True
        logging.info(
            "indicator_ddpg: the data has no goal columns: compares %s (not %s; --policy.context_keys conditions "
            "on a state without comparing it), relabels goals with later frames of the same episode, and uses "
            "each episode's last frame where the method keeps the recorded goal",
            self.observation_keys,
            [k for k in observed if k not in self.observation_keys],
        )
        return {**features, **{goal_key(k): features[k] for k in self.observation_keys if k in features}}

    def _validate_context_features(self, features: dict[str, PolicyFeature], visual: list[str]) -> None:
        """Choose (when not given: the goal-less state keys, unless an image is compared, as in the paper's
        visual tasks) and check the context keys against the input features."""
        if self.context_keys is None:
            self.context_keys = [] if visual else default_context_keys(features, self.observation_keys)
            if self.context_keys:
                logging.info("indicator_ddpg also conditions on the context %s", self.context_keys)
        self._check_context_keys()
        for key in self.context_keys:
            if key not in features:
                raise ValueError(f"context key {key!r} is missing from the input features {sorted(features)}")
            if features[key].type is FeatureType.VISUAL:
                raise ValueError(
                    f"context key {key!r} is an image: context inputs are state vectors; compare it "
                    "(observation_keys) or leave it out"
                )

    def preset_summary(self, images: bool) -> str:
        """The start-up line naming the preset and the n_step, inverse_dynamics and critic_output_scale in use."""
        inputs = "images" if images else "state"
        note = ""
        if images and self.trains_on_dataset_samples:
            inputs += ", lerobot-train samples"
            if self.preset == "auto":
                note = (
                    " (a lerobot-train sample holds no frames between o_{t+1} and the future ones, so no "
                    "3-step target: lerobot-indicator-train uses n_step=3)"
                )
        if self.preset == "paper":
            other = "--policy.preset=auto for the settings measured to learn"
        elif images:
            other = "--policy.preset=paper for the paper's one-step settings"
        else:
            other = "the paper's settings"
        return (
            f"indicator_ddpg preset={self.preset} ({inputs}): n_step={self.n_step}, "
            f"inverse_dynamics={self.inverse_dynamics}, critic_output_scale={self.critic_output_scale}{note}; "
            f"{other}"
        )

    @property
    def shared_encoder(self) -> bool:
        """One encoder for actor and critic, trained by the critic loss only: the "drq" design with images."""
        return self.image_encoder == "drq" and bool(self.image_keys)

    @property
    def image_keys(self) -> list[str]:
        return [k for k in self.observation_keys if self.input_features[k].type is FeatureType.VISUAL]

    @property
    def state_keys(self) -> list[str]:
        return [k for k in self.observation_keys if self.input_features[k].type is not FeatureType.VISUAL]

    @property
    def action_dim(self) -> int:
        feature: PolicyFeature = self.output_features[ACTION]
        return int(feature.shape[0])

    # lerobot-train dataset access: index 0 = o_t, 1 = o_{t+1}, then the future offsets, then (when fetched)
    # EPISODE_END_OFFSET, which LeRobot clamps to the episode's last frame (and flags in ``<key>_is_pad``).
    @property
    def observation_delta_indices(self) -> list[int]:
        return [0, 1, *self.future_offsets, *([EPISODE_END_OFFSET] if self.fetches_episode_end else [])]

    @property
    def fetches_episode_end(self) -> bool:
        """Whether lerobot-train fetches each episode's last frame: ``episode_end_goal``, or when unset, while
        the data's features are unknown (a fresh lerobot-train chooses the frames before it reads them)."""
        if self.episode_end_goal is not None:
            return self.episode_end_goal
        return not any(is_goal_key(k) for k in self.input_features or {})

    @property
    def action_delta_indices(self) -> None:
        return None

    @property
    def reward_delta_indices(self) -> None:
        return None

    def get_optimizer_preset(self) -> FusedAdamConfig:
        # No gradient clipping: the paper and baselines' HER do not clip, and a global norm clip over the
        # concatenated actor+critic parameters would couple their step sizes.
        return FusedAdamConfig(lr=self.learning_rate, grad_clip_norm=0.0)

    def get_scheduler_preset(self) -> None:
        return None


def _encode(config: IndicatorDDPGConfig, declared_type: type | None = None) -> dict:
    """draccus's encoding (config.json, train_config.json) without the IGNORED_KEYS."""
    if declared_type is not None and is_choice_type(declared_type):
        encoded = encode_choice(config, declared_type)  # with the "type" key
    else:
        encoded = encode_dataclass(config, declared_type)
    return {k: v for k, v in encoded.items() if k not in IGNORED_KEYS}


draccus.encode.register(IndicatorDDPGConfig, _encode)


def default_observation_keys(features: dict[str, PolicyFeature], kind: FeatureType | None) -> list[str]:
    """Observation keys of ``kind`` (None: any but images) that have a goal, never ground truth or goals."""
    return [
        k
        for k, ft in features.items()
        if k.startswith("observation.")
        and not is_goal_key(k)
        and not is_ground_truth_key(k)
        and goal_key(k) in features
        and ((ft.type is kind) if kind is not None else ft.type is not FeatureType.VISUAL)
    ]


def default_context_keys(features: dict[str, PolicyFeature], compared: list[str]) -> list[str]:
    """State (non-image) observation keys without a goal that are not compared, never ground truth or goals:
    e.g. the wrapped gymnasium tasks' ``observation.environment_state``."""
    return [
        k
        for k, ft in features.items()
        if k.startswith("observation.")
        and k not in compared
        and not is_goal_key(k)
        and not is_ground_truth_key(k)
        and goal_key(k) not in features
        and ft.type is not FeatureType.VISUAL
    ]


def preset_values(preset: str, images: bool, image_encoder: str, dataset_samples: bool) -> dict[str, Any]:
    """The values ``preset`` gives the PRESET_FIELDS for inputs with or without ``images``, trained on
    ``lerobot-train``'s ``dataset_samples`` or by the online trainer."""
    values = dict(PRESETS[preset])
    if preset == "auto" and images:
        values["n_step"] = 1 if dataset_samples else AUTO_IMAGES["n_step"]
        values["critic_output_scale"] = AUTO_IMAGES["critic_output_scale"]
        # The inverse-dynamics loss trains the one encoder actor and critic share, which only "drq" has.
        values["inverse_dynamics"] = AUTO_IMAGES["inverse_dynamics"] if image_encoder == "drq" else 0.0
    return values
