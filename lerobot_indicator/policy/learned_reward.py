"""The paper's learned-reward baselines (section 6 and appendix): an autoencoder (AE) and a beta-VAE.

Both are trained jointly with the agent, by one reconstruction step per update on the batch's o_t frames,
and replace the indicator in the TD target with a reward from their latent codes:

- AE: ``r(o, o_g) = max(0, phi(o)^T phi(o_g))``, phi the 32-d code after L2 normalisation (cosine
  similarity, clipped at 0); loss = L2 reconstruction.
- VAE (beta-VAE, beta = 5, following RIG): ``r(o, o_g) = -||z - z_g||_2`` with z the posterior mean;
  loss = L2 reconstruction + beta KL(q(z|o) || N(0, I)).

Architecture (appendix): 4 conv layers each followed by 2x2 max-pooling, a linear map to the latent code,
and a decoder of 4 up-sampling + convolution layers back to the input size. The networks see the compared
image keys stacked as channels, each channel standardised (and clipped) with the mean/std the policy's
encoders use.
"""

from collections.abc import Callable

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
from lerobot_indicator.policy.networks_indicator_ddpg import as_float, use_bf16


def ae_reward(code: Tensor, goal_code: Tensor) -> Tensor:
    """max(0, phi(o)^T phi(o_g)) with phi the L2-normalised code (AE baseline)."""
    return (F.normalize(code, dim=1) * F.normalize(goal_code, dim=1)).sum(dim=1).clamp_min(0.0)


def vae_reward(mean: Tensor, goal_mean: Tensor) -> Tensor:
    """-||z - z_g||_2 on the posterior means (VAE baseline, as in RIG)."""
    return -torch.linalg.vector_norm(mean - goal_mean, dim=1)


def gaussian_kl(mean: Tensor, log_var: Tensor) -> Tensor:
    """KL(N(mean, exp(log_var)) || N(0, I)) per sample, summed over the latent dimensions."""
    return 0.5 * (mean.pow(2) + log_var.exp() - 1.0 - log_var).sum(dim=1)


def reconstruction_error(reconstruction: Tensor, target: Tensor) -> Tensor:
    """Squared error per sample, summed over channels and pixels (the Gaussian log-likelihood up to constants,
    the scale at which beta = 5 was chosen in RIG)."""
    return (reconstruction - target).pow(2).flatten(1).sum(dim=1)


