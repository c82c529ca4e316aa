"""Configuration of the ``indicator_ddpg`` policy (Lin, Baweja, Held, CoRL 2019, section 5 and appendix)."""

import logging
from dataclasses import dataclass, field

from lerobot.configs import FeatureType, NormalizationMode, PolicyFeature, PreTrainedConfig
from lerobot.optim import AdamConfig, OptimizerConfig
from lerobot.utils.constants import ACTION

from lerobot_indicator.keys import goal_key, is_goal_key, is_ground_truth_key

# "ae" / "vae": the paper's learned-reward baselines (policy/learned_reward.py).
LEARNED_REWARDS = ("ae", "vae")
REWARD_MODES = ("indicator", "oracle", *LEARNED_REWARDS)
FILTER_Q_SOURCES = ("online", "target")
FILTER_STARTS = ("always", "calibrated")
BALANCE_FALLBACKS = ("recorded", "next")
# Per image encoder: the values of the conv and augmentation fields left at None. "paper": the appendix's
# 4 conv layers of 2x2 kernels, stride 2, 16/32/64/64 filters (as in the authors' HER code), no augmentation.
# "drq": DrQ-v2's 3x3 convs and 4-pixel random shift, with a second stride-2 layer and 16 filters in the first
# two layers (DrQ-v2: 32 everywhere, strides 2/1/1/1), which cut the CPU cost of an update at 64-100 px.
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


class IndicatorDDPGConfigError(Exception):
    """A bad ``--policy.*`` value. Not a ValueError on purpose: draccus replaces a ValueError raised while it
    builds a config by "Couldn't instantiate class ...", while other exceptions keep their message, which
    names the field and the value."""


@OptimizerConfig.register_subclass("fused_adam")
@dataclass
class FusedAdamConfig(AdamConfig):
    """LeRobot's ``adam`` with torch's fused kernel (``fused=False`` gives plain ``adam``).

    ``AdamConfig.build`` passes every field to ``torch.optim.Adam``. On CPU torch's default Adam loops over
    the tensors one by one; the fused kernel made a state-based update ~10% faster (docs/results/vs_sb3.json).
    """

    fused: bool = True


