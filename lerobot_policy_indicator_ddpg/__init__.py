"""Discovery shim: LeRobot imports this module (the distribution name) to register our plugin.

Importing the real package registers the ``indicator_ddpg`` policy type and our env types.
"""

import lerobot_indicator  # noqa: F401
