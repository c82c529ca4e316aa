"""Peer gradient updates and hardware peaks for benchmarking our policy's update speed.

``make_sac_update`` builds LeRobot 0.6.1's own SAC (``gaussian_actor`` policy + ``SACAlgorithm``) on a
single RGB-D image observation, so its update rate can be compared with ours on the same image batch.
``matmul_conv_flops`` counts the matmul/conv FLOPs of one update and ``measure_peaks`` measures what
this machine actually sustains, so both can be expressed as a fraction of the achievable peak.
``make_arms``: the arms of ``benchmarks/speed/run_policy_updates.py``, ours (``ENCODERS``) beside SAC's.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable

import torch
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.policies.gaussian_actor import GaussianActorConfig, GaussianActorPolicy
from lerobot.rl.algorithms.sac import SACAlgorithm, SACAlgorithmConfig
from lerobot.utils.constants import ACTION
from torch.utils.flop_counter import FlopCounterMode

from benchmarks.speed.updates import (
    STATE_FEATURES,
    make_batch,
    make_policy,
    policy_update,
    rgbd_features,
)
from lerobot_indicator.policy.networks_indicator_ddpg import native_bf16

IMAGE_KEY = "observation.images.front"

# DefaultImageEncoder: 7x7/2, 5x5/2, 3x3/2, 3x3/2 convolutions without padding.
_ENCODER_CONVS = ((7, 2), (5, 2), (3, 2), (3, 2))


def _encoder_output_size(size: int) -> int:
    """Spatial size after LeRobot's DefaultImageEncoder (unpadded strided convs)."""
    for kernel, stride in _ENCODER_CONVS:
        size = (size - kernel) // stride + 1
    return size


