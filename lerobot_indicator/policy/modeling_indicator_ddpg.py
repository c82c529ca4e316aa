"""``IndicatorDDPGPolicy``: the paper's goal-conditioned DDPG as a LeRobot policy.

``forward`` accepts either a ``lerobot-train`` dataset batch (observations stacked over
``observation_delta_indices``) or a transition batch (``indicator_core`` docstring), which is what the online
trainer passes. One returned loss trains actor and critic together; ``update()`` (called by lerobot-train
after each optimizer step) moves the target networks.
"""

import copy

import torch
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.utils.feature_utils import dataset_to_policy_features
from torch import Tensor, nn

from lerobot_indicator.finite import check_batch, check_loss
from lerobot_indicator.io_errors import reading
from lerobot_indicator.keys import goal_key, is_goal_key
from lerobot_indicator.policy import indicator_core
from lerobot_indicator.policy.configuration_indicator_ddpg import LEARNED_REWARDS, IndicatorDDPGConfig
from lerobot_indicator.policy.goal_observations import GoalObservations
from lerobot_indicator.policy.input_checks import PolicyInputError, check_policy_inputs, policy_env_options
from lerobot_indicator.policy.learned_reward import LearnedReward
from lerobot_indicator.policy.networks_indicator_ddpg import Actor, Critic


