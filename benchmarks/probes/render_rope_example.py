"""Picture of one rope-push episode for the docs: start, goal, the gripper pushing, and pushed results.

MUJOCO_GL=egl .venv/bin/python -m benchmarks.probes.render_rope_example --out docs/rope_push_example.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from lerobot_indicator.envs.rope_push import RopePushEnv
from lerobot_indicator.keys import GT_DISTANCE

PX = 200


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("docs/rope_push_example.png"))
    parser.add_argument("--seed", type=int, default=4)
    args = parser.parse_args()

    env = RopePushEnv(obs_type="rgb", camera={"width": PX, "height": PX})
    try:
        obs, info = env.reset(seed=args.seed)
        panels = [(obs["pixels"]["front"], f"start  (d={info[GT_DISTANCE]:.2f})")]
        panels.append((obs["pixels"]["goal_front"], "goal image (2 hidden pushes)"))
        hidden = env.goal_push_actions

        # A wrong first push: the mirror image of the first hidden push.
        saved = env.save_state()
        wrong = hidden[0].copy()
        wrong[[1, 3]] = wrong[[3, 1]]
        obs, _, _, _, info = env.step(wrong)
        wrong_panel = (obs["pixels"]["front"], f"a wrong push  (d={info[GT_DISTANCE]:.2f})")
        env.restore_state(saved)

        # Film the first hidden push and keep the frame half-way through it.
        frames = []
        env.sim.on_push_step = lambda: frames.append(env.render())
        obs, _, _, _, info = env.step(hidden[0])
        env.sim.on_push_step = None
        panels.append((frames[int(len(frames) * 0.6)], "pushing (gripper shown)"))
        panels.append((obs["pixels"]["front"], f"after hidden push 1  (d={info[GT_DISTANCE]:.2f})"))
        obs, _, _, _, info = env.step(hidden[1])
        ok = "success" if info["is_success"] else "fail"
        panels.append((obs["pixels"]["front"], f"after push 2  (d={info[GT_DISTANCE]:.2f}, {ok})"))
        panels.append(wrong_panel)
    finally:
        env.close()

    pad, caption = 6, 18
    canvas = Image.new("RGB", (len(panels) * (PX + pad) + pad, PX + caption + 2 * pad), "white")
    draw = ImageDraw.Draw(canvas)
    for i, (img, text) in enumerate(panels):
        x = pad + i * (PX + pad)
        canvas.paste(Image.fromarray(np.asarray(img)), (x, pad))
        draw.text((x + 2, PX + pad + 3), text, fill="black")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
