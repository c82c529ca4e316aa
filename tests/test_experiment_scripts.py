"""The experiment helpers: the no-movement reference distance, the comparison plot that draws it, and the sweep
runner's stop on a signal or a failed run."""

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import draccus
import gymnasium as gym
import numpy as np
import pytest

import lerobot_indicator  # noqa: F401  (registers the gym ids)
from benchmarks.experiments import runner as experiments
from benchmarks.experiments.start_distance import geometric_median
from benchmarks.probes.policy_probe import clipped_goal_dims
from lerobot_indicator.keys import EVAL_SEED_OFFSET

ROOT = Path(__file__).resolve().parents[1]


def test_start_distance_is_the_eval_goals_distance_at_reset(tmp_path):
    out = tmp_path / "start_distance_reach_state.json"
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.experiments.start_distance",
        "--env.type=sawyer_reach",
        "--episodes=2",
        f"--out={out}",
    ]
    subprocess.run(cmd, cwd=ROOT, check=True, env={**os.environ, "MUJOCO_GL": "egl"}, capture_output=True)
    record = json.loads(out.read_text())
    env = gym.make("lerobot_indicator/SawyerReach-v0", obs_type="state")
    try:
        infos = [env.reset(seed=EVAL_SEED_OFFSET + i)[1] for i in range(2)]
    finally:
        env.close()
    np.testing.assert_allclose(record["start_distances"], [i["gt_distance"] for i in infos], rtol=1e-6)
    assert record["start_distance_mean"] == np.mean(record["start_distances"])
    # Two goals: every point between them is a geometric median, each at half their distance on average.
    half_gap = np.linalg.norm(infos[0]["gt_desired_goal"] - infos[1]["gt_desired_goal"]) / 2
    assert record["goal_blind_distance_mean"] == pytest.approx(half_gap, rel=1e-4)
    assert record["command"].startswith("python ")

    reference = experiments.start_distances(tmp_path, ["reach_state", "rope_state"])
    assert reference == {"reach_state": record["start_distance_mean"]}
    lines = experiments.reference_lines(tmp_path, ["reach_state"])
    assert lines == {
        "reach_state": {
            "eval_final_distance": {
                "no movement (start distance)": reference["reach_state"],
                experiments.GOAL_BLIND: record["goal_blind_distance_mean"],
            }
        }
    }


def test_geometric_median_on_hand_made_points():
    # Collinear: the middle point, however far the outlier (the mean is at 2); a square: its centre.
    np.testing.assert_allclose(geometric_median(np.array([[0.0, 0], [1, 0], [5, 0]])), [1, 0], atol=1e-4)
    square = np.array([[1.0, 1], [1, -1], [-1, 1], [-1, -1]])
    np.testing.assert_allclose(geometric_median(square), [0, 0], atol=1e-9)


def test_rope_plots_carry_the_ceiling_random_and_not_moving_lines(tmp_path):
    """Every rope plot draws what the task allows on its own evaluation goals: the committed ceiling.json's
    CEM plan, uniformly random actions and not moving, averaged over the task's first eval_episodes goals."""
    from benchmarks.experiments.presets import TASKS

    record = json.loads(experiments.ROPE_CEILING.read_text())
    n = TASKS["rope_rgbd"].eval_episodes
    goals = record["goal_sets"][experiments.ROPE_GOAL_SET]["per_goal"][:n]
    lines = experiments.reference_lines(tmp_path, ["rope_rgbd", "reach_state"])
    assert set(lines) == {"rope_rgbd"}  # reach has no ceiling, and no start-distance file here
    distance = lines["rope_rgbd"]["eval_final_distance"]
    assert distance["ceiling: CEM with the true simulator"] == pytest.approx(
        np.mean([g["distance"] for g in goals])
    )
    assert distance["no movement (start distance)"] == pytest.approx(
        np.mean([g["start_distance"] for g in goals])
    )
    success = lines["rope_rgbd"]["eval_success_rate"]
    assert success["ceiling: CEM with the true simulator"] == pytest.approx(
        np.mean([g["distance"] < 0.1 for g in goals])
    )
    assert success["ceiling: CEM with the true simulator"] > success["uniformly random actions"]
    summary = experiments.summarize({0: _eval_rows([0.6, 0.5])})
    fig = experiments.plot({"rope_rgbd": {"oracle": summary}}, tmp_path / "rope.png", lines)
    heights = {round(line.get_ydata()[0], 6) for line in fig.axes[1].lines[1:]}
    assert heights == {round(v, 6) for v in distance.values()}


