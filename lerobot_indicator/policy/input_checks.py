"""Start-up check of a policy's inputs against the observations of the env or dataset it is used with.

A pretrained policy keeps the input features it was made for; an env or dataset with other keys or image sizes
would otherwise fail at the first rollout or batch, deep inside a conv or with a missing key. The check names
every key that is missing or of another shape, in one line, with the fix when the caller knows it.
"""

from __future__ import annotations

from lerobot.configs import PolicyFeature

from lerobot_indicator.keys import goal_key


class PolicyInputError(ValueError):
    """A policy input the env or dataset does not provide, or provides with another shape."""


def required_inputs(config, with_goals: bool = True) -> list[str]:
    """The observation keys the networks read: the compared keys, their goals (``with_goals``), the context
    keys."""
    keys = list(config.observation_keys or [])
    goals = [goal_key(k) for k in keys] if with_goals else []
    return keys + goals + list(getattr(config, "context_keys", None) or [])


def input_problems(
    config, features: dict[str, PolicyFeature], with_goals: bool = True
) -> tuple[list[str], dict[str, tuple[tuple[int, ...], tuple[int, ...]]]]:
    """(inputs missing from ``features``, {input: (the policy's shape, the data's shape)} where they differ)."""
    known = config.input_features or {}
    required = required_inputs(config, with_goals)
    missing = [k for k in required if k not in features]
    shapes = {
        k: (tuple(known[k].shape), tuple(features[k].shape))
        for k in required
        if k in features and k in known and tuple(known[k].shape) != tuple(features[k].shape)
    }
    return missing, shapes


def check_policy_inputs(
    config, features: dict[str, PolicyFeature], source: str, fix: str = "", with_goals: bool = True
) -> None:
    """Raise one :class:`PolicyInputError` line when the policy's inputs are not among ``features`` (those of
    ``source``, e.g. "env sawyer_reach (obs_type=state)") with the same shapes; ``fix`` is appended."""
    missing, shapes = input_problems(config, features, with_goals)
    if not missing and not shapes:
        return
    parts = []
    if missing:
        observed = sorted(k for k in features if k.startswith("observation."))
        parts.append(
            f"the policy's inputs {missing} are not among the observations of the {source}: {observed}"
        )
    if shapes:
        each = ", ".join(f"{k} {policy} vs {data}" for k, (policy, data) in shapes.items())
        parts.append(f"the policy was made for other shapes than the {source}'s: {each}")
    raise PolicyInputError("; ".join(parts) + (f"; {fix}" if fix else ""))
