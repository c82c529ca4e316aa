"""Goal-conditioned actor pi(o, o_g) and critic Q(o, o_g, a) of the paper (appendix, hyper-parameter table).

Observation and goal go through the *same* encoder (conv weights shared between them, paper appendix); actor
and critic each own their encoder (as in the authors' sibling HER code). Both take dicts keyed by the
compared observation keys; a goal dict uses the same keys (its values are goal observations), which is what
makes hindsight relabeling a plain swap of tensors.
"""

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig


class _SigmoidTanh(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x: Tensor) -> Tensor:
        y = torch.sigmoid(x * 2).mul_(2).sub_(1)
        ctx.save_for_backward(y)
        return y

    @staticmethod
    def backward(ctx, grad: Tensor) -> Tensor:
        (y,) = ctx.saved_tensors
        return torch.ops.aten.tanh_backward(grad, y)


# Eigen's float tanh: odd numerator and even denominator coefficients (in x^2), lowest order first.
_TANH_NUM = (
    4.89352455891786e-03,
    6.37261928875436e-04,
    1.48572235717979e-05,
    5.12229709037114e-08,
    -8.60467152213735e-11,
    2.00018790482477e-13,
    -2.76076847742355e-16,
)
_TANH_DEN = (4.89352518554385e-03, 2.26843463243900e-03, 1.18534705686654e-04, 1.19825839466702e-06)


class _RationalTanh(torch.autograd.Function):
    """tanh(x) ~= x p(x^2) / q(x^2) on [-7.9, 7.9] (constant +-1 to float precision beyond), Eigen's coefficients."""

    @staticmethod
    def forward(ctx, x: Tensor) -> Tensor:
        x = x.clamp(-7.90531110763549805, 7.90531110763549805)
        x2 = x * x
        p = x2 * _TANH_NUM[6] + _TANH_NUM[5]
        for a in _TANH_NUM[4::-1]:
            p = p * x2 + a
        q = x2 * _TANH_DEN[3] + _TANH_DEN[2]
        for b in _TANH_DEN[1::-1]:
            q = q * x2 + b
        y = x * p / q
        ctx.save_for_backward(y)
        return y

    @staticmethod
    def backward(ctx, grad: Tensor) -> Tensor:
        (y,) = ctx.saved_tensors
        return grad * (1 - y * y)


def tanh(x: Tensor) -> Tensor:
    """tanh; on CPU computed by the fastest float32-accurate formula for the executor.

    ATen's CPU tanh kernel took 210 us on a 256x256 tensor on the project's AVX2 CPUs, and the 3x256 tanh MLPs
    call it 17 times per DDPG update (~20% of a state update with torch.tanh; most of an RGB-D one, over the
    conv feature maps). Eager: 2 sigmoid(2x) - 1 (100 us, max abs error 2e-7, torch.tanh's 6e-8) with torch's
    ``tanh_backward``. Under ``torch.compile`` (``compile_model``), where Inductor's own tanh is as slow as
    ATen's: Eigen's / XLA's clamped rational approximation (13/6 odd/even polynomials, max abs error 4e-7),
    which Inductor fuses into one 67 us kernel; in eager it would be ~15 separate ops (316 us). The compiled
    branch is out of place: compile mis-traced the eager function's in-place ops (zero gradients below the
    last layer). Elsewhere (CUDA) torch.tanh is already fast and is used as is.
    """
    if x.device.type != "cpu":
        return torch.tanh(x)
    if torch.compiler.is_compiling():
        return _RationalTanh.apply(x)
    return _SigmoidTanh.apply(x)


class Tanh(nn.Module):
    def forward(self, x: Tensor) -> Tensor:
        return tanh(x)


def mlp(in_dim: int, hidden_dims: list[int], out_dim: int) -> nn.Sequential:
    layers: list[nn.Module] = []
    for h in hidden_dims:
        layers += [nn.Linear(in_dim, h), Tanh()]
        in_dim = h
    layers.append(nn.Linear(in_dim, out_dim))
    return nn.Sequential(*layers)