def test_eval_goals_flags_goals_the_encoder_clips():
    from lerobot.configs import FeatureType, PolicyFeature

    from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
    from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

    cfg = IndicatorDDPGConfig(device="cpu", hidden_dims=[8, 8, 8], input_clip=5.0, horizon=25)
    vec, rgb = PolicyFeature(FeatureType.STATE, (3,)), PolicyFeature(FeatureType.VISUAL, (3, 32, 32))
    cfg.input_features = {
        "observation.state": vec,
        "observation.goal_state": vec,
        "observation.images.front": rgb,
        "observation.images.goal_front": rgb,
    }
    cfg.output_features = {"action": PolicyFeature(FeatureType.ACTION, (3,))}
    cfg.observation_keys = ["observation.state", "observation.images.front"]
    policy = IndicatorDDPGPolicy(cfg)
    policy.set_observation_stats(
        {
            "observation.state": {"mean": np.zeros(3), "std": np.full(3, 0.1)},
            "observation.images.front": {"mean": np.full((3, 1, 1), 0.5), "std": np.full((3, 1, 1), 0.05)},
        }
    )
    image = np.full((2, 3, 32, 32), 0.5, np.float32)
    image[1, 2, 4, 4] = 0.8  # one pixel of channel 2, 6 std away
    goals = {
        "observation.state": np.array([[0.0, 0.49, -0.51], [0.1, 0.2, 0.3]], np.float32),
        "observation.images.front": image,
    }
    flagged = clipped_goal_dims(policy, goals)
    assert flagged == [["observation.state[2]"], ["observation.images.front[2]"]]


REACH_ARGS = ["--env.type=sawyer_reach", "--env.obs_type=state", "--env.episode_length=5"]
SCRIPT_ENV = {**os.environ, "MUJOCO_GL": "egl", "HF_HUB_OFFLINE": "1"}


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory) -> Path:
    """A 5-update online run on 5-step reach episodes (checkpoint and replay chunks kept)."""
    run = tmp_path_factory.mktemp("trained") / "run"
    train = [
        str(Path(sys.executable).parent / "lerobot-indicator-train"),
        *REACH_ARGS,
        "--policy.type=indicator_ddpg",
        "--policy.push_to_hub=false",
        "--policy.device=cpu",
        "--online.n_envs=1",
        "--online.use_async_envs=false",
        "--online.episodes_per_cycle=4",
        "--online.updates_per_cycle=5",
        "--online.batch_size=16",
        "--online.eval_episodes=1",
        "--steps=5",
        f"--output_dir={run}",
    ]
    subprocess.run(train, cwd=ROOT, check=True, env=SCRIPT_ENV, capture_output=True)
    return run


def test_eval_goals_on_a_trained_checkpoint(trained_run, tmp_path):
    env_args, env = REACH_ARGS, SCRIPT_ENV
    out = tmp_path / "eval_goals.json"
    policy_path = trained_run / "checkpoints" / "last" / "pretrained_model"
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.probes.run_eval_goals",
        *env_args,
        f"--policy_path={policy_path}",
        "--episodes=2",
    ]
    subprocess.run([*cmd, f"--out={out}"], cwd=ROOT, check=True, env=env, capture_output=True)
    record = json.loads(out.read_text())
    assert [r["seed"] for r in record["episodes"]] == [EVAL_SEED_OFFSET, EVAL_SEED_OFFSET + 1]
    for row in record["episodes"]:
        final = np.linalg.norm(np.subtract(row["gt_goal"], row["gt_final"]))
        assert abs(final - row["final_distance"]) < 1e-3  # positions are rounded to 0.1 mm
        assert row["success"] == (row["final_distance"] <= 0.05)
    assert record["success_rate"] == np.mean([r["success"] for r in record["episodes"]])
    assert set(record["input_stats"]) == {"observation.state"}


