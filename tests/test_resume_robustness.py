"""A run's saved files under failure: a corrupt checkpoint never blocks a resume whose own state is intact and
is one line naming the file wherever it is read; a full disk stops a run in one line saying what is kept; a
torn last metrics line never blocks a resume; metrics are strict JSON."""

import errno
import json
import math
import subprocess
import sys

import draccus
import pytest
from lerobot.common import train_utils
from test_online_training import BIN, ENVS, TINY, _env, _metrics

from lerobot_indicator.io_errors import CorruptFileError, DiskFullError
from lerobot_indicator.training import online, run_state
from lerobot_indicator.training.config import OnlineTrainConfig
from lerobot_indicator.training.run_state import METRICS_FILE, RunDir

REACH = ENVS["sawyer_reach"]


def _truncate(path, keep: int = 100) -> None:
    data = path.read_bytes()
    assert len(data) > keep
    path.write_bytes(data[:keep])


def _run(*args: str, ok: bool = True) -> subprocess.CompletedProcess:
    cmd = [str(BIN / "lerobot-indicator-train"), *TINY, *REACH, *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=_env())
    if ok:
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    return proc


def _last_line(proc: subprocess.CompletedProcess) -> str:
    return proc.stderr.strip().splitlines()[-1]


def test_resume_needs_only_its_own_state_and_a_corrupt_checkpoint_is_one_line_in_lerobot_eval(tmp_path):
    """A truncated checkpoints/last and a torn last metrics line (a crash or a full disk while saving): the resume
    continues from resume/ (the last metrics row is rewritten), and lerobot-eval of the corrupt checkpoint ends in
    one line naming its model.safetensors."""
    out = tmp_path / "run"
    _run(f"--output_dir={out}", "--steps=10")
    weights = (out / "checkpoints" / "last").resolve() / "pretrained_model" / "model.safetensors"
    _truncate(weights)
    rows = _metrics(out)
    metrics = out / METRICS_FILE
    metrics.write_text(metrics.read_text() + '{"cycle": 2, "step": 1')  # a torn append
    _run(f"--output_dir={out}", "--steps=15", "--resume=true")
    resumed = _metrics(out)
    assert [r["step"] for r in resumed] == [5, 10, 15]
    assert resumed[:2] == rows  # the rows before the resume state are kept as they were
    assert metrics.read_text().endswith("}\n")

    cmd = [str(BIN / "lerobot-eval"), f"--policy.path={weights.parent}", "--policy.device=cpu",
           "--eval.batch_size=1", "--eval.n_episodes=1", f"--output_dir={tmp_path / 'eval'}", *REACH]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=_env())
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    line = _last_line(proc)
    assert line.startswith("error: ") and f"{weights}: cannot read the policy weights" in line, line
    assert "truncated or corrupt" in line


def test_a_corrupt_resume_state_is_one_line_naming_the_file(tmp_path):
    from test_run_state import _policy_and_optimizer

    run_dir = RunDir(tmp_path)
    policy, optimizer = _policy_and_optimizer(0)
    run_dir.save_state(policy, optimizer, run_state.Progress(cycle=3, step=30))
    _truncate(tmp_path / "resume" / "model.safetensors", 50)
    with pytest.raises(
        CorruptFileError, match=r"resume/model\.safetensors: cannot read the resume state's weights"
    ):
        run_dir.load_state(policy, optimizer)
    (tmp_path / "resume" / "progress.json").write_text('{"cycle": 3, "st')
    with pytest.raises(CorruptFileError, match=r"progress\.json: cannot read"):
        run_dir.read_progress()


def test_from_pretrained_of_a_truncated_checkpoint_names_the_file(tmp_path):
    from test_policy import STATE, make_config, vec

    from lerobot_indicator.keys import goal_key
    from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

    policy = IndicatorDDPGPolicy(make_config({STATE: vec(), goal_key(STATE): vec()}))
    policy.save_pretrained(tmp_path)
    _truncate(tmp_path / "model.safetensors")
    with pytest.raises(CorruptFileError) as err:
        IndicatorDDPGPolicy.from_pretrained(tmp_path)
    message = str(err.value)
    assert str(tmp_path / "model.safetensors") in message and "\n" not in message
    assert "100 bytes" in message


def test_a_torn_last_metrics_line_is_dropped_and_others_are_an_error(tmp_path):
    run_dir = RunDir(tmp_path)
    for cycle in range(3):
        run_dir.append_metrics({"cycle": cycle, "step": 5 * (cycle + 1), "q": 0.5})
    metrics = tmp_path / METRICS_FILE
    metrics.write_text(metrics.read_text() + '{"cycle": 3, "st')
    run_dir.drop_metrics_from(2)
    assert [json.loads(line)["cycle"] for line in metrics.read_text().splitlines()] == [0, 1]
    metrics.write_text('{"cycle": 0}\n{"cyc\n{"cycle": 2}\n')
    with pytest.raises(CorruptFileError, match=r"metrics\.jsonl:2: not a JSON line"):
        run_dir.drop_metrics_from(2)


