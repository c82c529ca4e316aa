"""The paper's method arms and the task budgets of its comparison, as ``lerobot-indicator-train`` flags.

Used by ``benchmarks/experiments/run.py`` (the comparison), ``benchmarks/experiments/run_vs_sb3.py`` and the docs, so an arm is
defined once. A method is a list of ``--policy.*`` flags; a task preset the env flags and the budget.
"""

from dataclasses import astuple, dataclass

# Paper section 6: Oracle uses the ground-truth reward; methods without balancing relabel with a uniform
# future step with probability 0.9 and keep the original goal otherwise (HER-style). Balancing names its t = T-1
# fallback (o_{t+1}, the default) so that a run's command says what it did. Every arm starts from the paper's
# settings (--policy.preset=paper) and names each option it adds, so an arm means the same on state and images
# whatever the policy's defaults are (docs/policy.md "Presets").
PAPER = "--policy.preset=paper"
METHODS: dict[str, list[str]] = {
    "oracle": [PAPER, "--policy.reward=oracle", "--policy.balance=false", "--policy.filter=false"],
    "indicator": [PAPER, "--policy.reward=indicator", "--policy.balance=false", "--policy.filter=false"],
    "indicator_balance": [
        PAPER,
        "--policy.reward=indicator",
        "--policy.balance=true",
        "--policy.balance_fallback=next",
        "--policy.filter=false",
    ],
    "indicator_filter": [
        PAPER,
        "--policy.reward=indicator",
        "--policy.balance=false",
        "--policy.filter=true",
    ],
    "indicator_balance_filter": [
        PAPER,
        "--policy.reward=indicator",
        "--policy.balance=true",
        "--policy.balance_fallback=next",
        "--policy.filter=true",
    ],
}
PAPER_METHODS = list(METHODS)
# The paper's learned-reward baselines (appendix), for image tasks only: an AE / beta-VAE trained jointly
# with the agent gives the reward; goals are sampled as for the other methods without balancing.
LEARNED_REWARD_METHODS = {
    reward: [PAPER, f"--policy.reward={reward}", "--policy.balance=false", "--policy.filter=false"]
    for reward in ("ae", "vae")
}
# Variants of the paper's methods, each one flag away from it:
# - the other reading of balancing at t = T-1 (no t' >= t+2): the recorded goal instead of o_{t+1};
# - image inputs: the paper's encoder instead of the default ("drq", docs/policy.md), and float32 convs.
VARIANTS = {
    f"{m}_recorded_fallback": [
        a.replace("balance_fallback=next", "balance_fallback=recorded") for a in METHODS[m]
    ]
    for m in ("indicator_balance", "indicator_balance_filter")
}
VARIANTS["indicator_balance_filter_paper_encoder"] = [
    *METHODS["indicator_balance_filter"],
    "--policy.image_encoder=paper",
]
VARIANTS["indicator_balance_filter_fp32"] = [
    *METHODS["indicator_balance_filter"],
    "--policy.conv_precision=float32",
]
# - n-step TD targets (docs/policy.md) and the inverse-dynamics loss on the shared image encoder.
for _m in ("oracle", "indicator", "indicator_balance_filter"):
    VARIANTS[f"{_m}_n3"] = [*METHODS[_m], "--policy.n_step=3"]
VARIANTS["indicator_balance_filter_inverse_dynamics"] = [
    *METHODS["indicator_balance_filter"],
    "--policy.inverse_dynamics=1.0",
]
for _m in ("oracle", "indicator", "indicator_balance_filter"):
    VARIANTS[f"{_m}_n3_inverse_dynamics"] = [*VARIANTS[f"{_m}_n3"], "--policy.inverse_dynamics=1.0"]
# Balancing and filtering alone, with the same options as the RGB-D rope push comparison.
for _m in ("indicator_balance", "indicator_filter"):
    VARIANTS[f"{_m}_n3_inverse_dynamics"] = [
        *METHODS[_m],
        "--policy.n_step=3",
        "--policy.inverse_dynamics=1.0",
    ]
# The critic's MLP predicting (1-gamma) Q (docs/policy.md): an Oracle seed whose critic saturated learns with it.
for _m in ("oracle", "indicator", "indicator_balance_filter"):
    VARIANTS[f"{_m}_n3_inverse_dynamics_return_scale"] = [
        *VARIANTS[f"{_m}_n3_inverse_dynamics"],
        "--policy.critic_output_scale=return",
    ]
