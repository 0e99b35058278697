"""Running a saved policy deterministically (the mean action, or the most likely one), optionally filmed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from minippo.agent_files import load_policy
from minippo.envs import make_env
from minippo.errors import MinippoError
from minippo.run_folder import RunFolder


def evaluate(
    run_dir, episodes: int = 10, seed: int = 0, gif=None, max_frames: int = 300, frame_skip: int = 2, size: int = 320
):
    """Return the list of episode returns of the policy saved in ``run_dir`` (or a policy.npz path)."""
    path = Path(run_dir)
    if path.is_dir():
        path = RunFolder(path).policy_npz
    if episodes < 1:
        raise MinippoError(f"--episodes must be at least 1, not {episodes}")
    agent, normalizer, meta = load_policy(path)
    env = make_env(meta["env_id"], render_mode="rgb_array" if gif else None, size=size if gif else None)
    if gif:
        try:
            env.reset(seed=seed)
            env.render()
        except Exception as error:  # e.g. a renderer's package missing (gymnasium's DependencyNotInstalled)
            env.close()
            reason = str(error).splitlines()[0] if str(error) else type(error).__name__
            raise MinippoError(f"--gif: {meta['env_id']} cannot render here ({reason})")
    frames, returns = [], []
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        total, done = 0.0, False
        while not done:
            if gif and episode == 0 and len(frames) < max_frames:
                frames.append(env.render())
            out = agent.policy_output(normalizer(np.asarray(obs, dtype=np.float64)[None]))
            action = agent.distribution(out).mode()[0]
            if agent.kind == "continuous":
                action = np.clip(action, env.action_space.low, env.action_space.high)
            obs, reward, terminated, truncated, _ = env.step(action)
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    env.close()
    if gif:
        write_gif(frames[::frame_skip], gif, fps=int(round(env.metadata.get("render_fps", 50) / frame_skip)))
    return returns


def write_gif(frames, path, fps: int = 25) -> None:
    from PIL import Image

    if not frames:
        raise MinippoError("nothing was rendered, so no GIF was written")
    # one shared palette keeps the file small and the encoding fast
    first = Image.fromarray(np.asarray(frames[0])).quantize(colors=128, method=Image.Quantize.MEDIANCUT)
    images = [Image.fromarray(np.asarray(frame)).quantize(palette=first, dither=Image.Dither.NONE) for frame in frames]
    duration = int(1000 / max(fps, 1))
    images[0].save(path, save_all=True, append_images=images[1:], optimize=False, duration=duration, loop=0)
