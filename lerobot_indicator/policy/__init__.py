"""The ``indicator_ddpg`` policy; importing this package registers its config with LeRobot."""

from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig

__all__ = ["IndicatorDDPGConfig"]
