"""``benchmarks.speed.peers``: LeRobot's SAC update really trains, and its FLOP count scales with batch;
the update timer and the records' commit."""

import mmap
import re

import pytest
import torch

from benchmarks.records import git_commit
from benchmarks.speed.peers import make_sac_update, matmul_conv_flops, measure_peaks
from benchmarks.speed.updates import interleaved_rates

# The smallest square image LeRobot's DefaultImageEncoder (four unpadded stride-2 convs) accepts is 40x40.
SHAPE = (4, 40, 40)


@pytest.fixture(autouse=True)
def _one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def _critic_params(step) -> list[torch.Tensor]:
    return [p.detach().clone() for p in step.algorithm.critic_ensemble.critics.parameters()]


@pytest.mark.parametrize("freeze_vision_encoder", [True, False])
def test_sac_update_changes_critics_actor_and_temperature(freeze_vision_encoder):
    step = make_sac_update(SHAPE, batch_size=4, freeze_vision_encoder=freeze_vision_encoder)
    algo = step.algorithm
    conv = algo.policy.encoder_critic.image_encoder.image_enc_layers[0].weight
    before_critic = _critic_params(step)
    before_actor = algo.policy.actor.mean_layer.weight.detach().clone()
    before_conv = conv.detach().clone()
    before_alpha = algo.log_alpha.item()

    step()
    after_critic = _critic_params(step)
    assert all(not torch.equal(a, b) for a, b in zip(before_critic, after_critic, strict=True))
    assert not torch.equal(before_actor, algo.policy.actor.mean_layer.weight)
    assert algo.log_alpha.item() != before_alpha
    # The shared conv encoder trains (Adam steps ~lr=3e-4) only when freeze_vision_encoder is off. Frozen,
    # it still drifts by float rounding (~1e-8): the target critics share it, and the Polyak update
    # rewrites it as 0.005 * p + 0.995 * p.
    conv_change = (conv.detach() - before_conv).abs().max().item()
    assert (conv_change < 1e-6) if freeze_vision_encoder else (conv_change > 1e-5)
    assert algo._optimization_step == 1

    step()
    assert algo._optimization_step == 2
    assert any(not torch.equal(a, b) for a, b in zip(after_critic, _critic_params(step), strict=True))


def test_flops_positive_and_linear_in_batch():
    small = matmul_conv_flops(make_sac_update(SHAPE, batch_size=4))
    large = matmul_conv_flops(make_sac_update(SHAPE, batch_size=8))
    assert small > 0
    assert large == pytest.approx(2 * small, rel=0.01)


def test_too_small_image_is_rejected():
    with pytest.raises(ValueError, match="too small"):
        make_sac_update((4, 32, 32), batch_size=4)


def test_measure_peaks_reports_positive_rates():
    from lerobot_indicator.policy.networks_indicator_ddpg import native_bf16

    peaks = measure_peaks(seconds=0.05)
    bf16 = {"conv3x3_32ch_bf16_autocast_gflops"} if native_bf16("cpu") else set()
    assert set(peaks) == {"sgemm_256_gflops", "sgemm_1024_gflops", "conv3x3_32ch_gflops", *bf16}
    assert all(v > 0 for v in peaks.values())


def test_interleaved_rates_counts_updates_and_page_faults():
    calls = {"small": 0, "large": 0}

    def small() -> None:
        calls["small"] += 1

    def large() -> None:
        calls["large"] += 1
        # 64 MiB of fresh anonymous memory written (bypassing malloc, whose reuse depends on keep_freed_memory):
        # at least one page fault per page touched.
        with mmap.mmap(-1, 64 * 1024 * 1024) as fresh:
            fresh.write(bytes(64 * 1024 * 1024))

    rates = interleaved_rates({"small": small, "large": large}, seconds=0.3, rounds=3, warmup=1)
    assert rates["small"]["updates_per_s"] > rates["large"]["updates_per_s"] > 0
    assert len(rates["large"]["rounds_updates_per_s"]) == 3
    assert rates["large"]["minor_faults_per_update"] > rates["small"]["minor_faults_per_update"]
    assert rates["large"]["system_s_per_update"] >= 0


def test_git_commit_names_this_checkout():
    commit = git_commit()
    assert commit is not None and re.fullmatch(r"[0-9a-f]{40}\+?", commit)
