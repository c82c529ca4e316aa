"""What the rope-push camera shows under different framings, measured on one fixed set of simulator states.

The rope's states come from random pushes (the physics does not depend on the camera), and each framing
renders the same states: a camera pose / field of view and a ``supersample`` factor (render larger, area-average
down to the same 100 px). Per framing:

- rope pixels per frame: pixels whose green channel is at least ``ROPE_CONTRAST`` below the bare table's (the
  rope is orange, the table near white), and the frames where a rope link lies outside the view;
- pushes that change the image: among pushes that moved the rope, the fraction whose next RGB-D frame differs
  from the last one at all (what the indicator and the critic can see), and the pixels that change;
- a supervised probe: the policy's default image encoder plus a linear head trained to regress the 30 link-xy
  numbers from one RGB-D frame, test error (L2 over the 30 numbers, the success metric's distance) after a
  fixed number of updates, beside the error of predicting the training mean.

Ground truth is used here to *measure* what the pixels hold, never to train a policy.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from benchmarks.speed.updates import make_policy, rgbd_features
from lerobot_indicator.envs.rope_push import TABLE_TOP_Z, RopePushEnv, rope_camera_defaults
from lerobot_indicator.envs.rope_scene import RopeGeometry
from lerobot_indicator.keys import GT_ACHIEVED_GOAL

ROPE_CONTRAST = 30  # green-channel drop (0-255) that marks a pixel as showing rope
RGB, DEPTH = "observation.images.front", "observation.images.front_depth"


@dataclass
class Framing:
    name: str
    camera: dict = field(default_factory=dict)  # GoalCameraConfig overrides on rope_camera_defaults()


@dataclass
class RopeStates:
    states: np.ndarray  # (N, state_size) full simulator states
    link_xy: np.ndarray  # (N, 15, 2)
    episode: np.ndarray  # (N,) episode index; consecutive frames of one episode are one push apart


def collect_states(episodes: int, pushes: int, seed: int) -> RopeStates:
    """Random start/goal resets, then ``pushes`` uniform random pushes each; one state per frame."""
    env = RopePushEnv(obs_type="state")
    rng = np.random.default_rng(seed)
    states, xy, episode = [], [], []
    try:
        for e in range(episodes):
            _, info = env.reset(seed=seed * 100_000 + e)
            for k in range(pushes + 1):
                if k:
                    _, _, _, _, info = env.step(rng.uniform(-1, 1, 4).astype(np.float32))
                states.append(env.save_state())
                xy.append(np.asarray(info[GT_ACHIEVED_GOAL]).reshape(-1, 2))
                episode.append(e)
    finally:
        env.close()
    return RopeStates(np.stack(states), np.stack(xy), np.asarray(episode))


def load_or_collect(path: Path | None, episodes: int, pushes: int, seed: int) -> RopeStates:
    """The states of ``collect_states``, kept in ``path`` (npz) so that a rerun skips the physics."""
    if path is not None and path.exists():
        with np.load(path) as z:
            if (
                int(z["seed"]) == seed
                and len(np.unique(z["episode"])) == episodes
                and int(z["pushes"]) == pushes
            ):
                return RopeStates(z["states"], z["link_xy"], z["episode"])
    states = collect_states(episodes, pushes, seed)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp.npz")
        np.savez(
            tmp,
            states=states.states,
            link_xy=states.link_xy,
            episode=states.episode,
            seed=seed,
            pushes=pushes,
        )
        tmp.replace(path)
    return states


def top_down_camera(link_xy: np.ndarray, margin_m: float, fovy_deg: float = 58.0) -> dict:
    """A top-down camera whose square view covers every link in ``link_xy`` plus the rope radius and
    ``margin_m`` (same optics, lower camera)."""
    lo, hi = link_xy.reshape(-1, 2).min(0), link_xy.reshape(-1, 2).max(0)
    centre = (lo + hi) / 2
    half = float((hi - lo).max() / 2 + RopeGeometry().radius + margin_m)
    height = half / math.tan(math.radians(fovy_deg) / 2)
    return {
        "pos": [float(centre[0]), float(centre[1]), TABLE_TOP_Z + height],
        "lookat": [float(centre[0]), float(centre[1]), TABLE_TOP_Z],
        "fovy_deg": fovy_deg,
    }


def view_half_width(camera: dict) -> tuple[np.ndarray, float]:
    """Centre (x, y) and half-width of a top-down camera's square view on the table."""
    cam = {**rope_camera_defaults(), "fovy_deg": 58.0, **camera}
    height = cam["pos"][2] - TABLE_TOP_Z
    return np.asarray(cam["lookat"][:2]), height * math.tan(math.radians(cam["fovy_deg"]) / 2)


def render_states(framing: Framing, states: RopeStates, size: int) -> dict[str, np.ndarray]:
    """RGB (N, 3, H, W) uint8 and depth (N, 1, H, W) float32 mm of every state under ``framing``."""
    env = RopePushEnv(obs_type="rgbd", camera={**framing.camera, "width": size, "height": size})
    rgb, depth = [], []
    try:
        for state in states.states:
            env.restore_state(state)
            obs = env.camera_observation()
            rgb.append(obs["front"])
            depth.append(obs["front_depth"])
    finally:
        env.close()
    return {
        RGB: np.stack(rgb).transpose(0, 3, 1, 2).copy(),
        DEPTH: np.stack(depth).transpose(0, 3, 1, 2).astype(np.float32),
    }


