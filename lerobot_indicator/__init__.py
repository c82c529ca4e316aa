"""lerobot-indicator: indicator-reward goal-conditioned RL (Lin, Baweja, Held, CoRL 2019) as a LeRobot plugin."""

import lerobot_indicator.envs  # noqa: F401  (registers the sawyer_reach env type and gymnasium ids)
import lerobot_indicator.policy  # noqa: F401  (registers the indicator_ddpg policy type)
import lerobot_indicator.quiet_logs  # noqa: F401  (torchcodec's FFmpeg fallback in one line)
from lerobot_indicator import process

process.apply_environment()  # LEROBOT_INDICATOR_VIDEO_DECODER_THREADS, only when set (docs/policy.md)