# The paper's settings with the return-scaled critic output alone (state tasks).
for _m in ("oracle", "indicator", "indicator_balance_filter"):
    VARIANTS[f"{_m}_return_scale"] = [*METHODS[_m], "--policy.critic_output_scale=return"]
# The paper's encoder with the same 3-step targets (it has no shared encoder for the inverse-dynamics loss).
VARIANTS["indicator_balance_filter_paper_encoder_n3"] = [
    *VARIANTS["indicator_balance_filter_paper_encoder"],
    "--policy.n_step=3",
]
# The filter's options (docs/policy.md): Q from the target critic; filtering only in calibrated batches.
VARIANTS["indicator_balance_filter_target_q"] = [
    *METHODS["indicator_balance_filter"],
    "--policy.filter_q=target",
]
VARIANTS["indicator_balance_filter_calibrated"] = [
    *METHODS["indicator_balance_filter"],
    "--policy.filter_start=calibrated",
]
# The same options on the RGB-D rope push comparison's arm, where the filter drops the most genuine negatives.
for _option, _arg in (
    ("target_q", "--policy.filter_q=target"),
    ("calibrated", "--policy.filter_start=calibrated"),
):
    VARIANTS[f"indicator_balance_filter_n3_inverse_dynamics_{_option}"] = [
        *VARIANTS["indicator_balance_filter_n3_inverse_dynamics"],
        _arg,
    ]
METHODS.update(LEARNED_REWARD_METHODS)
# The learned-reward baselines with the same 3-step targets and inverse-dynamics loss as the arms they are
# compared with on RGB-D rope push.
for _m in LEARNED_REWARD_METHODS:
    VARIANTS[f"{_m}_n3_inverse_dynamics"] = [
        *METHODS[_m],
        "--policy.n_step=3",
        "--policy.inverse_dynamics=1.0",
    ]
# Without random-shift augmentation (the paper's networks see the frames as they are).
for _m in ("oracle", "indicator_balance_filter_inverse_dynamics"):
    VARIANTS[f"{_m}_no_augmentation"] = [*(METHODS | VARIANTS)[_m], "--policy.augment_pad=0"]