class ObservationEncoder(nn.Module):
    """Normalises each compared key with its dataset mean/std, stacks images as channels, flattens states.

    The same instance encodes observations and goals, so a goal is normalised with its *observation* key's
    statistics: relabeled goals (o_{t+1}, o_{t'}) and recorded goals share one representation.
    """

    def __init__(
        self, config: IndicatorDDPGConfig, dataset_stats: dict[str, dict[str, Tensor]] | None = None
    ):
        super().__init__()
        self.image_keys = config.image_keys
        self.state_keys = config.state_keys
        self.input_clip = config.input_clip
        for i, key in enumerate(config.observation_keys):
            shape = tuple(config.input_features[key].shape)
            self.register_buffer(f"mean_{i}", torch.zeros(shape))
            self.register_buffer(f"std_{i}", torch.ones(shape))
        self._index = {k: i for i, k in enumerate(config.observation_keys)}
        self.set_stats(dataset_stats or {})

        self.out_dim = sum(int(torch.tensor(config.input_features[k].shape).prod()) for k in self.state_keys)
        self.conv = None
        if self.image_keys:
            channels = sum(config.input_features[k].shape[0] for k in self.image_keys)
            height, width = config.input_features[self.image_keys[0]].shape[1:]
            layers: list[nn.Module] = []
            in_ch = channels
            for ch in config.conv_channels:
                layers += [nn.Conv2d(in_ch, ch, config.conv_kernel_size, config.conv_stride), Tanh()]
                in_ch = ch
            self.conv = nn.Sequential(*layers)
            with torch.no_grad():
                fmap = self.conv(torch.zeros(1, channels, height, width))
            self.keypoints = None
            if config.spatial_softmax:
                # Lazy import: the diffusion module pulls in optional dependencies.
                from lerobot.policies.diffusion.modeling_diffusion import SpatialSoftmax

                self.keypoints = SpatialSoftmax(
                    tuple(fmap.shape[1:]), num_kp=config.spatial_softmax_keypoints
                )
                self.out_dim += 2 * config.spatial_softmax_keypoints
            else:
                self.out_dim += int(fmap[0].numel())

    @torch.no_grad()
    def set_stats(self, stats: dict[str, dict[str, Tensor]]) -> None:
        """Normalisation of each compared key (and so of its goal) from ``{key: {"mean", "std"}}``;
        keys without stats keep theirs. The online trainer calls this every cycle with statistics of its
        replay buffer, since it has no dataset."""
        for key, i in self._index.items():
            if key not in stats or "mean" not in stats[key] or "std" not in stats[key]:
                continue
            mean, std = getattr(self, f"mean_{i}"), getattr(self, f"std_{i}")
            mean.copy_(torch.as_tensor(stats[key]["mean"], dtype=torch.float32).expand(mean.shape))
            # Constant dimensions (std 0) must not blow up: baselines' HER uses the same floor.
            std.copy_(
                torch.as_tensor(stats[key]["std"], dtype=torch.float32).expand(std.shape).clamp_min(1e-2)
            )

    def stats(self) -> dict[str, dict[str, Tensor]]:
        return {
            k: {"mean": getattr(self, f"mean_{i}"), "std": getattr(self, f"std_{i}")}
            for k, i in self._index.items()
        }

    def standardize(self, key: str, x: Tensor) -> Tensor:
        """``(x - mean) / std`` before clipping (values beyond ``input_clip`` are indistinguishable)."""
        i = self._index[key]
        return (x - getattr(self, f"mean_{i}")) / getattr(self, f"std_{i}")

    def normalize(self, key: str, x: Tensor) -> Tensor:
        return self.standardize(key, x).clamp(-self.input_clip, self.input_clip)

    def forward(self, obs: dict[str, Tensor]) -> Tensor:
        parts = [self.normalize(k, obs[k]).flatten(1) for k in self.state_keys]
        if self.conv is not None:
            images = torch.cat([self.normalize(k, obs[k]) for k in self.image_keys], dim=1)
            # channels_last halves the conv stack's CPU time (measured: 1.27 s -> 0.63 s fwd+bwd, batch 256).
            fmap = self.conv(images.contiguous(memory_format=torch.channels_last))
            parts.append(self.keypoints(fmap).flatten(1) if self.keypoints is not None else fmap.flatten(1))
        return torch.cat(parts, dim=1)


class Actor(nn.Module):
    """pi(o, o_g) = tanh(MLP([enc(o), enc(o_g)])), in the env's [-1, 1] action space."""

    def __init__(
        self, config: IndicatorDDPGConfig, dataset_stats: dict[str, dict[str, Tensor]] | None = None
    ):
        super().__init__()
        self.encoder = ObservationEncoder(config, dataset_stats)
        self.net = mlp(2 * self.encoder.out_dim, config.hidden_dims, config.action_dim)

    def forward(self, obs: dict[str, Tensor], goal: dict[str, Tensor]) -> Tensor:
        return tanh(self.net(torch.cat([self.encoder(obs), self.encoder(goal)], dim=1)))


class Critic(nn.Module):
    """Q(o, o_g, a) = MLP([enc(o), enc(o_g), a]); output bias starts at ``config.initial_q`` (Q initialised low).

    ``encode`` and ``head`` are split so a DDPG step encodes (o, o_g) once for Q(o, o_g, a) and
    Q(o, o_g, pi(o, o_g)): for images the conv encoder is most of an update's cost.
    """

    def __init__(
        self, config: IndicatorDDPGConfig, dataset_stats: dict[str, dict[str, Tensor]] | None = None
    ):
        super().__init__()
        self.encoder = ObservationEncoder(config, dataset_stats)
        self.net = mlp(2 * self.encoder.out_dim + config.action_dim, config.hidden_dims, 1)
        # Low initial Q keeps every Q below q0, so reward filtering cannot fire before the critic has learnt
        # (paper section 5.3). The minimum achievable return is the natural "low" value.
        last: nn.Linear = self.net[-1]
        nn.init.constant_(last.bias, config.initial_q)

    def encode(self, obs: dict[str, Tensor], goal: dict[str, Tensor]) -> Tensor:
        return torch.cat([self.encoder(obs), self.encoder(goal)], dim=1)

    def head(self, features: Tensor, action: Tensor, frozen: bool = False) -> Tensor:
        """Q from ``encode``'s features. ``frozen``: the MLP's weights are detached, so gradients reach
        ``action`` (the actor's loss) but never the critic."""
        x = torch.cat([features, action], dim=1)
        if not frozen:
            return self.net(x).squeeze(-1)
        for layer in self.net:
            x = (
                F.linear(x, layer.weight.detach(), layer.bias.detach())
                if isinstance(layer, nn.Linear)
                else layer(x)
            )
        return x.squeeze(-1)

    def forward(self, obs: dict[str, Tensor], goal: dict[str, Tensor], action: Tensor) -> Tensor:
        return self.head(self.encode(obs, goal), action)
