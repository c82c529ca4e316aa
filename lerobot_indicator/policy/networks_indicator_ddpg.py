"""Goal-conditioned actor pi(o, o_g) and critic Q(o, o_g, a) of the paper (appendix, hyper-parameter table).

Observation and goal go through the *same* encoder (conv weights shared between them, paper appendix); actor
and critic each own their encoder (as in the authors' sibling HER code). Both take dicts keyed by the
compared observation keys; a goal dict uses the same keys (its values are goal observations), which is what
makes hindsight relabeling a plain swap of tensors. An observation dict also holds the context keys
(``config.context_keys``): state vectors appended, normalised, after ``[enc(o), enc(o_g)]``; a goal has none.
"""

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig


def mlp(in_dim: int, hidden_dims: list[int], out_dim: int) -> nn.Sequential:
    layers: list[nn.Module] = []
    for h in hidden_dims:
        layers += [nn.Linear(in_dim, h), nn.Tanh()]
        in_dim = h
    layers.append(nn.Linear(in_dim, out_dim))
    return nn.Sequential(*layers)


class ObservationEncoder(nn.Module):
    """Normalises each compared key with its mean/std, encodes the images, flattens and appends the states;
    ``context`` normalises and flattens the context keys of an observation (never of a goal).

    The same instance encodes observations and goals, so a goal is normalised with its *observation* key's
    statistics: relabeled goals (o_{t+1}, o_{t'}) and recorded goals share one representation. Images (stacked
    as channels) go through the conv layers, then a flatten (or the spatial softmax) and, for the "drq"
    encoder, a linear projection with LayerNorm + tanh. Images are randomly shifted first
    when asked (``draw_shifts``): by the learning core, never when acting.
    """

    def __init__(
        self, config: IndicatorDDPGConfig, dataset_stats: dict[str, dict[str, Tensor]] | None = None
    ):
        super().__init__()
        self.image_keys = config.image_keys
        self.state_keys = config.state_keys
        self.input_clip = config.input_clip
        self.augment_pad = config.augment_pad
        self.context_keys = list(config.context_keys or [])
        # Context statistics come after the compared keys': without context the buffers are what they were.
        inputs = config.observation_keys + self.context_keys
        for i, key in enumerate(inputs):
            shape = tuple(config.input_features[key].shape)
            self.register_buffer(f"mean_{i}", torch.zeros(shape))
            self.register_buffer(f"std_{i}", torch.ones(shape))
        self._index = {k: i for i, k in enumerate(inputs)}
        self.set_stats(dataset_stats or {})

        def size(keys: list[str]) -> int:
            return sum(math.prod(config.input_features[k].shape) for k in keys)

        self.out_dim = size(self.state_keys)
        # Width of ``context``: what the actor's and critic's MLPs take besides [enc(o), enc(o_g)].
        self.context_dim = size(self.context_keys)
        self.conv = None
        if self.image_keys:
            drq = config.image_encoder == "drq"
            channels = sum(config.input_features[k].shape[0] for k in self.image_keys)
            height, width = config.input_features[self.image_keys[0]].shape[1:]
            layers: list[nn.Module] = []
            in_ch = channels
            for ch, stride in zip(config.conv_channels, config.conv_strides, strict=True):
                # Not in place: torch's in-place bfloat16 ReLU (clamp_min_) runs about 3x slower on CPU than
                # the out-of-place one.
                layers += [
                    nn.Conv2d(in_ch, ch, config.conv_kernel_size, stride),
                    nn.ReLU() if drq else nn.Tanh(),
                ]
                in_ch = ch
            size = min(height, width)
            for stride in config.conv_strides:
                size = (size - config.conv_kernel_size) // stride + 1
            if size < 1:
                raise ValueError(
                    f"images of {height}x{width} px are too small for the {config.image_encoder!r} encoder's conv "
                    f"layers (kernel {config.conv_kernel_size}, strides {config.conv_strides}): use larger images "
                    "or fewer / smaller strides (--policy.conv_strides)"
                )
            self.conv = nn.Sequential(*layers)
            self.conv_precision = config.conv_precision
            self.fold_normalization = drq
            with torch.no_grad():
                fmap = self.conv(torch.zeros(1, channels, height, width))
            # "drq" flattens in the feature maps' channels-last memory order: a view, and its gradient comes
            # back in the layout the conv layers use (a mixed-layout ReLU backward is several times slower).
            pool: nn.Module = ChannelsLastFlatten() if drq else nn.Flatten()
            pooled_dim = int(fmap[0].numel())
            if config.spatial_softmax:
                # Lazy import: the diffusion module pulls in optional dependencies.
                from lerobot.policies.diffusion.modeling_diffusion import SpatialSoftmax

                pool = nn.Sequential(
                    SpatialSoftmax(tuple(fmap.shape[1:]), num_kp=config.spatial_softmax_keypoints),
                    nn.Flatten(),
                )
                pooled_dim = 2 * config.spatial_softmax_keypoints
            # "drq"'s linear projection of the flattened maps runs in the convs' precision (bf16 with float32
            # accumulation where the CPU has it, several times faster than float32), LayerNorm in float32. The
            # spatial softmax's keypoint coordinates stay float32: bf16 would round them to about half a pixel.
            self.project_in_conv_precision = drq and not config.spatial_softmax
            if drq:
                self.trunk = nn.Sequential(
                    pool,
                    nn.Linear(pooled_dim, config.feature_dim),
                    nn.LayerNorm(config.feature_dim),
                    nn.Tanh(),
                )
                self.out_dim += config.feature_dim
            else:
                self.trunk = pool
                self.out_dim += pooled_dim

    @torch.no_grad()
    def set_stats(self, stats: dict[str, dict[str, Tensor]]) -> None:
        """Normalisation of each compared key (and so of its goal) and each context key from
        ``{key: {"mean", "std"}}``; keys without stats keep theirs. The online trainer calls this every cycle with statistics of its
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

    def context(self, obs: dict[str, Tensor]) -> list[Tensor]:
        """The normalised, clipped, flattened context keys of a batch of observations, as one (B, context_dim)
        tensor in a list (an empty list without context keys)."""
        if not self.context_keys:
            return []
        return [torch.cat([self.normalize(k, as_float(obs[k])).flatten(1) for k in self.context_keys], 1)]

    def join(self, h_obs: Tensor, h_goal: Tensor, obs: dict[str, Tensor]) -> Tensor:
        """``[enc(o), enc(o_g), context(o)]``, what the actor's and critic's MLPs take, from the encodings
        of o and o_g and the observation dict ``obs`` that ``h_obs`` encodes."""
        return torch.cat([h_obs, h_goal, *self.context(obs)], dim=1)

    def forward(self, obs: dict[str, Tensor], shift: Tensor | None = None) -> Tensor:
        """Features of a batch of frames; ``shift`` (``draw_shifts``): translate each frame's images first
        (the learning core's updates; actions are always chosen from the frames as they are)."""
        return self.encode_parts([obs], shift)

    def encode_parts(self, parts: list[dict[str, Tensor]], shift: Tensor | None = None) -> Tensor:
        """Features of several batches of frames as one batch (their rows in order), in one conv pass."""
        states = [
            self.normalize(k, as_float(torch.cat([p[k] for p in parts]))).flatten(1) for k in self.state_keys
        ]
        if self.conv is not None:
            fmap = self.conv_features(parts, shift)
            if fmap.dtype == torch.bfloat16 and self.project_in_conv_precision:
                with torch.autocast(fmap.device.type, torch.bfloat16):
                    states.append(self.trunk(fmap).float())
            else:
                states.append(self.trunk(fmap.float()))
        return torch.cat(states, dim=1)

    def conv_features(self, parts: list[dict[str, Tensor]], shift: Tensor | None = None) -> Tensor:
        """Conv feature maps (channels-last, in the conv precision) of the image keys, stacked as channels, of
        the frames of every part (one batch, their rows in order).

        Frames may arrive as stored (uint8 RGB, uint16 depth: the replay buffer's packing) or as float32. The
        "paper" encoder normalises and clips them as the state keys; "drq" folds the per-channel normalisation
        (and uint8's 1/255) into the first conv's weights, so no float copy of the frames is made before it:
        every part's frames are written once, cast to the conv precision, into one channels-last tensor,
        which is then shifted as a whole.
        """
        device = parts[0][self.image_keys[0]].device.type
        bf16 = use_bf16(self.conv_precision, device)
        if self.fold_normalization:
            images = pack_frames(parts, self.image_keys, torch.bfloat16 if bf16 else torch.float32)
            if shift is not None:
                images = random_shift(images, shift)
        else:
            frames = [torch.cat([p[k] for p in parts]) for k in self.image_keys]
            if shift is not None:
                frames = [random_shift(f, shift) for f in frames]
            images = torch.cat(
                [self.normalize(k, as_float(f)) for k, f in zip(self.image_keys, frames, strict=True)], 1
            )
            # channels_last: the layout oneDNN's CPU convolutions are fastest in.
            images = images.contiguous(memory_format=torch.channels_last)
        if self.fold_normalization:
            # The frames are already in the conv precision; each layer's weights are cast to it.
            x = images
            for i, conv in enumerate(self.conv[::2]):
                if i == 0:
                    weight, bias = self._folded_first_conv([parts[0][k].dtype for k in self.image_keys])
                else:
                    weight, bias = conv.weight, conv.bias
                x = F.relu(F.conv2d(x, weight.to(x.dtype), bias.to(x.dtype), conv.stride))
            return x
        with torch.autocast(device, torch.bfloat16, enabled=bf16):
            return self.conv(images)

    def _folded_first_conv(self, dtypes: list[torch.dtype]) -> tuple[Tensor, Tensor]:
        """First conv's weight and bias acting on raw frames: conv(W, (x * u - m) / s) = conv(W u / s, x) -
        sum(W m / s), with per-channel mean m and std s, and u = 1/255 for uint8 frames (else 1)."""
        scales, offsets = [], []
        for key, dtype in zip(self.image_keys, dtypes, strict=True):
            i = self._index[key]
            mean = getattr(self, f"mean_{i}").mean(dim=(1, 2))
            std = getattr(self, f"std_{i}").mean(dim=(1, 2))
            unit = 1 / 255 if dtype == torch.uint8 else 1.0
            scales.append(unit / std)
            offsets.append(mean / std)
        scale, offset = torch.cat(scales).view(1, -1, 1, 1), torch.cat(offsets).view(1, -1, 1, 1)
        first: nn.Conv2d = self.conv[0]
        return first.weight * scale, first.bias - (first.weight * offset).sum(dim=(1, 2, 3))


def as_float(x: Tensor) -> Tensor:
    """A stored frame's float32 value: uint8 k is k/255 (LeRobot's image convention and the replay buffer's
    packing), other integers are their value (uint16 depth)."""
    if x.dtype == torch.uint8:
        return x.float() / 255
    return x if x.dtype == torch.float32 else x.float()


def draw_shifts(n: int, pad: int, device: torch.device) -> Tensor | None:
    """DrQ's random shift of ``n`` frames: integer (dy, dx) in [-pad, pad], shape (2, n), from torch's global
    RNG (both trainers seed it); None when ``pad`` is 0."""
    if pad <= 0:
        return None
    return torch.randint(-pad, pad + 1, (2, n), device=device)


def pack_frames(parts: list[dict[str, Tensor]], keys: list[str], dtype: torch.dtype) -> Tensor:
    """The frames of ``keys`` (stacked as channels, in that order) of every part (rows in order), cast to
    ``dtype``, as one channels-last (N, C, H, W) tensor: each input is read and written once, with no
    intermediate concatenation."""
    first = parts[0][keys[0]]
    height, width = first.shape[2:]
    sizes = [p[keys[0]].shape[0] for p in parts]
    channels = [parts[0][k].shape[1] for k in keys]
    out = torch.empty(sum(sizes), height, width, sum(channels), dtype=dtype, device=first.device)
    row = 0
    for part, size in zip(parts, sizes, strict=True):
        ch = 0
        for key, c in zip(keys, channels, strict=True):
            # Plane by plane: contiguous reads, and about 2x faster than one transposing copy per key.
            for i in range(c):
                out[row : row + size, :, :, ch + i].copy_(part[key][:, i])
            ch += c
        row += size
    return out.permute(0, 3, 1, 2)


def widest_word(nbytes: int) -> torch.dtype:
    """The widest integer dtype whose size divides ``nbytes``: a run of ``nbytes`` bytes viewed as such words
    is moved or compared in the fewest operations, bit for bit."""
    return next(w for w in (torch.int64, torch.int32, torch.int16, torch.uint8) if nbytes % w.itemsize == 0)


def random_shift(x: Tensor, shift: Tensor) -> Tensor:
    """Translate frame i (all its channels) by ``shift[:, i]`` pixels, replicating the edges (DrQ's pad +
    crop). Returns a channels-last tensor in ``x``'s dtype.

    LeRobot's ``lerobot.rl.buffer.random_shift`` draws its own shift per call (per key) and pads a copy first;
    here the shift is given (the learning core shares one between a transition's o_t, o_{t+1} and goal, and
    RGB and depth packed as channels move together) and the replicating pad is folded into clamped indices
    of one gather, with no padded copy. A pixel's channels are gathered as one machine word where their bytes
    allow (RGB-D in bfloat16: 8 bytes), which is several times faster than gathering rows of channels.
    """
    b, c, h, w = x.shape
    device = x.device
    # Pixel indices as int32 where they fit: half the index data to write and read.
    index_dtype = torch.int32 if b * h * w < 2**31 else torch.int64
    arange = functools.partial(torch.arange, device=device, dtype=index_dtype)
    shift = shift.to(index_dtype)
    rows = (arange(h) + shift[0, :, None]).clamp_(0, h - 1)  # (b, h)
    cols = (arange(w) + shift[1, :, None]).clamp_(0, w - 1)  # (b, w)
    row_start = rows * w + (arange(b) * (h * w))[:, None]
    index = (row_start[:, :, None] + cols[:, None, :]).view(-1)  # one broadcast add over (b, h, w)
    pixels = x.permute(0, 2, 3, 1).contiguous().view(-1, c)
    if torch.compiler.is_compiling():
        # The gather is generated code, and Inductor cannot lower the dtype view back.
        return pixels.index_select(0, index).view(b, h, w, c).permute(0, 3, 1, 2)
    words = pixels.view(widest_word(c * x.element_size()))
    # A 1-d select of whole words is about 3x faster than selecting rows of one word.
    words = words.view(-1) if words.shape[1] == 1 else words
    shifted = words.index_select(0, index)
    return shifted.view(x.dtype).view(b, h, w, c).permute(0, 3, 1, 2)


@torch.compiler.assume_constant_result
def native_bf16(device_type: str) -> bool:
    """Whether ``device_type`` computes bfloat16 natively: CUDA with bf16, or a CPU with AVX512-BF16 / AMX.

    A constant to ``torch.compile``: tracing the ``/proc/cpuinfo`` read would break the compiled loss into
    pieces that recompile until Dynamo gives up on them."""
    return _native_bf16(device_type)


@functools.cache
def _native_bf16(device_type: str) -> bool:
    if device_type == "cuda":
        return torch.cuda.is_available() and torch.cuda.is_bf16_supported()
    if device_type == "cpu":
        cpuinfo = Path("/proc/cpuinfo")
        flags = cpuinfo.read_text() if cpuinfo.exists() else ""
        return any(f in flags for f in ("avx512_bf16", "amx_bf16"))
    return False


def use_bf16(precision: str, device_type: str) -> bool:
    return precision == "bfloat16" or (precision == "auto" and native_bf16(device_type))


def encode_frames(
    encoder: ObservationEncoder, parts: list[dict[str, Tensor]], shifts: list[Tensor] | None = None
) -> list[Tensor]:
    """Encode several batches of frames in one call (one conv pass over all of them), split back per batch;
    ``shifts``: one ``(2, n)`` shift per batch (``draw_shifts``), or None for none."""
    sizes = [next(iter(p.values())).shape[0] for p in parts]
    shift = None if shifts is None else torch.cat(shifts, dim=1)
    return list(encoder.encode_parts(parts, shift).split(sizes))


class ChannelsLastFlatten(nn.Module):
    """(N, C, H, W) -> (N, H * W * C): the flatten of a channels-last tensor that needs no copy."""

    def forward(self, x: Tensor) -> Tensor:
        return x.permute(0, 2, 3, 1).flatten(1)


@dataclass
class Features:
    """``[enc(o), enc(o_g), context(o)]`` as each network sees it in one update (``encode_batch``)."""

    critic: Tensor  # (o_t, g) for Q(o_t, g, a_t), with gradients into the critic's encoder
    actor: Tensor  # (o_t, g) for pi(o_t, g): the critic's, detached, when the encoder is shared
    target_critic: Tensor  # (o_{t+1}, g) for the TD target, without gradients
    target_actor: Tensor
    transition: Tensor | None = None  # (o_t, o_{t+1}) with gradients, shared encoder only
    target_critic_obs: Tensor | None = None  # (o_t, g) as the target critic sees it (filter_q="target")


class GoalConditioned(nn.Module):
    """An encoder shared by observation and goal, then an MLP on ``[enc(o), enc(o_g), context(o)]``."""

    encoder: ObservationEncoder
    net: nn.Sequential

    def encode(self, obs: dict[str, Tensor], goal: dict[str, Tensor], shift: Tensor | None = None) -> Tensor:
        """``[enc(o), enc(o_g), context(o)]``, o and o_g encoded in one call, both shifted by ``shift`` if
        given."""
        shifts = None if shift is None else [shift, shift]
        return self.encoder.join(*encode_frames(self.encoder, [obs, goal], shifts), obs)


class Actor(GoalConditioned):
    """pi(o, o_g) = tanh(MLP([enc(o), enc(o_g), context(o)])), in the env's [-1, 1] action space.

    With the shared ("drq") design the critic uses this encoder too and the actor's loss sees its features
    detached (``indicator_core.encode_batch``), so only the critic loss trains it."""

    def __init__(
        self, config: IndicatorDDPGConfig, dataset_stats: dict[str, dict[str, Tensor]] | None = None
    ):
        super().__init__()
        self.encoder = ObservationEncoder(config, dataset_stats)
        self.net = mlp(
            2 * self.encoder.out_dim + self.encoder.context_dim, config.hidden_dims, config.action_dim
        )

    def head(self, features: Tensor) -> Tensor:
        return torch.tanh(self.net(features))

    def forward(self, obs: dict[str, Tensor], goal: dict[str, Tensor]) -> Tensor:
        return self.head(self.encode(obs, goal))


class Critic(GoalConditioned):
    """Q(o, o_g, a) = s MLP([enc(o), enc(o_g), context(o), a]) with s = ``config.q_output_scale``; Q starts at
    ``config.initial_q`` (the output bias, Q initialised low).

    ``encode`` and ``head`` are split so a DDPG step encodes (o, o_g) once for Q(o, o_g, a) and
    Q(o, o_g, pi(o, o_g)): for images the conv encoder is most of an update's cost. ``encoder``: the actor's,
    for the shared ("drq") design.
    """

    def __init__(
        self,
        config: IndicatorDDPGConfig,
        dataset_stats: dict[str, dict[str, Tensor]] | None = None,
        encoder: ObservationEncoder | None = None,
    ):
        super().__init__()
        self.encoder = encoder if encoder is not None else ObservationEncoder(config, dataset_stats)
        inputs = 2 * self.encoder.out_dim + self.encoder.context_dim + config.action_dim
        self.net = mlp(inputs, config.hidden_dims, 1)
        # Low initial Q keeps every Q below q0, so reward filtering cannot fire before the critic has learnt
        # (paper section 5.3). The minimum achievable return is the natural "low" value.
        self.output_scale = config.q_output_scale
        last: nn.Linear = self.net[-1]
        nn.init.constant_(last.bias, config.initial_q / self.output_scale)
        # a_t from (enc(o_t), enc(o_{t+1})): an auxiliary loss on the encoder (config.inverse_dynamics).
        self.inverse = None
        if config.inverse_dynamics > 0:
            self.inverse = mlp(2 * self.encoder.out_dim, config.hidden_dims[:1], config.action_dim)

    def head(self, features: Tensor, action: Tensor, frozen: bool = False) -> Tensor:
        """Q from ``encode``'s features. ``frozen``: the MLP's weights are detached, so gradients reach
        ``action`` (the actor's loss) but never the critic."""
        x = torch.cat([features, action], dim=1)
        if not frozen:
            return self.output_scale * self.net(x).squeeze(-1)
        for layer in self.net:
            x = (
                F.linear(x, layer.weight.detach(), layer.bias.detach())
                if isinstance(layer, nn.Linear)
                else layer(x)
            )
        return self.output_scale * x.squeeze(-1)

    def forward(self, obs: dict[str, Tensor], goal: dict[str, Tensor], action: Tensor) -> Tensor:
        return self.head(self.encode(obs, goal), action)
