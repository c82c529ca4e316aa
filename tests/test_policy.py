"""IndicatorDDPGConfig validation, action selection, the dataset-batch path and save/load."""

import pytest
import torch
from lerobot.configs import FeatureType, PolicyFeature

from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.configuration_indicator_ddpg import (
    IndicatorDDPGConfig,
    IndicatorDDPGConfigError,
)
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

STATE, GOAL = "observation.state", "observation.goal_state"
RGB, DEPTH = "observation.images.front", "observation.images.front_depth"
GOAL_RGB, GOAL_DEPTH = "observation.images.goal_front", "observation.images.goal_front_depth"
ACTION = {"action": PolicyFeature(FeatureType.ACTION, (3,))}


def vec(n: int = 3) -> PolicyFeature:
    return PolicyFeature(FeatureType.STATE, (n,))


def img(c: int, size: int = 32) -> PolicyFeature:
    return PolicyFeature(FeatureType.VISUAL, (c, size, size))


def make_config(inputs: dict, **kwargs) -> IndicatorDDPGConfig:
    defaults = {"hidden_dims": [16, 16, 16], "horizon": 25, "observation_keys": [STATE]}
    cfg = IndicatorDDPGConfig(device="cpu", **{**defaults, **kwargs})
    cfg.input_features, cfg.output_features = dict(inputs), dict(ACTION)
    return cfg


def rgbd_config(**kwargs) -> IndicatorDDPGConfig:
    inputs = {RGB: img(3), DEPTH: img(1), GOAL_RGB: img(3), GOAL_DEPTH: img(1), STATE: vec(), GOAL: vec()}
    return make_config(inputs, observation_keys=[RGB, DEPTH], **kwargs)


@pytest.mark.parametrize(
    ("inputs", "keys", "message"),
    [
        ({STATE: vec(), RGB: img(3), GOAL_RGB: img(3)}, [STATE], "has no goal 'observation.goal_state'"),
        ({GOAL: vec()}, [STATE], "goal key 'observation.goal_state' has no observation"),
        ({STATE: vec(3), GOAL: vec(2)}, [STATE], "must be identical"),
        ({"observation.gt_achieved_goal": vec()}, ["observation.gt_achieved_goal"], "ground-truth key"),
        ({GOAL: vec()}, [GOAL], "is a goal key"),
        ({STATE: vec(), GOAL: vec()}, ["action"], "not an observation key"),
        ({RGB: img(3), GOAL_RGB: img(3, 16)}, [RGB], "must be identical"),
    ],
)
def test_config_validation_errors(inputs, keys, message):
    with pytest.raises((ValueError, IndicatorDDPGConfigError), match=message):
        make_config(inputs, observation_keys=keys).validate_features()


def test_inputs_are_exactly_the_compared_keys_and_goals():
    cfg = rgbd_config()
    cfg.input_features["observation.gt_achieved_goal"] = vec()
    cfg.validate_features()
    assert sorted(cfg.input_features) == sorted([RGB, DEPTH, GOAL_RGB, GOAL_DEPTH])
    assert cfg.observation_delta_indices == [0, 1, 2, 4, 8, 16]


def test_bad_hyper_parameters_are_rejected():
    with pytest.raises(IndicatorDDPGConfigError, match="future_offsets"):
        IndicatorDDPGConfig(device="cpu", future_offsets=[1, 4])
    with pytest.raises(IndicatorDDPGConfigError, match="reward must be one of"):
        IndicatorDDPGConfig(device="cpu", reward="dense")
    with pytest.raises(IndicatorDDPGConfigError, match="horizon"):
        IndicatorDDPGConfig(device="cpu", horizon=1)


def rgbd_batch(batch_size: int) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    return {
        RGB: torch.randint(0, 256, (batch_size, 3, 32, 32), generator=g) / 255.0,
        DEPTH: torch.randint(300, 2000, (batch_size, 1, 32, 32), generator=g).float(),
        GOAL_RGB: torch.randint(0, 256, (batch_size, 3, 32, 32), generator=g) / 255.0,
        GOAL_DEPTH: torch.randint(300, 2000, (batch_size, 1, 32, 32), generator=g).float(),
    }