def _sync(device: torch.device) -> None:
    """Wait for queued kernels so wall-clock timings include them (no-op on CPU)."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


class SACUpdate:
    """One full ``SACAlgorithm.update`` on a fixed batch; callable with no arguments.

    Exposes ``algorithm`` (the ``SACAlgorithm``) and ``batch`` so callers and tests can inspect the
    networks being trained.
    """

    def __init__(self, algorithm: SACAlgorithm, batch: dict[str, object]) -> None:
        self.algorithm = algorithm
        self.batch = batch
        # update() pulls utd_ratio batches per call; an endless repeat of the same batch serves any ratio.
        self._batches = itertools.repeat(batch)
        self._device = torch.device(algorithm.policy.config.device)

    def __call__(self) -> None:
        """Run one update (critic, actor, temperature, target EMA) and wait for the device."""
        self.algorithm.update(self._batches)
        _sync(self._device)


def make_sac_update(
    image_shape: tuple[int, int, int],
    batch_size: int,
    device: str = "cpu",
    action_dim: int = 3,
    seed: int = 0,
    freeze_vision_encoder: bool = True,
) -> Callable[[], None]:
    """Build LeRobot 0.6.1's SAC on one RGB-D image and return a closure running one update.

    The policy is ``GaussianActorPolicy`` with a single input feature ``observation.images.front`` of
    shape ``image_shape`` = (C, H, W) (no state), its ``DefaultImageEncoder`` (four unpadded strided
    convs, so H and W must be at least 40) shared between actor and critics (the config default), and
    ``SACAlgorithm`` with ``SACAlgorithmConfig.from_policy_config`` defaults (2 critics, utd_ratio=1,
    policy_update_freq=1) and its own Adam optimizers from ``make_optimizers_and_scheduler``.

    One call of the closure is exactly one ``SACAlgorithm.update``: one critic step (actor sampling on
    next_state and target critics for the TD target, online critics + shared encoder head backward,
    grad clipping, Adam), one actor step (encoder features detached), one temperature step, and one
    Polyak update of the target critics. On CUDA it synchronises before returning.

    ``freeze_vision_encoder`` defaults to True, LeRobot's config default: the DefaultImageEncoder's conv
    weights then get ``requires_grad=False`` and no conv backward runs (only the spatial embedding,
    post-encoder and MLP heads train). Pass False to train the convs too, as an end-to-end pixel
    policy does; with no ``vision_encoder_name`` no encoder features are cached either way, so the
    convs run forward 6 times per update (3 in the critic loss, 2 in the actor loss, 1 in the
    temperature loss). Unfrozen, the actor loss also backpropagates through the encoder via the online
    critics (only the actor's own encoder pass is detached); those encoder and critic gradients are
    discarded by the next critic ``zero_grad`` but their compute is part of LeRobot's update, so it is
    kept. Frozen, the conv weights still drift by float rounding (~1e-8 per update) because the target
    critics share the encoder and the Polyak update rewrites it as ``0.005 * p + 0.995 * p``.

    The batch is random and fixed, built once on ``device``: images float32 uniform in [0, 1] (what the
    replay buffer hands over), actions uniform in [-1, 1], rewards standard normal, ``done`` and
    ``truncated`` zeros. The policy's modeling code applies no normalisation: that lives in its
    processor pipeline, which LeRobot's ``RLTrainer`` applies to each sampled batch outside
    ``update()``, so it is skipped here, no dataset stats are needed and ``dataset_stats`` is None.
    DrQ augmentation (``random_shift``, pad 4) is likewise applied by LeRobot's ``ReplayBuffer.sample``,
    not inside ``update()``, so it is not part of this closure either.

    Args:
        image_shape: (C, H, W) of the image; C=4 for RGB-D.
        batch_size: transitions per update.
        device: torch device string ("cpu", "cuda", ...); raises if LeRobot would fall back to another.
        action_dim: continuous action dimension.
        seed: seeds network initialisation, the batch and the policy's action sampling.
        freeze_vision_encoder: LeRobot's flag of the same name (see above).

    Returns:
        A ``SACUpdate`` (callable with no arguments; ``.algorithm`` gives the ``SACAlgorithm``).
    """
    channels, height, width = image_shape
    if min(_encoder_output_size(height), _encoder_output_size(width)) < 1:
        raise ValueError(
            f"image {image_shape} is too small for LeRobot's DefaultImageEncoder (needs H, W >= 40)"
        )

    torch.manual_seed(seed)
    policy_cfg = GaussianActorConfig(
        input_features={IMAGE_KEY: PolicyFeature(type=FeatureType.VISUAL, shape=tuple(image_shape))},
        output_features={ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(action_dim,))},
        device=device,
        dataset_stats=None,
        freeze_vision_encoder=freeze_vision_encoder,
    )
    if torch.device(policy_cfg.device).type != torch.device(device).type:
        raise ValueError(f"device {device!r} is not available (LeRobot switched to {policy_cfg.device!r})")

    policy = GaussianActorPolicy(policy_cfg)
    policy.train()  # as LeRobot's learner does (the post-encoder has dropout)
    algorithm = SACAlgorithm(policy=policy, config=SACAlgorithmConfig.from_policy_config(policy_cfg))
    algorithm.make_optimizers_and_scheduler()

    dev = torch.device(device)
    gen = torch.Generator().manual_seed(seed)

    def images() -> dict[str, torch.Tensor]:
        return {IMAGE_KEY: torch.rand((batch_size, channels, height, width), generator=gen).to(dev)}

    batch: dict[str, object] = {
        "state": images(),
        ACTION: (torch.rand((batch_size, action_dim), generator=gen) * 2 - 1).to(dev),
        "reward": torch.randn((batch_size,), generator=gen).to(dev),
        "next_state": images(),
        "done": torch.zeros(batch_size, device=dev),
        "truncated": torch.zeros(batch_size, device=dev),
        "complementary_info": None,
    }
    return SACUpdate(algorithm, batch)


def matmul_conv_flops(step: Callable[[], None]) -> int:
    """FLOPs of one ``step()`` as counted by ``torch.utils.flop_counter.FlopCounterMode``.

    Runs ``step`` once (so it mutates any state ``step`` trains). FlopCounterMode counts only matmul-
    like ops (mm/addmm/bmm/baddbmm, convolution forward and backward, attention): elementwise ops,
    reductions, norms and optimizer updates are excluded, which is the part that maps onto a GEMM/conv
    peak.
    """
    return _count_flops(step)


def _best_rate(fn: Callable[[], object], flops_per_call: int, seconds: float, device: torch.device) -> float:
    """Best GFLOP/s over ~0.1 s chunks of repeated ``fn()`` calls within ``seconds`` (after a warm-up).

    The best chunk rather than the mean is taken because the peak is wanted and other processes on
    the machine only ever slow chunks down.
    """
    for _ in range(3):
        fn()
    _sync(device)
    # Calls per chunk from a short calibration, so each chunk lasts ~0.1 s.
    t0 = time.perf_counter()
    n = 0
    while time.perf_counter() - t0 < 0.05:
        fn()
        n += 1
        _sync(device)
    per_chunk = max(1, int(n * 0.1 / (time.perf_counter() - t0)))
    best = 0.0
    end = time.perf_counter() + seconds
    while True:
        t0 = time.perf_counter()
        for _ in range(per_chunk):
            fn()
        _sync(device)
        dt = time.perf_counter() - t0
        best = max(best, per_chunk * flops_per_call / dt / 1e9)
        if time.perf_counter() >= end:
            return best


def measure_peaks(seconds: float = 2.0, device: str = "cpu") -> dict[str, float]:
    """Measure this machine's float32 GEMM and conv throughput in GFLOP/s.

    Three measurements of about ``seconds`` each, with whatever ``torch.get_num_threads()`` is set:
    ``sgemm_256_gflops`` (256x256 @ 256x256, small-GEMM regime like MLP layers at small batch),
    ``sgemm_1024_gflops`` (1024^3, large-GEMM near-peak regime) and ``conv3x3_32ch_gflops`` (forward-only
    3x3 conv, 32->32 channels, padding 1, no bias, batch 128, 32x32 input, channels_last), and where the
    device computes bf16 natively the same conv under bf16 autocast. FLOPs per call come from
    FlopCounterMode, as in ``matmul_conv_flops``, so the ratios are consistent.
    """
    dev = torch.device(device)
    results: dict[str, float] = {}
    with torch.inference_mode():
        for n in (256, 1024):
            a = torch.randn(n, n, device=dev)
            b = torch.randn(n, n, device=dev)
            out = torch.empty(n, n, device=dev)

            def gemm(a: torch.Tensor = a, b: torch.Tensor = b, out: torch.Tensor = out) -> torch.Tensor:
                return torch.mm(a, b, out=out)

            results[f"sgemm_{n}_gflops"] = _best_rate(gemm, _count_flops(gemm), seconds, dev)

        conv = torch.nn.Conv2d(32, 32, kernel_size=3, padding=1, bias=False).to(dev)
        conv = conv.to(memory_format=torch.channels_last)
        x = torch.randn(128, 32, 32, 32, device=dev).to(memory_format=torch.channels_last)

        def conv_fwd() -> torch.Tensor:
            return conv(x)

        results["conv3x3_32ch_gflops"] = _best_rate(conv_fwd, _count_flops(conv_fwd), seconds, dev)
        if native_bf16(dev.type):  # the convs' precision under conv_precision=auto here

            def conv_bf16() -> torch.Tensor:
                with torch.autocast(dev.type, dtype=torch.bfloat16):
                    return conv(x)

            results["conv3x3_32ch_bf16_autocast_gflops"] = _best_rate(
                conv_bf16, _count_flops(conv_fwd), seconds, dev
            )
    return results


def _count_flops(fn: Callable[[], object]) -> int:
    """FlopCounterMode FLOPs of one ``fn()`` call."""
    counter = FlopCounterMode(display=False)
    with counter:
        fn()
    return int(counter.get_total_flops())


# The setting that learns RGB-D reach (docs/results/README.md): 3-step targets + inverse dynamics.
N3_INVERSE_DYNAMICS = {"image_encoder": "drq", "n_step": 3, "inverse_dynamics": 1.0}
ENCODERS = {
    "paper": {"image_encoder": "paper"},
    "paper_fp32": {"image_encoder": "paper", "conv_precision": "float32"},
    "drq": {"image_encoder": "drq"},
    "drq_fp32": {"image_encoder": "drq", "conv_precision": "float32"},
    "drq_n3_inverse_dynamics": N3_INVERSE_DYNAMICS,
    # The same under --policy.compile_model=true (the same math: its FLOPs are the eager arm's).
    "drq_n3_inverse_dynamics_compiled": {**N3_INVERSE_DYNAMICS, "compile_model": True},
    # A lighter drq stack: half the first layer's channels, the third conv strided (not a preset: it learns
    # reach more slowly, docs/results/README.md).
    "drq_light": {"image_encoder": "drq", "conv_channels": [8, 16, 32, 32], "conv_strides": [2, 2, 2, 1]},
}
COMPILED = "_compiled"


def make_arms(device: str, sizes: list[int], batch_size: int, **common: object) -> dict:
    """Update closures of every arm; ``common``: config fields given to each of our policies."""
    arms = {}
    for size in sizes:
        features = rgbd_features(size)
        for name, config in ENCODERS.items():
            batch = make_batch(features, batch_size, device, n_step=config.get("n_step", 1))
            arms[f"{name}_{size}px"] = policy_update(make_policy(features, device, **config, **common), batch)
        arms[f"lerobot_sac_{size}px"] = make_sac_update(
            (4, size, size), batch_size, device, freeze_vision_encoder=False
        )
        arms[f"lerobot_sac_frozen_convs_{size}px"] = make_sac_update((4, size, size), batch_size, device)
    arms["state_b256"] = policy_update(
        make_policy(STATE_FEATURES, device, **common), make_batch(STATE_FEATURES, 256, device)
    )
    return arms
