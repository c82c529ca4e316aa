"""The rope-push ceiling planner: its goals are the trainer's evaluation goals, its reported distances are what
the env gives when the plan is replayed, and CEM never ends worse than its own random samples."""

import json
import os
from contextlib import closing
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.importorskip("robosuite")
pytest.importorskip("mujoco")

from benchmarks.experiments import rope_ceiling as rc  # noqa: E402
from lerobot_indicator.envs.rope_cache import generate_cache  # noqa: E402
from lerobot_indicator.envs.rope_push import RopePushEnv  # noqa: E402
from lerobot_indicator.keys import GT_DISTANCE  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TINY = rc.CemConfig(population=4, iterations=2, elites=2)


@pytest.fixture(scope="module")
def cache_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("rope") / "cache.npz"
    return generate_cache(path, n=3, seed=0, workers=0, chunk_size=3, progress=False)


def test_rebuilt_cache_goals_equal_the_env_resets_from_the_file(cache_file):
    with closing(rc.env_for("cache:3")) as env:
        rebuilt = rc.eval_goals(env, "cache:3", 2)
    with closing(rc.env_for(f"file:{cache_file}")) as env:
        from_file = rc.eval_goals(env, f"file:{cache_file}", 2)
    for a, b in zip(rebuilt, from_file, strict=True):
        assert a.seed == b.seed and a.cache_index == b.cache_index
        np.testing.assert_array_equal(a.start_qpos, b.start_qpos)
        np.testing.assert_array_equal(a.goal_xy, b.goal_xy)
        assert a.start_distance == b.start_distance


def test_plans_replayed_in_a_fresh_env_give_the_reported_distance(cache_file, tmp_path):
    goal_set = f"file:{cache_file}"
    record = rc.run(rc.CeilingConfig(goal_sets=[goal_set], episodes=2, cem=TINY, out=tmp_path))
    per_goal = record["goal_sets"][goal_set]["per_goal"]
    with closing(RopePushEnv(obs_type="state", cache_path=str(cache_file))) as env:
        for g in per_goal:
            _, info = env.reset(seed=g["seed"])
            # info holds distances in float32.
            assert info[GT_DISTANCE] == pytest.approx(g["start_distance"], rel=1e-6)
            for action in np.asarray(g["plan"]).reshape(-1, 4):
                _, _, _, _, info = env.step(action.astype(np.float32))
            assert info[GT_DISTANCE] == pytest.approx(g["distance"], rel=1e-6)
            # Elites carry over: the best never worsens and never exceeds the iteration-0 random samples'.
            assert np.all(np.diff(g["history"]) <= 0) and g["distance"] == g["history"][-1]
            assert g["distance"] <= min(g["uniform_distances"] + g["random_push_distances"])
            # The goal is its hidden pushes away from the start, and replaying them is exact.
            assert g["goal_push_replay_distance"] == pytest.approx(0.0, abs=1e-12)
    summary = record["goal_sets"][goal_set]["summary"]
    for name in ("ceiling", "not_moving", "random_uniform", "random_push"):
        assert summary[name]["success_0.05"] <= summary[name]["success_0.1"]
    assert summary["convergence"]["rollouts_after_iteration"] == [4, 8]

    saved = json.loads((tmp_path / "ceiling.json").read_text())
    assert (tmp_path / "ceiling.png").stat().st_size > 0
    assert saved["goal_sets"][goal_set]["per_goal"] == per_goal
    lines = rc.ceiling_lines(tmp_path / "ceiling.json")
    assert lines["ceiling"] == pytest.approx(np.mean([g["distance"] for g in per_goal]))
    assert lines["not_moving"] == pytest.approx(np.mean([g["start_distance"] for g in per_goal]))
    assert lines["random"] == pytest.approx(np.mean([g["uniform_distances"] for g in per_goal]))
    assert rc.ceiling_lines(tmp_path / "ceiling.json", episodes=1)["ceiling"] == per_goal[0]["distance"]
    success = rc.ceiling_lines(tmp_path / "ceiling.json", metric="success_0.1")
    assert success["ceiling"] == np.mean([g["distance"] <= 0.1 for g in per_goal])


def test_rebuilt_4000_pair_cache_gives_the_state_comparisons_start_distances():
    record = json.loads((ROOT / "docs/results/experiments_rope/start_distance_rope_state.json").read_text())
    assert "rope_push_4k.npz" in record["command"]
    with closing(rc.env_for("cache:4000")) as env:
        goals = rc.eval_goals(env, "cache:4000", 2)
    # That record holds info's float32 distances.
    np.testing.assert_allclose([g.start_distance for g in goals], record["start_distances"][:2], rtol=1e-6)
