"""Where parallel work runs: local worker processes (the default) or Ray (`--ray`, `--ray ADDRESS`).

`task_executor(workers, ray=None)` gives a `concurrent.futures.Executor` for a batch of independent
tasks (missions, training runs, collection chunks), or None when `workers` is 1 and Ray is not asked
for (the caller then runs the tasks inline, as before):

- `ray=None`: a `ProcessPoolExecutor` of `workers` spawned processes.
- `ray="local"` (`--ray`): a private local Ray of `workers` CPUs, started for this run and gone
  with it (`drone_inspect_core.ray_head`: the head runs in its own session under a watchdog that kills the
  whole
  session when the run ends, however it ends, SIGKILL included).
- `ray="HOST:PORT"` (`--ray ADDRESS`): join an existing cluster (every node needs this project
  installed, as the driver has it); the cluster is left running.

Ray is an optional extra (`pip install -e '.[distributed]'`); nothing else imports it. Tasks keep
their seeds in their arguments, so a task computes the same result wherever it runs.
`gather(futures, describe)` collects results in submission order and reports a task that failed
(a worker that crashed, a node that left) by name, keeping every other result.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import multiprocessing
import os
import pickle
import secrets
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from pathlib import Path
from typing import Any, TypeVar

from drone_inspect_core.ports import free_port

log = logging.getLogger(__name__)

LOCAL = "local"
"""`--ray` without an address: start a private local Ray for this run."""
HEAD_READY_TIMEOUT_S = 90.0
QUIET_RAY_ENV = {"RAY_USAGE_STATS_ENABLED": "0", "RAY_enable_metrics_collection": "0"}
"""A private head sends no usage statistics and collects no metrics (the agents' CPU is the tasks')."""
T = TypeVar("T")


class RayUnavailableError(RuntimeError):
    """Ray was asked for but is not installed, or its head could not be started or reached."""


def add_ray_option(parser: Any) -> None:
    """`--ray [ADDRESS]` on an argparse parser (dest `ray`: None, "local" or the address)."""
    parser.add_argument(
        "--ray",
        nargs="?",
        const=LOCAL,
        default=None,
        metavar="ADDRESS",
        help="run the tasks on Ray: alone, a local Ray of --parallel/--workers CPUs started for this run; "
        "with HOST:PORT, an existing cluster (needs the [distributed] extra)",
    )


@contextlib.contextmanager
def task_executor(
    workers: int,
    ray: str | None = None,
    initializer: Callable[..., None] | None = None,
    initargs: tuple[Any, ...] = (),
) -> Iterator[Executor | None]:
    """An executor for `workers` parallel tasks (see the module doc); shut down on exit."""
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if ray is None and workers == 1:
        yield None
        return
    if ray is None:
        ctx = multiprocessing.get_context(
            "spawn"
        )  # not fork: the caller may hold threads or a PyBullet client
        pool: Executor = ProcessPoolExecutor(
            workers, mp_context=ctx, initializer=initializer, initargs=initargs
        )
    else:
        pool = RayExecutor(ray, workers, initializer, initargs)
    try:
        yield pool
    except BaseException:  # Ctrl-C, a failure: drop the tasks not started yet
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def gather(
    futures: list[Future[T]], describe: Callable[[int], str], progress: Any = None
) -> list[T | BaseException]:
    """Each future's result in submission order; a failed task's exception in its place, logged with
    `describe(index)` (its seed, its name). `progress`: a tqdm bar to advance."""
    out: list[T | BaseException] = []
    for index, future in enumerate(futures):
        try:
            out.append(future.result())
        except Exception as exc:
            log.error("task %s failed: %s: %s", describe(index), type(exc).__name__, exc)
            out.append(exc)
        if progress is not None:
            progress.update(1)
    return out


# -- Ray ------------------------------------------------------------------------------------------

_INITIALISED: set[bytes] = set()


def _run_task(
    init: tuple[Callable[..., None], tuple[Any, ...]] | None, fn: Callable[..., T], args: tuple, kwargs: dict
) -> T:
    """In a Ray worker: the pool initializer once per process (as a ProcessPoolExecutor runs it),
    then the task."""
    if init is not None:
        key = pickle.dumps((init[0].__module__, init[0].__qualname__, init[1]))
        if key not in _INITIALISED:
            init[0](*init[1])
            _INITIALISED.add(key)
    return fn(*args, **kwargs)


def _require_ray() -> Any:
    try:
        import ray
    except ImportError as exc:
        raise RayUnavailableError(
            "--ray needs Ray: pip install -e '.[distributed]' (or pip install 'ray>=2.9')"
        ) from exc
    return ray


def _refresh_ray_auth() -> None:
    """Ray reads RAY_AUTH_MODE and the token when it is imported: where it already was (a second
    run in one process), refresh what it cached, as Ray's own token setup does (best effort)."""
    with contextlib.suppress(Exception):
        from ray._raylet import AuthenticationTokenLoader, Config

        Config.initialize("")
        AuthenticationTokenLoader.instance().reset_cache()