# The paper's section-4 study (Fig. 2): DDPG + relabeling (the Oracle arm) on state reach with its ground-truth
# reward flipped at random, a true R+ to R- with p_FN or a true R- to R+ with p_FP; p_FP up to 0.9 to find
# where uniform flips stop learning.
REWARD_NOISE = {"fn": (0.1, 0.3, 0.5, 0.7, 0.9), "fp": (0.01, 0.05, 0.1, 0.3, 0.5, 0.7, 0.9)}
NOISE_FLAGS = {"fn": "reward_false_negative_rate", "fp": "reward_false_positive_rate"}
REWARD_NOISE_METHODS = {
    f"oracle_{kind}{rate:g}": [*METHODS["oracle"], f"--policy.{NOISE_FLAGS[kind]}={rate:g}"]
    for kind, rates in REWARD_NOISE.items()
    for rate in rates
}
VARIANTS.update(REWARD_NOISE_METHODS)
METHODS.update(VARIANTS)
LABELS = {
    "oracle": "Oracle",
    "indicator": "Indicator",
    "indicator_balance": "Indicator+Balance",
    "indicator_filter": "Indicator+Filter",
    "indicator_balance_filter": "Indicator+Balance+Filter",
    "indicator_balance_recorded_fallback": "Indicator+Balance (t=T-1: recorded goal)",
    "indicator_balance_filter_recorded_fallback": "Indicator+Balance+Filter (t=T-1: recorded goal)",
    "indicator_balance_filter_paper_encoder": "Indicator+Balance+Filter, paper encoder",
    "indicator_balance_filter_fp32": "Indicator+Balance+Filter, float32 convs",
    "oracle_n3": "Oracle, 3-step targets",
    "indicator_n3": "Indicator, 3-step targets",
    "indicator_balance_filter_n3": "Indicator+Balance+Filter, 3-step targets",
    "indicator_balance_filter_inverse_dynamics": "Indicator+Balance+Filter, inverse-dynamics loss",
    "indicator_balance_filter_n3_inverse_dynamics": "Indicator+Balance+Filter, 3-step, inverse dynamics",
    "oracle_n3_inverse_dynamics": "Oracle, 3-step, inverse dynamics",
    "indicator_n3_inverse_dynamics": "Indicator, 3-step, inverse dynamics",
    "indicator_balance_n3_inverse_dynamics": "Indicator+Balance, 3-step, inverse dynamics",
    "indicator_filter_n3_inverse_dynamics": "Indicator+Filter, 3-step, inverse dynamics",
    "oracle_n3_inverse_dynamics_return_scale": "Oracle, 3-step, inverse dynamics, critic output x T",
    "oracle_return_scale": "Oracle, critic output x T",
    "indicator_return_scale": "Indicator, critic output x T",
    "indicator_balance_filter_return_scale": "Indicator+Balance+Filter, critic output x T",
    "indicator_n3_inverse_dynamics_return_scale": "Indicator, 3-step, inverse dynamics, critic output x T",
    "indicator_balance_filter_n3_inverse_dynamics_return_scale": (
        "Indicator+Balance+Filter, 3-step, inverse dynamics, critic output x T"
    ),
    "indicator_balance_filter_paper_encoder_n3": "Indicator+Balance+Filter, paper encoder, 3-step",
    "oracle_no_augmentation": "Oracle, no augmentation",
    "indicator_balance_filter_inverse_dynamics_no_augmentation": "Indicator+Balance+Filter, inverse dynamics, no augmentation",
    "indicator_balance_filter_target_q": "Indicator+Balance+Filter, filter Q from the target critic",
    "indicator_balance_filter_calibrated": "Indicator+Balance+Filter, filter once Q is calibrated",
    "indicator_balance_filter_n3_inverse_dynamics_target_q": (
        "Indicator+Balance+Filter, 3-step, inverse dynamics, filter Q from the target critic"
    ),
    "indicator_balance_filter_n3_inverse_dynamics_calibrated": (
        "Indicator+Balance+Filter, 3-step, inverse dynamics, filter once Q is calibrated"
    ),
    "ae": "AE",
    "vae": "VAE",
    "ae_n3_inverse_dynamics": "AE, 3-step, inverse dynamics",
    "vae_n3_inverse_dynamics": "VAE, 3-step, inverse dynamics",
}
# Distinct dashes, so methods whose curves coincide (e.g. filtering never fires) stay visible.
STYLES = {
    "oracle": ("tab:blue", "-"),
    "indicator": ("tab:orange", "-"),
    "indicator_balance": ("tab:green", "--"),
    "indicator_filter": ("tab:red", ":"),
    "indicator_balance_filter": ("tab:purple", "-."),
    "indicator_balance_recorded_fallback": ("tab:olive", "--"),
    "indicator_balance_filter_recorded_fallback": ("tab:brown", "-."),
    "indicator_balance_filter_paper_encoder": ("tab:gray", "--"),
    "indicator_balance_filter_fp32": ("tab:pink", ":"),
    "oracle_n3": ("tab:cyan", "-"),
    "indicator_n3": ("gold", "-"),
    "indicator_balance_filter_n3": ("darkgreen", "-"),
    "indicator_balance_filter_inverse_dynamics": ("tab:brown", ":"),
    "indicator_balance_filter_n3_inverse_dynamics": ("tab:red", "-"),
    "oracle_n3_inverse_dynamics": ("navy", "-"),
    "indicator_n3_inverse_dynamics": ("darkorange", "-"),
    "indicator_balance_n3_inverse_dynamics": ("tab:green", "-"),
    "indicator_filter_n3_inverse_dynamics": ("tab:pink", "-"),
    "oracle_n3_inverse_dynamics_return_scale": ("navy", "--"),
    "indicator_n3_inverse_dynamics_return_scale": ("darkorange", "--"),
    "indicator_balance_filter_n3_inverse_dynamics_return_scale": ("tab:red", "--"),
    "oracle_return_scale": ("navy", ":"),
    "indicator_return_scale": ("darkorange", ":"),
    "indicator_balance_filter_return_scale": ("tab:red", ":"),
    "indicator_balance_filter_paper_encoder_n3": ("dimgray", "-"),
    "oracle_no_augmentation": ("tab:blue", ":"),
    "indicator_balance_filter_inverse_dynamics_no_augmentation": ("tab:brown", "--"),
    "indicator_balance_filter_target_q": ("tab:cyan", "--"),
    "indicator_balance_filter_calibrated": ("tab:cyan", ":"),
    "indicator_balance_filter_n3_inverse_dynamics_target_q": ("tab:red", "--"),
    "indicator_balance_filter_n3_inverse_dynamics_calibrated": ("tab:red", ":"),
    "ae": ("tab:gray", "-"),
    "vae": ("tab:gray", ":"),
    "ae_n3_inverse_dynamics": ("black", "-"),
    "vae_n3_inverse_dynamics": ("black", "--"),
}
# The noise arms: one hue per kind (blue: false negatives, red: false positives), darker at higher rates.
_NOISE_SHADES = {
    "fn": ("#9ecae1", "#6baed6", "#4292c6", "#2171b5", "#08306b"),
    "fp": ("#fcbba1", "#fc9272", "#fb6a4a", "#ef3b2c", "#cb181d", "#a50f15", "#67000d"),
}
for _kind, _rates in REWARD_NOISE.items():
    for _rate, _colour in zip(_rates, _NOISE_SHADES[_kind], strict=True):
        LABELS[f"oracle_{_kind}{_rate:g}"] = f"Oracle, p_{_kind.upper()} = {_rate:g}"
        STYLES[f"oracle_{_kind}{_rate:g}"] = (_colour, "-")
