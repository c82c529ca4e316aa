"""Start-up check of a policy's inputs against the observations of the env or dataset it is used with.

A pretrained policy keeps the input features it was made for; an env or dataset with other keys or image sizes
would otherwise fail at the first rollout or batch, deep inside a conv or with a missing key. The check names
every key that is missing or of another shape, in one line, with the fix when the caller knows it.
"""

from __future__ import annotations

import functools
import sys
from pathlib import Path

from lerobot.configs import PolicyFeature

from lerobot_indicator.keys import DEPTH_SUFFIX, goal_key, is_goal_key


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


def policy_env_options(config) -> str:
    """The ``--env.*`` options under which this plugin's envs give the inputs the policy was made for (its own
    features: no env config needed), as a hint."""
    known = config.input_features or {}
    images = [k for k in required_inputs(config) if k in known and len(known[k].shape) == 3]
    if not images:
        return "use --env.obs_type=state"
    obs_type = "rgbd" if any(k.endswith(DEPTH_SUFFIX) for k in images) else "rgb"
    _, height, width = known[images[0]].shape
    return f"use --env.obs_type={obs_type} --env.camera.height={height} --env.camera.width={width}"


def check_env_for_policy(config, env_cfg, what: str = "eval env") -> None:
    """Before any episode: the env ``env_cfg`` gives every input of the policy ``config`` in its shape; else one
    :class:`PolicyInputError` line naming both shapes and the ``--env.*`` options that fix it."""
    from lerobot.envs.utils import env_to_policy_features

    features = env_to_policy_features(env_cfg)
    if input_problems(config, features) == ([], {}):
        return
    from lerobot_indicator.training.online import env_input_fix

    obs_type = getattr(env_cfg, "obs_type", None)
    source = f"{what} {env_cfg.type}" + (f" (obs_type={obs_type})" if obs_type else "")
    fix = env_input_fix(env_cfg, config) or policy_env_options(config)
    # The env already has that obs_type: what it lacks is the goal of a compared key.
    if obs_type and fix == f"use --env.obs_type={obs_type}":
        with_goal = sorted(
            k
            for k in features
            if k.startswith("observation.") and not is_goal_key(k) and goal_key(k) in features
        )
        fix = (
            f"the env gives goals only for {with_goal}: train the policy with "
            f"--policy.observation_keys=[{','.join(with_goal)}]"
        )
    check_policy_inputs(config, features, source, fix)


def _env_checked(make_policy, train_cfg: dict):
    """LeRobot's ``make_policy`` followed by :func:`check_env_for_policy` on the env the policy will be
    evaluated in: ``env_cfg`` (``lerobot-eval``) or the run's eval env (``lerobot-train``, captured in
    ``train_cfg`` when its datasets are made, checked only when it evaluates: ``--env_eval_freq`` > 0)."""

    @functools.wraps(make_policy)
    def make_checked(*args, **kwargs):
        policy = make_policy(*args, **kwargs)
        config = getattr(policy, "config", None)
        env_cfg, what = kwargs.get("env_cfg"), "eval env"
        run = train_cfg.get("cfg")
        if env_cfg is None and run is not None and getattr(run, "env_eval_freq", 0) > 0:
            env_cfg, what = run.env, "eval env (--env.*)"
        if (
            env_cfg is not None
            and getattr(config, "type", None) == "indicator_ddpg"
            and not kwargs.get("rename_map")
        ):
            check_env_for_policy(config, env_cfg, what)
        return policy

    make_checked.checks_env = True
    return make_checked


def install_lerobot_env_check() -> bool:
    """In a ``lerobot-eval`` or ``lerobot-train`` process, check the policy against its eval env right after
    ``make_policy``: at start-up, not at the first evaluation. LeRobot has no hook there, so this wraps the
    script's ``make_policy`` (and, in ``lerobot-train``, ``make_train_eval_datasets``, to see the run's
    ``--env.*``, which ``make_policy`` is not given). Returns whether a script was found."""
    found = False
    for name in ("lerobot.scripts.lerobot_train", "lerobot.scripts.lerobot_eval", "__main__"):
        module = sys.modules.get(name)
        script = Path(str(getattr(module, "__file__", ""))).name
        if module is None or script not in ("lerobot_train.py", "lerobot_eval.py"):
            continue
        make = getattr(module, "make_policy", None)
        if make is None or getattr(make, "checks_env", False):
            found = True
            continue
        train_cfg: dict = {}
        module.make_policy = _env_checked(make, train_cfg)
        datasets = getattr(module, "make_train_eval_datasets", None)
        if datasets is not None:

            @functools.wraps(datasets)
            def capture(cfg, *args, _make=datasets, _train_cfg=train_cfg, **kwargs):
                _train_cfg["cfg"] = cfg
                return _make(cfg, *args, **kwargs)

            module.make_train_eval_datasets = capture
        found = True
    return found
