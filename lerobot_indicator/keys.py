"""Key names and constants shared by envs, datasets, the policy and the trainers (see docs/conventions.md).

Every module takes these names from here, so a key is spelled once.
"""

OBS_PREFIX = "observation."
# Goal observations: ``<name>`` -> ``goal_<name>`` (env keys and the last part of batch keys, ``goal_key``).
GOAL_PREFIX = "goal_"
# Depth images: camera ``<cam>`` -> ``<cam>_depth`` (env key, dataset feature and batch key).
DEPTH_SUFFIX = "_depth"
# The previous step's images of camera ``<cam>`` (``previous_frame`` envs): camera ``<cam>_prev``.
PREVIOUS_SUFFIX = "_prev"

# Ground truth, as the envs' ``info`` dict names it (evaluation and the oracle baseline only) ...
GT_ACHIEVED_GOAL = "gt_achieved_goal"
GT_DESIRED_GOAL = "gt_desired_goal"
GT_DISTANCE = "gt_distance"
GT_INFO_KEYS = (GT_ACHIEVED_GOAL, GT_DESIRED_GOAL, GT_DISTANCE)
# ... and as datasets and batches name it: ``observation.gt_*``, never a network input.
GT_PREFIX = OBS_PREFIX + "gt_"
OBS_GT_ACHIEVED_GOAL = OBS_PREFIX + GT_ACHIEVED_GOAL
OBS_GT_DESIRED_GOAL = OBS_PREFIX + GT_DESIRED_GOAL
OBS_GT_DISTANCE = OBS_PREFIX + GT_DISTANCE
# Recorded datasets: true on an episode's final-observation frame o_T, whose action is padding (no action follows
# o_T; docs/dataset_format.md). Under LeRobot's ``complementary_info.`` prefix, so no policy takes it as a feature.
ACTION_IS_PAD = "complementary_info.action_is_pad"

# Evaluation episodes reset with seed EVAL_SEED_OFFSET + i, so they never share a seed with a training
# episode, and every evaluation (trainer, scripts, benchmarks) sees the same goals.
EVAL_SEED_OFFSET = 10**9


def depth_key(camera: str) -> str:
    """``front -> front_depth``; works on env keys and batch keys alike."""
    return f"{camera}{DEPTH_SUFFIX}"


def previous_key(camera: str) -> str:
    """``front -> front_prev``: the camera name under which an env gives the previous step's images."""
    return f"{camera}{PREVIOUS_SUFFIX}"


def observed_cameras(camera: str, previous_frame: bool) -> list[str]:
    """The camera names an env's observation holds: ``camera``, and ``previous_key(camera)`` with
    ``previous_frame``."""
    return [camera, previous_key(camera)] if previous_frame else [camera]


def ground_truth_key(info_key: str) -> str:
    """``gt_distance -> observation.gt_distance``: the dataset / batch key of an ``info`` ground-truth key."""
    if not info_key.startswith("gt_"):
        raise ValueError(f"{info_key!r} is not a ground-truth info key (must start with 'gt_')")
    return OBS_PREFIX + info_key


def goal_key(observation_key: str) -> str:
    """Key of the goal observation that ``observation_key`` is compared with.

    One rule for every modality, so a config only has to name the compared keys:
    ``observation.state -> observation.goal_state``,
    ``observation.images.front -> observation.images.goal_front``.
    """
    if not observation_key.startswith(OBS_PREFIX):
        raise ValueError(f"{observation_key!r} is not an observation key (must start with 'observation.')")
    head, _, name = observation_key.rpartition(".")
    if name.startswith(GOAL_PREFIX):
        raise ValueError(f"{observation_key!r} is already a goal key")
    return f"{head}.{GOAL_PREFIX}{name}"


def observation_key(goal: str) -> str:
    """The observation key a goal key is the goal of: ``goal_key``'s inverse."""
    head, _, name = goal.rpartition(".")
    if not goal.startswith(OBS_PREFIX) or not name.startswith(GOAL_PREFIX):
        raise ValueError(f"{goal!r} is not a goal key (observation.<...>.{GOAL_PREFIX}<name>)")
    return f"{head}.{name.removeprefix(GOAL_PREFIX)}"


def is_goal_key(key: str) -> bool:
    return key.rpartition(".")[2].startswith(GOAL_PREFIX)


def is_ground_truth_key(key: str) -> bool:
    """Ground-truth keys are for evaluation and the oracle baseline only, never network inputs."""
    return key.startswith(GT_PREFIX)