RGBD_KEYS = "--policy.observation_keys=[observation.images.front,observation.images.front_depth]"


@dataclass
class TaskPreset:
    env_args: list[str]
    steps: int
    updates_per_cycle: int
    episodes_per_cycle: int
    env_eval_freq: int
    eval_episodes: int = 20


REACH_RGBD_ENV = [
    "--env.type=sawyer_reach",
    "--env.obs_type=rgbd",
    "--env.camera.height=64",
    "--env.camera.width=64",
    RGBD_KEYS,
]
TASKS: dict[str, TaskPreset] = {
    "reach_state": TaskPreset(["--env.type=sawyer_reach", "--env.obs_type=state"], 1600, 40, 4, 200),
    # From pixels only, 64x64 RGB-D: 20,000 updates = 20,000 env steps (one update per env step: the Oracle
    # learns faster per env step than at 0.4, Indicator+Balance+Filter does not; docs/results/README.md).
    "reach_rgbd": TaskPreset(REACH_RGBD_ENV, 20000, 100, 4, 1000, 20),
    # The same at 0.4 updates per env step (the state task's ratio): 8000 updates = 20,000 env steps.
    "reach_rgbd_low_utd": TaskPreset(REACH_RGBD_ENV, 8000, 40, 4, 400, 20),
    "rope_state": TaskPreset(
        ["--env.type=rope_push", "--env.obs_type=state", "--policy.observation_keys=[observation.rope_xy]"],
        6000,
        40,
        8,
        400,
        20,
    ),
    # Paper appendix B: RopePush's image encoder ends in a spatial softmax (32 keypoints).
    "rope_rgbd": TaskPreset(
        ["--env.type=rope_push", "--env.obs_type=rgbd", RGBD_KEYS, "--policy.spatial_softmax=true"],
        2000,
        40,
        8,
        400,
        10,
    ),
}
# The authors' observations as far as their public env shows them: RGB only (the paper's 100x100x3), each
# link its own colour. For measuring whether the learned-reward baselines are exploited there.
TASKS["rope_rgb_link_colours"] = TaskPreset(
    [
        "--env.type=rope_push",
        "--env.obs_type=rgb",
        "--env.link_colours=tab20",
        "--policy.observation_keys=[observation.images.front]",
        "--policy.spatial_softmax=true",
    ],
    2000,
    40,
    8,
    400,
    10,
)
# RGB-D rope push with the pusher in view, resting where its last push ended: whether a visible, directly
# controlled object in the images changes the ordering of the indicator and the learned-reward baselines.
TASKS["rope_rgbd_pusher_visible"] = TaskPreset(
    [*TASKS["rope_rgbd"].env_args, "--env.pusher_rest=push_end"], 2000, 40, 8, 400, 10
)
# The same with each 100 px frame area-averaged from a 400 px render (docs/results/rope_framing.json).
TASKS["rope_rgbd_supersample4"] = TaskPreset(
    [*TASKS["rope_rgbd"].env_args, "--env.camera.supersample=4"], 2000, 40, 8, 400, 10
)

