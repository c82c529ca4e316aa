"""Compare rope-push camera framings on one fixed set of rope states (``benchmarks.probes.framing``).

    MUJOCO_GL=egl OMP_NUM_THREADS=1 nice -n 15 python -m benchmarks.probes.run_rope_framing \\
        --out docs/results/rope_framing.json --png docs/results/rope_framing.png

Framings: the default camera (1.7 m above the table, 58 degree fovy: a 1.0 m square view), a tighter top-down
view fitted to where the rope's links were in the first half of the episodes (its cropping is then counted on
all of them), and each with ``camera.supersample`` 4 (400 px rendered, area-averaged to 100 px).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch
from PIL import Image, ImageDraw

from benchmarks.probes.framing import (
    RGB,
    Framing,
    framing_statistics,
    load_or_collect,
    probe_framings,
    top_down_camera,
)
from benchmarks.records import command_line


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--png", type=Path, default=None)
    parser.add_argument("--states", type=Path, default=Path("outputs/rope_framing_states.npz"))
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--pushes", type=int, default=5, help="random pushes after each reset")
    parser.add_argument("--size", type=int, default=100)
    parser.add_argument("--supersample", type=int, default=4)
    parser.add_argument(
        "--margin", type=float, default=0.02, help="metres around the links for the tight view"
    )
    parser.add_argument("--updates", type=int, default=400, help="probe updates per framing; 0: no probe")
    parser.add_argument("--batch_size", type=int, default=32)
    parser.add_argument("--every", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    torch.set_num_threads(1)

    states = load_or_collect(args.states, args.episodes, args.pushes, args.seed)
    fit = states.link_xy[states.episode < args.episodes // 2]
    tight = top_down_camera(fit, args.margin)
    ss = {"supersample": args.supersample}
    framings = [
        Framing("default"),
        Framing(f"default_supersample{args.supersample}", ss),
        Framing("tight", tight),
        Framing(f"tight_supersample{args.supersample}", {**tight, **ss}),
    ]
    header = {
        "command": command_line(),
        "frames": len(states.states),
        "episodes": args.episodes,
        "pushes_per_episode": args.pushes,
        "link_xy_range_m": {
            "min": states.link_xy.reshape(-1, 2).min(0).tolist(),
            "max": states.link_xy.reshape(-1, 2).max(0).tolist(),
        },  # fmt: skip
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)

    def write(results: dict) -> None:
        args.out.write_text(json.dumps({**header, "framings": results}, indent=2) + "\n")
        print(f"wrote {args.out}: {json.dumps(results)}", flush=True)

    results, rendered = framing_statistics(framings, states, args.size, on_update=write)
    if args.png is not None:
        save_examples({name: frames[RGB][0].transpose(1, 2, 0) for name, frames in rendered.items()}, args)
    if args.updates > 0:
        probe = {
            "updates": args.updates,
            "batch_size": args.batch_size,
            "every": args.every,
            "seed": args.seed,
        }
        probe_framings(results, rendered, states, probe, on_update=write)


def save_examples(examples: dict[str, np.ndarray], args: argparse.Namespace) -> None:
    """One state's RGB frame under every framing, side by side, enlarged 3x without smoothing."""
    scale, pad, caption = 3, 6, 18
    px = args.size * scale
    canvas = Image.new("RGB", (len(examples) * (px + pad) + pad, px + caption + 2 * pad), "white")
    draw = ImageDraw.Draw(canvas)
    for i, (name, img) in enumerate(examples.items()):
        x = pad + i * (px + pad)
        canvas.paste(Image.fromarray(np.ascontiguousarray(img)).resize((px, px), Image.NEAREST), (x, pad))
        draw.text((x, px + pad + 3), f"{name} ({args.size} px)", fill="black")
    canvas.save(args.png)
    print(f"wrote {args.png}")


if __name__ == "__main__":
    main()
