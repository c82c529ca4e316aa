"""Camera framing options: supersampled rendering with area averaging, and the framing probe's geometry."""

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from benchmarks.probes import framing
from lerobot_indicator.envs.hardware import GoalCameraConfig
from lerobot_indicator.envs.rendering import area_downsample, metres_to_uint16_mm
from lerobot_indicator.envs.rope_push import TABLE_TOP_Z, RopePushEnv


def test_area_downsample_is_torch_area_interpolation():
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (12, 8, 3), dtype=np.uint8)
    depth = rng.uniform(0.5, 1.5, (12, 8)).astype(np.float32)
    torch_rgb = F.interpolate(torch.from_numpy(rgb).permute(2, 0, 1)[None].double(), size=(3, 2), mode="area")
    expected_rgb = np.rint(torch_rgb[0].permute(1, 2, 0).numpy()).astype(np.uint8)
    np.testing.assert_array_equal(area_downsample(rgb, 4), expected_rgb)
    torch_depth = F.interpolate(torch.from_numpy(depth)[None, None], size=(3, 2), mode="area")[0, 0].numpy()
    np.testing.assert_allclose(area_downsample(depth, 4), torch_depth, rtol=1e-6)
    assert area_downsample(rgb, 1) is rgb


def test_supersampled_rope_frames_are_the_area_average_of_a_larger_render():
    small = RopePushEnv(obs_type="rgbd", camera={"width": 16, "height": 16, "supersample": 2})
    large = RopePushEnv(obs_type="rgbd", camera={"width": 32, "height": 32})
    try:
        obs, _ = small.reset(seed=3)
        large.reset(seed=3)
        assert obs["pixels"]["front"].shape == (16, 16, 3) and obs["front_depth"].shape == (16, 16, 1)
        assert obs["front_depth"].dtype == np.uint16
        rgb, depth_m = large.renderer.render(large.data, "front", depth=True)
        np.testing.assert_array_equal(obs["pixels"]["front"], area_downsample(rgb, 2))
        cam = small.camera_cfg
        mm = metres_to_uint16_mm(area_downsample(depth_m, 2), cam.depth_min_m, cam.depth_max_m)
        np.testing.assert_array_equal(obs["front_depth"][..., 0], mm)
        # What the observation holds is what camera_observation() and render() give for the same state.
        np.testing.assert_array_equal(small.camera_observation()["front"], obs["pixels"]["front"])
        np.testing.assert_array_equal(small.render(), obs["pixels"]["front"])
        # The goal image is rendered the same way: replaying the hidden pushes, which reproduces the goal state
        # bit for bit for most seeds, reproduces the goal image bit for bit.
        exact = 0
        for seed in (3, 0):
            obs, _ = small.reset(seed=seed)
            for action in small.goal_push_actions:
                obs, _, _, _, info = small.step(action.astype(np.float32))
            if info["gt_distance"] == 0.0:
                exact += 1
                np.testing.assert_array_equal(obs["pixels"]["front"], obs["pixels"]["goal_front"])
                np.testing.assert_array_equal(obs["front_depth"], obs["goal_front_depth"])
        assert exact >= 1
    finally:
        small.close()
        large.close()


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"supersample": 0}, "camera.supersample must be >= 1, got 0"),
        (
            {"supersample": 2, "type": "intelrealsense", "serial_number_or_name": "d435"},
            "camera.supersample is a simulation render option",
        ),
    ],
)
def test_bad_supersample_names_the_field(overrides, message):
    with pytest.raises(ValueError, match=message):
        GoalCameraConfig(**overrides)


