"""Episode replay buffer for the online trainer (paper Algorithm 1).

Whole episodes are stored, because relabeling needs future observations *of the same episode*.

Observations are stored under the policy's batch keys (``observation.images.front``...), i.e. after
LeRobot's ``preprocess_observation`` and the env processors, exactly as eval and datasets deliver
them, so there is one conversion path and a dataset can seed the buffer. To keep a 5e3-transition
visual buffer small they are packed losslessly: RGB in [0, 1] that is k/255 goes back to uint8,
integer-valued depth to uint16 (checked on every episode; a key that stops packing exactly is
widened to float32). Goal observations are constant within an episode and stored once per episode.
Resuming a run does not save this buffer: the online trainer rebuilds it from its per-cycle episode
chunks (``online.py``).

Input-normalisation statistics come from per-episode moment sums kept per slot, so refreshing them every
cycle costs nothing even for a full image buffer, and they depend only on what the buffer holds (a
resumed run gets the same ones bit for bit).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from lerobot_indicator.keys import GT_ACHIEVED_GOAL, GT_DESIRED_GOAL, goal_key, is_goal_key

Arrays = dict[str, np.ndarray]
_PACKINGS = ((np.uint8, 255.0), (np.uint16, 1.0))


def unpack(stored: np.ndarray, scale: float) -> np.ndarray:
    out = stored.astype(np.float32)
    return out if scale == 1.0 else out / np.float32(scale)


def pack_exactly(value: np.ndarray, dtype: np.dtype, scale: float) -> np.ndarray | None:
    """``value`` as ``dtype`` such that ``unpack`` gives it back bit for bit, or None."""
    value = np.asarray(value, dtype=np.float32)
    info = np.iinfo(dtype)
    scaled = np.rint(value * np.float32(scale))
    if scaled.size and not (
        np.isfinite(scaled).all() and info.min <= scaled.min() and scaled.max() <= info.max
    ):
        return None
    packed = scaled.astype(dtype)
    # Bit patterns, not values: -0.0 packs to 0 and would come back as +0.0 (they compare equal as floats).
    return packed if np.array_equal(unpack(packed, scale).view(np.uint32), value.view(np.uint32)) else None


def pack(value: np.ndarray) -> tuple[np.ndarray, float]:
    """``(stored, scale)`` in the smallest packing that ``unpack`` reverses bit for bit, else float32."""
    for dtype, scale in _PACKINGS:
        packed = pack_exactly(value, np.dtype(dtype), scale)
        if packed is not None:
            return packed, scale
    return np.asarray(value, dtype=np.float32), 1.0


class _PackedArray:
    """A ``(rows, ...)`` float32 array stored in the smallest dtype that holds it exactly."""

    def __init__(self, shape: tuple[int, ...], first: np.ndarray):
        self.dtype, self.scale = np.dtype(np.float32), 1.0
        for dtype, scale in _PACKINGS:
            if pack_exactly(first, np.dtype(dtype), scale) is not None:
                self.dtype, self.scale = np.dtype(dtype), scale
                break
        self.data = np.zeros(shape, dtype=self.dtype)

    def __setitem__(self, index, value: np.ndarray) -> None:
        if self.dtype.kind != "f":
            packed = pack_exactly(value, self.dtype, self.scale)
            if packed is not None:
                self.data[index] = packed
                return
            self.data, self.dtype, self.scale = self[:], np.dtype(np.float32), 1.0  # widen
        self.data[index] = value

    def __getitem__(self, index) -> np.ndarray:
        return unpack(self.data[index], self.scale)


class EpisodeReplayBuffer:
    """FIFO buffer of fixed-horizon episodes.

    An episode is ``T`` actions and ``T + 1`` observations ``o_0..o_T``; transition ``t`` is
    ``(o_t, a_t, o_{t+1})``. Ground truth (optional; evaluation, oracle and reward-accuracy stats
    only) is ``gt_achieved_goal`` per observation and ``gt_desired_goal`` per episode.
    """

    def __init__(self, capacity_transitions: int, horizon: int):
        if horizon < 1:
            raise ValueError(f"horizon must be >= 1, got {horizon}")
        if capacity_transitions < horizon:
            raise ValueError(
                f"capacity ({capacity_transitions} transitions) must hold at least one episode of {horizon}"
            )
        self.horizon = horizon
        self.capacity = capacity_transitions // horizon  # in episodes
        self.obs: dict[str, _PackedArray] = {}  # (capacity, T + 1, ...) per non-goal key
        self.goals: dict[str, _PackedArray] = {}  # (capacity, ...) per goal key
        self.actions: np.ndarray | None = None  # (capacity, T, action_dim)
        self.gt_achieved: np.ndarray | None = None  # (capacity, T + 1, goal_dim)
        self.gt_desired: np.ndarray | None = None  # (capacity, goal_dim)
        # Per slot and observation key: float64 frame count, sum and sum of squares over the episode's T + 1
        # frames and its goal, per dimension (vectors) or per channel (images, CHW). See observation_stats().
        self.moments: dict[str, np.ndarray] = {}  # (capacity, 3, dim or C)
        self.num_episodes = 0
        self.next_slot = 0
        self.total_episodes_added = 0

    def __len__(self) -> int:
        """Number of stored transitions."""
        return self.num_episodes * self.horizon

    @property
    def keys(self) -> list[str]:
        return sorted([*self.obs, *self.goals])

    def _allocate(self, observations: Arrays, actions: np.ndarray, gt: Mapping | None) -> None:
        cap, T = self.capacity, self.horizon
        for key, value in observations.items():
            if is_goal_key(key):
                self.goals[key] = _PackedArray((cap, *value.shape[1:]), value[:1])
            else:
                self.obs[key] = _PackedArray((cap, T + 1, *value.shape[1:]), value)
                self.moments[key] = np.zeros((cap, 3, value.shape[1]), dtype=np.float64)
        self.actions = np.zeros((cap, T, actions.shape[-1]), dtype=np.float32)
        if gt is not None:
            self.gt_achieved = np.zeros((cap, T + 1, gt[GT_ACHIEVED_GOAL].shape[-1]), dtype=np.float32)
            self.gt_desired = np.zeros((cap, gt[GT_DESIRED_GOAL].shape[-1]), dtype=np.float32)

    def add_episode(
        self, observations: Arrays, actions: np.ndarray, ground_truth: Mapping | None = None
    ) -> None:
        """Store one episode.

        Args:
            observations: policy key -> ``(T + 1, ...)`` float array. Goal keys only need a leading
                step axis of any length (``(1, ...)`` is fine): a goal is constant within an episode.
            actions: ``(T, action_dim)``.
            ground_truth: optional ``gt_achieved_goal`` ``(T + 1, g)`` and ``gt_desired_goal`` ``(g,)``.
        """
        T = self.horizon
        if actions.ndim != 2 or actions.shape[0] != T:
            raise ValueError(
                f"episode actions have shape {actions.shape}, expected (T, action_dim) with T = {T}"
            )
        achieved = None if ground_truth is None else ground_truth.get(GT_ACHIEVED_GOAL)
        if achieved is not None and np.ndim(achieved) != 2:
            raise ValueError(f"{GT_ACHIEVED_GOAL} has shape {np.shape(achieved)}, expected (T + 1, goal_dim)")
        for key, value in observations.items():
            if not is_goal_key(key) and value.shape[0] != T + 1:
                raise ValueError(f"observation {key!r} has {value.shape[0]} steps, expected T + 1 = {T + 1}")
        if self.actions is None:
            self._allocate(observations, actions, ground_truth)
        if sorted(observations) != self.keys:
            raise ValueError(f"episode keys {sorted(observations)} differ from the buffer's {self.keys}")
        if (self.gt_achieved is not None) != (ground_truth is not None):
            raise ValueError("either every episode in a buffer carries ground truth or none does")
        slot = self.next_slot
        for key, value in observations.items():
            if is_goal_key(key):
                self.goals[key][slot] = value[0]
            else:
                self.obs[key][slot] = value
                goal = observations.get(goal_key(key))
                frames = np.asarray(value if goal is None else np.concatenate([value, goal[:1]]), np.float64)
                axes = (0, *range(2, frames.ndim))  # all but the dimension / channel axis
                count = frames.size / frames.shape[1]
                moments = self.moments[key][slot]
                moments[0], moments[1], moments[2] = (
                    count,
                    frames.sum(axis=axes),
                    np.square(frames).sum(axis=axes),
                )
        self.actions[slot] = actions
        if ground_truth is not None:
            self.gt_achieved[slot] = ground_truth[GT_ACHIEVED_GOAL]
            self.gt_desired[slot] = ground_truth[GT_DESIRED_GOAL]
        self.next_slot = (slot + 1) % self.capacity
        self.num_episodes = min(self.num_episodes + 1, self.capacity)
        self.total_episodes_added += 1

    def start_at(self, total_episodes: int) -> None:
        """Continue as if ``total_episodes`` had been added (the FIFO evicted them), so the next added episode
        lands in the slot it had in the run that added them: how a resumed run rebuilds an evicted buffer."""
        self.total_episodes_added = total_episodes
        self.next_slot = total_episodes % self.capacity
        self.num_episodes = min(total_episodes, self.capacity)

    def sample(
        self, batch_size: int, rng: np.random.Generator, packed: bool = False, n_step: int = 1
    ) -> dict:
        """Sample transitions uniformly, each with one future observation of its own episode.

        The future index is uniform in ``{t+2, ..., T}`` (paper Algorithm 1). For ``t = T - 1`` that
        set is empty: ``has_future`` is False and ``future_obs`` holds ``o_T`` as a placeholder.
        Returns float32 dicts ``obs`` (goal keys included: the recorded goal), ``next_obs`` and
        ``future_obs``, plus ``action``, ``has_future`` and, when stored, ground truth
        ``gt_next_achieved``, ``gt_future_achieved`` and ``gt_desired``. ``packed``: observations stay in
        their stored dtype (uint8 = k/255, uint16 = its value; 4x / 2x smaller than float32), so they move to
        the device as they are and the networks convert them there (``networks_indicator_ddpg.as_float``).
        ``n_step`` > 1 adds ``path_obs`` o_{t+2..t+n} (B, n-1, ...; steps past T hold o_T), ``path_valid``
        (t+i <= T) and, with ground truth, ``gt_path_achieved``: what an n-step TD target compares and
        bootstraps from.
        """
        if self.num_episodes == 0:
            raise RuntimeError("cannot sample from an empty replay buffer")
        T = self.horizon
        ep = rng.integers(0, self.num_episodes, size=batch_size)
        t = rng.integers(0, T, size=batch_size)
        has_future = t + 2 <= T
        span = np.maximum(T - t - 1, 1)  # |{t+2..T}|, 1 where empty (masked)
        future = np.where(has_future, t + 2 + (rng.random(batch_size) * span).astype(np.int64), T)
        arrays = {**self.obs, **self.goals}
        get = (lambda k, *i: arrays[k].data[i]) if packed else (lambda k, *i: arrays[k][i])
        obs = {k: get(k, ep, t) for k in self.obs}
        obs.update({k: get(k, ep) for k in self.goals})
        batch = {
            "obs": obs,
            "next_obs": {k: get(k, ep, t + 1) for k in self.obs},
            "future_obs": {k: get(k, ep, future) for k in self.obs},
            "action": self.actions[ep, t],
            "has_future": has_future,
            "episode": ep,
            "t": t,
            "future_t": future,
        }
        if n_step > 1:
            steps = t[:, None] + np.arange(2, n_step + 1)
            path = np.minimum(steps, T)
            batch["path_obs"] = {k: get(k, ep[:, None], path) for k in self.obs}
            batch["path_valid"] = steps <= T
            if self.gt_achieved is not None:
                batch["gt_path_achieved"] = self.gt_achieved[ep[:, None], path]
        if self.gt_achieved is not None:
            batch["gt_next_achieved"] = self.gt_achieved[ep, t + 1]
            batch["gt_future_achieved"] = self.gt_achieved[ep, future]
            batch["gt_desired"] = self.gt_desired[ep]
        return batch

    def observation_stats(self) -> dict[str, dict[str, np.ndarray]]:
        """Mean/std of every observation key over the stored episodes' frames and their goals, per dimension
        for vectors and per channel (shaped ``(C, 1, 1)``) for images, in LeRobot's dataset-stats layout.

        Goals count because they share the observation's normalisation: stats of the frames alone miss
        goals the policy has not visited yet, and clipping then makes those goals indistinguishable.
        """
        stats = {}
        for key, moments in self.moments.items():
            count, total, total_sq = moments[: self.num_episodes].sum(axis=0)
            mean, mean_sq = total / count, total_sq / count
            std = np.sqrt(np.maximum(mean_sq - np.square(mean), 0.0))
            shape = (-1,) + (1,) * (self.obs[key].data.ndim - 3)
            stats[key] = {
                "mean": mean.astype(np.float32).reshape(shape),
                "std": std.astype(np.float32).reshape(shape),
            }
        return stats