# The paper's Gym tasks (appendix table; docs/envs.md "gymnasium goal envs"), on the wrapped gymnasium(-robotics)
# envs, with the paper's horizon and success radius spelled out (the env defaults are the same): T = 50,
# epsilon 0.01 m (Reacher) / 0.05 m (Fetch). State runs compare the paper's 3-d goal space (observation.state:
# the grip point, FetchPush's block) and condition on the wrapped env's observation (observation.environment_state,
# never compared, relabeled or in a goal); visual runs compare the images at the paper's 100x100.
# Budgets follow OpenAI baselines' HER on Fetch: 2 episodes (100 env steps) and 40 updates per cycle, 0.4 updates
# per env step. fetch_reach_state's budget was chosen from a 1-seed probe (docs/results/gym_tasks/README.md), and
# fetch_reach_rgbd's 20,000 env steps are the budget (both image arms reach 0.9 by 11,000 on 1 seed);
# fetch_push_state's and reacher_rgb's are first guesses (the README gives what they cost and what they learned).
GYM_STATE_KEYS = [
    "--policy.observation_keys=[observation.state]",
    "--policy.context_keys=[observation.environment_state]",
]
FETCH_T_EPS = ["--env.episode_length=50", "--env.epsilon=0.05"]
TASKS["fetch_reach_state"] = TaskPreset(
    ["--env.type=fetch_reach", "--env.obs_type=state", *FETCH_T_EPS, *GYM_STATE_KEYS], 2000, 40, 2, 80, 20
)
TASKS["fetch_push_state"] = TaskPreset(
    ["--env.type=fetch_push", "--env.obs_type=state", *FETCH_T_EPS, *GYM_STATE_KEYS], 40000, 40, 2, 2000, 20
)
# FetchPush with the data-to-update ratio of baselines' HER on 8 MPI workers (2 episodes each per cycle, 40
# updates of their averaged batch-256 gradients): 16 episodes and 40 updates of batch 2048 per cycle, 0.05 updates
# per env step. Single-worker HER does not learn FetchPush (TianhongDai/hindsight-experience-replay#19).
# 50,000 updates = 1M env steps.
TASKS["fetch_push_state_8workers"] = TaskPreset(
    [*TASKS["fetch_push_state"].env_args, "--online.batch_size=2048"], 50000, 40, 16, 400, 20
)
# Visual: one update per env step, as reach_rgbd; 100x100 as the paper's table.
TASKS["fetch_reach_rgbd"] = TaskPreset(
    ["--env.type=fetch_reach", "--env.obs_type=rgbd", *FETCH_T_EPS, RGBD_KEYS], 20000, 100, 2, 1000, 20
)
# Reacher from state (fingertip xy compared; joint cos, sin and velocities as context): what the visual preset's
# arms reach when the image is not the bottleneck, at the state tasks' 0.4 updates per env step.
TASKS["reacher_state"] = TaskPreset(
    [
        "--env.type=reacher",
        "--env.obs_type=state",
        "--env.episode_length=50",
        "--env.epsilon=0.01",
        *GYM_STATE_KEYS,
    ],
    8000,
    40,
    2,
    400,
    20,
)
# The same without the context input: the fingertip xy alone, so the policy cannot see the velocities.
TASKS["reacher_state_tip_only"] = TaskPreset(
    [*TASKS["reacher_state"].env_args[:4], GYM_STATE_KEYS[0], "--policy.context_keys=[]"],
    *astuple(TASKS["reacher_state"])[1:],
)
TASKS["reacher_rgb"] = TaskPreset(
    [
        "--env.type=reacher",
        "--env.obs_type=rgb",
        "--env.episode_length=50",
        "--env.epsilon=0.01",
        "--policy.observation_keys=[observation.images.front]",
    ],
    20000,
    100,
    2,
    1000,
    20,
)
# The same images with the joint cos, sin and velocities as context (never compared): a torque-driven arm's
# velocities are in no single image, and reacher_state_tip_only shows the task does not learn without them.
TASKS["reacher_rgb_env_state"] = TaskPreset(
    [
        *TASKS["reacher_rgb"].env_args,
        "--env.env_state_with_images=true",
        "--policy.context_keys=[observation.environment_state]",
    ],
    *astuple(TASKS["reacher_rgb"])[1:],
)
# Pixels only, with the previous step's image compared beside the current one (--env.previous_frame): the
# motion that reacher_rgb's single image lacks, without handing the policy any state.
TASKS["reacher_rgb_previous_frame"] = TaskPreset(
    [
        *TASKS["reacher_rgb"].env_args[:4],
        "--env.previous_frame=true",
        "--policy.observation_keys=[observation.images.front,observation.images.front_prev]",
    ],
    *astuple(TASKS["reacher_rgb"])[1:],
)