@PreTrainedConfig.register_subclass("indicator_ddpg")
@dataclass
class IndicatorDDPGConfig(PreTrainedConfig):
    """Goal-conditioned DDPG trained with indicator rewards, hindsight relabeling, balancing and filtering.

    ``observation_keys`` are the *compared* keys: the reward is R+ only when every one of them equals its goal
    (``keys.goal_key``) bit for bit. The networks see exactly these keys and their goals.
    """

    # Compared observation keys; goals are ``goal_key(k)``. Images and states may be mixed. None = every
    # camera key of the dataset / env that has a goal (never the state when there are cameras: training on
    # observation.state must be asked for by name), or its state keys when it has no camera.
    observation_keys: list[str] | None = None

    # Episode horizon T: gamma = (T-1)/T and the filter threshold q0 follow from it. None = the episode length
    # of the dataset (lerobot-train) or of the env (lerobot-indicator-train); a given value must match it.
    horizon: int | None = None

    # Reward: "indicator" (the paper's method), "oracle" (ground-truth distance <= oracle_epsilon), or a
    # learned-reward baseline trained jointly on the batch's images (paper appendix): "ae" (max(0, cosine of
    # the L2-normalised codes)) or "vae" (beta-VAE, -||z - z_g|| of the posterior means).
    reward: str = "indicator"
    oracle_epsilon: float = 0.1
    positive_reward: float = 1.0
    negative_reward: float = -1.0

    # Relabeling (Algorithm 1). balance=True: p(next)=0.45, p(future t'>=t+2)=0.45, p(recorded)=0.1.
    # balance=False (the paper's "Indicator" baseline): p(future over {t+1..T})=0.9, p(recorded)=0.1.
    balance: bool = True
    p_next: float = 0.45
    p_future: float = 0.45
    p_future_unbalanced: float = 0.9
    # Goal of the balanced future branch when no t' >= t+2 exists (t = T-1; the paper does not say):
    # "next" uses o_{t+1} = o_T, what clipping t' to T gives (a positive); "recorded" keeps it a mostly negative
    # example. Matters at short horizons: at T = 3 a third of the transitions have t = T-1, and "recorded"
    # made rope push worse than no balancing at all (docs/results/README.md).
    balance_fallback: str = "next"
    # Reward filtering: drop R- transitions whose Q(o_t, o_g, a_t) exceeds q0.
    filter: bool = True
    # The filter's Q: "online" (the paper: the critic being trained) or "target" (the target critic, which
    # trails it and is not pulled up by the batch it filters).
    filter_q: str = "online"
    # When the filter acts: "always" (the paper) or "calibrated": in a batch only when at least
    # filter_calibration of its R+ transitions (relabeled positives, whose return is known to be high) have a
    # filter Q above q0, i.e. once the critic tells positives from negatives at the threshold q0.
    filter_start: str = "always"
    filter_calibration: float = 0.9
    # Initial Q (the critic's output bias). The paper initialises Q "relatively low" so that filtering
    # is not fooled early; None = R-/(1-gamma), the lowest possible return. Any value well below q0 keeps
    # filtering safe; see docs/policy.md for the effect on learning speed.
    q_init: float | None = None
    # Units of the critic's output layer: "paper" (Q itself) or "return": the MLP predicts (1-gamma) Q, a
    # per-step reward in [R-, R+], and is scaled by 1/(1-gamma). With Q starting at R-/(1-gamma) and tanh
    # layers, Adam's fastest way to move Q by tens is to saturate the last hidden layer to a constant; once
    # saturated, Q stops depending on the input (a pixel Oracle seed never learned: docs/policy.md).
    critic_output_scale: str = "paper"

    # Offsets t'-t of the future frames fetched from a dataset in lerobot-train (all >= 2). One valid
    # offset is picked uniformly per sample; docs/policy.md compares this with uniform t' in {t+2..T}.
    future_offsets: list[int] = field(default_factory=lambda: [2, 4, 8, 16])

    # Networks (paper appendix): 3 hidden layers of 256, tanh; conv weights shared by observation and goal.
    hidden_dims: list[int] = field(default_factory=lambda: [256, 256, 256])
    # Image encoder (docs/policy.md describes both; docs/results/policy_updates.json times them):
    # "drq": one encoder shared by actor and critic and trained by the critic loss only (the actor sees
    #   detached features), ReLU convs, a linear projection with LayerNorm + tanh, random-shift augmentation;
    #   the design of DrQ-v2 and of LeRobot's SAC (gaussian_actor) encoder.
    # "paper": the paper's, as in the authors' HER code: actor and critic (and each target) own a CNN of
    #   2x2 stride-2 convs with tanh, flattened (or a spatial softmax), no projection, no augmentation.
    image_encoder: str = "drq"
    # Conv layers (one stride per layer), the projection width ("drq": DrQ-v2's feature_dim) and the
    # random-shift augmentation (DrQ: images the networks see in training are padded by augment_pad pixels,
    # edge replicated, and randomly cropped back, each frame independently; 0 = off; the indicator reward and
    # relabeling always compare the raw frames). None = the image encoder's preset (ENCODER_PRESETS).
    conv_channels: list[int] | None = None
    conv_kernel_size: int | None = None
    conv_strides: list[int] | None = None
    feature_dim: int = 50
    augment_pad: int | None = None
    # Precision of the conv layers: "float32", "bfloat16" (autocast; the rest of the networks stays float32)
    # or "auto" = bfloat16 where the device computes it natively (CUDA with bf16; CPUs with AVX512-BF16 or
    # AMX), float32 elsewhere, where bf16 would be emulated and slower (docs/results/policy_updates.json).
    conv_precision: str = "auto"
    # "drq" only: weight of a self-supervised inverse-dynamics loss on the shared encoder, ||g(enc(o_t),
    # enc(o_{t+1})) - a_t||^2, which needs no ground truth (the actions are the agent's own) and makes the
    # features locate what the actions move; 0 = off (the critic loss alone trains the encoder).
    inverse_dynamics: float = 0.0
    # "drq" only: the target critic keeps its own EMA copy of the encoder (as in SAC-AE / CURL) instead of
    # using the online encoder's features of o_{t+1} and the goal (DrQ-v2).
    target_encoder: bool = False
    # RopePush: spatial softmax with 32 keypoints before the fully connected layers.
    spatial_softmax: bool = False
    spatial_softmax_keypoints: int = 32
    # Learned-reward baselines ("ae", "vae"): 3x3 convs each followed by 2x2 max-pooling, then a linear map to
    # the latent code; the decoder mirrors them with 4 up-sampling + conv layers. vae_beta weights the KL term.
    reward_conv_channels: list[int] = field(default_factory=lambda: [16, 32, 64, 64])
    reward_latent_dim: int = 32
    vae_beta: float = 5.0
    # A learned reward counts as "positive" for the logged false-positive/negative rates when it is >= this;
    # None = 0.9 for "ae" (cosine of the codes) and -1.0 for "vae" (latent distance within 1 prior std).
    learned_reward_positive: float | None = None
    # Inputs normalised with the observation key's mean/std (observation and goal alike) are clipped.
    input_clip: float = 5.0

    # DDPG.
    # n-step TD target (DrQ-v2 uses 3): sum_{i=1..n} gamma^(i-1) r_{t+i} + gamma^n Q'(o_{t+n}, g), with every
    # r_{t+i} the same reward (indicator: o_{t+i} equals the goal) and n cut at the episode end. 1 = the paper's
    # one-step target. From images a goal k steps ahead is worth its value only after k-1 bootstraps through
    # learnt features; n > 1 carries the one exact match back n steps per update. Online trainer only: a
    # lerobot-train sample holds o_t, o_{t+1} and the future frames, not the frames in between.
    n_step: int = 1
    tau: float = 0.98  # target <- tau * target + (1 - tau) * online
    action_l2: float = 1.0  # baselines' HER penalty on the squared actor output
    learning_rate: float = 1e-3
    # torch.compile the loss (relabel -> reward -> filter -> DDPG losses) into one graph: fuses the
    # elementwise work around the matmuls (docs/policy.md has the measured gain); the first update pays the
    # compilation (tens of seconds on CPU, needs a C++ compiler). Same names as LeRobot's pi0 config.
    compile_model: bool = False
    compile_mode: str = "default"
    # torch intra-op threads while this policy trains or acts on CPU (both trainers and lerobot-eval build it),
    # None = torch's default (one per core). 1 is the default because the second core is usually busy: with
    # lerobot-train's loader workers or other jobs, OpenMP threads spinning against them made updates ~3x slower.
    # A lone online run on an idle 2-core machine updates faster with 2 (1.3x state, 1.7x RGB-D at 64 px):
    # docs/results/policy_updates.json has both.
    cpu_threads: int | None = 1
    # Keep freed memory in the process for reuse (glibc; policy/cpu_memory.py) instead of page-faulting every
    # large tensor in afresh: 1.45x faster RGB-D updates with 3-step targets on this project's VMs.
    keep_freed_memory: bool = True
    # Threads per video decoder that LeRobot's pyav reader opens in this process and in forked loader workers
    # (data/video_decoder_threads.py): 1 = single-threaded, None = FFmpeg's choice (one per core + 1). Small
    # frames give decoder threads nothing to share, and on 2 busy cores every hand-off waits: lerobot-train
    # with 3 fork workers loads faster with 1 (docs/results/README.md, "Loading RGB-D datasets"). Spawned
    # workers (lerobot-train's default start method) start from FFmpeg's choice.
    video_decoder_threads: int | None = 1
    # Exploration (used by the online trainer only, never by select_action).
    noise_eps: float = 0.2
    random_eps: float = 0.3

    # lerobot-train's sampler never picks the last frame of an episode: it has no o_{t+1}.
    drop_n_last_frames: int = 1

    # Observations are normalised inside the networks (identically for observation and goal) so that the
    # indicator comparison and relabeling see raw values; actions are in the env's [-1, 1] action space.
    normalization_mapping: dict[str, NormalizationMode] = field(
        default_factory=lambda: {
            "VISUAL": NormalizationMode.IDENTITY,
            "STATE": NormalizationMode.IDENTITY,
            "ENV": NormalizationMode.IDENTITY,
            "ACTION": NormalizationMode.IDENTITY,
        }
    )

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
        if self.horizon is not None:
            self.set_horizon(self.horizon)
        if self.reward not in REWARD_MODES:
            raise ValueError(f"reward must be one of {REWARD_MODES}, got {self.reward!r}")
        if self.reward in LEARNED_REWARDS and self.filter:
            raise ValueError(
                f"filter=True drops R- transitions, but reward={self.reward!r} gives a continuous reward with no "
                "R-: pass --policy.filter=false"
            )
        if self.filter_q not in FILTER_Q_SOURCES:
            raise ValueError(f"filter_q must be one of {FILTER_Q_SOURCES}, got {self.filter_q!r}")
        if self.filter_start not in FILTER_STARTS:
            raise ValueError(f"filter_start must be one of {FILTER_STARTS}, got {self.filter_start!r}")
        if self.critic_output_scale not in CRITIC_OUTPUT_SCALES:
            raise ValueError(
                f"critic_output_scale must be one of {CRITIC_OUTPUT_SCALES}, got {self.critic_output_scale!r}"
            )
        if self.video_decoder_threads is not None and self.video_decoder_threads < 1:
            raise ValueError(
                f"video_decoder_threads must be None (FFmpeg's choice) or >= 1, got {self.video_decoder_threads}"
            )
        if not 0 < self.filter_calibration <= 1:
            raise ValueError(f"filter_calibration must be in (0, 1], got {self.filter_calibration}")
        if not self.reward_conv_channels or self.reward_latent_dim < 1:
            raise ValueError(
                f"reward_conv_channels must list at least one conv layer, got {self.reward_conv_channels}; "
                f"reward_latent_dim must be >= 1, got {self.reward_latent_dim}"
            )
        if not self.positive_reward > self.negative_reward:
            raise ValueError("positive_reward must be larger than negative_reward")
        if min(self.p_next, self.p_future) < 0 or self.p_next + self.p_future > 1:
            raise ValueError(
                f"p_next={self.p_next}, p_future={self.p_future} are not probabilities summing <= 1"
            )
        if self.balance_fallback not in BALANCE_FALLBACKS:
            raise ValueError(
                f"balance_fallback must be one of {BALANCE_FALLBACKS}, got {self.balance_fallback!r}"
            )
        if not 0 <= self.p_future_unbalanced <= 1:
            raise ValueError(f"p_future_unbalanced must be in [0, 1], got {self.p_future_unbalanced}")
        if not self.future_offsets or min(self.future_offsets) < 2:
            raise ValueError(
                f"future_offsets must be non-empty and all >= 2 (t' >= t+2), got {self.future_offsets}"
            )
        if self.n_step < 1:
            raise ValueError(f"n_step must be >= 1 (1 = the paper's one-step TD target), got {self.n_step}")
        if not 0 <= self.tau <= 1:
            raise ValueError(f"tau must be in [0, 1], got {self.tau}")
        if self.image_encoder not in IMAGE_ENCODERS:
            raise ValueError(f"image_encoder must be one of {IMAGE_ENCODERS}, got {self.image_encoder!r}")
        if self.inverse_dynamics < 0:
            raise ValueError(f"inverse_dynamics must be >= 0 (0 = off), got {self.inverse_dynamics}")
        if self.inverse_dynamics > 0 and self.image_encoder != "drq":
            raise ValueError(
                f"inverse_dynamics={self.inverse_dynamics} trains the shared image encoder, which "
                f"image_encoder={self.image_encoder!r} does not have: use image_encoder=drq or inverse_dynamics=0"
            )
        for name, value in ENCODER_PRESETS[self.image_encoder].items():
            if getattr(self, name) is None:
                setattr(self, name, value)
        if len(self.conv_channels) == 0 or len(self.hidden_dims) == 0:
            raise ValueError("conv_channels and hidden_dims must not be empty")
        if len(self.conv_strides) != len(self.conv_channels):
            raise ValueError(
                f"conv_strides has {len(self.conv_strides)} entries but conv_channels has "
                f"{len(self.conv_channels)}: give one stride per conv layer"
            )
        if self.conv_precision not in CONV_PRECISIONS:
            raise ValueError(f"conv_precision must be one of {CONV_PRECISIONS}, got {self.conv_precision!r}")
        if self.augment_pad < 0:
            raise ValueError(f"augment_pad must be >= 0 pixels, got {self.augment_pad}")

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
        truth included); the networks use exactly the compared keys and their goals.
        """
        features = self.input_features or {}
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
        if self.inverse_dynamics > 0 and not visual:
            raise ValueError(
                f"inverse_dynamics={self.inverse_dynamics} trains the shared image encoder, and the observation "
                f"keys {self.observation_keys} hold no image: use inverse_dynamics=0"
            )
        keep = self.observation_keys + self.goal_keys
        self.input_features = {k: features[k] for k in keep}

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

    # lerobot-train dataset access: index 0 = o_t, 1 = o_{t+1}, then the future offsets.
    @property
    def observation_delta_indices(self) -> list[int]:
        return [0, 1, *self.future_offsets]

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
