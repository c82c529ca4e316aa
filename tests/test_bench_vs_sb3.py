"""The SB3 GoalEnv adapter of ``benchmarks/experiments/run_vs_sb3.py``: vectorised reward and a few SB3 DDPG+HER steps."""

import json

import numpy as np
import pytest

from lerobot_indicator.envs.goal_env_adapter import GoalEnvAdapter, make_goal_env, sparse_goal_reward


def test_sparse_goal_reward_is_vectorised_and_uses_epsilon():
    achieved = np.zeros((4, 3), np.float32)
    desired = np.array([[0, 0, 0], [0.05, 0, 0], [0.0501, 0, 0], [0, 0.3, 0.4]], np.float32)
    np.testing.assert_array_equal(sparse_goal_reward(achieved, desired, 0.05), [1, 1, -1, -1])
    assert sparse_goal_reward(achieved[0], desired[3], 0.05).shape == ()
    with pytest.raises(ValueError, match="differ in shape"):
        sparse_goal_reward(achieved, desired[:2], 0.05)


def test_adapter_matches_env_reward_and_info():
    env = make_goal_env()
    try:
        obs, info = env.reset(seed=3)
        assert set(obs) == {"observation", "achieved_goal", "desired_goal"}
        assert env.observation_space.contains(obs)
        np.testing.assert_array_equal(obs["desired_goal"], info["gt_desired_goal"])
        achieved, desired, rewards = [], [], []
        for _ in range(5):
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
            achieved.append(obs["achieved_goal"])
            desired.append(obs["desired_goal"])
            rewards.append(reward)
        # The batch call agrees with the env's own per-step ground-truth reward...
        batch = env.compute_reward(np.stack(achieved), np.stack(desired), [info] * 5)
        np.testing.assert_array_equal(batch, rewards)
        # ...and an episode relabeled with its own achieved goal is a success.
        assert env.compute_reward(obs["achieved_goal"], obs["achieved_goal"], info) == 1.0
    finally:
        env.close()


def test_adapter_rejects_image_observations():
    import gymnasium as gym

    class Images(gym.Env):
        observation_space = gym.spaces.Dict(
            {
                "agent_pos": gym.spaces.Box(-1, 1, (3,)),
                "goal_state": gym.spaces.Box(-1, 1, (3,)),
                "pixels": gym.spaces.Box(0, 255, (8, 8, 3)),
            }
        )
        action_space = gym.spaces.Box(-1, 1, (3,))

    with pytest.raises(ValueError, match="state observations only"):
        GoalEnvAdapter(Images())


def test_sb3_ddpg_her_runs_on_the_reach_env():
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import DDPG, HerReplayBuffer

    env = make_goal_env()
    model = DDPG(
        "MultiInputPolicy",
        env,
        learning_starts=0,
        batch_size=16,
        train_freq=(1, "episode"),
        gradient_steps=2,
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
        policy_kwargs={"net_arch": [16, 16]},
        buffer_size=1000,
        seed=0,
        device="cpu",
    )
    model.learn(total_timesteps=50)  # two episodes: HER relabels through compute_reward
    assert model.num_timesteps == 50 and model._n_updates == 4
    # HER's relabeled samples get their reward from the adapter's compute_reward: it must agree with the
    # (achieved, desired) goals of every sample, relabeled (80%) or not.
    samples = model.replay_buffer.sample(64)
    achieved = samples.next_observations["achieved_goal"].numpy()
    desired = samples.observations["desired_goal"].numpy()
    expected = sparse_goal_reward(achieved, desired, env.epsilon)
    np.testing.assert_array_equal(samples.rewards.numpy()[:, 0], expected)
    assert (expected == 1.0).any()  # some relabeled goals are reached (HER at work)
    action, _ = model.predict(env.reset(seed=0)[0], deterministic=True)
    assert action.shape == (3,) and np.all(np.abs(action) <= 1)


