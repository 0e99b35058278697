"""An animation of a trained policy for the book, through minippo's own evaluation (``minippo.evaluate.evaluate``).

    MUJOCO_GL=egl python tools/animate.py benchmarks/runs/mujoco/Hopper-v5-seed2 book/_static/media/hopper.gif

Same as ``minippo eval RUN --episodes 1 --gif OUT`` (the deterministic policy, first episode, reset seed 0), with the
frame spacing chosen for GIF players: a GIF stores delays in hundredths of a second and browsers slow delays of
10 ms or less down to 100 ms, so Hopper's 125 frames per second are thinned to 25 (every 5th frame, 40 ms each).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", help="a run folder with policy.npz")
    parser.add_argument("out", help="the GIF to write")
    parser.add_argument("--fps", type=int, default=25, help="frames per second of the GIF (at most 50)")
    parser.add_argument("--seconds", type=float, default=4.0, help="simulated seconds to film")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if not 1 <= args.fps <= 50 or args.seconds <= 0:
        print("animate.py: error: --fps must lie in 1..50 and --seconds be positive", file=sys.stderr)
        return 2
    if not (Path(args.run) / "policy.npz").exists():
        print(f"animate.py: error: no policy.npz in {args.run}", file=sys.stderr)
        return 2
    import minippo.evaluate
    from minippo.agent_files import load_policy
    from minippo.envs import make_env
    from minippo.errors import MinippoError
    from minippo.evaluate import evaluate

    def make_tracking_env(*args, **kwargs):
        # minippo asks for a camera that follows the robot, but two things undo it here: its "type": 2 is
        # mjCAMERA_FIXED in MuJoCo's numbering (tracking is 1), and Gymnasium 1.4 renders with camera_id = -1,
        # which resets the camera to a free one at every frame. Ask for tracking, and pass no camera id.
        env = make_env(*args, **kwargs)
        renderer = getattr(env.unwrapped, "mujoco_renderer", None)
        if renderer is not None and kwargs.get("size") is not None and renderer.default_cam_config:
            import mujoco

            renderer.default_cam_config = {**renderer.default_cam_config, "type": mujoco.mjtCamera.mjCAMERA_TRACKING}
            renderer.camera_id = None
        return env

    minippo.evaluate.make_env = make_tracking_env

    try:
        _, _, meta = load_policy(Path(args.run) / "policy.npz")
        env = make_env(meta["env_id"])
        render_fps = env.metadata.get("render_fps", 50)
        env.close()
        frame_skip = max(1, math.ceil(render_fps / args.fps))
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        max_frames = int(args.seconds * render_fps)
        returns = evaluate(args.run, 1, args.seed, args.out, max_frames=max_frames, frame_skip=frame_skip)
    except MinippoError as error:
        print(f"animate.py: error: {error}", file=sys.stderr)
        return 2
    size = Path(args.out).stat().st_size / 1e6
    print(
        f"return {returns[0]:.1f}; {max_frames // frame_skip} frames, every {frame_skip}th, {size:.1f} MB -> {args.out}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