def test_experiments_aggregate_and_table_at_a_shared_budget(tmp_path):
    """Runs of different lengths compare at a shared env-step budget; a metric missing from early rows (added
    mid-run) and the filter's precision in cycles that filtered nothing are NaN, not zeros averaged in."""
    cfg = experiments.ExperimentConfig(
        tasks=["rope_state"],
        methods=["indicator", "indicator_balance_filter"],
        seeds=[0, 1],
        runs_dir=tmp_path,
    )
    curves = {  # method -> seed -> eval distances at env steps 100, 200, (300)
        "indicator": {0: [0.6, 0.5], 1: [0.7, 0.3]},
        "indicator_balance_filter": {0: [0.6, 0.4, 0.2], 1: [0.8, 0.6, 0.4]},
    }
    for method, seeds in curves.items():
        for seed, distances in seeds.items():
            rows = []
            for i, d in enumerate(distances):
                row = {
                    "step": i,
                    "env_steps": 100 * (i + 1),
                    "wall_time_s": 1.0,
                    "eval_success_rate": float(d < 0.35),
                }
                row |= {"eval_final_distance": d, "frac_filtered": 0.1 * i}
                if i > 0:  # logged from the second cycle on; the first filtered nothing anyway
                    row["filtered_gt_success_rate"] = 0.25 * (seed + 1)
                rows.append(row)
            out = experiments.run_dir(cfg, "rope_state", method, seed)
            out.mkdir(parents=True)
            (out / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))

    summary = experiments.aggregate(cfg, "rope_state")
    ibf = summary["indicator_balance_filter"]
    assert ibf["final_env_steps"] == 300
    assert ibf["final_distance"]["mean"] == pytest.approx(0.3)
    precision = ibf["series"]["filtered_gt_success_rate"]["mean"]
    assert precision[0] is None and precision[1:] == pytest.approx([0.375, 0.375])

    text = experiments.table({"rope_state": summary}, env_steps=[200, 300], window=2)
    rows = [
        [c.strip() for c in line.split("|")[2:10]] for line in text.splitlines() if "| rope_state" in line
    ]
    # last-2 window: Indicator seeds (0.55, 0.5) at 200; I+B+F seeds (0.3, 0.5) at 300, (0.5, 0.7) at 200;
    # the last column: mean success over seeds never reaches 0.9 here ("-")
    ind, ibf = "Indicator", "Indicator+Balance+Filter"
    assert rows[0] == [
        ind,
        "2",
        "200",
        "0.50 ± 0.50",
        "0.400 ± 0.100",
        "0.525 ± 0.025",
        "-",
        "s0 0.550, s1 0.500",
    ]
    assert rows[1] == [
        ibf,
        "2",
        "300",
        "0.50 ± 0.50",
        "0.300 ± 0.100",
        "0.400 ± 0.100",
        "-",
        "s0 0.300, s1 0.500",
    ]
    assert rows[2] == [
        ibf,
        "2",
        "200",
        "0.00 ± 0.00",
        "0.500 ± 0.100",
        "0.600 ± 0.100",
        "-",
        "s0 0.500, s1 0.700",
    ]
    # No budget row repeats a final row (Indicator's 200, I+B+F's 300); Indicator never reached 300.
    assert len(rows) == 3
    summary["indicator"]["per_seed"]["eval_success_rate"] = [[0.8, 1.0], [1.0, 0.9]]  # mean 0.9 at 100
    assert experiments.table({"rope_state": summary}).splitlines()[2].split("|")[8].strip() == "100"
    fig = experiments.plot({"rope_state": summary}, tmp_path / "comparison.png")
    assert (tmp_path / "comparison.png").stat().st_size > 0
    success, distance = fig.axes[0], fig.axes[1]
    assert success.get_ylim() == (-0.02, 1.02) and distance.get_ylim() != (-0.02, 1.02)


