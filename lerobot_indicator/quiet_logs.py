"""Known-harmless third-party warnings reduced to one line.

Where torchcodec cannot load FFmpeg's shared libraries, LeRobot logs torchcodec's whole loading traceback (about
40 lines, one block per FFmpeg version tried) each time it picks a video backend, then falls back to pyav,
which decodes the same videos. Importing this package (the CLIs and LeRobot's plugin discovery do) replaces
that record by one line saying which backend is used.
"""

import logging

TORCHCODEC_TRACEBACK = "[start of libtorchcodec loading traceback]"


class _TorchcodecFallback(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        if TORCHCODEC_TRACEBACK in str(record.msg):
            record.msg = "torchcodec cannot load FFmpeg's libraries here; videos are decoded with pyav"
            record.args = ()
        return True


logging.getLogger("lerobot.utils.import_utils").addFilter(_TorchcodecFallback())
