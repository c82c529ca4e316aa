"""Rope push: the rope stays a rope, pushes move it (or not), cached pairs reproduce bit for bit,
hidden goal pushes are replayable, bad caches fail clearly, and LeRobot's env path gives the keys."""

import json
import os
from contextlib import closing, contextmanager

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.importorskip("robosuite")
pytest.importorskip("mujoco")

import gymnasium as gym  # noqa: E402

from lerobot_indicator.envs import ROPE_PUSH_ID  # noqa: E402
from lerobot_indicator.envs import rope_cache as rc  # noqa: E402
from lerobot_indicator.envs.rope_push import RopePushEnv  # noqa: E402

SMALL_CAMERA = {"width": 48, "height": 48}
NO_OP = np.zeros(4)


@pytest.fixture(scope="module")
def state_env():
    with closing(RopePushEnv(obs_type="state")) as env:
        yield env


@pytest.fixture(scope="module")
def cache_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("rope") / "cache.npz"
    return rc.generate_cache(path, n=2, seed=3, workers=0, chunk_size=1, progress=False)


def straight(env):
    env.sim.reset_straight()
    return env.sim.link_positions()


def push_points(env, start, end):
    """Push between table points (metres) through the public action mapping."""
    action = env.sim.points_to_action(np.asarray(start, float), np.asarray(end, float))
    return env.step(action.astype(np.float32))


@contextmanager
def envs_differing_in(field: str, values: tuple[str, ...], cache_file, obs_type: str):
    """One small-camera env per value of a rope_push config ``field``, built through the env config."""
    from lerobot.envs.factory import make_env_config

    envs = {}
    try:
        for value in values:
            cfg = make_env_config(
                "rope_push",
                obs_type=obs_type,
                camera=SMALL_CAMERA,
                cache_path=str(cache_file),
                **{field: value},
            )
            envs[value] = gym.make(ROPE_PUSH_ID, **cfg.gym_kwargs).unwrapped
        yield envs
    finally:
        for env in envs.values():
            env.close()


def joint_gaps(env) -> np.ndarray:
    """Distance between the end of link i and the start of link i+1 (0 for a connected chain)."""
    n, half = env.sim.config.geometry.n_links, env.sim.config.geometry.spacing / 2
    ids = [env.model.body(f"rope_b{i}").id for i in range(n)]
    centre, axis = env.data.xpos[ids], env.data.xmat[ids].reshape(-1, 3, 3)[:, :, 0]  # links lie along body x
    return np.linalg.norm((centre[:-1] + half * axis[:-1]) - (centre[1:] - half * axis[1:]), axis=1)


def test_spaces_and_registration():
    env = gym.make(ROPE_PUSH_ID, obs_type="rgbd", camera=SMALL_CAMERA, disable_env_checker=True)
    try:
        assert env.spec.max_episode_steps == 3
        assert env.action_space.shape == (4,)
        obs, info = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        assert obs["agent_pos"].shape == obs["goal_state"].shape == (45,)
        assert obs["rope_xy"].shape == obs["goal_rope_xy"].shape == (30,)
        assert obs["pixels"]["front"].shape == (48, 48, 3) and obs["front_depth"].dtype == np.uint16
        assert info["gt_achieved_goal"].shape == info["gt_desired_goal"].shape == (30,)
        assert info["is_success"] is False  # episodes never start solved
        assert env.render().shape == (48, 48, 3)
        # The rope is in the picture: rope pixels are much redder than the table.
        rgb = obs["pixels"]["front"].astype(int)
        assert ((rgb[..., 0] - rgb[..., 2]) > 100).sum() >= 10
        with pytest.raises(ValueError, match="4 numbers"):
            env.step(np.zeros(3))
    finally:
        env.close()


def test_rope_stays_a_rope_after_100_random_pushes(state_env):
    env, rng = state_env, np.random.default_rng(0)
    straight(env)
    top = env.sim.config.geometry.table_top_z
    moved = 0
    for i in range(100):
        # Half the authors' random pushes (always across the rope), half uniform actions (often misses).
        action = env.sim.random_push_action(rng) if i % 2 == 0 else rng.uniform(-1, 1, 4)
        moved += env.sim.push(action)
        links = env.sim.link_positions()
        assert np.isfinite(env.data.qpos).all()
        assert joint_gaps(env).max() < 1e-3, f"links came apart after push {i}"
        assert (links[:, 2] > top).all() and (links[:, 2] < top + 0.1).all(), (
            f"rope left the table at push {i}"
        )
        assert (np.abs(links[:, :2]) < 0.8).all()
    assert moved >= 25  # pushes that touched the rope (the rest were skipped as misses)


