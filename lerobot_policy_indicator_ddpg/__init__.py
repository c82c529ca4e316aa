"""Discovery shim: LeRobot imports this module (the distribution name) to register our plugin.

Importing the real package registers the ``indicator_ddpg`` policy type and our env types. LeRobot's CLIs
(``lerobot-train``, ``lerobot-eval``) import it through plugin discovery; in them, this plugin's config errors,
corrupt checkpoint files and full disks end in one line instead of a traceback (``lerobot_indicator.io_errors``).
In ``lerobot-train`` the dataset is also checked (info.json, shapes, content hashes:
``lerobot_indicator.data.integrity``) before LeRobot reads it. In both, an indicator_ddpg policy is checked
against the eval env right after it is made (keys and image sizes: ``lerobot_indicator.policy.input_checks``).
"""

import lerobot_indicator  # noqa: F401
from lerobot_indicator.data.integrity import install_lerobot_train_check
from lerobot_indicator.io_errors import install_excepthook
from lerobot_indicator.policy.input_checks import install_lerobot_env_check

install_excepthook()
install_lerobot_train_check()
install_lerobot_env_check()
