"""Every network's features for one update, each distinct frame encoded once per encoder.

The fast path behind ``indicator_core.encode_batch`` (its default). It gives the values of the plain path,
``indicator_core.encode_plain`` (DrQ-v2's update: each network encodes its own inputs), with fewer frames
through the conv layers, which are most of an image update's cost:

- a goal that *is* the frame the TD target bootstraps from (``goal_is_next``: about half the batch with
  balancing and one-step targets) takes that frame's encoding instead of being encoded again;
- with the shared ("drq") encoder one conv pass over o_t, o_{t+1} and the other goals serves all four
  networks; the o_{t+1} that only the targets read are encoded in a second pass without gradients, so the
  backward pass covers 2B frames instead of 2B + #(goals != o_{t+1}).

Under ``torch.compile`` (static shapes) and for state inputs no goal is skipped: every goal is encoded, in
the same single pass.
"""

import torch
from torch import Tensor, nn

from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
from lerobot_indicator.policy.networks_indicator_ddpg import Critic, Features, encode_frames


class BootstrapFrames:
    """The bootstrap frames o_{t+1} and the goals of one update, encoded together by ``encode``."""

    def __init__(
        self,
        next_obs: dict[str, Tensor],
        goal: dict[str, Tensor],
        goal_is_next: Tensor,
        shift: Tensor | None,
        dedupe: bool,
    ):
        self.next_obs, self.goal, self.goal_is_next = next_obs, goal, goal_is_next
        self.shift, self.dedupe = shift, dedupe
        if dedupe:
            self.rest = (~goal_is_next).nonzero().squeeze(1)  # the goals that are not o_{t+1}
            # index_select: a row copy, several times faster than advanced indexing on CPU.
            self.goal_rest = {k: v.index_select(0, self.rest) for k, v in goal.items()}

    def shifts(self, *rows: Tensor | None) -> list[Tensor] | None:
        """The shifts of each group of frames (``rows`` of the batch; None: all of them)."""
        if self.shift is None:
            return None
        return [self.shift if r is None else self.shift[:, r] for r in rows]

    def encode(
        self, encoder: nn.Module, frames: list[dict[str, Tensor]], next_needs_grad: bool = True
    ) -> list[Tensor]:
        """Encodings of ``frames`` (batches of o_t) + [o_{t+1}, g], in one conv pass, a goal's rows that are
        o_{t+1} taken from o_{t+1}'s encoding. Without ``next_needs_grad`` (o_{t+1} feeds only the targets,
        except where it is the goal) the o_{t+1} that are not goals are encoded in a second pass without
        gradients."""
        everyone = [None] * len(frames)
        if not self.dedupe:
            return encode_frames(
                encoder, [*frames, self.next_obs, self.goal], self.shifts(*everyone, None, None)
            )
        rest = self.rest
        if next_needs_grad or not torch.is_grad_enabled() or rest.numel() == 0:
            rows = self.shifts(*everyone, None, rest)
            *h, h_next, h_rest = encode_frames(encoder, [*frames, self.next_obs, self.goal_rest], rows)
            return [*h, h_next, h_next.index_put((rest,), h_rest)]
        is_goal = self.goal_is_next.nonzero().squeeze(1)  # the o_{t+1} that are goals
        next_goal = {k: v.index_select(0, is_goal) for k, v in self.next_obs.items()}
        rows = self.shifts(*everyone, is_goal, rest)
        *h, h_next_goal, h_rest = encode_frames(encoder, [*frames, next_goal, self.goal_rest], rows)
        with torch.no_grad():
            next_rest = {k: v.index_select(0, rest) for k, v in self.next_obs.items()}
            (h_next_rest,) = encode_frames(encoder, [next_rest], self.shifts(rest))
        batch_size = self.goal_is_next.shape[0]
        h_goal = h_rest.new_empty(batch_size, h_rest.shape[1]).index_put((is_goal,), h_next_goal)
        h_next = h_goal.index_put((rest,), h_next_rest)
        return [*h, h_next, h_goal.index_put((rest,), h_rest)]


def encode_distinct_frames(
    obs: dict[str, Tensor],
    next_obs: dict[str, Tensor],
    goal: dict[str, Tensor],
    goal_is_next: Tensor,
    actor: nn.Module,
    critic: Critic,
    target_actor: nn.Module,
    target_critic: nn.Module,
    config: IndicatorDDPGConfig,
    shift: Tensor | None,
    transition_next: dict[str, Tensor] | None = None,
) -> Features:
    """``indicator_core.encode_plain``'s features, each distinct frame encoded once per encoder (module
    docstring). With the shared encoder the targets use the online encoder's features of (o_{t+1}, g)
    without gradients, or their own EMA encoder's (``target_encoder``). The context keys of o_t and of
    ``next_obs`` are appended to their features (``ObservationEncoder.join``); a goal has none."""
    dedupe = bool(config.image_keys) and not torch.compiler.is_compiling()
    frames = BootstrapFrames(next_obs, goal, goal_is_next, shift, dedupe)
    target_obs = config.filter and config.filter_q == "target"

    def target_critic_features() -> tuple[Tensor, Tensor | None]:
        """The target critic's (o_{t+1}, g) and, for the filter, (o_t, g), from its own encoder."""
        encoder = target_critic.encoder
        with torch.no_grad():
            *h_obs, h_next, h_goal = frames.encode(encoder, [obs] if target_obs else [])
            target_o = encoder.join(h_obs[0], h_goal, obs) if target_obs else None
            return encoder.join(h_next, h_goal, next_obs), target_o

    if config.shared_encoder:
        extra = [] if transition_next is None else [transition_next]
        # o_{t+1} trains the encoder only through the inverse-dynamics loss of a one-step target.
        next_needs_grad = critic.inverse is not None and transition_next is None
        h_obs, *h_extra, h_next, h_goal = frames.encode(critic.encoder, [obs, *extra], next_needs_grad)
        features = critic.encoder.join(h_obs, h_goal, obs)
        target = critic.encoder.join(h_next, h_goal, next_obs).detach()
        target_o = features.detach() if target_obs else None
        if config.target_encoder:
            target, target_o = target_critic_features()
        return Features(
            critic=features,
            actor=features.detach(),
            target_critic=target,
            target_actor=target,
            transition=torch.cat([h_obs, h_extra[0] if h_extra else h_next], dim=1),
            target_critic_obs=target_o,
        )
    target_c, target_o = target_critic_features()
    with torch.no_grad():
        target_a = target_actor.encoder.join(*frames.encode(target_actor.encoder, []), next_obs)
    return Features(
        critic=critic.encode(obs, goal, shift),
        actor=actor.encode(obs, goal, shift),
        target_critic=target_c,
        target_actor=target_a,
        target_critic_obs=target_o,
    )