class RayExecutor(Executor):
    """`submit()` runs a task on Ray, one CPU each; its future is a `concurrent.futures.Future`."""

    def __init__(
        self,
        address: str,
        workers: int,
        initializer: Callable[..., None] | None = None,
        initargs: tuple[Any, ...] = (),
    ) -> None:
        self._head: LocalRayHead | None = None
        self._saved_env: dict[str, str | None] = {}
        if address == LOCAL:
            if importlib.util.find_spec("ray") is None:  # not imported yet: Ray reads its auth at import
                _require_ray()
            self._head = LocalRayHead(workers).start()
            address = self._head.address
            for name, value in self._head.auth_env.items():  # this run's own token, for ray.init
                self._saved_env[name] = os.environ.get(name)
                os.environ[name] = value
            _refresh_ray_auth()
        ray = _require_ray()
        self._ray = ray
        self._init = (initializer, initargs) if initializer is not None else None
        self._refs: list[Any] = []
        try:
            # Task failures come back as exceptions; workers' own output stays in Ray's log folder
            # (streaming it to the driver cost a 2-core machine measurable time).
            ray.init(address=address, logging_level=logging.WARNING, log_to_driver=False)
        except Exception as exc:
            self._stop_head()
            raise RayUnavailableError(
                f"could not join Ray at {address}: {type(exc).__name__}: {exc}"
            ) from exc
        self._remote = ray.remote(num_cpus=1, max_retries=0)(_run_task)
        log.info("Ray: %s CPUs at %s", ray.cluster_resources().get("CPU"), address)

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:
        ref = self._remote.remote(self._init, fn, args, kwargs)
        self._refs.append(ref)
        return ref.future()

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        ray = self._ray
        try:
            if cancel_futures:
                for ref in self._refs:
                    with contextlib.suppress(Exception):
                        ray.cancel(ref, force=True)
            if ray.is_initialized():
                ray.shutdown()
        finally:  # the watchdog stops Ray's processes within seconds: the run need not wait for it
            self._stop_head(wait=False)

    def _stop_head(self, wait: bool = True) -> None:
        if self._head is not None:
            self._head.stop(wait=wait)
            self._head = None
        for name, value in self._saved_env.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
        self._saved_env = {}


class LocalRayHead:
    """A private Ray head on 127.0.0.1 with `cpus` CPUs, run by `python -m drone_inspect_core.ray_head` (a
    watchdog
    in its own session that stops Ray's whole session when this process goes, however it goes)."""

    def __init__(self, cpus: int) -> None:
        self.cpus = cpus
        self.port = free_port("tcp")
        self.address = f"127.0.0.1:{self.port}"
        self.temp_dir = Path(tempfile.mkdtemp(prefix="ray-", dir="/tmp"))  # short: Ray's socket paths
        self.log_path = self.temp_dir / "head.log"
        # Ray's token authentication with a token of this run's own: no other driver joins this head
        # (it listens on every interface), and this run joins no other head.
        self.auth_env = {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}
        self._process: subprocess.Popen[bytes] | None = None

    def start(self) -> LocalRayHead:
        command = [
            sys.executable, "-m", "drone_inspect_core.ray_head", "--parent", str(os.getpid()),
            "--port", str(self.port),
            "--cpus", str(self.cpus), "--temp-dir", str(self.temp_dir),
        ]  # fmt: skip
        env = {**os.environ, **QUIET_RAY_ENV, **self.auth_env}
        with self.log_path.open("wb") as log_file:
            self._process = subprocess.Popen(
                command, stdin=subprocess.DEVNULL, stdout=log_file, stderr=subprocess.STDOUT, env=env,
                start_new_session=True,  # a Ctrl-C in the terminal reaches the run, which then stops Ray
            )  # fmt: skip
        deadline = time.monotonic() + HEAD_READY_TIMEOUT_S
        while time.monotonic() < deadline:
            if self._process.poll() is not None:
                raise RayUnavailableError(f"the local Ray head exited: {self._log_tail()}")
            if b"Ray runtime started" in self.log_path.read_bytes():
                return self
            time.sleep(0.05)
        self.stop()
        raise RayUnavailableError(
            f"the local Ray head was not up within {HEAD_READY_TIMEOUT_S:g} s: {self._log_tail()}"
        )

    def _log_tail(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-1500:]
        except OSError:
            return "(no log)"

    def stop(self, wait: bool = True) -> None:
        """SIGTERM to the watchdog (it stops Ray's session within seconds); `wait`: until it has, with
        SIGKILL to its group if it hangs. Not waiting is safe: the watchdog also acts when we are gone."""
        process, self._process = self._process, None
        if process is None or process.poll() is not None:
            return
        process.send_signal(signal.SIGTERM)
        if not wait:
            return
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=5)
