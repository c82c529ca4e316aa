"""Naming rules shared by envs, datasets, the policy and the trainers (see docs/conventions.md)."""

GT_PREFIX = "observation.gt_"
GOAL_PREFIX = "goal_"


def goal_key(observation_key: str) -> str:
    """Key of the goal observation that ``observation_key`` is compared with.

    One rule for every modality, so a config only has to name the compared keys:
    ``observation.state -> observation.goal_state``,
    ``observation.images.front -> observation.images.goal_front``.
    """
    if not observation_key.startswith("observation."):
        raise ValueError(f"{observation_key!r} is not an observation key (must start with 'observation.')")
    head, _, name = observation_key.rpartition(".")
    if name.startswith(GOAL_PREFIX):
        raise ValueError(f"{observation_key!r} is already a goal key")
    return f"{head}.{GOAL_PREFIX}{name}"


def is_goal_key(key: str) -> bool:
    return key.rpartition(".")[2].startswith(GOAL_PREFIX)


def is_ground_truth_key(key: str) -> bool:
    """Ground-truth keys are for evaluation and the oracle baseline only, never network inputs."""
    return key.startswith(GT_PREFIX)
