"""A live stand-up rehearsed on one machine: the live graph fed by ``serve-c3d``, its latency observed.

:func:`run_live` starts the live graph (``live.yaml``: mocap_bridge -> human_com -> retargeter -> driver -> recorder;
CAD plant by default; the skeleton calibrated beforehand with ``human-calibrate``, so the estimator runs in real time
from its first frame) alone; once the retargeter is ready for the capture, a latency probe
(:mod:`sit2stand.nodes.latency_probe`) and ``serve-c3d`` start, both in real time above the graph where permitted (a
capture PC and an observer are machines of their own; late on a shared one, their lateness would count as the
graph's). Latencies run from each frame's capture time (serve-c3d's clock origin + frame / rate) to DDS's reception
at the probe (:mod:`sit2stand.capture.latency`) of the frame's ``/mocap/markers``, its ``/human/com`` and its IK pose
on ``/robot/retarget/ik``, published right after the frame's joint command. ``make bench-live`` and the live graph's
tests run it.
"""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..data import folder
from ..errors import Sit2StandError
from ..io.topics import HUMAN_COM_TOPIC, MARKERS_TOPIC, ROBOT_RETARGET_IK_TOPIC
from ..retarget.pacing import READY_LINE
from ..retarget.report import analyse
from ..scheduling import CAPTURE_STAND_IN_PRIORITY, OBSERVER_PRIORITY, Scheduling
from .latency import PROBE_READY, capture_origin_ns, latencies_ms

PROTOCOL_ARGS = {"qtm": (), "natnet": ("up:=+Y", "plates:=[]")}
"""The live graph's arguments for each protocol: NatNet serves markers only, y up (Motive's default), so the bridge
is told so and the estimator expects no plates (its seat-off and the retargeter's from the pelvis markers)."""
TOPICS = (MARKERS_TOPIC, HUMAN_COM_TOPIC, ROBOT_RETARGET_IK_TOPIC)


class LiveRunError(Sit2StandError, RuntimeError):
    """A live run that did not get as far as its figures; the message ends with the logs' tails."""


@dataclass
class LiveRun:
    """One live stand-up: latencies [ms] per topic (one per frame), the graph's exit code and log, and the recording's
    analysis (:func:`sit2stand.retarget.report.analyse`: stood up, fallen, pelvis heights, COM tracking)."""

    latencies_ms: dict[str, np.ndarray]
    exit_code: int
    log: str
    report: dict = field(default_factory=dict)
    logs: dict[str, Path] = field(default_factory=dict)

    @property
    def stood_up(self) -> bool:
        """Stood up by the recording (the stand-up graph's verdict) and no fall seen by the driver."""
        return bool(self.report.get("stood_up")) and "FALLEN" not in self.log

    def figures(self) -> dict[str, float]:
        out = {"stood_up": float(self.stood_up), "frames": float(len(self.latencies_ms[MARKERS_TOPIC])),
               "com_tracking_rms_cm": float(self.report.get("com_tracking_rms_m", np.nan)) * 100}
        for topic, key in zip(TOPICS, ("markers", "human_com", "command")):
            values = self.latencies_ms[topic]
            out[f"capture_to_{key}_p50_ms"] = float(np.percentile(values, 50))
            out[f"capture_to_{key}_p99_ms"] = float(np.percentile(values, 99))
        return out


def _start(args: list[str], env: dict[str, str], log: Path, fifo_priority: int | None = None) -> subprocess.Popen:
    """``python -m args`` with its output in ``log``; in real time at ``fifo_priority`` where permitted."""
    with open(log, "wb") as f:
        return subprocess.Popen([sys.executable, "-m", *args], env=env, stdout=f, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, preexec_fn=None if fifo_priority is None else
                                lambda: Scheduling("fifo", fifo_priority).try_apply(0))


