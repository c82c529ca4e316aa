#!/usr/bin/env python
"""Record LeRobotDataset episodes of a lerobot-indicator task (see docs/dataset_format.md).

    MUJOCO_GL=egl python scripts/record.py --env.type=sawyer_reach --env.obs_type=rgbd \
        --policy=noisy_scripted --num_episodes=50 --repo_id=<user>/sawyer_reach_rgbd \
        --root=outputs/datasets/sawyer_reach_rgbd --push_to_hub=false

``--policy``: random | scripted | noisy_scripted | <pretrained policy directory>. ``--resume=true``
continues an existing dataset (also after a killed recording). ``--use_videos=true`` stores lossless
HEVC video instead of PNG/TIFF frames: the same decoded frames, cheaper for ``lerobot-train`` to load.
"""

from lerobot_indicator.data.recorder import main

if __name__ == "__main__":
    main()