def test_eval_curve_hooks_exclude_evaluation_time(monkeypatch):
    from benchmarks.experiments import vs_sb3
    from lerobot_indicator.training.hooks import PhaseEnd

    clock = iter([10.0, 15.0, 30.0])  # first cycle start, first eval end, second eval end
    monkeypatch.setattr(vs_sb3.time, "perf_counter", lambda: next(clock))
    timing = vs_sb3.EvalCurve()
    hooks = timing.hooks()
    hooks.on_cycle_start(0)
    hooks.on_collect_end(PhaseEnd(0, 0, 50, 1.0), [])
    hooks.on_update_end(PhaseEnd(0, 40, 50, 2.0), {})
    hooks.on_eval_end(PhaseEnd(0, 40, 50, 3.0), {"eval_success_rate": 0.5})  # evaluated from 12 to 15
    hooks.on_cycle_start(1)
    hooks.on_update_end(PhaseEnd(1, 80, 100, 2.5), {})
    hooks.on_eval_end(PhaseEnd(1, 80, 100, 4.0), {"eval_success_rate": 1.0})  # from 26 to 30
    assert [c["train_wall_s"] for c in timing.curve] == [2.0, 26.0 - 10.0 - 3.0]
    assert [(c["env_steps"], c["updates"]) for c in timing.curve] == [(50, 40), (100, 80)]
    assert (timing.collect_s, timing.optimise_s, timing.eval_s) == (1.0, 4.5, 7.0)


def test_our_learners_are_the_package_presets(tmp_path):
    from benchmarks.experiments import vs_sb3
    from benchmarks.experiments.presets import METHODS

    s = vs_sb3.Settings(env_steps=500, eval_every=250)
    for learner, preset in vs_sb3.OURS.items():
        cfg = vs_sb3.ours_config(learner, 0, s, tmp_path / learner, s.steps())
        flags = dict(f.removeprefix("--policy.").split("=") for f in METHODS[preset])
        assert {k: str(getattr(cfg.policy, k)).lower() for k in flags} == flags
        assert cfg.steps == 500 * 40 // (2 * 25) and cfg.env_eval_freq == 250 * 40 // (2 * 25)
    with pytest.raises(ValueError, match=r"multiples of one cycle \(50 env steps\)"):
        vs_sb3.Settings(eval_every=260).validate()


def test_fetch_reach_task_runs_our_env_and_sb3_on_fetchreach_v4(tmp_path):
    from benchmarks.experiments import vs_sb3

    s = vs_sb3.Settings(task="fetch_reach_state", env_steps=1000, eval_every=200)
    s.validate()
    assert s.horizon == 50 and s.steps() == 1000 * 40 // (2 * 50)
    for learner in vs_sb3.OURS:
        cfg = vs_sb3.ours_config(learner, 0, s, tmp_path / learner, s.steps())
        assert (cfg.env.type, cfg.env.obs_type, cfg.env.episode_length, cfg.env.epsilon) == (
            "fetch_reach",
            "state",
            50,
            0.05,
        )
        assert cfg.policy.observation_keys == ["observation.state"]
        assert cfg.policy.context_keys == ["observation.environment_state"]
        assert cfg.env_eval_freq == 200 * 40 // (2 * 50)
    with pytest.raises(ValueError, match=r"multiples of one cycle \(100 env steps\)"):
        vs_sb3.Settings(task="fetch_reach_state", eval_every=250).validate()
    with pytest.raises(ValueError, match="choose from"):
        vs_sb3.Settings(task="fetch_slide_state").validate()


def test_fetch_push_task_runs_our_block_env_and_sb3_on_fetchpush_v4(tmp_path):
    from benchmarks.experiments import vs_sb3

    s = vs_sb3.Settings(task="fetch_push_state", env_steps=1000, eval_every=200)
    s.validate()
    cfg = vs_sb3.ours_config("ours_indicator", 0, s, tmp_path / "ours", s.steps())
    assert (cfg.env.type, cfg.env.obs_type, cfg.env.episode_length, cfg.env.epsilon) == (
        "fetch_push",
        "state",
        50,
        0.05,
    )
    assert cfg.policy.observation_keys == ["observation.state"]
    assert cfg.policy.context_keys == ["observation.environment_state"]
    env = vs_sb3.make_sb3_env(s)
    assert env.spec.id == "FetchPush-v4" and env.spec.max_episode_steps == 50
    obs, _ = env.reset(seed=0)
    assert obs["observation"].shape == (25,) and obs["desired_goal"].shape == (3,)
    # its own reward: 0 within 0.05 m of the goal, else -1
    goal = obs["desired_goal"]
    near, far = goal + np.array([0.049, 0.0, 0.0]), goal + np.array([0.051, 0.0, 0.0])
    assert env.unwrapped.compute_reward(np.stack([near, far]), np.stack([goal, goal]), {}).tolist() == [
        0.0,
        -1.0,
    ]


