"""``--policy.preset``: the defaults of n_step, inverse_dynamics and critic_output_scale.

"auto" (the default) gives image inputs the return-scaled critic output, a 3-step target and the inverse-dynamics
loss (with the shared "drq" encoder), except on lerobot-train samples (n_step=1), and state inputs the paper's
values (the return-scaled output regresses state reach); "paper" gives
the paper's one-step target, no inverse dynamics and Q straight from the MLP. A given value always wins.
"""

import json
import logging
from pathlib import Path
from types import SimpleNamespace

import draccus
import pytest
import torch
from lerobot.configs import FeatureType, PolicyFeature, PreTrainedConfig
from lerobot.policies import make_policy

from lerobot_indicator.policy.configuration_indicator_ddpg import (
    IndicatorDDPGConfig,
    IndicatorDDPGConfigError,
)
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

FIELDS = ("n_step", "inverse_dynamics", "critic_output_scale")
IMAGE, IMAGE_GOAL = "observation.images.front", "observation.images.goal_front"
STATE, STATE_GOAL = "observation.state", "observation.goal_state"
# 40 px: the smallest size the drq encoder's conv layers take with room to spare.
INPUTS = {
    "images": {IMAGE: (FeatureType.VISUAL, (3, 40, 40)), IMAGE_GOAL: (FeatureType.VISUAL, (3, 40, 40))},
    "state": {STATE: (FeatureType.STATE, (3,)), STATE_GOAL: (FeatureType.STATE, (3,))},
}
TINY = {"hidden_dims": [8], "conv_channels": [4, 4, 4, 4], "feature_dim": 8, "conv_precision": "float32"}


def resolved(inputs: str, **config: object) -> IndicatorDDPGConfig:
    """A config given ``config``, with ``inputs``' features known (what make_policy does before the policy)."""
    cfg = IndicatorDDPGConfig(device="cpu", horizon=5, **config)
    cfg.input_features = {k: PolicyFeature(t, s) for k, (t, s) in INPUTS[inputs].items()}
    cfg.output_features = {"action": PolicyFeature(FeatureType.ACTION, (3,))}
    cfg.validate_features()
    return cfg


def values(cfg: IndicatorDDPGConfig) -> tuple:
    return tuple(getattr(cfg, name) for name in FIELDS)


@pytest.mark.parametrize(
    "inputs, config, expected",
    [
        ("images", {}, (3, 1.0, "return")),
        # The paper's encoder has no shared encoder for the inverse-dynamics loss to train.
        ("images", {"image_encoder": "paper"}, (3, 0.0, "return")),
        ("state", {}, (1, 0.0, "paper")),
        ("images", {"preset": "paper"}, (1, 0.0, "paper")),
        ("state", {"preset": "paper"}, (1, 0.0, "paper")),
    ],
)
def test_each_preset_resolves_to_concrete_values_once_the_inputs_are_known(inputs, config, expected):
    assert values(resolved(inputs, **config)) == expected


def test_what_does_not_depend_on_the_inputs_is_set_when_the_config_is_built():
    auto, paper = IndicatorDDPGConfig(device="cpu"), IndicatorDDPGConfig(device="cpu", preset="paper")
    assert values(auto) == (None, None, None)
    assert values(paper) == (1, 0.0, "paper")


@pytest.mark.parametrize("preset", ["auto", "paper"])
@pytest.mark.parametrize("inputs", ["images", "state"])
def test_explicit_values_win_over_either_preset(preset, inputs):
    given = {"n_step": 2, "critic_output_scale": "paper" if preset == "auto" else "return"}
    if inputs == "images":
        given["inverse_dynamics"] = 0.0 if preset == "auto" else 0.5
    cfg = resolved(inputs, preset=preset, **given)
    for name, value in given.items():
        assert getattr(cfg, name) == value