def test_push_across_rope_moves_it(state_env):
    links = straight(state_env)
    middle = links[7, :2]
    obs, *_ = push_points(state_env, middle + [0, 0.2], middle - [0, 0.2])
    after = obs["agent_pos"].reshape(15, 3)
    assert after[7, 1] < middle[1] - 0.1  # pushed along -y by more than 10 cm
    assert np.linalg.norm(after - links, axis=1).max() > 0.1


def test_push_missing_rope_does_not_move_it(state_env):
    links = straight(state_env)
    qpos = state_env.data.qpos.copy()
    push_points(state_env, [0.4, 0.3], [0.4, -0.3])  # beyond the rope's end: skipped
    assert np.array_equal(state_env.data.qpos, qpos)
    # Passing 4 cm beside the rope: close enough to be simulated (not skipped), too far to touch it.
    sim = state_env.sim
    assert sim.push(sim.points_to_action(links[0, :2] + [-0.05, 0.04], links[-1, :2] + [0.05, 0.04]))
    assert np.abs(state_env.sim.link_positions() - links).max() < 1e-3


def test_push_that_goes_unstable_is_undone(state_env, caplog):
    """MuJoCo resets every joint (the straight rope) when the simulation blows up; such a push is undone and
    reported, so no transition shows a rope that jumped to straight. The next push works as usual."""
    links = straight(state_env)
    push_points(
        state_env, links[7, :2] + [0, 0.2], links[7, :2] - [0, 0.2]
    )  # a bent rope: not the reset state
    sim, qpos = state_env.sim, state_env.data.qpos.copy()
    across = sim.points_to_action(links[3, :2] + [0, 0.2], links[3, :2] - [0, 0.2])

    def blow_up():
        state_env.data.qvel[0] = 1e12  # past MuJoCo's mjMAXVAL: its bad-qvel warning and auto-reset
        sim.on_push_step = None

    sim.on_push_step = blow_up
    with caplog.at_level("WARNING", logger="lerobot_indicator.envs.rope_sim"):
        assert sim.push(across) is False
    assert np.array_equal(state_env.data.qpos, qpos) and not np.array_equal(qpos, sim.straight_qpos)
    assert "went unstable" in caplog.text and "mjWARN_BADQVEL" in caplog.text
    caplog.clear()
    assert sim.push(across) is True and not np.array_equal(state_env.data.qpos, qpos)
    assert "went unstable" not in caplog.text


def test_replaying_hidden_goal_pushes_succeeds(state_env):
    successes = exact = 0
    for seed in range(5):
        state_env.reset(seed=seed)
        expected = [*state_env.goal_push_actions, NO_OP, NO_OP][:3]
        for action in expected:
            assert np.array_equal(state_env.scripted_action(), action.astype(np.float32))
            _, reward, *_, info = state_env.step(state_env.scripted_action())
        successes += info["is_success"]
        exact += info["gt_distance"] == 0.0  # float32 actions repeat the hidden pushes bit for bit
        assert (reward == 1.0) == info["is_success"]
    assert successes >= 4 and exact >= 4


def test_cache_reproduces_bit_identical_observations(cache_file):
    data = rc.load_cache(cache_file)
    assert data["start_qpos"].shape[0] == 2 and data["params"]["seed"] == 3
    envs = [RopePushEnv(obs_type="rgbd", camera=SMALL_CAMERA, cache_path=str(cache_file)) for _ in range(2)]
    try:
        a, _ = envs[0].reset(seed=0, options={"cache_index": 1})
        b, _ = envs[1].reset(seed=1, options={"cache_index": 1})
        for key in ("agent_pos", "goal_state", "front_depth", "goal_front_depth"):
            assert np.array_equal(a[key], b[key]), key
        for key in ("front", "goal_front"):
            assert np.array_equal(a["pixels"][key], b["pixels"][key]), key
        # Regenerating pair 1 from its seed gives the cached states bit for bit.
        pair = rc.generate_pair(envs[0].sim, rc.sample_rng(3, 1), envs[0].epsilon)
        assert np.array_equal(pair["start_qpos"], data["start_qpos"][1])
        assert np.array_equal(pair["goal_qpos"], data["goal_qpos"][1])
        # Replaying the hidden pushes from the cached start reproduces the goal image exactly.
        env = envs[1]
        env.reset(options={"cache_index": 1})
        for action in env.goal_push_actions:
            obs, *_ = env.step(action)
        assert np.array_equal(obs["pixels"]["front"], obs["pixels"]["goal_front"])
        assert np.array_equal(obs["front_depth"], obs["goal_front_depth"])
    finally:
        for env in envs:
            env.close()