def test_sb3_on_fetchreach_v4_uses_its_own_reward_and_our_eval_protocol():
    pytest.importorskip("stable_baselines3")
    from benchmarks.experiments import vs_sb3

    s = vs_sb3.Settings(task="fetch_reach_state", episodes_per_cycle=1, updates_per_cycle=2, batch_size=16)
    model = vs_sb3.make_sb3(0, s)
    env = model.get_env().envs[0].unwrapped
    assert env.spec.id == "FetchReach-v4" and model.gamma == 1 - 1 / 50
    model.learn(total_timesteps=100)  # two episodes
    assert model.num_timesteps == 100 and model._n_updates == 4
    # HER's relabeled rewards come from FetchReach-v4's own compute_reward: 0 within 0.05 m, else -1.
    samples = model.replay_buffer.sample(64)
    achieved = samples.next_observations["achieved_goal"].numpy()
    desired = samples.observations["desired_goal"].numpy()
    distance = np.linalg.norm(achieved - desired, axis=-1)
    np.testing.assert_array_equal(samples.rewards.numpy()[:, 0], -(distance > 0.05).astype(np.float32))
    result = vs_sb3.evaluate_sb3(model, vs_sb3.make_sb3_env(s), 2, s.horizon)
    assert 0 <= result["eval_success_rate"] <= 1 and result["eval_final_distance"] > 0


def test_ratios_of_env_steps_to_90():
    from benchmarks.experiments import vs_sb3

    def run(method, seed, successes):
        curve = [{"env_steps": 100 * (i + 1), "eval_success_rate": x} for i, x in enumerate(successes)]
        hit = next((c["env_steps"] for c in curve if c["eval_success_rate"] >= 0.9), None)
        return {"method": method, "seed": seed, "curve": curve, "summary": {"env_steps_to_90": hit}}

    runs = [
        run("sb3_ddpg_her", 0, [0.0, 0.5, 0.9, 1.0]),
        run("sb3_ddpg_her", 1, [0.0, 0.9, 1.0, 1.0]),
        run("ours_indicator", 0, [0.9, 1.0, 1.0, 1.0]),
        run("ours_indicator", 1, [0.5, 0.8, 1.0, 1.0]),
        run("ours_oracle", 0, [0.0, 0.0, 0.0, 1.0]),
        run("ours_oracle", 1, [0.0, 0.0, 0.0, 0.0]),  # never
    ]
    r = vs_sb3.ratios(runs, list(vs_sb3.LEARNERS))
    # mean curves: SB3 0, 0.7, 0.95 -> 300; ours indicator 0.7, 0.9 -> 200; oracle 0.5 at most -> never
    assert r["env_steps_to_90_mean_curve"] == {
        "sb3_ddpg_her": 300,
        "ours_oracle": None,
        "ours_indicator": 200,
    }
    ind = r["ours_indicator_over_sb3"]
    assert ind["mean_curve"] == pytest.approx(200 / 300)
    assert ind["mean_of_seeds"] == pytest.approx(((100 + 300) / 2) / ((300 + 200) / 2))
    assert ind["per_seed"] == {0: pytest.approx(100 / 300), 1: pytest.approx(300 / 200)}
    assert r["ours_oracle_over_sb3"]["mean_curve"] is None
    assert r["ours_oracle_over_sb3"]["mean_of_seeds"] is None  # a seed never reached it


def test_sb3_with_normalised_inputs_stores_raw_goals_and_evaluates_normalised():
    pytest.importorskip("stable_baselines3")
    from benchmarks.experiments import vs_sb3

    s = vs_sb3.Settings(task="fetch_reach_state", episodes_per_cycle=1, updates_per_cycle=2, batch_size=16)
    model = vs_sb3.make_sb3(0, s, learner="sb3_ddpg_her_norm")
    normalizer = model.get_vec_normalize_env()
    assert normalizer is not None and normalizer.clip_obs == 5.0 and not normalizer.norm_reward
    model.learn(total_timesteps=100)
    # HER relabels with raw goals (the buffer keeps raw observations): rewards follow the raw distance.
    raw = model.replay_buffer.observations["achieved_goal"][:100, 0]
    assert 1.0 < raw[:, 0].mean() < 1.6  # FetchReach's world x (m) around the table, not z-scores
    samples = model.replay_buffer.sample(64, env=None)
    distance = np.linalg.norm(
        samples.next_observations["achieved_goal"].numpy() - samples.observations["desired_goal"].numpy(),
        axis=-1,
    )
    np.testing.assert_array_equal(samples.rewards.numpy()[:, 0], -(distance > 0.05).astype(np.float32))
    result = vs_sb3.evaluate_sb3(model, vs_sb3.make_sb3_env(s), 1, s.horizon)
    assert result["eval_success_rate"] in (0.0, 1.0)


