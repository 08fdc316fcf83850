"""The scheduling class of a process that changes its own once it runs (the estimator after its live calibration)."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = """
import os, threading
from sit2stand.scheduling import Scheduling
started, done = threading.Event(), threading.Event()
def middleware():
    started.set()
    done.wait()
thread = threading.Thread(target=middleware)
thread.start()
started.wait()
permitted = Scheduling("other", nice=7).try_apply_to_process()
print(permitted, os.getpriority(os.PRIO_PROCESS, threading.get_native_id()),
      os.getpriority(os.PRIO_PROCESS, thread.native_id))
done.set()
"""


def test_a_class_set_on_the_process_reaches_the_threads_already_running():
    """A thread started before (as the middleware's receive threads are) takes the class too: Linux schedules
    threads, and a class set on one left the others time-shared at the old priority."""
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, check=True, timeout=60)
    assert out.stdout.split() == ["True", "7", "7"], out.stdout + out.stderr