def test_worker_processes_generate_the_same_pairs(cache_file, tmp_path):
    parallel = rc.generate_cache(tmp_path / "p.npz", n=2, seed=3, workers=2, chunk_size=1, progress=False)
    a, b = rc.load_cache(cache_file), rc.load_cache(parallel)
    for key in rc.ARRAY_KEYS:
        assert np.array_equal(a[key], b[key]), key


def test_generation_resumes_from_finished_chunks(tmp_path, monkeypatch):
    path = tmp_path / "c.npz"
    real = rc._generate_chunk
    calls = []

    def crash_on_third(job):
        calls.append(job)
        if len(calls) == 3:
            raise RuntimeError("simulated crash")
        return real(job)

    monkeypatch.setattr(rc, "_generate_chunk", crash_on_third)
    with pytest.raises(RuntimeError, match="simulated crash"):
        rc.generate_cache(path, n=3, seed=5, workers=0, chunk_size=1, progress=False)
    assert not path.exists() and len(list((tmp_path / "c.npz.parts").glob("chunk_*.npz"))) == 2
    calls.clear()
    monkeypatch.setattr(rc, "_generate_chunk", lambda job: calls.append(job) or real(job))
    rc.generate_cache(path, n=3, seed=5, workers=0, chunk_size=1, progress=False)
    assert calls == [(5, 2, 3)]  # only the missing chunk was generated
    assert rc.load_cache(path)["start_qpos"].shape[0] == 3 and not (tmp_path / "c.npz.parts").exists()


def test_bad_cache_fails_clearly(cache_file, tmp_path):
    with pytest.raises(FileNotFoundError, match="generate_rope_cache"):
        RopePushEnv(cache_path=str(tmp_path / "missing.npz"))
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"not a zip file at all")
    with pytest.raises(rc.RopeCacheError, match="corrupt"):
        RopePushEnv(cache_path=str(corrupt))
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(cache_file.read_bytes()[:200])
    with pytest.raises(rc.RopeCacheError, match="corrupt"):
        RopePushEnv(cache_path=str(truncated))
    # Same arrays, different generation parameters: refused, naming the field.
    with np.load(cache_file) as f:
        arrays = {k: f[k] for k in f.files}
    params = json.loads(str(arrays.pop("params_json")))
    params["push"]["push_speed"] = 1.0
    other = tmp_path / "other.npz"
    np.savez_compressed(other, params_json=np.array(json.dumps(params)), **arrays)
    with pytest.raises(rc.RopeCacheError, match="push.push_speed"):
        RopePushEnv(cache_path=str(other))
    with pytest.raises(rc.RopeCacheError, match="goal_pushes"):
        RopePushEnv(cache_path=str(cache_file), goal_pushes=1)


def test_lerobot_make_env_gives_documented_keys():
    import torch
    from lerobot.envs.factory import make_env, make_env_config
    from lerobot.envs.utils import close_envs, preprocess_observation

    cfg = make_env_config("rope_push", obs_type="rgbd", camera=SMALL_CAMERA)
    envs = make_env(cfg, n_envs=1)
    try:
        vec = next(iter(next(iter(envs.values())).values()))
        obs, _ = vec.reset(seed=[0])
        env_pre, _ = cfg.get_env_processors()
        batch = env_pre(preprocess_observation(obs))
        expected = {
            "observation.state": (1, 45),
            "observation.goal_state": (1, 45),
            "observation.rope_xy": (1, 30),
            "observation.goal_rope_xy": (1, 30),
            "observation.images.front": (1, 3, 48, 48),
            "observation.images.goal_front": (1, 3, 48, 48),
            "observation.images.front_depth": (1, 1, 48, 48),
            "observation.images.goal_front_depth": (1, 1, 48, 48),
        }
        for key, shape in expected.items():
            assert tuple(batch[key].shape) == shape and batch[key].dtype == torch.float32, key
        _, _, _, _, info = vec.step(np.zeros((1, 4), np.float32))
        assert "is_success" in info and "gt_distance" in info
    finally:
        close_envs(envs)


