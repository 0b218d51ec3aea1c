"""The peer of `dronectl bench sim`'s camera world: a PyFlyt QuadX hovering with its 224x224 camera at 30 fps.

Run as a script by the interpreter that has PyFlyt (the optional extra `[peer]`; PyFlyt 0.29 pins
numpy < 2, so it usually lives in a venv of its own): `python controller/benchmarks/pyflyt_peer.py
--seconds 10` prints one JSON line, the real-time factor of `seconds` of simulated hovering after a
warm-up second. It imports nothing of this project (the product never imports PyFlyt), so it runs in
an environment that holds only PyFlyt and its dependencies.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time


def hover_rtf(seconds: float, resolution: int, fps: int) -> dict[str, float]:
    """Simulated seconds per wall second of a QuadX holding a position with its camera on."""
    import numpy as np
    from PyFlyt.core import Aviary

    env = Aviary(
        start_pos=np.array([[0.0, 0.0, 1.0]]),
        start_orn=np.array([[0.0, 0.0, 0.0]]),
        drone_type="quadx",
        drone_options={"use_camera": True, "camera_resolution": (resolution, resolution), "camera_fps": fps},
        render=False,
    )
    try:
        env.set_mode(7)  # position control: hold [x, y, yaw, z]
        env.set_setpoint(0, np.array([0.0, 0.0, 0.0, 1.0]))
        step_s = env.updates_per_step / env.physics_hz
        for _ in range(round(1.0 / step_s)):  # warm-up: textures, first frames
            env.step()
        steps = round(seconds / step_s)
        start, cpu = time.perf_counter(), time.process_time()
        for _ in range(steps):
            env.step()
        wall_s, cpu_s = time.perf_counter() - start, time.process_time() - cpu
        frames = steps * env.updates_per_step // env.drones[0].physics_camera_ratio
        return {
            "real_time_factor": steps * step_s / wall_s,
            "cpu_real_time_factor": steps * step_s / cpu_s,
            "sim_s": steps * step_s,
            "wall_s": wall_s,
            "frames": float(frames),
            "height_m": float(env.state(0)[-1][-1]),
        }
    finally:
        env.disconnect()


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated seconds timed")
    parser.add_argument("--resolution", type=int, default=224, help="camera width and height, px")
    parser.add_argument("--fps", type=int, default=30, help="camera frames per simulated second")
    args = parser.parse_args(argv)
    try:
        import PyFlyt  # noqa: F401
    except ImportError:
        print(json.dumps({"error": f"PyFlyt is not installed for {sys.executable}"}))
        return 2
    result = hover_rtf(args.seconds, args.resolution, args.fps)
    print(json.dumps({**result, "load_avg_1min": os.getloadavg()[0]}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
