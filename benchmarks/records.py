"""Benchmark and diagnostics records: what they say about the machine, and writing them."""

import json
import os
import platform
import shlex
import subprocess
import sys
from pathlib import Path

import torch

# The repository root: benchmarks run from it as ``python -m benchmarks.<group>.<cli>``.
REPO = Path(__file__).resolve().parents[1]


def command_line() -> str:
    """The command that started this process, as ``python -m <module> <args>`` when run with ``-m``."""
    spec = getattr(sys.modules["__main__"], "__spec__", None)
    program = ["-m", spec.name] if spec is not None else [sys.argv[0]]
    return shlex.join(["python", *program, *sys.argv[1:]])


# CPU features that change which kernels torch's CPU ops use.
MATMUL_FLAGS = ("avx2", "avx512f", "avx512_bf16", "amx_bf16", "amx_tile")


def cpu_model() -> str:
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def cpu_flags() -> set[str]:
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("flags"):
                return set(line.split(":", 1)[1].split())
    return set()


def git_commit() -> str | None:
    """The checked-out commit of this repository (a ``+`` suffix when files outside docs/results have changes,
    where records are written), None outside git: a record names the code it measured."""
    root = REPO
    try:
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", ".", ":!docs/results"],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return head + ("+" if dirty else "")


def machine_record() -> dict[str, object]:
    """CPU model, the matmul-relevant flags it has, torch's CPU capability, versions and load."""
    flags = cpu_flags()
    return {
        "cpu": cpu_model(),
        "cpu_count": os.cpu_count(),
        "cpu_flags": {f: f in flags for f in MATMUL_FLAGS},
        "torch_cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "torch": torch.__version__,
        "python": platform.python_version(),
        "torch_threads": torch.get_num_threads(),
        "load_average_1_5_15_min": os.getloadavg(),
    }


def write_json(path: Path | None, record: dict) -> None:
    """Write ``record`` as indented JSON to ``path`` (parents created); nothing when ``path`` is None."""
    if path is None:
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=2) + "\n")