@pytest.mark.parametrize("spatial_softmax", [False, True])
def test_select_action_rgbd_is_deterministic_and_bounded(spatial_softmax):
    stats = {DEPTH: {"mean": torch.full((1, 1, 1), 1000.0), "std": torch.full((1, 1, 1), 400.0)}}
    policy = IndicatorDDPGPolicy(rgbd_config(spatial_softmax=spatial_softmax), dataset_stats=stats)
    batch = rgbd_batch(5)
    action = policy.select_action(batch)
    assert action.shape == (5, 3) and action.abs().max() <= 1
    assert torch.equal(action, policy.select_action(batch))
    assert torch.equal(policy.predict_action_chunk(batch)[:, 0], action)
    # The goal is an input: changing it changes the action.
    other = dict(batch, **{GOAL_RGB: batch[RGB]})
    assert not torch.equal(policy.select_action(other), action)


def test_select_action_names_missing_inputs():
    policy = IndicatorDDPGPolicy(rgbd_config())
    batch = rgbd_batch(2)
    del batch[GOAL_DEPTH]
    with pytest.raises(KeyError, match="goal_front_depth"):
        policy.select_action(batch)


def test_select_action_on_a_time_stacked_batch_names_key_and_shapes():
    """lerobot-train's delta indices stack frames as (B, T, ...); select_action takes one frame per key."""
    policy = IndicatorDDPGPolicy(rgbd_config())
    batch = {k: v[:, None].expand(-1, 6, -1, -1, -1) for k, v in rgbd_batch(2).items()}
    with pytest.raises(ValueError) as err:
        policy.select_action(batch)
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith(f"{RGB}: expected shape (B, 3, 32, 32), got (2, 6, 3, 32, 32)")
    state_policy = IndicatorDDPGPolicy(make_config({STATE: vec(), GOAL: vec()}))
    with pytest.raises(ValueError, match=r"observation.state: expected shape \(B, 3\), got \(4, 6, 3\)"):
        state_policy.select_action({STATE: torch.zeros(4, 6, 3), GOAL: torch.zeros(4, 6, 3)})


def test_policy_on_images_of_another_size_names_key_and_sizes():
    """A 32 px policy given 64 px frames (e.g. a 64 px env) fails with the key, expected and actual HxW."""
    policy = IndicatorDDPGPolicy(rgbd_config())
    batch = {k: torch.nn.functional.interpolate(v, size=(64, 64)) for k, v in rgbd_batch(2).items()}
    with pytest.raises(ValueError) as err:
        policy.select_action(batch)
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith(f"{RGB}: the policy was made for 32x32 (HxW) images, got 64x64")
    # Only the goal of another size: its own key is named.
    mixed = dict(rgbd_batch(2), **{GOAL_DEPTH: batch[GOAL_DEPTH]})
    with pytest.raises(ValueError, match=f"^{GOAL_DEPTH}: the policy was made for 32x32"):
        policy.select_action(mixed)


def test_exploration_action_noise_and_random_actions():
    policy = IndicatorDDPGPolicy(make_config({STATE: vec(), GOAL: vec()}))
    batch = {STATE: torch.zeros(4000, 3), GOAL: torch.ones(4000, 3)}
    greedy = policy.select_action(batch)
    g = torch.Generator().manual_seed(0)
    assert torch.equal(policy.select_exploration_action(batch, 0.0, 0.0, g), greedy)
    explore = policy.select_exploration_action(batch, noise_eps=0.2, random_eps=0.3, generator=g)
    assert explore.abs().max() <= 1
    changed_a_lot = ((explore - greedy).abs() > 0.8).any(dim=1).float().mean().item()
    assert 0.1 < changed_a_lot < 0.35  # ~random_eps of rows are uniform random actions
    a = policy.select_exploration_action(batch, generator=torch.Generator().manual_seed(1))
    b = policy.select_exploration_action(batch, generator=torch.Generator().manual_seed(1))
    assert torch.equal(a, b)


