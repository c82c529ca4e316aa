"""``keep_freed_memory``: a large tensor allocated again after being freed reuses mapped pages (no page faults),
and the policy applies it unless told not to. Each measurement runs in a fresh interpreter: the setting is
process-wide and cannot be undone."""

import json
import subprocess
import sys

import pytest

from benchmarks.speed.updates import STATE_FEATURES, make_policy
from lerobot_indicator.policy import modeling_indicator_ddpg

FAULTS_OF_A_REALLOCATION = """
import json, resource, sys, torch
from lerobot_indicator.policy.cpu_memory import keep_freed_memory
took = keep_freed_memory() if sys.argv[1] == "keep" else None
for _ in range(3):  # the heap settles after a couple of aligned allocations of this size
    x = torch.ones(16 * 1024 * 1024)  # 64 MiB, above glibc's largest mmap threshold
    del x
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
x = torch.ones(16 * 1024 * 1024)
print(json.dumps({"took": took, "faults": resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before}))
"""


def faults_of_a_reallocation(mode: str) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", FAULTS_OF_A_REALLOCATION, mode], capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_freed_memory_is_reused_without_page_faults():
    default, kept = faults_of_a_reallocation("default"), faults_of_a_reallocation("keep")
    if not kept["took"]:
        pytest.skip("the C library has no mallopt (not glibc)")
    # By default the 64 MiB are unmapped on free and faulted in again (16,384 pages of 4 KiB; 32 if the kernel
    # backs them with 2 MiB pages); kept, they are reused as they are.
    assert default["faults"] >= 32
    assert kept["faults"] * 10 < default["faults"]


def test_policy_keeps_freed_memory_unless_told_not_to(monkeypatch):
    calls = []
    monkeypatch.setattr(modeling_indicator_ddpg, "keep_freed_memory", lambda: calls.append(1))
    make_policy(STATE_FEATURES)
    assert calls == [1]
    make_policy(STATE_FEATURES, keep_freed_memory=False)
    assert calls == [1]
