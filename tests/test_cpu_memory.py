"""``keep_freed_memory``: a large tensor allocated again after being freed reuses mapped pages (no page faults),
and glibc's environment variables of docs/policy.md ("Process settings") give the same. Each measurement runs
in a fresh interpreter: the setting is process-wide and cannot be undone."""

import ctypes
import ctypes.util
import json
import os
import subprocess
import sys

import pytest

from lerobot_indicator import process

FAULTS_OF_A_REALLOCATION = """
import json, resource, sys, torch
from lerobot_indicator.process import keep_freed_memory
took = keep_freed_memory() if sys.argv[1] == "keep" else None
for _ in range(10):  # the heap settles after a few aligned allocations of this size
    x = torch.ones(16 * 1024 * 1024)  # 64 MiB, above glibc's largest mmap threshold
    del x
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
x = torch.ones(16 * 1024 * 1024)
print(json.dumps({"took": took, "faults": resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before}))
"""


def faults_of_a_reallocation(mode: str, env: dict[str, str] | None = None) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", FAULTS_OF_A_REALLOCATION, mode],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, **(env or {})},
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def default_faults() -> int:
    """Page faults of the reallocation with glibc's defaults: the 64 MiB are unmapped on free and faulted in
    again (16,384 pages of 4 KiB; 32 if the kernel backs them with 2 MiB pages)."""
    if not hasattr(ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6"), "mallopt"):
        pytest.skip("the C library has no mallopt (not glibc)")
    faults = faults_of_a_reallocation("default")["faults"]
    assert faults >= 32
    return faults


def test_freed_memory_is_reused_without_page_faults(default_faults):
    kept = faults_of_a_reallocation("keep")
    assert kept["took"]
    assert kept["faults"] * 10 < default_faults  # reused as they are


@pytest.mark.parametrize("variables", ["MALLOC_", "GLIBC_TUNABLES"])
def test_glibc_environment_variables_keep_freed_memory_too(default_faults, variables):
    env = process.environment(cpu_threads=None, keep_freed=True, video_decoder_threads=None)
    assert env == {"MALLOC_MMAP_MAX_": "0", "MALLOC_TRIM_THRESHOLD_": str(2**31 - 1)}
    if variables == "GLIBC_TUNABLES":
        env = {"GLIBC_TUNABLES": "glibc.malloc.mmap_max=0:glibc.malloc.trim_threshold=2147483647"}
    assert faults_of_a_reallocation("default", env)["faults"] * 10 < default_faults