def image_statistics(frames: dict[str, np.ndarray], states: RopeStates, camera: dict) -> dict:
    green = frames[RGB][:, 1].astype(np.int16)
    table_green = np.median(green)
    rope_px = (green <= table_green - ROPE_CONTRAST).sum(axis=(1, 2))
    centre, half = view_half_width(camera)
    outside = (np.abs(states.link_xy - centre) > half).any(axis=(1, 2))
    same_episode = states.episode[1:] == states.episode[:-1]
    moved = same_episode & (np.abs(np.diff(states.link_xy, axis=0)).max(axis=(1, 2)) > 1e-6)
    changed_px = (frames[RGB][1:] != frames[RGB][:-1]).any(axis=1).sum(axis=(1, 2))
    image_changed = np.zeros(len(moved), dtype=bool)
    for k in (RGB, DEPTH):
        image_changed |= (frames[k][1:] != frames[k][:-1]).reshape(len(moved), -1).any(axis=1)
    return {
        "view_half_width_m": half,
        "rope_pixels_per_frame_mean": float(rope_px.mean()),
        "rope_pixels_per_frame_min": int(rope_px.min()),
        "frac_frames_rope_partly_outside_view": float(outside.mean()),
        "pushes": int(same_episode.sum()),
        "pushes_that_moved_the_rope": int(moved.sum()),
        "frac_moving_pushes_that_change_the_image": float(image_changed[moved].mean())
        if moved.any()
        else 0.0,
        "frac_still_pushes_that_change_the_image": float(image_changed[same_episode & ~moved].mean())
        if (same_episode & ~moved).any()
        else 0.0,
        "changed_rgb_pixels_per_moving_push_mean": float(changed_px[moved].mean()) if moved.any() else 0.0,
    }


def link_probe(
    frames: dict[str, np.ndarray], states: RopeStates, updates: int, batch_size: int, every: int, seed: int
) -> dict:
    """Test error (m, L2 over the 30 link-xy numbers) of the default image encoder + a linear head trained to
    regress them; episodes split 80/20 so that test frames come from unseen episodes."""
    size = frames[RGB].shape[-1]
    target = torch.from_numpy(states.link_xy.reshape(len(states.link_xy), -1)).float()
    episodes = np.unique(states.episode)
    test_episodes = np.random.default_rng(seed).permutation(episodes)[: max(1, len(episodes) // 5)]
    is_test = np.isin(states.episode, test_episodes)
    train, test = np.flatnonzero(~is_test), np.flatnonzero(is_test)
    torch.manual_seed(seed)
    encoder = make_policy(rgbd_features(size), conv_precision="float32", hidden_dims=[8, 8, 8]).critic.encoder
    stats = {}
    for key, x in frames.items():
        x = torch.from_numpy(x[train]).float() / (255.0 if x.dtype == np.uint8 else 1.0)
        stats[key] = {
            "mean": x.mean(dim=(0, 2, 3)).view(-1, 1, 1),
            "std": x.std(dim=(0, 2, 3)).view(-1, 1, 1),
        }
    encoder.set_stats(stats)
    mean, std = target[train].mean(0), target[train].std(0).clamp_min(1e-3)
    head = torch.nn.Linear(encoder.out_dim, target.shape[1])
    optimizer = torch.optim.Adam([*encoder.parameters(), *head.parameters()], lr=1e-3)
    tensors = {k: torch.from_numpy(v) for k, v in frames.items()}

    def predict(rows: np.ndarray) -> torch.Tensor:
        return head(encoder({k: v[rows] for k, v in tensors.items()})) * std + mean

    def test_error() -> float:
        with torch.no_grad():
            return float(torch.linalg.vector_norm(predict(test) - target[test], dim=1).mean())

    gen = np.random.default_rng(seed)
    curve, start = [], time.perf_counter()
    for step in range(1, updates + 1):
        rows = gen.choice(train, batch_size)
        loss = (((predict(rows) - target[rows]) / std) ** 2).mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        if step % every == 0 or step == updates:
            curve.append({"updates": step, "test_error_m": test_error()})
    baseline = float(torch.linalg.vector_norm(mean - target[test], dim=1).mean())
    return {
        "train_frames": len(train),
        "test_frames": len(test),
        "predict_train_mean_error_m": baseline,
        "curve": curve,
        "final_test_error_m": curve[-1]["test_error_m"],
        "wall_s": time.perf_counter() - start,
    }


def framing_statistics(
    framings: list[Framing], states: RopeStates, size: int, on_update: Callable[[dict], None] | None = None
) -> tuple[dict, dict[str, dict[str, np.ndarray]]]:
    """Image statistics of every framing on the same states, and the rendered frames (for ``probe_framings``).
    ``on_update`` gets the results so far after each framing (a slow machine keeps what it measured)."""
    results, rendered = {}, {}
    for framing in framings:
        t0 = time.perf_counter()
        frames = render_states(framing, states, size)
        results[framing.name] = {
            "camera": {**rope_camera_defaults(), **framing.camera, "width": size, "height": size},
            "render_s_per_frame": (time.perf_counter() - t0) / len(states.states),
            **image_statistics(frames, states, framing.camera),
        }
        rendered[framing.name] = frames
        if on_update is not None:
            on_update(results)
    return results, rendered


def probe_framings(
    results: dict,
    rendered: dict[str, dict[str, np.ndarray]],
    states: RopeStates,
    probe: dict,
    on_update: Callable[[dict], None] | None = None,
) -> dict:
    """Adds ``link_probe(frames, states, **probe)`` of every framing to ``results`` (same seed and split)."""
    for name, frames in rendered.items():
        results[name]["probe"] = link_probe(frames, states, **probe)
        if on_update is not None:
            on_update(results)
    return results
