"""Callbacks of the online trainer's loop, for timing and logging without subclassing the trainer.

Every hook is optional. Each phase hook gets a ``PhaseEnd`` (which cycle, the counters as the phase ended,
its wall-clock seconds) and what the phase produced:

* ``on_cycle_start(cycle)``;
* ``on_collect_end(phase, rollouts)``: the behaviour-policy episodes of the cycle;
* ``on_update_end(phase, stats)``: the learning core's mean statistics over the cycle's updates;
* ``on_eval_end(phase, metrics)``: ``eval_success_rate`` and ``eval_final_distance``;
* ``on_cycle_end(phase, record)``: the cycle's ``metrics.jsonl`` line (``phase.seconds``: the whole cycle).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class PhaseEnd:
    cycle: int
    step: int  # optimisation steps done
    env_steps: int
    seconds: float  # wall-clock of the phase


@dataclass
class TrainerHooks:
    on_cycle_start: Callable[[int], None] | None = None
    on_collect_end: Callable[[PhaseEnd, Any], None] | None = None
    on_update_end: Callable[[PhaseEnd, dict[str, float]], None] | None = None
    on_eval_end: Callable[[PhaseEnd, dict[str, float]], None] | None = None
    on_cycle_end: Callable[[PhaseEnd, dict], None] | None = None