def test_link_colours_change_what_the_camera_sees_not_the_physics(cache_file):
    from lerobot.envs.factory import make_env_config

    from lerobot_indicator.envs.rope_scene import link_geom_name

    with pytest.raises(ValueError, match="link_colours: unknown 'rainbow'"):
        make_env_config("rope_push", link_colours="rainbow")
    with envs_differing_in("link_colours", ("single", "tab20"), cache_file, obs_type="rgb") as envs:
        obs = {}
        for scheme, env in envs.items():
            env.reset(seed=0, options={"cache_index": 0})
            obs[scheme], *_ = env.step(np.array([-0.5, 0.0, 0.5, 0.1], np.float32))
            rgba = {tuple(env.model.geom_rgba[env.model.geom(link_geom_name(i)).id]) for i in range(15)}
            assert len(rgba) == (15 if scheme == "tab20" else 1), scheme
        assert np.array_equal(obs["single"]["agent_pos"], obs["tab20"]["agent_pos"])
        differs = (obs["single"]["pixels"]["front"] != obs["tab20"]["pixels"]["front"]).any(axis=-1)
        assert 0 < differs.mean() < 0.1  # the rope's pixels only


def test_pusher_rest_shows_where_the_last_push_ended_and_leaves_the_physics(cache_file):
    from lerobot.envs.factory import make_env_config

    with pytest.raises(ValueError, match="pusher_rest: unknown 'hovering'"):
        make_env_config("rope_push", pusher_rest="hovering")
    with envs_differing_in("pusher_rest", ("out_of_view", "push_end"), cache_file, obs_type="rgbd") as envs:
        obs = {}
        for rest, env in envs.items():
            first, _ = env.reset(seed=0, options={"cache_index": 1})
            steps = [env.step(action)[0] for action in env.goal_push_actions]
            obs[rest] = (first, steps)
        env = envs["push_end"]
        lift_z = env.sim.config.lift_z
        end = env.sim.action_to_points(env.goal_push_actions[-1])[1]
        np.testing.assert_array_equal(env.data.mocap_pos[env.sim.mocap_id], [*end, lift_z])
        for a, b in zip(obs["out_of_view"][1], obs["push_end"][1], strict=True):
            assert np.array_equal(a["agent_pos"], b["agent_pos"])  # the resting pusher never touches the rope
            differs = (a["pixels"]["front"] != b["pixels"]["front"]).any(axis=-1)
            assert 0 < differs.mean() < 0.1  # the pusher's pixels only
        for rest, (_, steps) in obs.items():
            # Replaying the hidden pushes reproduces the goal image, pusher included, bit for bit.
            last = steps[-1]
            assert np.array_equal(last["pixels"]["front"], last["pixels"]["goal_front"]), rest
            assert np.array_equal(last["front_depth"], last["goal_front_depth"]), rest
        # The start image shows the pusher after the start's random push; a skipped push leaves it there.
        first = obs["push_end"][0]
        assert (first["pixels"]["front"] != obs["out_of_view"][0]["pixels"]["front"]).any()
        skipped, *_ = env.step(NO_OP)
        assert np.array_equal(skipped["pixels"]["front"], obs["push_end"][1][-1]["pixels"]["front"])


def test_pusher_visible_task_preset_builds_the_env_with_the_pusher_in_view():
    import draccus

    from benchmarks.experiments.presets import TASKS
    from lerobot_indicator.training.config import OnlineTrainConfig

    args = [
        "--policy.type=indicator_ddpg",
        "--policy.push_to_hub=false",
        *TASKS["rope_rgbd_pusher_visible"].env_args,
    ]
    cfg = draccus.parse(OnlineTrainConfig, args=args)
    assert cfg.env.gym_kwargs["pusher_rest"] == "push_end" and cfg.env.obs_type == "rgbd"
    assert cfg.env.gym_kwargs["link_colours"] == "single"  # one change from the rope_rgbd task
