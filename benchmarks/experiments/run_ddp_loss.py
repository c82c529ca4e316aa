"""Loss curve of 2-process ``lerobot-train`` (DDP over gloo, CPU) vs 1 process at the same global batch size,
on a state-based Sawyer reach dataset recorded for the run (noisy scripted policy). Thin CLI over
``benchmarks.experiments.ddp_loss``.

    MUJOCO_GL=egl .venv/bin/python -m benchmarks.experiments.run_ddp_loss --out docs/results/ddp_loss_curve.json

Writes the JSON and, beside it, the curves as PNG (same name).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
REPO_ID = "local/ddp_loss_reach_state"


def main() -> None:
    from benchmarks.experiments import ddp_loss
    from benchmarks.speed.scaling import machine
    from lerobot_indicator.data.recorder import RecordConfig, record
    from lerobot_indicator.envs.configs import SawyerReachEnvConfig

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--global_batch", type=int, default=256)
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--window", type=int, default=20)
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "data"
        record(
            RecordConfig(
                env=SawyerReachEnvConfig(obs_type="state"), repo_id=REPO_ID, root=root, policy="noisy_scripted",
                num_episodes=a.episodes, image_writer_threads=0,
            )
        )  # fmt: skip
        before = machine()
        result = ddp_loss.compare(
            root, REPO_ID, a.global_batch, a.steps, [1, 2], [], Path(tmp) / "runs", a.window
        )
    command = "benchmarks/experiments/run_ddp_loss.py " + " ".join(
        f"--{k}={v}" for k, v in vars(a).items() if k != "out"
    )
    result = {
        "command": command,
        "episodes": a.episodes,
        "machine_before": before,
        "machine_after": machine(),
        **result,
    }
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(result, indent=2) + "\n")
    ddp_loss.plot(result, a.out.with_suffix(".png"))
    print(json.dumps({k: v for k, v in result.items() if k != "runs"}, indent=2))


if __name__ == "__main__":
    main()