def _wait_for(log: Path, text: str, proc: subprocess.Popen, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if text in log.read_text(errors="replace"):
            return True
        if proc.poll() is not None:
            return text in log.read_text(errors="replace")
        time.sleep(0.05)
    return False


def _wait(proc: subprocess.Popen, name: str, timeout_s: float, logs: dict[str, Path]) -> int:
    """``proc``'s exit code; LiveRunError naming it when it runs past ``timeout_s``."""
    try:
        return proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        raise LiveRunError(f"{name} still running after {timeout_s:g} s{_tails(logs)}") from None


def _stop(proc: subprocess.Popen | None, sig: int = signal.SIGKILL) -> None:
    """Send ``sig`` to a process still running and reap it (killed if it does not go within 30 s)."""
    if proc is None or proc.poll() is not None:
        return
    proc.send_signal(sig)
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(10)


def _tails(logs: dict[str, Path]) -> str:
    return "".join(f"\n--- {name} ---\n{path.read_text(errors='replace')[-3000:]}" for name, path in logs.items()
                   if path.exists())


def _free_port(protocol: str) -> int:
    """A free local port for serve-c3d: TCP for QTM; for NatNet a UDP port whose next one is free too (its data)."""
    kind = socket.SOCK_STREAM if protocol == "qtm" else socket.SOCK_DGRAM
    for _ in range(20):
        with socket.socket(type=kind) as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
            if protocol == "qtm":
                return port
            try:
                with socket.socket(type=kind) as data:
                    data.bind(("127.0.0.1", port + 1))
                return port
            except OSError:
                continue
    raise LiveRunError("no free pair of local UDP ports for NatNet")


def run_live(work: Path, env: dict[str, str], calibration: Path, demonstration: Path,
             plant: str | Path | None = None, graph_args: tuple[str, ...] = (), protocol: str = "qtm",
             rate_hz: float = 100.0, robot: str | None = None) -> LiveRun:
    """One live stand-up (see the module docstring) in ``work`` (its logs, probe record and bag); ``calibration``:
    the skeleton's (``human-calibrate``); ``demonstration``: the bag or C3D file serve-c3d serves, captured
    at ``rate_hz``; ``plant``: default the CAD plant; ``graph_args``: more of the graph's
    ``name:=value`` arguments; ``protocol``: serve-c3d's and the bridge's (qtm, or natnet: markers only, served y up:
    give ``PROTOCOL_ARGS["natnet"]``); ``robot``: the robot profile (None: the plant's, TALOS).

    Raises:
        LiveRunError: a process did not start, hung or failed before the figures (the logs' tails attached).
    """
    port = _free_port(protocol)
    logs = {name: work / f"{name}.log" for name in ("launch", "probe", "serve")}
    record = work / "latency.json"
    graph = _start(["sit2stand.cli", "launch", str(folder("graphs") / "live.yaml"), f"out:={work / 'run'}",
                    f"plant:={plant or 'cad'}", f"robot:={robot or ''}", f"protocol:={protocol}",
                    f"capture_port:={port}",
                    f"rate_hz:={rate_hz:g}", f"calibration:={calibration}", "estimator_policy:=fifo", *graph_args,
                    "--timeout", "200"], env, logs["launch"])
    probe = server = None
    try:
        if not _wait_for(logs["launch"], READY_LINE, graph, 180):
            raise LiveRunError(f"the live graph did not log {READY_LINE!r}{_tails(logs)}")
        probe = _start(["sit2stand.nodes.latency_probe", str(record), *TOPICS], env, logs["probe"], OBSERVER_PRIORITY)
        if not _wait_for(logs["probe"], PROBE_READY, probe, 30):
            raise LiveRunError(f"the latency probe did not start{_tails(logs)}")
        server = _start(["sit2stand.cli", "serve-c3d", str(demonstration), "--protocol", protocol, "--port",
                         str(port), "--host", "127.0.0.1"], env, logs["serve"], CAPTURE_STAND_IN_PRIORITY)
        if _wait(server, "serve-c3d", 120, logs) != 0:
            raise LiveRunError(f"serve-c3d failed{_tails(logs)}")
        code = _wait(graph, "the live graph", 240, logs)
    finally:
        _stop(probe, signal.SIGINT)        # it writes its record at SIGINT
        _stop(server)
        _stop(graph)
    return LiveRun(_latencies(record, logs, rate_hz), code, logs["launch"].read_text(errors="replace"),
                   _analysis(work / "run", demonstration, plant, logs, robot), logs)


def _latencies(record: Path, logs: dict[str, Path], rate_hz: float) -> dict[str, np.ndarray]:
    """Capture -> arrival [ms] per topic of the probe's record; LiveRunError when a topic got nothing."""
    try:
        origin = capture_origin_ns(logs["serve"].read_text(errors="replace"))
        lat = {t: latencies_ms(record, t, origin, rate_hz) for t in TOPICS}
    except (OSError, ValueError, KeyError, IndexError) as err:
        raise LiveRunError(f"no latency figures ({err}){_tails(logs)}") from None
    if empty := [t for t, values in lat.items() if not len(values)]:
        raise LiveRunError(f"no {', '.join(empty)} message reached the probe{_tails(logs)}")
    return lat


def _analysis(run: Path, demonstration: Path, plant: str | Path | None, logs: dict[str, Path],
              robot: str | None = None) -> dict:
    """The recording's analysis summary (the stand-up graph's verdict, COM tracking)."""
    try:
        return analyse(run, demonstration.stem, None, plant or "cad", robot=robot).summary
    except (OSError, ValueError, IndexError) as err:
        raise LiveRunError(f"the run's recording cannot be analysed ({err}){_tails(logs)}") from None
