"""``--policy.push_to_hub=true`` of ``lerobot-indicator-train``: the trained policy, its processors, train config
and model card to the Hub, through LeRobot's own ``PreTrainedPolicy.push_model_to_hub`` (as ``lerobot-train``).

``push_model_to_hub`` reads a ``lerobot-train`` config: ``dataset.repo_id`` (the card's dataset), ``steps``,
``batch_size``, ``seed``, ``optimizer`` (the card's training table) and ``save_pretrained`` (train_config.json).
An online run has no ``batch_size`` field (``--online.batch_size`` may be None: the paper's, chosen by the
trainer) and may have no ``--dataset.*``, so :class:`PushedRunConfig` answers those reads from the run.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata
from lerobot.policies.pretrained import PreTrainedPolicy

from lerobot_indicator.training.config import OnlineTrainConfig


class PolicyPushError(Exception):
    """The push after training failed; the message (one line) says where the trained policy is kept."""


@dataclass
class PushedRunConfig:
    """What ``PreTrainedPolicy.push_model_to_hub`` reads of a training config, for an online run."""

    run: OnlineTrainConfig
    batch_size: int

    @property
    def dataset(self) -> SimpleNamespace:
        """The card's dataset: ``--dataset.repo_id``, else the run's own ``--record.repo_id``, else none."""
        repo_id = self.run.dataset.repo_id if self.run.dataset is not None else self.run.record.repo_id
        return SimpleNamespace(repo_id=repo_id)

    @property
    def steps(self) -> int:
        return self.run.steps

    @property
    def seed(self) -> int:
        return self.run.seed

    @property
    def optimizer(self):
        return self.run.policy.get_optimizer_preset()

    def save_pretrained(self, save_directory: Path) -> None:
        """train_config.json: the online run's own config (``lerobot-indicator-train --config_path`` reads it)."""
        self.run.save_pretrained(save_directory)


def _dataset_meta(cfg: OnlineTrainConfig) -> LeRobotDatasetMetadata | None:
    """The ``--dataset.*`` metadata for the card (episodes, fps, robot type); the dataset is local by now."""
    if cfg.dataset is None:
        return None
    return LeRobotDatasetMetadata(cfg.dataset.repo_id, root=cfg.dataset.root, revision=cfg.dataset.revision)


def push_policy(
    policy: PreTrainedPolicy, processors, cfg: OnlineTrainConfig, batch_size: int, keep: Callable[[], Path]
) -> None:
    """Push ``policy`` and its pre/post processors to ``--policy.repo_id``. Any failure becomes one
    :class:`PolicyPushError` line naming ``keep()``: the trained policy's directory on disk."""
    repo_id = cfg.policy.repo_id
    try:
        policy.push_model_to_hub(PushedRunConfig(cfg, batch_size), dataset_meta=_dataset_meta(cfg))
        processors.pre.push_to_hub(repo_id)
        processors.post.push_to_hub(repo_id)
    except Exception as err:  # network, auth, card validation: the run's result is kept either way
        reason = (str(err).strip().splitlines() or [""])[0]
        kept = keep()
        raise PolicyPushError(
            f"--policy.push_to_hub: pushing to {repo_id} failed ({type(err).__name__}: {reason}); the trained "
            f"policy is kept at {kept} (push it later with: hf upload {repo_id} {kept})"
        ) from err
    logging.info("policy, processors and model card pushed to %s", repo_id)
