"""Rope-push physics: push macro-actions, the authors' random pushes, and canonical rest states.

A push is (x1, y1, x2, y2) in [-1, 1]^4, mapped linearly onto the table rectangle ``region_low`` ..
``region_high`` (metres; the straight rope lies along x, centred on the origin). As in the authors'
environment:

* a push whose swept pusher can never touch a link is skipped: the rope cannot move;
* the pusher starts where the push line first comes within ``approach_distance`` of a link (no time is
  simulated for free motion far from the rope). If that start lies on the rope it is backed off along
  the line until lowering there cannot touch the rope (documented difference: the authors lowered onto
  the rope, which with a kinematic pusher squeezes links into the table);
* the pusher is put above the start at ``lift_z``, lowered to ``push_z``, pushed in a straight line to
  the end point, lifted, and parked out of the camera's view; the rope then settles;
* a push during which the simulation went unstable (MuJoCo's NaN/Inf/huge qpos, qvel or qacc warning, after
  which MuJoCo silently resets every joint to the straight rope) is undone: the rope is put back where it
  was and the push counts as skipped, with a logged warning, so no transition shows a rope that jumped
  to straight.

After every push the state is canonicalised (velocities, warm start and time zeroed, pusher parked), so
the simulator state is a function of ``qpos`` alone: cached states restore bit-exactly and the same
pushes from the same state give bit-identical rope configurations.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field

import numpy as np

from lerobot_indicator.envs.rope_scene import PUSHER_BODY, RopeGeometry, link_geom_name

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class PushConfig:
    """Everything that changes the physics or the sampled configurations (the cache's parameters)."""

    geometry: RopeGeometry = field(default_factory=RopeGeometry)
    region_low: tuple[float, float] = (-0.45, -0.45)
    region_high: tuple[float, float] = (0.45, 0.45)
    push_z: float = 0.803  # pusher bottom while pushing (table top + 3 mm)
    lift_z: float = 0.86  # pusher bottom before lowering / after lifting
    timestep: float = 0.005
    push_speed: float = 0.3  # m/s along the push
    vertical_speed: float = 1.0  # m/s when lowering and lifting (contact-free or nearly)
    approach_distance: float = 0.1  # authors: start where the line first comes within 0.1 m of a link
    settle_max_time: float = 1.0  # s of simulation after lifting, at most
    settle_speed_tol: float = 2e-3  # the rope is at rest once every |qvel| is below this
    # Authors' random push: across a random link from (dx, +-dy) to the mirrored point, dx in [-0.1, 0.1].
    random_push_dx: float = 0.1
    random_push_dy: float = 0.2
    goal_pushes: int = 2

    def __post_init__(self):
        g = self.geometry
        low, high = np.asarray(self.region_low, float), np.asarray(self.region_high, float)
        if low.shape != (2,) or high.shape != (2,) or np.any(low >= high):
            raise ValueError(
                f"push region: need 2 numbers each with low < high, got {self.region_low}, {self.region_high}"
            )
        if not g.table_top_z <= self.push_z < g.table_top_z + g.radius:
            raise ValueError(
                f"push_z={self.push_z} must be in [table top {g.table_top_z}, table top + rope radius "
                f"{g.table_top_z + g.radius}): the pusher must not enter the table and must catch the rope"
            )
        if self.lift_z <= self.push_z + 2 * g.radius:
            raise ValueError(f"lift_z={self.lift_z} must clear the rope: > push_z + rope diameter")
        for key in ("timestep", "push_speed", "vertical_speed", "settle_max_time", "settle_speed_tol"):
            if getattr(self, key) <= 0:
                raise ValueError(f"{key} must be > 0, got {getattr(self, key)}")
        if self.goal_pushes < 1:
            raise ValueError(f"goal_pushes must be >= 1, got {self.goal_pushes}")

    def to_dict(self) -> dict:
        """Plain (JSON-able) parameters; tuples become lists."""
        return _jsonable(asdict(self))


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


class RopeSim:
    """Push primitive on a compiled rope scene (``model``, ``data`` owned by the caller)."""

    def __init__(self, model, data, config: PushConfig):
        import mujoco

        self._mj = mujoco
        self.model, self.data, self.config = model, data, config
        g = config.geometry
        self.link_geom_ids = np.array([model.geom(link_geom_name(i)).id for i in range(g.n_links)])
        self.mocap_id = model.body(PUSHER_BODY).mocapid[0]
        self._low = np.asarray(config.region_low, float)
        self._high = np.asarray(config.region_high, float)
        hx, hy, _ = g.pusher_half_size
        # Farther than this from the pusher's centre line, a link centre cannot be touched (+1 cm margin).
        self.reach = float(np.hypot(hx, hy) + g.radius + 0.01)
        self.straight_qpos = model.qpos0.copy()
        # Called after every physics step while the pusher moves (e.g. to film a push); None: nothing.
        self.on_push_step = None
        warning = mujoco.mjtWarning
        self._instability_warnings = [
            int(w) for w in (warning.mjWARN_BADQPOS, warning.mjWARN_BADQVEL, warning.mjWARN_BADQACC)
        ]

    # ----- state -------------------------------------------------------------------------------
    def canonicalize(self) -> None:
        """Rest state that depends on qpos only (see module docstring)."""
        d = self.data
        d.qvel[:] = 0.0
        d.qacc_warmstart[:] = 0.0
        d.time = 0.0
        d.mocap_pos[self.mocap_id] = self.config.geometry.park_pos
        self._mj.mj_forward(self.model, d)

    def set_qpos(self, qpos: np.ndarray) -> None:
        qpos = np.asarray(qpos, dtype=np.float64)
        if qpos.shape != (self.model.nq,):
            raise ValueError(f"rope state must have shape ({self.model.nq},), got {qpos.shape}")
        self.data.qpos[:] = qpos
        self.canonicalize()

    def rest_pusher_above(self, xy: np.ndarray) -> None:
        """Put the pusher at ``lift_z`` above table point ``xy``: clear of the rope (``lift_z`` is above
        it), so only what the camera sees changes; :meth:`canonicalize` parks it again."""
        self.data.mocap_pos[self.mocap_id] = (*np.asarray(xy, float), self.config.lift_z)
        self._mj.mj_forward(self.model, self.data)

    def reset_straight(self) -> None:
        self.set_qpos(self.straight_qpos)

    def link_positions(self) -> np.ndarray:
        """(n_links, 3) link centres in the world frame (rope centre at x = y = 0 when straight)."""
        return self.data.geom_xpos[self.link_geom_ids].copy()

    # ----- actions -----------------------------------------------------------------------------
    def action_to_points(self, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        action = np.asarray(action, dtype=np.float64).reshape(-1)
        if action.shape != (4,):
            raise ValueError(f"push action must have 4 numbers (x1, y1, x2, y2), got shape {action.shape}")
        if not np.all(np.isfinite(action)):
            raise ValueError(f"push action must be finite, got {action}")
        a = np.clip(action, -1.0, 1.0)
        scale = (self._high - self._low) / 2
        centre = (self._high + self._low) / 2
        return centre + a[:2] * scale, centre + a[2:] * scale

    def points_to_action(self, start: np.ndarray, end: np.ndarray) -> np.ndarray:
        scale = (self._high - self._low) / 2
        centre = (self._high + self._low) / 2
        return np.clip(np.concatenate([(start - centre) / scale, (end - centre) / scale]), -1.0, 1.0)

    def random_push_action(self, rng: np.random.Generator) -> np.ndarray:
        """Authors' random push across a random link, expressed (and clipped) in action space."""
        c = self.config
        link = self.link_positions()[rng.integers(c.geometry.n_links), :2]
        offset = np.array([rng.uniform(-c.random_push_dx, c.random_push_dx), c.random_push_dy])
        if rng.random() < 0.5:
            offset[1] = -offset[1]
        # float32-representable, so a policy's float32 action can repeat it bit for bit.
        return self.points_to_action(link + offset, link - offset).astype(np.float32).astype(np.float64)

    # ----- the push primitive ------------------------------------------------------------------
    def _distances_to_segment(self, start: np.ndarray, end: np.ndarray) -> np.ndarray:
        """Distance from every link centre (xy) to the segment start-end."""
        links = self.link_positions()[:, :2]
        d = end - start
        length2 = float(d @ d)
        t = np.zeros(len(links)) if length2 == 0 else np.clip((links - start) @ d / length2, 0.0, 1.0)
        return np.linalg.norm(links - (start + t[:, None] * d), axis=1)

    def _first_t_within(self, start: np.ndarray, end: np.ndarray, radius: float) -> float:
        """Smallest t in [0, 1] where start + t (end - start) is within ``radius`` of a link centre."""
        links = self.link_positions()[:, :2]
        d = end - start
        f = start - links
        a, b, c = float(d @ d), 2 * f @ d, np.einsum("ij,ij->i", f, f) - radius**2
        disc = b * b - 4 * a * c
        hit = disc >= 0
        t_exit = (-b[hit] + np.sqrt(disc[hit])) / (2 * a)
        t_enter = (-b[hit] - np.sqrt(disc[hit])) / (2 * a)
        ahead = t_exit >= 0
        if not ahead.any():
            return 1.0
        return float(np.clip(np.maximum(t_enter[ahead], 0.0).min(), 0.0, 1.0))

    def push(self, action: np.ndarray) -> bool:
        """Execute one push; False when it was skipped: the pusher cannot touch the rope, or the simulation
        went unstable during it (the rope is then put back where it was)."""
        start, end = self.action_to_points(action)
        length = float(np.linalg.norm(end - start))
        if length < 1e-6 or self._distances_to_segment(start, end).min() > self.reach:
            return False
        before = self.data.qpos.copy()
        for w in self._instability_warnings:
            self.data.warning[w].number = 0
        self._push(start, end, length)
        unstable = [w for w in self._instability_warnings if self.data.warning[w].number > 0]
        if unstable:
            logger.warning(
                "rope push %s: the simulation went unstable (MuJoCo warning %s); the push is undone",
                np.round(np.asarray(action, dtype=float), 4).tolist(),
                [self._mj.mjtWarning(w).name for w in unstable],
            )
            for w in unstable:
                self.data.warning[w].number = 0
            self.set_qpos(before)
            return False
        return True

    def _push(self, start: np.ndarray, end: np.ndarray, length: float) -> None:
        c = self.config
        direction = (end - start) / length
        p = start + self._first_t_within(start, end, c.approach_distance) * (end - start)
        backed = 0.0
        while self._distances_to_segment(p, p).min() <= self.reach and backed < c.approach_distance:
            p, backed = p - 0.005 * direction, backed + 0.005
        self.data.mocap_pos[self.mocap_id] = (*p, c.lift_z)
        self._glide(np.array([*p, c.push_z]), c.vertical_speed)
        self._glide(np.array([*end, c.push_z]), c.push_speed)
        self._glide(np.array([*end, c.lift_z]), c.vertical_speed)
        self.data.mocap_pos[self.mocap_id] = c.geometry.park_pos
        self._settle()
        self.canonicalize()

    def _glide(self, target: np.ndarray, speed: float) -> None:
        """Move the pusher in a straight line at ``speed``, one physics step per increment."""
        m, d, mj = self.model, self.data, self._mj
        src = d.mocap_pos[self.mocap_id].copy()
        n = max(1, int(np.ceil(np.linalg.norm(target - src) / (speed * m.opt.timestep))))
        for k in range(1, n + 1):
            d.mocap_pos[self.mocap_id] = src + (target - src) * (k / n)
            mj.mj_step(m, d)
            if self.on_push_step is not None:
                self.on_push_step()

    def _settle(self) -> None:
        m, d, c = self.model, self.data, self.config
        every = 10
        for _ in range(max(1, round(c.settle_max_time / (m.opt.timestep * every)))):
            self._mj.mj_step(m, d, every)
            if np.abs(d.qvel).max() < c.settle_speed_tol:
                return