def _eval_rows(distances: list[float], filtered: float = 0.0) -> list[dict]:
    return [
        {"env_steps": 100 * (i + 1), "eval_success_rate": float(d < 0.35), "eval_final_distance": d,
         "frac_filtered": filtered, "filtered_gt_success_rate": 0.5, "wall_time_s": 10.0 * (i + 1)}
        for i, d in enumerate(distances)
    ]  # fmt: skip


def test_included_summaries_merge_seed_by_seed(tmp_path):
    """Seeds of a committed summary join the runs here seed by seed: a seed run here is kept, a missing seed
    is added, seeds not asked for are left out, and the merged aggregate is the one of all the seeds' rows."""
    here = {0: _eval_rows([0.6, 0.5, 0.4]), 1: _eval_rows([0.7, 0.3], filtered=0.1)}
    elsewhere = {1: _eval_rows([9.0, 9.0]), 2: _eval_rows([0.5, 0.1], filtered=0.2), 3: _eval_rows([1.0])}
    # The summary round trip keeps every seed's values, past the evaluations all seeds share (the filter's precision is undefined where nothing
    # was filtered: NaN, null in the JSON).
    rebuilt = experiments.summary_runs(json.loads(json.dumps(experiments.summarize(elsewhere))), "x")
    assert sorted(rebuilt) == [1, 2, 3] and [r["eval_final_distance"] for r in rebuilt[2]] == [0.5, 0.1]
    assert [r["env_steps"] for r in rebuilt[3]] == [100]  # each seed's whole curve, the longer ones too
    assert rebuilt[2][0]["frac_filtered"] == 0.2 and rebuilt[2][0]["filtered_gt_success_rate"] == 0.5
    assert np.isnan(rebuilt[1][0]["filtered_gt_success_rate"])
    other = tmp_path / "summary.json"
    old_format = {  # one seed, per-seed values of the eval metrics only: the rest from the mean series
        "seeds": [0], "n_seeds": 1, "env_steps": [100, 200], "wall_time_s_per_run": 7.0,
        "per_seed": {"eval_success_rate": [[0.0, 1.0]], "eval_final_distance": [[0.8, 0.2]]},
        "series": {"reward_accuracy": {"mean": [0.9, 0.95], "std": [0.0, 0.0]}},
    }  # fmt: skip
    other.write_text(json.dumps({"tasks": {
        "rope_state": {"indicator": experiments.summarize({1: elsewhere[1], 2: elsewhere[2]}),
                       "oracle": old_format},
        "reach_state": {"oracle": old_format},
    }}))  # fmt: skip
    runs = {"rope_state": {"indicator": dict(here)}}
    added = experiments.include_summaries(runs, [other], ["indicator", "oracle"], seeds=[0, 1, 2])
    assert added == {str(other): ["rope_state/indicator/seed_2", "rope_state/oracle/seed_0"]}
    assert runs["rope_state"]["indicator"][1] is here[1]  # run here, kept
    ind = experiments.summarize(runs["rope_state"]["indicator"])
    assert ind["seeds"] == [0, 1, 2] and ind["env_steps"] == [100, 200]  # the shortest seed's evaluations
    assert ind["final_distance"]["mean"] == pytest.approx((0.5 + 0.3 + 0.1) / 3)
    assert ind["series"]["frac_filtered"]["mean"] == pytest.approx([0.1, 0.1])
    assert ind["wall_time_s_per_run"] == pytest.approx(20.0)
    oracle = experiments.summarize(runs["rope_state"]["oracle"])
    assert oracle["series"]["reward_accuracy"]["mean"] == [0.9, 0.95] and oracle["wall_time_s_per_run"] == 7.0
    # Not mergeable: no seed ids; several seeds without per-seed values; evaluations at other env steps.
    with pytest.raises(ValueError, match="no 'seeds' list"):
        experiments.summary_runs({k: v for k, v in old_format.items() if k != "seeds"}, "x")
    with pytest.raises(ValueError, match="2 seeds but no per-seed values of 'reward_accuracy'"):
        experiments.summary_runs({**old_format, "seeds": [0, 1], "n_seeds": 2}, "x")
    with pytest.raises(ValueError, match="seed 1: evaluations at other env steps"):
        experiments.summarize({0: _eval_rows([0.5]), 1: [{**_eval_rows([0.5])[0], "env_steps": 150}]})


