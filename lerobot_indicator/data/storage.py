"""How recorded camera frames are stored: lossless video encoders for LeRobot's writer (docs/dataset_format.md).

The indicator reward needs identical decoded frames for identical stored frames and different decoded frames
for different stored ones, so every codec here is lossless on what the envs render:

- RGB: HEVC (x265 ``lossless=1``) in planar RGB (``gbrp``), so no RGB -> YUV rounding happens; pyav decodes
  it back to the recorded uint8 RGB bit for bit.
- Depth: LeRobot's depth codec (12-bit codes, HEVC lossless) with a *linear* map of 1 mm per code from 0 to
  4095 mm instead of LeRobot's default log map over 0.01-10 m, so uint16 mm depth up to 4.095 m (0 =
  invalid included) comes back as the same integer millimetres. Deeper readings would be clipped:
  :func:`check_depth_range` refuses them.

Video keeps the images out of the parquet rows, which is what makes ``lerobot-train``'s per-key delta queries
cheap (docs/dataset_format.md, "Loading cost").
"""

from typing import Any

import numpy as np
from lerobot.configs.video import DEPTH_QMAX, DepthEncoderConfig, RGBEncoderConfig

LOSSLESS_X265 = {"x265-params": "lossless=1"}
# Depth codes are millimetres: code q <-> q mm for q in [0, DEPTH_QMAX].
DEPTH_MAX_MM = DEPTH_QMAX


class DepthRangeError(ValueError):
    """A depth frame deeper than lossless video storage can hold."""


def video_encoders() -> dict[str, Any]:
    """``rgb_encoder`` / ``depth_encoder`` keyword arguments of ``LeRobotDataset.create`` / ``resume``."""
    return {
        "rgb_encoder": RGBEncoderConfig(vcodec="hevc", pix_fmt="gbrp", crf=None, extra_options=LOSSLESS_X265),
        "depth_encoder": DepthEncoderConfig(
            vcodec="hevc",
            pix_fmt="gray12le",
            crf=None,
            extra_options=LOSSLESS_X265,
            depth_min=0.0,
            depth_max=DEPTH_MAX_MM / 1000.0,
            use_log=False,
        ),
    }


def check_depth_range(key: str, depth_mm: np.ndarray) -> None:
    """Refuse a depth frame that lossless video storage would clip (one line: key, limit, actual)."""
    deepest = int(np.max(depth_mm))
    if deepest > DEPTH_MAX_MM:
        raise DepthRangeError(
            f"{key}: video storage holds depth up to {DEPTH_MAX_MM} mm losslessly, got {deepest} mm; "
            "record with --use_videos=false (16-bit frames) for deeper scenes"
        )
