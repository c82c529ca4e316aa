"""Rollouts on a Ray cluster (``--online.backend=ray``): CPU workers collect, the learner learns.

Each worker is a Ray actor that owns a vector env built from the run's env config (``--online.n_envs``
sub-envs, synchronous: the actor is the unit of parallelism) and a CPU copy of the policy, of which only the
actor network's weights (with its input-normalisation buffers) are ever sent: once per cycle, through the
object store. A cycle is a list of ``EpisodeBatch`` specs, handed to whichever worker is free; each returns
whole episodes in the local collector's ``Rollouts`` format. On the wire, frames travel packed to the
replay buffer's lossless dtypes (uint8 RGB, uint16 depth) and goals once per episode.

Nothing of a cycle reaches the learner before all of its batches are back, so a worker that dies (node lost,
``ray.kill``) is replaced and its batch collected again by the new worker: a spec gives the same episodes
wherever it runs, so no episode is counted twice and none is lost.
"""

from __future__ import annotations

import copy
import logging
import pickle
import signal
import threading
from dataclasses import dataclass, field, replace

import numpy as np
import torch

from lerobot_indicator.training.replay_buffer import pack, unpack
from lerobot_indicator.training.rollout import EpisodeBatch, Rollouts

# Replacements allowed per cycle and worker before a cycle gives up (a worker that cannot even start, such
# as a node without the package, would otherwise be replaced forever).
MAX_REPLACEMENTS_PER_WORKER = 3


@dataclass
class PackedArray:
    """A float32 array as ``replay_buffer.pack`` stores it; ``per_episode``: constant over time, kept once."""

    data: np.ndarray
    scale: float
    per_episode: bool
    steps: int

    @classmethod
    def of(cls, value: np.ndarray) -> PackedArray:
        steps = value.shape[1]
        per_episode = bool(np.array_equal(value, np.broadcast_to(value[:, :1], value.shape)))
        data, scale = pack(value[:, :1] if per_episode else value)
        return cls(data, scale, per_episode, steps)

    def array(self) -> np.ndarray:
        value = unpack(self.data, self.scale)
        return np.repeat(value, self.steps, axis=1) if self.per_episode else value


@dataclass
class WireRollouts:
    """``Rollouts`` as a worker returns them: observations packed, everything else as is."""

    observations: dict[str, PackedArray]
    rest: Rollouts = field(repr=False)

    @classmethod
    def of(cls, rollouts: Rollouts) -> WireRollouts:
        packed = {k: PackedArray.of(v) for k, v in rollouts.observations.items()}
        return cls(packed, replace(rollouts, observations={}))

    def rollouts(self) -> Rollouts:
        return replace(self.rest, observations={k: v.array() for k, v in self.observations.items()})

    def nbytes(self) -> int:
        """Serialised size: what one batch puts on the wire."""
        return len(pickle.dumps(self, protocol=5))


def actor_weights(policy) -> dict[str, torch.Tensor]:
    """What a worker needs of the learner's policy: the actor and its input normalisation, on CPU."""
    return {k: v.detach().to("cpu", copy=True) for k, v in policy.actor.state_dict().items()}


class RolloutWorker:
    """Body of one Ray actor: an env and a CPU policy built from the run's config."""

    def __init__(self, cfg):
        from lerobot.envs import make_env, make_env_pre_post_processors
        from lerobot.policies import make_policy, make_pre_post_processors
        from lerobot.utils.import_utils import register_third_party_plugins

        from lerobot_indicator.training.rollout import Processors, stored_keys

        register_third_party_plugins()
        policy_cfg = copy.deepcopy(cfg.policy)
        policy_cfg.device = "cpu"
        policy_cfg.pretrained_path = None  # weights come from the learner
        policy_cfg.compile_model = False  # the loss is never computed here
        n_envs = cfg.online.n_envs
        self.vec_env = make_env(cfg.env, n_envs=n_envs, use_async_envs=False)[cfg.env.type][0]
        self.horizon = int(self.vec_env.call("_max_episode_steps")[0])
        self.policy = make_policy(policy_cfg, env_cfg=cfg.env)
        env_pre, env_post = make_env_pre_post_processors(cfg.env, policy_cfg)
        pre, post = make_pre_post_processors(policy_cfg)
        self.processors = Processors(env_pre=env_pre, env_post=env_post, pre=pre, post=post)
        self.keys = stored_keys(policy_cfg.observation_keys, policy_cfg.context_keys)

    def set_weights(self, weights: dict[str, torch.Tensor]) -> None:
        self.policy.actor.load_state_dict(weights)

    def run(self, batch: EpisodeBatch) -> WireRollouts:
        return WireRollouts.of(batch.run(self.vec_env, self.policy, self.processors, self.keys, self.horizon))