class IndicatorDDPGPolicy(PreTrainedPolicy):
    config_class = IndicatorDDPGConfig
    name = "indicator_ddpg"

    def __init__(
        self,
        config: IndicatorDDPGConfig,
        dataset_stats: dict[str, dict[str, Tensor]] | None = None,
        dataset_meta=None,
    ):
        super().__init__(config)
        config.validate_features()
        if dataset_meta is not None and getattr(dataset_meta, "features", None):
            # A pretrained policy keeps its input features: the dataset must give them (lerobot-train).
            check_policy_inputs(
                config,
                dataset_to_policy_features(dataset_meta.features),
                f"dataset {dataset_meta.repo_id}",
                with_goals=not getattr(config, "episode_end_goal", False),
            )
        if dataset_meta is not None and getattr(dataset_meta, "episodes", None) is not None:
            horizon = dataset_horizon(dataset_meta, config.horizon)
            config.set_horizon(horizon, source=f"dataset {dataset_meta.repo_id}")
        if config.horizon is None:
            raise ValueError(
                "indicator_ddpg needs the episode horizon T: pass --policy.horizon, or make the policy for a "
                "dataset or env (its episode length is used)"
            )
        self.config = config
        self.actor = Actor(config, dataset_stats)
        shared = self.actor.encoder if config.shared_encoder else None
        self.critic = Critic(config, dataset_stats, encoder=shared)
        # One deepcopy of both keeps a shared encoder shared between the targets too.
        self.target_actor, self.target_critic = copy.deepcopy((self.actor, self.critic))
        self.target_actor.requires_grad_(False)
        self.target_critic.requires_grad_(False)
        # The AE / VAE baselines' reward network, trained by its own loss in the same backward and step.
        self.reward_model = LearnedReward(config, dataset_stats) if config.reward in LEARNED_REWARDS else None
        self._loss = indicator_core.indicator_ddpg_loss
        if config.compile_model:
            # Static shapes: a second batch size (a last short batch, another policy in the same process)
            # recompiles instead of going symbolic, which torch.rand(size, generator=...) does not support.
            self._loss = torch.compile(self._loss, mode=config.compile_mode, dynamic=False)

    @classmethod
    def _load_as_safetensor(cls, model, model_file: str, map_location: str, strict: bool):
        """LeRobot's loading of ``model.safetensors`` (``from_pretrained``); a truncated or corrupt file is one
        line naming it."""
        with reading(model_file, "policy weights", "save the policy again or use another checkpoint"):
            return super()._load_as_safetensor(model, model_file, map_location, strict)

    def set_observation_stats(self, stats: dict[str, dict[str, Tensor]]) -> None:
        """Input normalisation of every network (online and target) from ``{key: {"mean", "std"}}``."""
        for net in (self.actor, self.critic, self.target_actor, self.target_critic):
            net.encoder.set_stats(stats)
        if self.reward_model is not None:
            self.reward_model.set_stats(stats)

    def get_optim_params(self) -> list[dict]:
        # Target networks are moved by update(), never by the optimizer; a shared encoder is listed once.
        # The reward model's parameters are disjoint from the agent's, so one Adam step over both (lerobot-train
        # builds one optimizer) is its own separate step at the same learning rate.
        trained = [self.actor, self.critic] + ([self.reward_model] if self.reward_model is not None else [])
        return [{"params": list(nn.ModuleList(trained).parameters())}]

    def reset(self) -> None:
        pass

    def update(self) -> None:
        # Both pairs in one call: a shared encoder is moved once.
        indicator_core.soft_update(
            nn.ModuleList([self.target_actor, self.target_critic]),
            nn.ModuleList([self.actor, self.critic]),
            self.config.tau,
        )

    def forward(
        self, batch: dict[str, Tensor], generator: torch.Generator | None = None
    ) -> tuple[Tensor, dict[str, float]]:
        """Loss and logging stats; ``generator`` drives relabeling (default: torch's global RNG, which
        lerobot-train seeds and restores on resume)."""
        check_batch(batch)
        if not indicator_core.is_transition_batch(batch, self.config):
            batch = indicator_core.dataset_batch_to_transitions(batch, self.config, generator)
        loss, stats = self._loss(
            batch,
            self.actor,
            self.critic,
            self.target_actor,
            self.target_critic,
            self.config,
            generator,
            self.reward_model,
        )
        check_loss(loss, stats)  # before any backward or optimizer step can spread it into the weights
        return loss, indicator_core.stats_to_floats(stats)

    def _split(self, batch: dict[str, Tensor]) -> tuple[dict[str, Tensor], dict[str, Tensor]]:
        """The observation (compared and context keys) and the goal (the compared keys' goals) of a batch."""
        context = self.config.context_keys or []
        inputs = self.config.observation_keys + self.config.goal_keys + context
        missing = [k for k in inputs if k not in batch]
        if missing:
            # What lerobot-eval / lerobot-rollout first hand the policy: one line (the plugin's excepthook) with
            # the fix, not a KeyError traceback from inside the rollout.
            hint = (
                "goals at deployment: --policy.goal_path (docs/own_data.md)"
                if is_goal_key(missing[0])
                else f"{policy_env_options(self.config)} (this plugin's envs), or an env or robot that gives them"
            )
            raise MissingInputError(f"batch lacks the policy inputs {missing} (has {sorted(batch)}); {hint}")
        for key in inputs:
            check_input_shape(key, batch[key], tuple(self.config.input_features[key].shape))
        obs = {k: batch[k] for k in self.config.observation_keys + context}
        goal = {k: batch[goal_key(k)] for k in self.config.observation_keys}
        return obs, goal

    def _with_goals(self, batch: dict[str, Tensor]) -> dict[str, Tensor]:
        """The batch with ``--policy.goal_path``'s goals where it has none: LeRobot's robot CLIs (lerobot-rollout)
        load the checkpoint's own pre-processor and deliver only the robot's observations."""
        if self.config.goal_path is None or all(k in batch for k in self.config.goal_keys):
            return batch
        if getattr(self, "_goal_observations", None) is None:
            self._goal_observations = GoalObservations(self.config.goal_path, self.config.observation_keys)
        return self._goal_observations.add(batch)

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        return self.select_action(batch)[:, None]

    @torch.no_grad()
    def select_action(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        """Deterministic pi(o, o_g), (B, A) in [-1, 1] (evaluation)."""
        obs, goal = self._split(self._with_goals(batch))
        return self.actor(obs, goal)

    @torch.no_grad()
    def select_exploration_action(
        self,
        batch: dict[str, Tensor],
        noise_eps: float | None = None,
        random_eps: float | None = None,
        generator: torch.Generator | None = None,
    ) -> Tensor:
        """Behaviour policy of baselines' HER: pi + N(0, noise_eps^2) clipped to [-1, 1], replaced by a
        uniform random action with probability random_eps (defaults from the config)."""
        noise_eps = self.config.noise_eps if noise_eps is None else noise_eps
        random_eps = self.config.random_eps if random_eps is None else random_eps
        action = self.select_action(batch)
        gen_device = generator.device if generator is not None else action.device
        noise = torch.randn(action.shape, generator=generator, device=gen_device).to(action.device)
        action = (action + noise_eps * noise).clamp(-1.0, 1.0)
        rand_action = (
            torch.rand(action.shape, generator=generator, device=gen_device).to(action.device) * 2 - 1
        )
        use_random = torch.rand(action.shape[0], generator=generator, device=gen_device).to(action.device)
        return torch.where((use_random < random_eps)[:, None], rand_action, action)


class InputShapeError(PolicyInputError):
    """A policy input whose shape is not the one the policy was made for."""


class MissingInputError(PolicyInputError, KeyError):
    """A policy input the batch lacks (a ``KeyError`` whose message is printed unquoted)."""

    __str__ = PolicyInputError.__str__


def check_input_shape(key: str, value: Tensor, feature_shape: tuple[int, ...]) -> None:
    """One line naming ``key``, the expected and the actual shape, for an input that is not (B, *feature_shape).

    Catches a time-stacked batch (``lerobot-train``'s delta indices add a time axis: (B, T, ...)) and an image
    of another size (a 32 px policy on a 64 px env), which would otherwise fail deep inside a conv or matmul.
    """
    actual = tuple(value.shape)
    if actual[1:] == feature_shape:
        return
    expected = f"(B, {', '.join(map(str, feature_shape))})"
    if len(feature_shape) == 3 and len(actual) == 4 and actual[1] == feature_shape[0]:
        raise InputShapeError(
            f"{key}: the policy was made for {feature_shape[1]}x{feature_shape[2]} (HxW) images, got "
            f"{actual[2]}x{actual[3]} (batch shape {actual}, expected {expected}); use an env or dataset of "
            f"that image size (this plugin's envs: --env.camera.height={feature_shape[1]} "
            f"--env.camera.width={feature_shape[2]})"
        )
    stacked = (
        " (a time-stacked batch? select_action takes one frame per key)"
        if len(actual) == len(feature_shape) + 2
        else ""
    )
    raise InputShapeError(f"{key}: expected shape {expected}, got {actual}{stacked}")


def dataset_horizon(dataset_meta, given: int | None = None) -> int:
    """T of a recorded dataset: each episode holds o_0..o_T as T + 1 frames (docs/dataset_format.md), and
    the indicator reward's gamma and q0 assume one fixed horizon. Episodes of several lengths (teleoperation)
    take the ``given`` T (--policy.horizon) as the discount's time scale."""
    lengths = sorted(set(dataset_meta.episodes["length"]))
    if len(lengths) != 1 and given is None:
        raise ValueError(
            f"dataset {dataset_meta.repo_id} mixes episode lengths {lengths[:5]}: indicator_ddpg needs one "
            f"horizon T (gamma and q0 follow from it): pass --policy.horizon, e.g. {max(lengths) - 1}"
        )
    return int(lengths[0]) - 1 if len(lengths) == 1 else given