def dataset_batch(batch_size: int, offsets: list[int], pad_from: torch.Tensor) -> dict[str, torch.Tensor]:
    """A lerobot-train style batch: frame j of sample i is the value 100*i + delta_j; pad from index pad_from[i]."""
    deltas = torch.tensor([0, 1, *offsets], dtype=torch.float)
    frames = 100 * torch.arange(batch_size, dtype=torch.float)[:, None] + deltas[None]
    state = frames[..., None].expand(-1, -1, 3).clone()
    is_pad = torch.arange(len(deltas))[None] >= pad_from[:, None]
    goal = torch.full_like(state, -7.0)
    return {
        STATE: state,
        f"{STATE}_is_pad": is_pad,
        GOAL: goal,
        "observation.gt_achieved_goal": state.clone(),
        "observation.gt_desired_goal": goal.clone(),
        "action": torch.zeros(batch_size, 3),
    }


def test_dataset_batch_picks_a_valid_future_offset_uniformly():
    cfg = make_config({STATE: vec(), GOAL: vec()}, future_offsets=[2, 4, 8, 16], n_step=1)
    n = 20_000
    pad_from = torch.tensor([6, 4, 2, 1]).repeat(n // 4)  # all valid / offsets 2,4 / none / no o_{t+1}
    out = core.dataset_batch_to_transitions(
        dataset_batch(n, cfg.future_offsets, pad_from), cfg, torch.Generator()
    )
    offset = out[core.FUTURE + STATE][:, 0] - 100 * torch.arange(n)
    assert torch.equal(out[core.NEXT + STATE][:, 0] - 100 * torch.arange(n), torch.ones(n))
    assert out[core.HAS_FUTURE].tolist()[:4] == [True, True, False, False]
    assert out[core.FUTURE_COUNT].tolist()[:4] == [4, 2, 0, 0]
    assert out[core.NEXT_VALID].tolist()[:4] == [True, True, True, False]
    full, half = offset[0::4], offset[1::4]
    for value in (2, 4, 8, 16):
        assert (full == value).float().mean().item() == pytest.approx(0.25, abs=0.02)
    assert set(half.tolist()) == {2.0, 4.0}
    assert (half == 2).float().mean().item() == pytest.approx(0.5, abs=0.03)
    assert torch.equal(out[GOAL], torch.full((n, 3), -7.0))
    assert torch.equal(out[core.GT_FUTURE_ACHIEVED], out[core.FUTURE + STATE])


def test_forward_on_dataset_batch_drops_invalid_and_reports_reward_statistics():
    cfg = make_config({STATE: vec(), GOAL: vec()}, future_offsets=[2, 4], oracle_epsilon=0.5)
    policy = IndicatorDDPGPolicy(cfg)
    pad_from = torch.tensor([4, 4, 3, 1] * 64)
    batch = dataset_batch(256, cfg.future_offsets, pad_from)
    loss, stats = policy.forward(batch, generator=torch.Generator().manual_seed(0))
    assert loss.isfinite()
    # Each sample's frames differ by >= 1 (> epsilon): ground truth agrees with the indicator exactly.
    assert stats["reward_accuracy"] == 1.0 and stats["false_negative_rate"] == 0.0
    assert stats["false_positive_rate"] == 0.0
    assert stats["frac_positive"] == pytest.approx(stats["frac_goal_next"])


def test_oracle_reward_counts_near_goals_and_indicator_misses_them():
    cfg = make_config({STATE: vec(), GOAL: vec()}, future_offsets=[2, 4], oracle_epsilon=1e6)
    batch = dataset_batch(512, cfg.future_offsets, torch.full((512,), 4))
    _, stats = IndicatorDDPGPolicy(cfg).forward(batch, generator=torch.Generator().manual_seed(0))
    # Everything is a ground-truth success: every R- of the indicator is a false negative.
    assert stats["frac_gt_positive"] == 1.0
    assert stats["false_negative_rate"] == pytest.approx(1 - stats["frac_positive"])
    cfg.reward = "oracle"
    _, stats = IndicatorDDPGPolicy(cfg).forward(batch, generator=torch.Generator().manual_seed(0))
    assert stats["frac_positive"] == 1.0 and stats["reward_accuracy"] == 1.0


def test_filter_precision_counts_ground_truth_successes_among_filtered():
    """``filtered_gt_success_rate`` = P(ground-truth success | filtered): 1 where every R- is a near miss
    (huge oracle epsilon), 0 where ground truth agrees with the indicator (every frame differs by >= 1)."""
    for epsilon, expected in ((1e6, 1.0), (0.5, 0.0)):
        cfg = make_config({STATE: vec(), GOAL: vec()}, future_offsets=[2, 4], oracle_epsilon=epsilon)
        policy = IndicatorDDPGPolicy(cfg)
        torch.nn.init.constant_(policy.critic.net[-1].bias, cfg.q0 + 100)  # every R- is filtered
        batch = dataset_batch(256, cfg.future_offsets, torch.full((256,), 4))
        _, stats = policy.forward(batch, generator=torch.Generator().manual_seed(0))
        assert (
            stats["frac_filtered"] == pytest.approx(1 - stats["frac_positive"]) and stats["frac_filtered"] > 0
        )
        assert stats["filtered_gt_success_rate"] == expected


def test_oracle_reward_without_ground_truth_is_an_error():
    cfg = make_config({STATE: vec(), GOAL: vec()}, future_offsets=[2, 4], reward="oracle")
    batch = dataset_batch(8, cfg.future_offsets, torch.full((8,), 4))
    del batch["observation.gt_desired_goal"]
    with pytest.raises(ValueError, match="needs ground truth"):
        IndicatorDDPGPolicy(cfg).forward(batch)


def test_save_load_round_trip(tmp_path):
    stats = {DEPTH: {"mean": torch.full((1, 1, 1), 1000.0), "std": torch.full((1, 1, 1), 400.0)}}
    policy = IndicatorDDPGPolicy(rgbd_config(horizon=7), dataset_stats=stats)
    policy.update()
    policy.save_pretrained(tmp_path)
    loaded = IndicatorDDPGPolicy.from_pretrained(tmp_path)
    assert loaded.config.horizon == 7 and loaded.config.observation_keys == [RGB, DEPTH]
    assert sorted(loaded.config.input_features) == sorted([RGB, DEPTH, GOAL_RGB, GOAL_DEPTH])
    batch = rgbd_batch(3)
    torch.testing.assert_close(loaded.select_action(batch), policy.select_action(batch))
    for (name, a), b in zip(policy.state_dict().items(), loaded.state_dict().values(), strict=True):
        assert torch.equal(a, b), name  # target nets and normalisation buffers included


def test_checkpoint_with_process_settings_loads_and_saves_without_them(tmp_path):
    """Checkpoints of earlier versions hold cpu_threads, keep_freed_memory and video_decoder_threads: they
    load (the keys are ignored, the process is left alone) and are saved again without them."""
    import json

    from lerobot.configs import PreTrainedConfig

    from lerobot_indicator.policy.configuration_indicator_ddpg import IGNORED_KEYS

    policy = IndicatorDDPGPolicy(rgbd_config(horizon=7))
    policy.save_pretrained(tmp_path)
    path = tmp_path / "config.json"
    saved = json.loads(path.read_text())
    assert saved["type"] == "indicator_ddpg" and not set(IGNORED_KEYS) & set(saved)
    path.write_text(
        json.dumps({**saved, "cpu_threads": 7, "keep_freed_memory": True, "video_decoder_threads": 1})
    )
    threads = torch.get_num_threads()
    loaded = IndicatorDDPGPolicy.from_pretrained(tmp_path)
    assert torch.get_num_threads() == threads
    assert loaded.config == policy.config and PreTrainedConfig.from_pretrained(tmp_path).horizon == 7
    loaded.save_pretrained(tmp_path)
    assert not set(IGNORED_KEYS) & set(json.loads(path.read_text()))
    with pytest.raises(SystemExit):  # not a --policy.* flag: lerobot-indicator-train has --cpu_threads
        PreTrainedConfig.from_pretrained(tmp_path, cli_overrides=["--cpu_threads=2"])


@pytest.fixture
def one_thread():
    """Small nets on a shared 2-core machine: extra intra-op threads only wait (docs/policy.md, benchmarks)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def test_learns_goal_reaching_from_random_walks_with_indicator_rewards(one_thread):
    """End to end on a 9-cell line (exact float positions, so indicator equality is meaningful): offline
    random-walk data, relabeling + indicator rewards only, and the greedy policy then reaches every goal."""
    n_cells, horizon, episodes = 9, 8, 400
    g = torch.Generator().manual_seed(0)
    torch.manual_seed(0)

    def env_step(s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        return (s + (a[:, 0] > 0.3).long() - (a[:, 0] < -0.3).long()).clamp(0, n_cells - 1)

    s = torch.randint(0, n_cells, (episodes,), generator=g)
    states, actions = [s], []
    for _ in range(horizon):
        actions.append(torch.rand(episodes, 1, generator=g) * 2 - 1)
        s = env_step(s, actions[-1])
        states.append(s)
    states, actions = torch.stack(states, 1).float(), torch.stack(actions, 1)
    goals = torch.randint(0, n_cells, (episodes,), generator=g).float()

    cfg = make_config({STATE: vec(1), GOAL: vec(1)}, horizon=horizon, hidden_dims=[64, 64, 64])
    cfg.output_features = {"action": PolicyFeature(FeatureType.ACTION, (1,))}
    policy = IndicatorDDPGPolicy(
        cfg, dataset_stats={STATE: {"mean": torch.tensor([4.0]), "std": torch.tensor([2.5])}}
    )
    optimizer = cfg.get_optimizer_preset().build(policy.get_optim_params())

    def sample(batch_size: int) -> dict[str, torch.Tensor]:
        """What the online trainer's episode buffer hands the core: t' uniform in {t+2..T}."""
        ep = torch.randint(0, episodes, (batch_size,), generator=g)
        t = torch.randint(0, horizon, (batch_size,), generator=g)
        has_future = t + 2 <= horizon
        span = (horizon - t - 1).clamp_min(1)
        future = torch.where(has_future, t + 2 + (torch.rand(batch_size, generator=g) * span).long(), horizon)
        return {
            STATE: states[ep, t, None],
            core.NEXT + STATE: states[ep, t + 1, None],
            core.FUTURE + STATE: states[ep, future, None],
            GOAL: goals[ep, None],
            "action": actions[ep, t],
            core.HAS_FUTURE: has_future,
            core.FUTURE_COUNT: horizon - t - 1,
        }

    def success_rate() -> float:
        start = torch.arange(n_cells).repeat_interleave(n_cells)
        goal = torch.arange(n_cells).repeat(n_cells).float()
        s = start
        for _ in range(horizon):
            s = env_step(s, policy.select_action({STATE: s.float()[:, None], GOAL: goal[:, None]}))
        return (s.float() == goal).float().mean().item()

    before = success_rate()
    for _ in range(600):
        loss, _ = policy.forward(sample(128), generator=g)
        loss.backward()
        optimizer.step()
        optimizer.zero_grad()
        policy.update()
    assert before < 0.5
    assert success_rate() >= 0.9


def test_compiled_loss_matches_eager_loss_and_gradients():
    """``compile_model=True`` must change speed only: same relabeling draws, loss, stats and gradients."""
    cfg = make_config({STATE: vec(), GOAL: vec()}, future_offsets=[2, 4], oracle_epsilon=0.5)
    torch.manual_seed(0)
    eager = IndicatorDDPGPolicy(cfg)
    compiled = IndicatorDDPGPolicy(
        make_config({STATE: vec(), GOAL: vec()}, future_offsets=[2, 4], compile_model=True)
    )
    compiled.load_state_dict(eager.state_dict())
    batch = dataset_batch(64, cfg.future_offsets, torch.tensor([4, 4, 3, 1] * 16))
    batch = core.dataset_batch_to_transitions(batch, cfg, torch.Generator().manual_seed(1))
    results = []
    for policy in (eager, compiled):
        generator = torch.Generator().manual_seed(2)
        loss, stats = policy.forward(batch, generator=generator)
        loss.backward()
        results.append(
            (loss, stats, generator.get_state(), [p.grad for p in policy.parameters() if p.requires_grad])
        )
    (loss_e, stats_e, gen_e, grads_e), (loss_c, stats_c, gen_c, grads_c) = results
    assert torch.equal(gen_e, gen_c)  # the compiled graph draws from the caller's generator
    torch.testing.assert_close(loss_c, loss_e)
    assert stats_c.keys() == stats_e.keys()
    for key in stats_e:
        assert stats_c[key] == pytest.approx(stats_e[key], rel=1e-5, abs=1e-6), key
    for grad_c, grad_e in zip(grads_c, grads_e, strict=True):
        assert grad_e.abs().max() > 0
        torch.testing.assert_close(grad_c, grad_e, rtol=1e-4, atol=1e-6)
    # A second batch size (a last short batch) recompiles rather than failing on a symbolic size.
    small = {k: v[:10] for k, v in batch.items()}
    torch.testing.assert_close(
        compiled.forward(small, generator=torch.Generator().manual_seed(3))[0],
        eager.forward(small, generator=torch.Generator().manual_seed(3))[0],
    )


def test_default_keys_are_the_cameras_never_the_state_and_state_is_logged_when_chosen(caplog):
    inputs = {RGB: img(3), DEPTH: img(1), GOAL_RGB: img(3), GOAL_DEPTH: img(1), STATE: vec(), GOAL: vec()}
    cfg = make_config(inputs, observation_keys=None)
    cfg.input_features["observation.gt_achieved_goal"] = vec()
    cfg.input_features["observation.gt_desired_goal"] = vec()
    cfg.validate_features()
    assert cfg.observation_keys == [RGB, DEPTH]
    state_only = make_config(
        {STATE: vec(), GOAL: vec(), "observation.gt_achieved_goal": vec()}, observation_keys=None
    )
    state_only.validate_features()
    assert state_only.observation_keys == [STATE]
    with caplog.at_level("WARNING"):
        make_config(inputs, observation_keys=[STATE]).validate_features()
    assert "although the data has the camera keys" in caplog.text and RGB in caplog.text
    with pytest.raises(ValueError, match="no observation key with a goal"):
        make_config({GOAL: vec()}, observation_keys=None).validate_features()


def test_horizon_comes_from_the_data_and_a_different_given_value_is_an_error():
    from types import SimpleNamespace

    from lerobot_indicator.policy.modeling_indicator_ddpg import dataset_horizon

    cfg = IndicatorDDPGConfig(device="cpu", horizon=None)
    with pytest.raises(ValueError, match="horizon T is not known"):
        _ = cfg.gamma
    cfg.set_horizon(3, source="dataset x")
    assert cfg.gamma == pytest.approx(2 / 3) and cfg.q0 == pytest.approx(0.5 * (-1 + 2 + 3))
    with pytest.raises(ValueError, match=r"--policy.horizon=3 but the episodes of the env rope have T = 25"):
        cfg.set_horizon(25, source="env rope")
    meta = SimpleNamespace(repo_id="u/rope", episodes={"length": [4, 4, 4]})
    assert dataset_horizon(meta) == 3
    with pytest.raises(ValueError, match=r"mixes episode lengths \[4, 26\]"):
        dataset_horizon(SimpleNamespace(repo_id="u/mixed", episodes={"length": [4, 26]}))
    # The paper's natural initial Q, R-/(1-gamma) = -25 at T = 25, is accepted despite float rounding.
    IndicatorDDPGConfig(device="cpu", horizon=25, q_init=-25.0)


def test_critic_output_scale_is_one_or_the_horizon_and_is_checked():
    assert IndicatorDDPGConfig(device="cpu", horizon=25, critic_output_scale="paper").q_output_scale == 1.0
    assert IndicatorDDPGConfig(device="cpu", horizon=25, critic_output_scale="return").q_output_scale == 25.0
    with pytest.raises(
        IndicatorDDPGConfigError, match=r"critic_output_scale must be one of \('paper', 'return'\)"
    ):
        IndicatorDDPGConfig(device="cpu", critic_output_scale="popart")