def test_metrics_are_strict_json_with_null_for_non_finite_values(tmp_path):
    from lerobot_indicator.training.plots import read_metrics

    RunDir(tmp_path).append_metrics(
        {"cycle": 0, "step": 5, "a": math.nan, "b": math.inf, "c": -math.inf, "d": 1.5}
    )
    line = (tmp_path / METRICS_FILE).read_text()
    assert json.loads(line, parse_constant=pytest.fail) == {"cycle": 0, "step": 5, "a": None, "b": None,
                                                            "c": None, "d": 1.5}  # fmt: skip
    (row,) = read_metrics(tmp_path / METRICS_FILE)
    assert math.isnan(row["a"]) and row["d"] == 1.5  # the learning curve plots null as a gap


def _disk_full(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def _cfg(out, *args: str) -> OnlineTrainConfig:
    cfg = draccus.parse(OnlineTrainConfig, args=[*TINY, *REACH, f"--output_dir={out}", *args])
    return cfg


@pytest.mark.parametrize(
    ("target", "kept"),
    [
        # The resume state of cycle 1 (step 10) fails: cycle 0's state and the step-10 checkpoint are kept.
        (
            (run_state, "save_model", 2),
            ["checkpoint {out}/checkpoints/000010", "resume state of cycle 0 (step 5)"],
        ),
        # The step-10 checkpoint fails after its weights were written: nothing of it is left, the resume state
        # of cycle 0 is kept.
        ((train_utils, "save_training_state", 1), ["resume state of cycle 0 (step 5)"]),
        # The metrics line of cycle 1 fails.
        ((RunDir, "append_metrics", 2), ["resume state of cycle 0 (step 5)"]),
    ],
)
def test_a_full_disk_stops_the_run_in_one_line_saying_what_is_kept(
    tmp_path, monkeypatch, caplog, target, kept
):
    owner, name, failing_call = target
    real, calls = getattr(owner, name), []

    def write(*args, **kwargs):
        calls.append(1)
        if len(calls) == failing_call:
            _disk_full()
        return real(*args, **kwargs)

    monkeypatch.setattr(owner, name, write)
    out = tmp_path / "run"
    with caplog.at_level("INFO"), pytest.raises(DiskFullError) as err:
        online.train(_cfg(out, "--steps=20"))
    message = str(err.value)
    assert "\n" not in message and f"the disk holding {out} is full" in message
    assert "No space left on device" in message and "--resume=true" in message
    for what in kept:
        assert what.format(out=out) in message, message
    if len(kept) == 1:
        assert "checkpoint" not in message.split("Kept:")[1]
        assert not (out / "checkpoints" / "000010").exists()  # no part-written checkpoint is left
    assert "building 1 sawyer_reach env(s) (obs_type=state)" in caplog.text  # said before the first update

    monkeypatch.setattr(owner, name, real)  # space freed: the run resumes and finishes
    online.train(_cfg(out, "--steps=20", "--resume=true"))
    assert [r["step"] for r in _metrics(out)] == [5, 10, 15, 20]


ENOSPC_IN_CHILD = """
import errno, sys
from lerobot_indicator.training import online, run_state

def full(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")

run_state.save_model = full
sys.argv = ["lerobot-indicator-train", *sys.argv[1:]]
online.main()
"""


def test_lerobot_indicator_train_on_a_full_disk_ends_in_one_line(tmp_path):
    out = tmp_path / "run"
    cmd = [sys.executable, "-c", ENOSPC_IN_CHILD, *TINY, *REACH, f"--output_dir={out}", "--steps=10"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=_env())
    assert proc.returncode == 1
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    line = _last_line(proc)
    assert line.startswith("error: stopped: the disk holding") and "nothing to resume from yet" in line, line
    assert not (out / "resume").exists() and not (out / "resume.tmp").exists()  # what was written is freed


@pytest.mark.parametrize("updates_per_cycle", [5, 7])
def test_steps_are_honoured_exactly_and_the_bar_keeps_its_total(tmp_path, monkeypatch, updates_per_cycle):
    bars = []
    real_update = online.tqdm.update

    def update(bar, n=1):
        result = real_update(bar, n)
        bars.append((bar.n, bar.total))
        return result

    monkeypatch.setattr(online.tqdm, "update", update)
    out = tmp_path / "run"
    cfg = _cfg(out, "--steps=12", f"--online.updates_per_cycle={updates_per_cycle}", "--env_eval_freq=0")
    online.train(cfg)
    steps = [r["step"] for r in _metrics(out)]
    expected = list(range(updates_per_cycle, 12, updates_per_cycle)) + [12]
    assert steps == expected
    assert bars[-1] == (12, 12) and all(n <= total for n, total in bars)
    assert (out / "checkpoints" / "last").resolve().name == "000012"
    assert "eval_success_rate" in _metrics(out)[-1]  # the last, shortened cycle is still the last
