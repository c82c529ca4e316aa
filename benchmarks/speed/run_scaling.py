"""Scale-out benchmarks (docs/scaling.md), each a thin CLI over ``benchmarks.speed.scaling``.

# env steps/s of 2 Ray workers vs 1 on RGB-D reach at 64 px (rendering-bound)
MUJOCO_GL=egl .venv/bin/python -m benchmarks.speed.run_scaling rollouts --out docs/results/scaling_rollouts.json
# bytes per episode on the wire at 100 px RGB-D (the paper's Visual Reacher)
MUJOCO_GL=egl .venv/bin/python -m benchmarks.speed.run_scaling wire --out docs/results/scaling_wire.json
# learner updates/s with --online.backend=ray vs local at the same batch size
MUJOCO_GL=egl .venv/bin/python -m benchmarks.speed.run_scaling learner --out docs/results/scaling_learner.json
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")


def env(obs_type: str) -> list[str]:
    return ["--env.type=sawyer_reach", f"--env.obs_type={obs_type}", "--env.light_render=true"]


POLICY = ["--policy.type=indicator_ddpg", "--policy.push_to_hub=false", "--policy.device=cpu"]
LOCAL_ENV = ["--online.n_envs=1", "--online.use_async_envs=false", "--online.eval_episodes=1"]


def size(px: int) -> list[str]:
    return [f"--env.camera.width={px}", f"--env.camera.height={px}"]


def main() -> None:
    from benchmarks.speed import scaling

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("what", choices=["rollouts", "wire", "learner"])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument(
        "--px", type=int, default=None, help="camera size (default: 64 rollouts/learner, 100 wire)"
    )
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--batches_per_worker", type=int, default=2)
    p.add_argument("--updates_per_cycle", type=int, default=20)
    p.add_argument("--cycles", type=int, default=3)
    p.add_argument("--batch_size", type=int, default=128)
    p.add_argument("--nice", type=int, default=0, help="priority of the work; Ray's control plane keeps ours")
    p.add_argument("--obs_type", default="rgbd", choices=["state", "rgb", "rgbd"])
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if a.what == "rollouts":
            px = a.px or 64
            args = [*env(a.obs_type), *size(px), *POLICY, *LOCAL_ENV]
            result = scaling.rollout_throughput(
                args, [1, 2], a.batches_per_worker, a.repeats, tmp / "run", a.nice
            )
        elif a.what == "wire":
            px = a.px or 100
            args = [*env(a.obs_type), *size(px), *POLICY, *LOCAL_ENV]
            scaling.lower_priority(a.nice)
            result = scaling.bytes_per_episode(args, tmp / "run")
        else:
            px = a.px or 64
            args = [
                *env(a.obs_type), *size(px), *POLICY, *LOCAL_ENV, "--online.num_workers=2", "--online.episodes_per_cycle=2",
                f"--online.updates_per_cycle={a.updates_per_cycle}", f"--online.batch_size={a.batch_size}",
                f"--steps={a.updates_per_cycle * a.cycles}", "--env_eval_freq=0", "--save_checkpoint=false",
            ]  # fmt: skip
            result = scaling.learner_updates(args, ["local", "ray"], a.repeats, tmp, a.nice)
    result = {
        "command": f"benchmarks/speed/run_scaling.py {a.what} "
        + " ".join(f"--{k}={v}" for k, v in vars(a).items() if k not in ("what", "out")),
        "px": px,
        "args": args,
        **result,
    }
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
