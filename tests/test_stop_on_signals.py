"""A simulator's stop signal is taken whatever its main thread holds at that moment.

`stop_on_signals` once set its event from a Python signal handler. The handler runs in the
main thread, and the serving loops sit in `stop.wait()`: a signal landing while that wait held
the event's own (non-re-entrant) lock deadlocked the process for good (`sim-vehicle` under a
process-group SIGTERM, about once in a few hundred stops). Here the main thread holds that lock
on purpose when the signal arrives. Each case runs in a child, so a hang is a timeout, not a stuck suite.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

CHILD = """
import logging, os, signal, sys, time
logging.basicConfig(level=logging.INFO)
from sim_world.process_entry import stop_on_signals
stop = stop_on_signals("test")
with stop._cond:  # what Event.wait() holds around its sleeps
    os.kill(os.getpid(), signal.{name})
    time.sleep(0.3)  # a Python-level handler would run here, under the lock
print("stopped" if stop.wait(10.0) else "not stopped", flush=True)
"""


@pytest.mark.parametrize("name", ["SIGTERM", "SIGINT", "SIGHUP"])
def test_a_stop_signal_while_the_main_thread_holds_the_events_lock_still_stops(name: str) -> None:
    proc = subprocess.run(
        [sys.executable, "-c", CHILD.format(name=name)], capture_output=True, text=True, timeout=30
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "stopped"
    assert f"test: {name} received, stopping" in proc.stderr


def test_a_stop_that_hangs_ends_hard_with_every_threads_stack() -> None:
    child = (
        "import os, signal, time\n"
        "import sim_world.process_entry as pe\n"
        "pe.SIGNAL_STOP_GRACE_S = 0.5\n"
        "stop = pe.stop_on_signals('test')\n"
        "os.kill(os.getpid(), signal.SIGTERM)\n"
        "stop.wait(5.0)\n"
        "time.sleep(20)  # a stop that never finishes\n"
    )
    proc = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, timeout=30)
    assert proc.returncode == 3
    assert "test: still stopping 0 s after SIGTERM: ending hard" in proc.stderr
    assert proc.stderr.count("(most recent call first)") >= 2  # the main thread and the stop's own