def test_filter_diagnostics_counts_by_goal_source(trained_run, tmp_path):
    """Per-source counts add up, o_{t+1} goals are always indicator and ground-truth positives, recorded goals
    are never indicator positives here, and what the filter drops is a subset of the R- transitions."""
    from benchmarks.probes import filter_diagnostics as diagnostics

    cfg = diagnostics.FilterDiagnosticsConfig(
        run_dirs=[trained_run], batches=3, batch_size=64, out=tmp_path / "fd.json"
    )
    record = diagnostics.run(cfg)
    assert json.loads((tmp_path / "fd.json").read_text()) == json.loads(json.dumps(record))
    (run,) = record["runs"].values()
    assert list(run["steps"]) == [5] and run["balance"] and run["filter"]
    stats = run["steps"][5]
    assert stats["all"]["samples"] == 3 * 64
    for key in ("samples", "positive", "gt_success", "dropped", "dropped_gt_success"):
        assert sum(stats[s][key] for s in ("next", "future", "recorded")) == stats["all"][key]
    nxt, recorded = stats["next"], stats["recorded"]
    assert nxt["samples"] > 0 and nxt["positive"] == nxt["gt_success"] == nxt["samples"]
    assert nxt["dropped"] == 0  # positives are never filtered
    assert recorded["samples"] > 0 and recorded["positive"] == 0  # a reach goal is never hit bit for bit
    for source in stats.values():
        assert source["dropped"] <= source["samples"] - source["positive"]
        assert source["dropped_gt_success"] <= min(source["dropped"], source["gt_success"])

    with pytest.raises(ValueError, match="run_dirs"):
        diagnostics.run(diagnostics.FilterDiagnosticsConfig())


FAKE_TRAINER = """#!/usr/bin/env bash
# A trainer's clean stop takes a moment; a second signal within it is logged again.
trap 'kill $! 2>/dev/null; echo INT >> "$MARK"; sleep 0.5; exit 130' INT
trap 'kill $! 2>/dev/null; echo TERM >> "$MARK"; sleep 0.5; exit 143' TERM
echo started >> "$MARK"
case "$FAKE_MODE" in
  crash) exit 1 ;;
  killed) exit 143 ;;
  *) sleep 60 </dev/null >/dev/null 2>&1 & wait $! ;;
esac
"""
SWEEP_ARGS = ["--tasks=[reach_state]", "--methods=[oracle]", "--seeds=[0,1]"]


def _fake_trainer(tmp_path: Path, monkeypatch, mode: str) -> Path:
    """A fake ``lerobot-indicator-train`` for the sweep runner; it logs its start and the signals it gets."""
    bin_dir, mark = tmp_path / "bin", tmp_path / "mark"
    bin_dir.mkdir()
    (bin_dir / "lerobot-indicator-train").write_text(FAKE_TRAINER)
    (bin_dir / "lerobot-indicator-train").chmod(0o755)
    monkeypatch.setattr(experiments, "BIN", bin_dir)
    monkeypatch.setenv("MARK", str(mark))
    monkeypatch.setenv("FAKE_MODE", mode)
    return mark