class LearnedReward(nn.Module):
    """Convolutional AE (``config.reward == "ae"``) or beta-VAE (``"vae"``) over the compared image keys."""

    def __init__(
        self, config: IndicatorDDPGConfig, dataset_stats: dict[str, dict[str, Tensor]] | None = None
    ):
        super().__init__()
        self.image_keys = config.image_keys
        if not self.image_keys:
            raise ValueError(
                f"reward={config.reward!r} learns its reward from images, but observation_keys "
                f"{config.observation_keys} has no camera key"
            )
        self.variational = config.reward == "vae"
        self.conv_precision = config.conv_precision
        self.beta = config.vae_beta
        self.input_clip = config.input_clip
        channels = [int(config.input_features[k].shape[0]) for k in self.image_keys]
        self.register_buffer("mean", torch.zeros(sum(channels)))
        self.register_buffer("std", torch.ones(sum(channels)))
        self._channels = channels
        self.set_stats(dataset_stats or {})

        in_ch = sum(channels)
        height, width = (int(s) for s in config.input_features[self.image_keys[0]].shape[1:])
        self.sizes = [(height, width)]
        layers: list[nn.Module] = []
        for ch in config.reward_conv_channels:
            layers += [nn.Conv2d(in_ch, ch, 3, padding=1), nn.ReLU(), nn.MaxPool2d(2)]
            in_ch = ch
            height, width = height // 2, width // 2
            self.sizes.append((height, width))
        if min(height, width) < 1:
            raise ValueError(
                f"images of {self.sizes[0][0]}x{self.sizes[0][1]} px are too small for "
                f"{len(config.reward_conv_channels)} conv + max-pool layers of the {config.reward!r} reward"
            )
        self.encoder = nn.Sequential(*layers, nn.Flatten())
        flat = in_ch * height * width
        latent = config.reward_latent_dim
        self.to_code = nn.Linear(flat, 2 * latent if self.variational else latent)
        self.from_code = nn.Linear(latent, flat)
        self.bottleneck = (in_ch, height, width)
        up_channels = [*reversed(config.reward_conv_channels[:-1]), sum(channels)]
        self.decoder = nn.ModuleList()
        ch = in_ch
        for out in up_channels:
            self.decoder.append(nn.Conv2d(ch, out, 3, padding=1))
            ch = out

    @torch.no_grad()
    def set_stats(self, stats: dict[str, dict[str, Tensor]]) -> None:
        """Per-channel standardisation from ``{key: {"mean", "std"}}`` (keys without stats keep theirs)."""
        start = 0
        for key, n in zip(self.image_keys, self._channels, strict=True):
            if key in stats and "mean" in stats[key] and "std" in stats[key]:
                for name in ("mean", "std"):
                    value = torch.as_tensor(stats[key][name], dtype=torch.float32)
                    per_channel = value.expand(n, *value.shape[1:]).reshape(n, -1).mean(dim=1)
                    getattr(self, name)[start : start + n] = per_channel
                self.std[start : start + n].clamp_(min=1e-2)
            start += n

    def images(self, frames: dict[str, Tensor]) -> Tensor:
        """The image keys as float channels, standardised and clipped as the policy's encoders do: what the
        AE reconstructs."""
        x = torch.cat([as_float(frames[k]) for k in self.image_keys], dim=1)
        x = (x - self.mean.view(1, -1, 1, 1)) / self.std.view(1, -1, 1, 1)
        return x.clamp(-self.input_clip, self.input_clip)

    def _convs(self, x: Tensor) -> torch.autocast:
        """The conv layers' precision: the policy's ``conv_precision`` (bf16 where the CPU or GPU computes it
        natively). Callers hand the convs channels-last maps, the layout oneDNN's convs and max-pooling are
        fastest in."""
        return torch.autocast(
            x.device.type, torch.bfloat16, enabled=use_bf16(self.conv_precision, x.device.type)
        )

    def encode(self, x: Tensor) -> tuple[Tensor, Tensor | None]:
        """(code, log-variance) of standardised images; the code is the posterior mean for the VAE. The linear
        map to the code is float32."""
        with self._convs(x):
            h = self.encoder(x.contiguous(memory_format=torch.channels_last))
        h = self.to_code(h.float())
        if not self.variational:
            return h, None
        mean, log_var = h.chunk(2, dim=1)
        return mean, log_var

    def decode(self, code: Tensor) -> Tensor:
        x = self.from_code(code).view(-1, *self.bottleneck).contiguous(memory_format=torch.channels_last)
        with self._convs(x):
            for i, conv in enumerate(self.decoder):
                x = F.interpolate(x, size=self.sizes[-2 - i], mode="nearest")
                x = conv(x)
                if i < len(self.decoder) - 1:
                    x = F.relu(x)
        return x.float()

    def loss(self, frames: dict[str, Tensor]) -> tuple[Tensor, dict[str, Tensor]]:
        """Reconstruction (+ beta KL for the VAE) averaged over the batch, and its parts for logging."""
        x = self.images(frames)
        mean, log_var = self.encode(x)
        code = mean
        if log_var is not None:
            code = mean + torch.randn_like(mean) * (0.5 * log_var).exp()
        recon = reconstruction_error(self.decode(code), x).mean()
        stats = {"reward_model_reconstruction": recon.detach()}
        if log_var is None:
            return recon, stats
        kl = gaussian_kl(mean, log_var).mean()
        stats["reward_model_kl"] = kl.detach()
        return recon + self.beta * kl, stats

    @torch.no_grad()
    def reward_to(self, goal: dict[str, Tensor]) -> Callable[[dict[str, Tensor]], Tensor]:
        """r(., o_g) for the batch's goals, (B,) per call: the goals are encoded once, however many steps of an
        n-step return ask for a reward."""
        goal_code, _ = self.encode(self.images(goal))

        @torch.no_grad()
        def reward(frames: dict[str, Tensor]) -> Tensor:
            code, _ = self.encode(self.images(frames))
            return vae_reward(code, goal_code) if self.variational else ae_reward(code, goal_code)

        return reward

    def reward(self, next_obs: dict[str, Tensor], goal: dict[str, Tensor]) -> Tensor:
        """The baseline's reward r(o_{t+1}, o_g), (B,)."""
        return self.reward_to(goal)(next_obs)
