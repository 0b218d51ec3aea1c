"""Render the forward camera in worker processes while the physics runs on.

TinyRenderer is single-threaded and a 224 px frame costs ~10 ms, so a 30 Hz camera
rendered inline costs ~0.3 s of CPU per simulated second: the camera, not the
physics, bounds the real-time factor. `RenderWorkers` keeps N processes, each with
a mirror of the world (built from the same config and seed, so the same scene),
and hands them camera poses round-robin: a frame is requested at its simulation
time and collected later, so rendering overlaps the physics and, with two workers,
uses both cores. Frames come back in request order.

Noise: each request carries a seed drawn from the caller's generator, so frames
are reproducible (though not identical to `World.render`, which draws from the
world's own stream).
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
from collections import deque
from multiprocessing.connection import Connection
from types import TracebackType

import numpy as np

from sim_world.physics.quadrotor import RigidBodyState
from sim_world.rendering.camera import Render
from sim_world.world import World, WorldConfig

logger = logging.getLogger(__name__)

_READY = "ready"


class RenderWorkerError(RuntimeError):
    """A render worker failed to start, died, or did not answer in time."""


def _serve(conn: Connection, config: WorldConfig, seed: int) -> None:
    """Worker loop: build the mirror world, then render each (state, noise seed, with_seg) request."""
    import pybullet as p

    try:
        world = World(config, seed)
    except Exception as exc:  # reported to the parent, which raises RenderWorkerError
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    conn.send((_READY, None))
    with world:
        while True:
            request = conn.recv()
            if request is None:
                return
            position, quaternion, noise_seed, with_seg = request
            p.resetBasePositionAndOrientation(
                world.drone.body_id, position, quaternion, physicsClientId=world.client_id
            )
            render = world.render(with_seg=with_seg, rng=np.random.default_rng(noise_seed))
            conn.send(("frame", render))


class RenderWorkers:
    """N render processes mirroring one world; `submit()` a state now, `collect()` its frame later."""

    def __init__(
        self, config: WorldConfig, seed: int, workers: int = 2, start_timeout_s: float = 60.0
    ) -> None:
        if workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        if config.gui:
            raise ValueError("render workers need a headless config (gui=False)")
        ctx = multiprocessing.get_context("spawn")
        self._conns: list[Connection] = []
        self._procs: list[multiprocessing.process.BaseProcess] = []
        self._pending: deque[int] = deque()  # worker index of each outstanding request, in order
        self._next = 0
        self.timeout_s = start_timeout_s
        try:
            for _ in range(workers):
                parent, child = ctx.Pipe()
                proc = ctx.Process(target=_serve, args=(child, config, seed), daemon=True)
                proc.start()
                child.close()
                self._conns.append(parent)
                self._procs.append(proc)
            for conn in self._conns:
                self._receive(conn, start_timeout_s, expect=_READY)
        except BaseException:
            self.close()
            raise

    @property
    def outstanding(self) -> int:
        """Requests submitted and not yet collected."""
        return len(self._pending)

    def submit(self, state: RigidBodyState, noise_seed: int, with_seg: bool = False) -> None:
        """Ask the next worker (round-robin) to render the camera at `state`.

        A worker holds one request at a time: if the next worker is still busy, its
        frame must be collected first (`collect()`), which is the back-pressure.
        """
        index = self._next
        if index in self._pending:
            raise RenderWorkerError(f"worker {index} is busy: collect() its frame before submitting")
        request = (state.position_enu_m.tolist(), state.quaternion_xyzw.tolist(), int(noise_seed), with_seg)
        self._conns[index].send(request)
        self._pending.append(index)
        self._next = (index + 1) % len(self._conns)

    def collect(self, timeout_s: float = 10.0) -> Render:
        """The oldest outstanding frame (waits for it)."""
        if not self._pending:
            raise RenderWorkerError("collect() with no frame requested")
        index = self._pending.popleft()
        return self._receive(self._conns[index], timeout_s, expect="frame")

    def _receive(self, conn: Connection, timeout_s: float, expect: str) -> Render:
        if not conn.poll(timeout_s):
            raise RenderWorkerError(f"render worker did not answer within {timeout_s:.0f} s")
        try:
            kind, payload = conn.recv()
        except EOFError:
            raise RenderWorkerError("render worker died") from None
        if kind == "error":
            raise RenderWorkerError(f"render worker failed to build its world: {payload}")
        if kind != expect:
            raise RenderWorkerError(f"render worker sent {kind!r}, expected {expect!r}")
        return payload

    def close(self) -> None:
        """Stop the workers (idempotent)."""
        for conn in self._conns:
            with contextlib.suppress(BrokenPipeError, OSError):
                conn.send(None)
        for proc in self._procs:
            proc.join(timeout=5.0)
            if proc.is_alive():
                logger.warning("render worker %s did not stop; terminating it", proc.pid)
                proc.terminate()
                proc.join(timeout=5.0)
        for conn in self._conns:
            conn.close()
        self._conns, self._procs = [], []
        self._pending.clear()

    def __enter__(self) -> RenderWorkers:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