def test_sb3_td3_and_zoo_sac_learners_are_built_with_their_settings():
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import SAC, TD3

    from benchmarks.experiments import vs_sb3

    s = vs_sb3.Settings(task="fetch_reach_state", episodes_per_cycle=1, updates_per_cycle=2, batch_size=16)
    td3 = vs_sb3.make_sb3(0, s, learner="sb3_td3_her")
    # The shared settings (as DDPG's): gamma 1 - 1/T, tau 0.02, the cycle's gradient steps, HER future x4.
    assert isinstance(td3, TD3) and td3.gamma == 1 - 1 / 50 and td3.tau == 0.02 and td3.gradient_steps == 2
    assert td3.replay_buffer_kwargs == {"n_sampled_goal": 4, "goal_selection_strategy": "future"}
    sac = vs_sb3.make_sb3(0, s, learner="sb3_sac_her_zoo")
    # rl-baselines3-zoo's FetchReach settings, not the shared ones.
    assert (
        isinstance(sac, SAC) and sac.gamma == 0.95 and sac.batch_size == 256 and sac.learning_starts == 1000
    )
    assert sac.ent_coef == "auto" and sac.train_freq.frequency == 1 and sac.gradient_steps == 1
    sac.learn(total_timesteps=50)
    assert sac.get_env().envs[0].unwrapped.spec.id == "FetchReach-v4" and sac._n_updates == 0


def test_eval_curve_state_resumes_and_a_redone_cycle_replaces_its_evaluation(monkeypatch, tmp_path):
    from benchmarks.experiments import vs_sb3
    from lerobot_indicator.training.hooks import PhaseEnd

    state = tmp_path / "timing.json"
    # cycle start and its save, eval end and its save, next cycle start's save (then the process dies)
    clock = iter([10.0, 10.0, 15.0, 15.0, 16.0])
    monkeypatch.setattr(vs_sb3.time, "perf_counter", lambda: next(clock))
    first = vs_sb3.EvalCurve(state).hooks()
    first.on_cycle_start(0)
    first.on_collect_end(PhaseEnd(0, 0, 50, 1.0), [])
    first.on_eval_end(PhaseEnd(0, 40, 50, 3.0), {"eval_success_rate": 0.5})  # evaluated from 12 to 15
    first.on_cycle_start(1)  # 6 s after the start, 3 of them evaluating
    # The new process resumes at cycle 1, and again at cycle 0 (its resume state was older than timing.json).
    clock = iter([100.0, 100.0, 104.0, 104.0])
    monkeypatch.setattr(vs_sb3.time, "perf_counter", lambda: next(clock))
    timing = vs_sb3.EvalCurve(state)
    assert (timing.eval_s, timing.collect_s) == (3.0, 1.0)
    hooks = timing.hooks()
    hooks.on_cycle_start(0)  # the clock goes on from 6 s: start = 94
    hooks.on_eval_end(PhaseEnd(0, 40, 50, 2.0), {"eval_success_rate": 0.7})  # from 102 to 104
    assert [(c["env_steps"], c["eval_success_rate"]) for c in timing.curve] == [(50, 0.7)]
    assert timing.curve[0]["train_wall_s"] == 102.0 - 94.0 - 3.0
    assert json.loads(state.read_text())["curve"] == timing.curve