def test_tight_top_down_camera_covers_the_links_with_the_margin():
    links = np.array([[[-0.2, -0.1], [0.2, 0.3]]])  # x span 0.4, y span 0.4
    camera = framing.top_down_camera(links, margin_m=0.02, fovy_deg=58.0)
    assert camera["lookat"] == pytest.approx([0.0, 0.1, TABLE_TOP_Z])
    half = 0.2 + 0.01 + 0.02  # half span + rope radius + margin
    assert camera["pos"][2] - TABLE_TOP_Z == pytest.approx(half / math.tan(math.radians(29.0)))
    centre, got = framing.view_half_width(camera)
    assert got == pytest.approx(half) and centre.tolist() == pytest.approx([0.0, 0.1])
    _, default_half = framing.view_half_width({})
    assert default_half == pytest.approx(0.9 * math.tan(math.radians(29.0)))  # 1.7 m camera, table at 0.8 m


def test_image_statistics_on_hand_made_frames():
    # 3 frames of one episode, 4x4 px: a 2-px rope in frame 0, moved by one pixel in frame 1, frame 2 unchanged.
    rgb = np.full((3, 3, 4, 4), 240, dtype=np.uint8)
    rgb[0, 1, 0, :2] = 60
    rgb[1, 1, 0, 1:3] = 60
    rgb[2] = rgb[1]
    frames = {framing.RGB: rgb, framing.DEPTH: np.full((3, 1, 4, 4), 900.0, dtype=np.float32)}
    link_xy = np.zeros((3, 15, 2))
    link_xy[1:] += 0.01  # push 1 moved the rope, push 2 did not
    link_xy[0, 0, 0] = 0.6  # frame 0 has a link beyond the default view (half-width 0.4989 m)
    states = framing.RopeStates(np.zeros((3, 1)), link_xy, np.zeros(3, dtype=int))
    stats = framing.image_statistics(frames, states, {})
    assert stats["rope_pixels_per_frame_mean"] == 2.0
    assert stats["frac_frames_rope_partly_outside_view"] == pytest.approx(1 / 3)
    assert stats["pushes"] == 2 and stats["pushes_that_moved_the_rope"] == 1
    assert stats["frac_moving_pushes_that_change_the_image"] == 1.0
    assert stats["changed_rgb_pixels_per_moving_push_mean"] == 2.0  # pixel 0 and pixel 2 of row 0


def test_framing_statistics_and_probe_run_on_collected_states():
    states = framing.collect_states(episodes=2, pushes=1, seed=0)
    assert states.states.shape[0] == 4 and states.link_xy.shape == (4, 15, 2)
    assert states.episode.tolist() == [0, 0, 1, 1]
    framings = [framing.Framing("default"), framing.Framing("ss2", {"supersample": 2})]
    results, rendered = framing.framing_statistics(framings, states, size=24)
    assert rendered["ss2"][framing.RGB].shape == (4, 3, 24, 24) and rendered["ss2"][framing.DEPTH].shape == (
        4,
        1,
        24,
        24,
    )
    assert results["ss2"]["pushes"] == 2 and results["ss2"]["camera"]["supersample"] == 2
    probe = {"updates": 2, "batch_size": 2, "every": 1, "seed": 0}
    framing.probe_framings(results, rendered, states, probe)
    for name in ("default", "ss2"):
        p = results[name]["probe"]
        assert (p["train_frames"], p["test_frames"]) == (
            2,
            2,
        )  # one episode each: test frames are unseen episodes
        assert [c["updates"] for c in p["curve"]] == [1, 2] and math.isfinite(p["final_test_error_m"])


def test_supersampled_rope_task_preset_keeps_the_observation_size():
    import draccus

    from benchmarks.experiments.presets import TASKS
    from lerobot_indicator.training.config import OnlineTrainConfig

    args = [
        "--policy.type=indicator_ddpg",
        "--policy.push_to_hub=false",
        *TASKS["rope_rgbd_supersample4"].env_args,
    ]
    cfg = draccus.parse(OnlineTrainConfig, args=args)
    assert cfg.env.camera.supersample == 4
    assert (cfg.env.camera.height, cfg.env.camera.width) == (100, 100)
    assert cfg.env.gym_kwargs["camera"].supersample == 4  # what the env is built with