def test_a_policy_made_for_a_dataset_keeps_one_step_targets_and_says_why(caplog):
    """lerobot-train's make_policy(ds_meta=...) tells the config (set_dataset_feature_metadata): its samples hold no
    frames between o_{t+1} and the future ones, so "auto" keeps n_step=1 there, with inverse dynamics."""
    hwc = {"dtype": "image", "shape": (40, 40, 3), "names": ["height", "width", "channels"]}
    features = {IMAGE: hwc, IMAGE_GOAL: hwc, "action": {"dtype": "float32", "shape": (3,), "names": None}}
    meta = SimpleNamespace(features=features, stats=None, repo_id="local/tiny")
    cfg = IndicatorDDPGConfig(device="cpu", horizon=5, future_offsets=[2, 3], **TINY)
    with caplog.at_level(logging.INFO):
        policy = make_policy(cfg, ds_meta=meta)
    assert values(policy.config) == (1, 1.0, "return") and policy.critic.inverse is not None
    assert (
        "indicator_ddpg preset=auto (images, lerobot-train samples): n_step=1, inverse_dynamics=1.0, "
        "critic_output_scale=return (a lerobot-train sample holds no frames between o_{t+1}" in caplog.text
    )
    # A lerobot-train batch (o_t, o_{t+1}, the future offsets) trains with these defaults.
    gen = torch.Generator().manual_seed(0)
    frames = (4, 2 + len(cfg.future_offsets), 3, 40, 40)
    batch = {IMAGE: torch.rand(frames, generator=gen), IMAGE_GOAL: torch.rand(frames, generator=gen)}
    batch["action"] = torch.rand(4, 3, generator=gen) * 2 - 1
    loss, stats = policy.forward(batch, generator=gen)
    assert loss.isfinite() and stats["inverse_dynamics_loss"] > 0
    # The trainer's own policy (no dataset metadata) gets the 3-step target.
    assert resolved("images", **TINY).n_step == 3


def test_the_start_up_line_names_the_preset_and_the_values_in_use(caplog):
    with caplog.at_level(logging.INFO):
        resolved("images")
    assert (
        "indicator_ddpg preset=auto (images): n_step=3, inverse_dynamics=1.0, critic_output_scale=return; "
        "--policy.preset=paper for the paper's one-step settings"
    ) in caplog.messages
    caplog.clear()
    with caplog.at_level(logging.INFO):
        resolved("state", preset="paper", n_step=2)
    assert (
        "indicator_ddpg preset=paper (state): n_step=2, inverse_dynamics=0.0, critic_output_scale=paper; "
        "--policy.preset=auto for the settings measured to learn"
    ) in caplog.messages


@pytest.mark.parametrize("preset", ["auto", "paper"])
def test_saved_checkpoints_reload_with_the_resolved_values(tmp_path: Path, preset):
    cfg = resolved("images", preset=preset, **TINY)
    policy = IndicatorDDPGPolicy(cfg)
    policy.save_pretrained(tmp_path)
    saved = json.loads((tmp_path / "config.json").read_text())
    assert tuple(saved[name] for name in FIELDS) == values(cfg) and saved["preset"] == preset
    assert "_dataset_samples" not in saved
    loaded = IndicatorDDPGPolicy.from_pretrained(tmp_path)
    assert values(loaded.config) == values(cfg)
    assert (loaded.critic.inverse is None) == (policy.critic.inverse is None)


def test_a_checkpoint_with_concrete_values_and_no_preset_loads_unchanged(tmp_path: Path):
    """What checkpoints saved before the presets hold: the paper's values, which "auto" must not replace."""
    resolved("images", preset="paper", **TINY).save_pretrained(tmp_path)
    config_file = tmp_path / "config.json"
    saved = json.loads(config_file.read_text())
    del saved["preset"]
    config_file.write_text(json.dumps(saved))
    cfg = PreTrainedConfig.from_pretrained(tmp_path)
    assert cfg.preset == "auto" and values(cfg) == (1, 0.0, "paper")
    cfg.validate_features()
    assert values(cfg) == (1, 0.0, "paper")


def test_the_preset_is_a_command_line_choice():
    cfg = draccus.parse(IndicatorDDPGConfig, args=["--preset=paper", "--n_step=3", "--device=cpu"])
    assert values(cfg) == (3, 0.0, "paper")
    with pytest.raises(
        IndicatorDDPGConfigError, match=r"preset must be one of \('auto', 'paper'\), got 'fast'"
    ):
        IndicatorDDPGConfig(device="cpu", preset="fast")
