"""Process-wide settings of the CLIs: torch's CPU threads, glibc's allocator, FFmpeg's video decoder threads.

Each changes the whole process and the processes it forks, so the policy never sets them (loading a policy,
e.g. in ``lerobot-eval``, leaves the process as it is). ``lerobot-indicator-train`` applies its own flags
(``--cpu_threads``, ``--keep_freed_memory``, ``--video_decoder_threads``) with ``apply``. Under LeRobot's
CLIs, ``environment`` gives the variables with the same effect; the plugin honours
``LEROBOT_INDICATOR_VIDEO_DECODER_THREADS`` when it is imported (docs/policy.md, "Process settings").
"""

import ctypes
import ctypes.util
import functools
import glob
import logging
import os
from pathlib import Path

import torch

VIDEO_DECODER_THREADS_ENV = "LEROBOT_INDICATOR_VIDEO_DECODER_THREADS"
# mallopt parameters (glibc malloc.h) and the trim threshold that never trims.
M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4
NEVER_TRIM = 2**31 - 1


def apply(cpu_threads: int | None, keep_freed: bool, video_decoder_threads: int | None) -> None:
    """torch's intra-op threads (None = torch's default), glibc keeping freed memory, and the threads of every
    video decoder opened from now on (None = FFmpeg's choice)."""
    if cpu_threads:
        torch.set_num_threads(cpu_threads)
    if keep_freed:
        keep_freed_memory()
    if not set_video_decoder_threads(video_decoder_threads) and video_decoder_threads:
        logging.warning(
            "video_decoder_threads=%d not applied: pyav's libavutil was not found in this process; video "
            "decoders keep FFmpeg's thread choice",
            video_decoder_threads,
        )


def environment(
    cpu_threads: int | None = 1, keep_freed: bool = True, video_decoder_threads: int | None = 1
) -> dict[str, str]:
    """The environment variables that give a process started with them the settings of ``apply``."""
    env = {}
    if cpu_threads:
        env["OMP_NUM_THREADS"] = str(cpu_threads)
    if keep_freed:  # glibc's names for mallopt(M_MMAP_MAX, 0) and mallopt(M_TRIM_THRESHOLD, NEVER_TRIM)
        env |= {"MALLOC_MMAP_MAX_": "0", "MALLOC_TRIM_THRESHOLD_": str(NEVER_TRIM)}
    if video_decoder_threads:
        env[VIDEO_DECODER_THREADS_ENV] = str(video_decoder_threads)
    return env


def apply_environment() -> None:
    """Apply ``LEROBOT_INDICATOR_VIDEO_DECODER_THREADS`` when it is set (a count >= 1); nothing otherwise."""
    value = os.environ.get(VIDEO_DECODER_THREADS_ENV, "").strip()
    if not value:
        return
    if not value.isdigit() or int(value) < 1:
        raise ValueError(f"{VIDEO_DECODER_THREADS_ENV} must be a thread count >= 1, got {value!r}")
    apply(None, False, int(value))


@functools.cache
def keep_freed_memory() -> bool:
    """Serve every allocation from the heap and never give freed heap memory back to the OS (glibc ``mallopt``).

    glibc maps each block above its mmap threshold (at most 32 MiB) afresh and unmaps it when freed, and trims
    the heap's free top. An image update allocates and frees dozens of such blocks (packed frames, feature
    maps and their gradients), so each is page-faulted in again on every update, one fault per 4 KiB page;
    on virtual machines that hand freed pages back to their host those faults are slow (docs/policy.md,
    "Process settings"). The process keeps its peak heap instead. Returns whether the setting took (False
    where the C library has no ``mallopt``)."""
    try:
        mallopt = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    return bool(mallopt(M_MMAP_MAX, 0)) and bool(mallopt(M_TRIM_THRESHOLD, NEVER_TRIM))


# FFmpeg's decoder threads. LeRobot's pyav reader opens one decoder per video key per sample and leaves its
# thread count to FFmpeg, which picks one thread per core plus one. pyav exposes no process-wide default, so
# ``set_video_decoder_threads`` sets the core count FFmpeg's automatic choice starts from (``av_cpu_force_count``
# in the libavutil that pyav loaded). Decoders already open keep their threads; a forked child inherits the
# setting, a spawned one starts from FFmpeg's default.


@functools.cache
def _libavutil() -> ctypes.CDLL | None:
    """The libavutil pyav's decoders use, or None if it is not found. Other packages may map their own copy
    (opencv bundles one), so the copy is picked by pyav's libavutil version, e.g. ``libavutil...so.59.39.100``."""
    import av

    version = ".".join(map(str, av.library_versions["libavutil"]))
    maps = Path("/proc/self/maps")
    mapped = set()
    if maps.exists():
        mapped = {line.split(maxsplit=5)[-1] for line in maps.read_text().splitlines() if "libavutil" in line}
    package = os.path.dirname(av.__file__)
    bundled = glob.glob(os.path.join(os.path.dirname(package), "av.libs", "libavutil*")) + glob.glob(
        os.path.join(package, ".dylibs", "libavutil*")
    )
    # pyav's version first, its wheel's copy before another package's copy of the same version
    candidates = sorted(
        {path for path in mapped | set(bundled) if version in os.path.basename(path)},
        key=lambda path: path not in bundled,
    )
    for path in candidates:
        try:
            lib = ctypes.CDLL(path)
            lib.av_cpu_force_count.argtypes = [ctypes.c_int]
            lib.av_cpu_count.restype = ctypes.c_int
            return lib
        except (OSError, AttributeError):
            continue
    return None


def set_video_decoder_threads(threads: int | None) -> bool:
    """Threads for the video decoders opened from now on in this process: 1 = single-threaded, n > 1 = FFmpeg's
    choice for n cores (n + 1 threads), None or 0 = FFmpeg's choice for the detected cores. Returns whether the
    setting took (False where pyav's libavutil could not be found)."""
    if threads is not None and threads < 0:
        raise ValueError(f"video_decoder_threads must be None or >= 0, got {threads}")
    lib = _libavutil()
    if lib is None:
        return False
    lib.av_cpu_force_count(threads or 0)
    return True


def ffmpeg_cores() -> int | None:
    """The core count FFmpeg's automatic thread choice starts from now (None where libavutil is not found)."""
    lib = _libavutil()
    return None if lib is None else int(lib.av_cpu_count())
