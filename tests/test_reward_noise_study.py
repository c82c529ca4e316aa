"""The section-4 reward-noise study's sweep (every arm and seed once, a failed runner stops it) and its figure."""

import json
import sys

import draccus
import pytest

from benchmarks.experiments import reward_noise
from benchmarks.experiments.presets import METHODS, REWARD_NOISE


def test_sweep_runs_every_noise_arm_once_per_seed_with_its_flag():
    cfg = draccus.parse(reward_noise.RewardNoiseConfig, args=["--seeds=[4,7]", "--steps=10"])
    runs = []
    for cmd in reward_noise.sweep_groups(cfg):
        (methods,) = [a for a in cmd if a.startswith("--methods=")]
        (seeds,) = [a for a in cmd if a.startswith("--seeds=")]
        assert "--steps=10" in cmd
        runs += [(m, seeds) for m in methods.removeprefix("--methods=[").removesuffix("]").split(",")]
    arms = ["oracle"] + [f"oracle_{k}{r:g}" for k, rates in REWARD_NOISE.items() for r in rates]
    assert sorted(runs) == sorted((a, f"--seeds=[{s}]") for a in arms for s in (4, 7))
    assert "--policy.reward_false_negative_rate=0.9" in METHODS["oracle_fn0.9"]
    assert "--policy.reward_false_positive_rate=0.01" in METHODS["oracle_fp0.01"]


def test_a_failed_runner_stops_the_sweep_with_its_command(tmp_path, monkeypatch):
    failing = [[sys.executable, "-c", "import sys; sys.exit(3)"]]
    monkeypatch.setattr(reward_noise, "sweep_groups", lambda cfg: failing)
    with pytest.raises(SystemExit, match="exited with 3"):
        reward_noise.run_sweep(reward_noise.RewardNoiseConfig(out=tmp_path, jobs=2))


def test_figure_has_one_curve_per_rate_in_each_panel(tmp_path):
    def arm(level):
        return {"env_steps": [0, 100], "series": {"eval_success_rate": {"mean": [0, level], "std": [0, 0.1]}}}

    arms = {m: arm(0.5) for ms in reward_noise.noise_methods().values() for m in ms}
    summary = {"tasks": {reward_noise.TASK: arms}}
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    fig = reward_noise.plot(summary, tmp_path / "reward_noise.png")
    fn_panel, fp_panel = fig.axes
    assert [line.get_label() for line in fn_panel.lines] == ["p_FN = 0"] + [
        f"p_FN = {r:g}" for r in REWARD_NOISE["fn"]
    ]
    assert len(fp_panel.lines) == 1 + len(REWARD_NOISE["fp"])
    assert (tmp_path / "reward_noise.png").stat().st_size > 0