class RayRollouts:
    """``num_workers`` rollout actors on the Ray cluster at ``address`` (None: a new local one on this
    machine's cores), or on the cluster this process is already connected to."""

    def __init__(self, cfg, num_workers: int, address: str | None = None):
        try:
            import ray
        except ImportError as e:
            raise ImportError(
                "--online.backend=ray needs Ray: pip install 'lerobot_policy_indicator_ddpg[distributed]'"
            ) from e

        self.owns_ray = not ray.is_initialized()
        if self.owns_ray:
            # Ray's driver swaps in a SIGTERM handler that exits at once; the caller's is put back, so that
            # lerobot-indicator-train still stops as on Ctrl-C (workers, dataset and wandb closed).
            sigterm = signal.getsignal(signal.SIGTERM)
            # "local": a new instance even where another Ray cluster runs on this machine.
            ray.init(address=address or "local", include_dashboard=False, logging_level=logging.WARNING)
            if sigterm is not None and threading.current_thread() is threading.main_thread():
                signal.signal(signal.SIGTERM, sigterm)
        self.cfg = cfg
        self.actor_class = ray.remote(num_cpus=1, max_restarts=0)(RolloutWorker)
        self.workers = [self._spawn() for _ in range(num_workers)]
        self.replacements = 0
        self._weights = None
        self._pending: dict = {}  # ObjectRef -> (batch index, worker index)
        self._queue: list[int] = []
        self._batches: list[EpisodeBatch] = []
        self._results: dict[int, WireRollouts] = {}

    def _spawn(self):
        return self.actor_class.remote(self.cfg)

    def collect(self, batches: list[EpisodeBatch], policy) -> list[Rollouts]:
        """Run ``batches`` with ``policy``'s current actor; results in the order of ``batches``."""
        self.submit(batches, policy)
        return self.gather()

    def submit(self, batches: list[EpisodeBatch], policy) -> None:
        """Send the weights to every worker (once) and start one batch on each."""
        import ray

        self._weights = ray.put(actor_weights(policy))
        self._batches, self._results, self._pending = list(batches), {}, {}
        self._queue = list(range(len(batches)))
        for w, worker in enumerate(self.workers):
            worker.set_weights.remote(self._weights)
            self._start_next(w)

    def _start_next(self, w: int) -> None:
        if self._queue:
            i = self._queue.pop(0)
            self._pending[self.workers[w].run.remote(self._batches[i])] = (i, w)

    def gather(self) -> list[Rollouts]:
        """Wait for every batch, replacing workers that die and giving their batch to the replacement."""
        import ray
        from ray.exceptions import NodeDiedError, OutOfMemoryError, RayActorError, WorkerCrashedError

        # How a dead worker shows on its call: killed, crashed, killed by Ray's memory monitor, node lost.
        died = (RayActorError, WorkerCrashedError, OutOfMemoryError, NodeDiedError)

        budget = MAX_REPLACEMENTS_PER_WORKER * len(self.workers)
        while self._pending:
            [ref], _ = ray.wait(list(self._pending), num_returns=1)
            i, w = self._pending.pop(ref)
            try:
                self._results[i] = ray.get(ref)
            except died as e:
                if budget == 0:
                    raise RuntimeError(
                        f"Ray rollout workers died {MAX_REPLACEMENTS_PER_WORKER * len(self.workers)} times in "
                        f"one cycle (last: {e}); giving up"
                    ) from e
                budget -= 1
                self.replacements += 1
                logging.warning("Ray rollout worker %d died; replacing it and collecting its batch again", w)
                self._queue.insert(0, i)  # a worker runs one batch at a time: this was its only one
                self.workers[w] = self._spawn()
                self.workers[w].set_weights.remote(self._weights)
            self._start_next(w)
        return [self._results[i].rollouts() for i in range(len(self._batches))]

    def close(self) -> None:
        import ray

        if not ray.is_initialized():
            return
        for worker in self.workers:
            ray.kill(worker)
        if self.owns_ray:
            ray.shutdown()