def test_a_run_resumes_from_its_state_and_a_finished_one_is_read_back(tmp_path):
    from benchmarks.experiments import vs_sb3

    small = {"eval_every": 50, "eval_episodes": 1, "updates_per_cycle": 2, "batch_size": 16}
    state = tmp_path / "reach_state" / "ours_indicator" / "seed_0"
    first = vs_sb3.run_learner("ours_indicator", 0, vs_sb3.Settings(env_steps=50, **small), state)
    [so_far] = vs_sb3.runs_so_far(
        [0, 1], ["ours_indicator"], vs_sb3.Settings(env_steps=100, **small), tmp_path
    )
    assert (so_far["finished"], so_far["curve"], so_far["updates"]) == (False, first["curve"], 2)
    record = vs_sb3.run_benchmark(
        [0],
        ["ours_indicator"],
        vs_sb3.Settings(env_steps=100, **small),
        tmp_path / "out",
        "cmd",
        False,
        tmp_path,
        True,
    )
    assert record["update_throughput"] is None and record["runs"][0]["finished"] is False
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["vs_sb3_so_far.json", "vs_sb3_so_far.png"]
    run = vs_sb3.run_learner("ours_indicator", 0, vs_sb3.Settings(env_steps=100, **small), state)
    assert [(c["env_steps"], c["updates"]) for c in run["curve"]] == [(50, 2), (100, 4)]
    assert run["curve"][0] == first["curve"][0]  # continued: the first evaluation was not run again
    assert run["updates"] == 4 and run["curve"][1]["train_wall_s"] > run["curve"][0]["train_wall_s"]
    s = vs_sb3.Settings(env_steps=100, **small)
    (state / "run.json").write_text(json.dumps(run))
    assert vs_sb3.run_in_subprocess("ours_indicator", 0, s, tmp_path)["curve"] == run["curve"]
    assert vs_sb3.runs_so_far([0], ["ours_indicator"], s, tmp_path)[0]["finished"] is True
    with pytest.raises(ValueError, match="other settings"):
        vs_sb3.run_in_subprocess("ours_indicator", 0, vs_sb3.Settings(env_steps=200, **small), tmp_path)
    with pytest.raises(ValueError, match="other settings"):
        vs_sb3.runs_so_far([0], ["ours_indicator"], vs_sb3.Settings(env_steps=200, **small), tmp_path)


def test_sb3_run_resumes_from_its_state(tmp_path):
    pytest.importorskip("stable_baselines3")
    from benchmarks.experiments import vs_sb3

    small = {"eval_every": 50, "eval_episodes": 1, "updates_per_cycle": 2, "batch_size": 16}
    first = vs_sb3.run_sb3(0, vs_sb3.Settings(env_steps=50, **small), "sb3_td3_her", tmp_path)
    run = vs_sb3.run_sb3(0, vs_sb3.Settings(env_steps=100, **small), "sb3_td3_her", tmp_path)
    assert [(c["env_steps"], c["updates"]) for c in run["curve"]] == [(50, 2), (100, 4)]
    assert run["curve"][0] == first["curve"][0]  # continued: the first evaluation was not run again
    assert sorted(p.name for p in (tmp_path / "ckpt").iterdir()) == [
        "model.zip",
        "progress.json",
        "replay_buffer.pkl",
    ]


def test_zero_action_reference_never_acts_and_scores_the_start(monkeypatch):
    import gymnasium as gym

    from benchmarks.experiments import vs_sb3
    from lerobot_indicator.keys import EVAL_SEED_OFFSET

    class Line(gym.Env):
        """A point on a line: the action moves it; episode i's goal lies 0.1 * i from the start."""

        action_space = gym.spaces.Box(-1, 1, (1,))
        actions: list[float] = []

        def reset(self, seed=None, options=None):
            self.t, self.pos, self.goal = 0, 0.0, 0.1 * (seed - EVAL_SEED_OFFSET)
            return self.obs(), {}

        def obs(self):
            return {"achieved_goal": np.array([self.pos]), "desired_goal": np.array([self.goal])}

        def step(self, action):
            self.t += 1
            self.actions.append(float(action[0]))
            self.pos += float(action[0])
            success = abs(self.pos - self.goal) < 0.05
            return self.obs(), 0.0, False, self.t == 25, {"is_success": success}

    monkeypatch.setattr(vs_sb3, "make_sb3_env", lambda s: Line())
    ref = vs_sb3.zero_action_reference(vs_sb3.Settings(eval_episodes=3))
    assert ref == {"eval_success_rate": pytest.approx(1 / 3), "eval_final_distance": pytest.approx(0.1)}
    assert Line.actions == [0.0] * 75