def _when_started(mark: Path, then) -> threading.Thread:
    def wait_and_act():
        deadline = time.monotonic() + 60
        while not (mark.exists() and "started" in mark.read_text()) and time.monotonic() < deadline:
            time.sleep(0.05)
        then()

    thread = threading.Thread(target=wait_and_act, daemon=True)
    thread.start()
    return thread


@pytest.mark.parametrize(
    ("mode", "signum", "code", "line"),
    [
        ("wait", signal.SIGTERM, 143, "interrupted: rerun the same command"),  # kill of the sweep
        ("killed", None, 143, "interrupted: rerun the same command"),  # pkill of the trainer itself
        ("crash", None, 1, "stopped: reach_state/oracle/seed_0 failed with exit code 1"),
    ],
)
def test_sweep_stops_with_one_line_and_the_shells_exit_code(
    tmp_path, monkeypatch, capsys, mode, signum, code, line
):
    mark = _fake_trainer(tmp_path, monkeypatch, mode)
    dirs = [f"--out={tmp_path / 'out'}", f"--runs_dir={tmp_path / 'runs'}"]
    cfg = draccus.parse(experiments.ExperimentConfig, args=[*SWEEP_ARGS, *dirs])
    handler = signal.getsignal(signal.SIGTERM)
    if signum is not None:
        _when_started(mark, lambda: os.kill(os.getpid(), signum))
    with pytest.raises(SystemExit) as stop:
        experiments.launch_all(cfg)
    assert stop.value.code == code
    assert line in capsys.readouterr().err
    assert signal.getsignal(signal.SIGTERM) is handler  # the caller's SIGTERM handler is back
    # The trainer got the signal (forwarded), and the sweep did not go on to seed 1.
    assert mark.read_text().split() == ["started"] + (["TERM"] if signum else [])


def test_ctrl_c_reaches_the_trainer_once_and_the_sweep_exits_without_a_traceback(tmp_path, monkeypatch):
    """Ctrl-C signals the terminal's whole process group: the trainer must get it once, from the sweep."""
    mark = _fake_trainer(tmp_path, monkeypatch, "wait")
    # SIGINT handled as in a terminal: a test runner started in the background ignores it, and so would its children.
    run_sweep = (
        "import signal, sys; from pathlib import Path; from benchmarks.experiments import runner as e; "
        "signal.signal(signal.SIGINT, signal.default_int_handler); "
        "e.BIN = Path(sys.argv[1]); sys.argv = sys.argv[1:]; e.main()"
    )
    cmd = [sys.executable, "-c", run_sweep, str(experiments.BIN), *SWEEP_ARGS]
    cmd += [f"--out={tmp_path / 'out'}", f"--runs_dir={tmp_path / 'runs'}"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        _when_started(mark, lambda: os.killpg(proc.pid, signal.SIGINT)).join(timeout=120)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert "interrupted: rerun the same command" in err and "Traceback" not in err, err
    assert mark.read_text().split() == ["started", "INT"]


def test_replot_draws_the_chosen_arms_and_keeps_summary_and_table(tmp_path, monkeypatch):
    out = tmp_path / "experiments"
    shutil.copytree(ROOT / "docs" / "results" / "experiments", out)
    before = {name: (out / name).read_bytes() for name in ("summary.json", "table.md")}
    drawn = {}
    monkeypatch.setattr(
        experiments, "plot", lambda summary, path, reference: drawn.update({path.name: summary})
    )
    paper = ["oracle", "indicator_balance_filter", "indicator"]
    written = experiments.replot(out, paper, ["indicator_balance_recorded_fallback"])
    assert [p.name for p in written] == ["comparison.png", "ablations.png"]
    assert list(drawn["comparison.png"]["reach_state"]) == paper  # in the order asked for
    assert list(drawn["ablations.png"]["reach_state"]) == ["indicator_balance_recorded_fallback"]
    assert {name: (out / name).read_bytes() for name in before} == before
    with pytest.raises(ValueError, match="holds none of the methods"):
        experiments.replot(out, ["vae"], [])
