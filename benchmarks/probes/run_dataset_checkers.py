"""Third-party LeRobotDataset checkers on a fresh ``lerobot-indicator-record`` recording: what each reports.

Records a small RGB-D Sawyer reach dataset (videos, the scripted noisy policy), then runs ``lerobot-doctor``,
``lelint`` (lerobot-lint) and ``lerobot-quality-gates`` on it and writes every finding with its severity to one
JSON. The checkers are not project dependencies: install them where ``--checkers_path`` points, without their
dependencies (they need only packages the project already has, plus ``typer`` for lelint)::

    pip install --no-deps --target /tmp/checkers lerobot-doctor==0.2.0 lerobot-lint==0.1.1 \\
        lerobot-quality-gates==0.1.7 typer shellingham annotated-doc
    MUJOCO_GL=egl python -m benchmarks.probes.run_dataset_checkers --checkers_path /tmp/checkers \\
        --out docs/results/dataset_checkers.json
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.records import command_line

BIN = Path(sys.executable).parent
CHECKERS = {
    "lerobot-doctor": ["-m", "lerobot_doctor.cli", "check", "--json"],
    "lelint": ["-m", "lerobot_lint.cli", "check", "--json", "{json}"],
    "lerobot-quality-gates": ["-m", "lerobot_quality_gates.cli", "check", "--format", "json"],
}


def run_checker(name: str, root: Path, env: dict[str, str], tmp: Path) -> dict:
    """One checker's verdict on ``root``: its exit code and its findings as it reports them."""
    report = tmp / f"{name}.json"
    args = [a.replace("{json}", str(report)) for a in CHECKERS[name]]
    proc = subprocess.run([sys.executable, *args, str(root)], capture_output=True, text=True, env=env)
    text = report.read_text() if report.exists() else proc.stdout
    start = text.find("{")
    try:
        parsed = json.loads(text[start:]) if start >= 0 else None
    except json.JSONDecodeError:
        parsed = None
    return {"returncode": proc.returncode, "report": parsed if parsed is not None else text[-4000:]}


def findings(name: str, report: dict | str) -> list[dict]:
    """The warnings and errors (not the informational lines) of a checker's report, in one shape."""
    if not isinstance(report, dict):
        return []
    if name == "lelint":
        return [{"severity": f["severity"], "check": f["check"], "message": f["message"]}
                for f in report["findings"] if f["severity"] != "info"]  # fmt: skip
    if name == "lerobot-quality-gates":
        return [{"severity": f.get("severity"), "check": f.get("gate"), "message": f.get("finding") or f.get("message")}
                for f in report.get("findings", [])]  # fmt: skip
    return [{"severity": m["severity"].lower(), "check": check["name"], "message": m["message"]}
            for check in report.get("checks", []) for m in check.get("messages", [])
            if m["severity"] not in ("PASS", "INFO")]  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--checkers_path", type=Path, required=True, help="where the checkers are installed")
    p.add_argument("--episodes", type=int, default=6)
    p.add_argument("--out", type=Path, default=Path("docs/results/dataset_checkers.json"))
    args = p.parse_args()
    env = {**os.environ, "PYTHONPATH": str(args.checkers_path), "HF_HUB_OFFLINE": "1"}
    env.setdefault("MUJOCO_GL", "egl")
    with tempfile.TemporaryDirectory() as tmp:
        tmp, root = Path(tmp), Path(tmp) / "reach_rgbd"
        record = [str(BIN / "lerobot-indicator-record"), "--env.type=sawyer_reach", "--env.obs_type=rgbd",
                  "--repo_id=local/checked_reach_rgbd", f"--root={root}", f"--num_episodes={args.episodes}",
                  "--policy=noisy_scripted", "--use_videos=true", "--push_to_hub=false"]  # fmt: skip
        subprocess.run(record, check=True, capture_output=True, env=env)
        results = {}
        for name in CHECKERS:
            verdict = run_checker(name, root, env, tmp)
            results[name] = {"returncode": verdict["returncode"], "findings": findings(name, verdict["report"]),
                             "report": verdict["report"]}  # fmt: skip
        files = sorted(p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file())
    versions = {}
    for dist in ("lerobot_doctor", "lerobot_lint", "lerobot_quality_gates"):
        found = list(args.checkers_path.glob(f"{dist}-*.dist-info"))
        versions[dist] = re.sub(rf"^{dist}-|\.dist-info$", "", found[0].name) if found else None
    record_out = {
        "what": "third-party LeRobotDataset checkers on a lerobot-indicator-record RGB-D recording",
        "command": command_line(),
        "recording": " ".join(record[:4] + record[5:]),
        "checker_versions": versions,
        "dataset_files": files,
        "checkers": results,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record_out, indent=1, default=str) + "\n")
    for name, r in results.items():
        print(f"{name}: exit {r['returncode']}, {len(r['findings'])} warnings/errors")
        for f in r["findings"][:8]:
            print(f"  [{f['severity']}] {f['check']}: {f['message']}")


if __name__ == "__main__":
    main()
