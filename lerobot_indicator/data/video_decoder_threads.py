"""How many threads FFmpeg gives each video decoder that LeRobot's pyav reader opens in this process.

LeRobot's pyav reader opens one decoder per video key per sample and leaves its thread count to FFmpeg, which
picks one thread per core plus one. A 64-100 px frame is one or two rows of HEVC coding blocks, so those threads
have almost nothing to share: each frame is handed to them and collected again, and with loader workers and
the update competing for 2 cores every hand-off waits for a core. One thread per decoder avoids that (the
measured effect on ``lerobot-train`` is in docs/results/README.md, "Loading RGB-D datasets").

pyav exposes no process-wide default, so this sets the core count FFmpeg's automatic choice starts from
(``av_cpu_force_count`` in the libavutil that pyav loaded): 1 makes every later decoder single-threaded,
n > 1 gives FFmpeg's choice for n cores, and 0 returns to the detected count. Decoders already open keep
their threads; a forked child inherits the setting, a spawned one starts from FFmpeg's default.
"""

import ctypes
import functools
import glob
import os
from pathlib import Path


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
