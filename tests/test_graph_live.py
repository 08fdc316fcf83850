"""The live stand-up: serve-c3d (a QTM or OptiTrack Motive stand-in) -> mocap_bridge -> human_com -> retargeter ->
driver -> recorder."""

import re
from pathlib import Path

import pytest

from sit2stand.capture.latency import p50_p99
from sit2stand.capture.rehearsal import PROTOCOL_ARGS, TOPICS, LiveRunError, run_live
from sit2stand.io.topics import MARKERS_TOPIC

pytestmark = pytest.mark.graph
LOSS_TOLERATED = 50
"""Messages (of ~48,000 in a run: 0.1 %) the recorder may report lost in this test: on 2 cores, at the stream's
start (five real-time processes: the stand-in, the probe, the bridge, the retargeter's calibration, the estimator),
it lost 2-5 of the driver's state messages in 3 of 10 runs and 30 feet-plate samples in another on 2026-12-02 (a
known gap; the recorder reports them and exits 1, as it must)."""
ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("protocol", PROTOCOL_ARGS)
def test_the_robot_stands_up_from_a_live_stream_of_the_shipped_elderly_demonstration(tmp_path, ros_env, protocol,
                                                                                     elderly_calibration):
    calibration = elderly_calibration
    try:
        run = run_live(tmp_path, ros_env, calibration, ROOT / "bags" / "elderly", graph_args=PROTOCOL_ARGS[protocol],
                       protocol=protocol)
    except LiveRunError as err:
        pytest.fail(str(err))
    log = run.log
    assert run.exit_code == 0 or "FALLEN" in log or _only_a_few_lost(log), log[-4000:]
    print("; ".join(f"capture -> {topic} {p50_p99(run.latencies_ms[topic])}" for topic in TOPICS))
    assert "[mocap_bridge] 531 frames, 0 lost, 1 connection(s)" in log, log[-4000:]
    assert "[retargeter] 531 frames" in log, log[-4000:]
    assert len(run.latencies_ms[MARKERS_TOPIC]) == 531
    assert run.stood_up, f"{run.report}\n{log[-3000:]}"


def _only_a_few_lost(output: str) -> bool:
    """Whether the graph failed only because its recorder reported at most LOSS_TOLERATED messages lost (printed
    for the record)."""
    found = re.search(r"\[recorder\] error: lost (\d+) messages \(([^)]*)\)", output)
    failed = {name for name, code in re.findall(r"(\w+) exited with code (-?\d+)", output) if code != "0"}
    if not found or failed != {"recorder"}:
        return False
    print(f"the recorder lost {found.group(1)} messages ({found.group(2)})")
    return int(found.group(1)) <= LOSS_TOLERATED
