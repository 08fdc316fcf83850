"""sit2stand.capture.latency and the live benchmark's pooling: capture -> arrival latencies from a probe's record."""

import json

import numpy as np
import pytest

from sit2stand.bench.live import summary
from sit2stand.capture.latency import capture_origin_ns, latencies_ms, p50_p99


def test_the_origin_is_read_from_serve_c3ds_line_and_its_absence_is_named():
    assert capture_origin_ns("serve-c3d: capture clock origin 1796403290937245152 ns\n") == 1796403290937245152
    with pytest.raises(ValueError, match="capture clock origin"):
        capture_origin_ns("serve-c3d: stopped: 531 frames sent")


def test_each_frame_is_timed_from_its_own_capture_time_found_by_its_stamp(tmp_path):
    """Frame k was captured at origin + k / rate; the stamps carry the bridge's mapped clock (any offset), so k comes
    from the distance to the first marker frame's stamp. A frame missing from a topic does not shift the others."""
    origin, rate = 5_000_000_000, 100.0
    stamp0 = 123_000_000_000                     # the ROS clock's mapping of capture time 0
    frames = [0, 1, 2, 4]                        # frame 3 never reached the probe on /human/com
    record = {"/mocap/markers": [[stamp0 + k * 10_000_000, origin + k * 10_000_000 + 1_000_000] for k in range(5)],
              "/human/com": [[stamp0 + k * 10_000_000, origin + k * 10_000_000 + (4 + k) * 1_000_000]
                             for k in frames]}
    (tmp_path / "probe.json").write_text(json.dumps(record))
    assert latencies_ms(tmp_path / "probe.json", "/mocap/markers", origin, rate) == pytest.approx([1.0] * 5)
    assert latencies_ms(tmp_path / "probe.json", "/human/com", origin, rate) == pytest.approx([4.0, 5.0, 6.0, 8.0])
    assert p50_p99(np.array([1.0, 2.0, 3.0])) == "p50 2.00 ms p99 2.98 ms (n=3)"
    (tmp_path / "none.json").write_text(json.dumps({"/mocap/markers": [], "/human/com": record["/human/com"]}))
    with pytest.raises(ValueError, match="no /mocap/markers message reached the probe"):
        latencies_ms(tmp_path / "none.json", "/human/com", origin, rate)


def test_the_benchmark_counts_the_runs_that_met_each_target():
    run = {"stood_up": 1.0, "capture_to_markers_p50_ms": 0.8, "capture_to_human_com_p50_ms": 3.0,
           "capture_to_command_p50_ms": 4.0, "capture_to_markers_p99_ms": 1.2, "capture_to_human_com_p99_ms": 6.0,
           "capture_to_command_p99_ms": 7.0, "com_tracking_rms_cm": 0.8}
    late = {**run, "stood_up": 0.0, "capture_to_markers_p99_ms": 2.5, "capture_to_command_p99_ms": 19.0}
    s = summary([run, run, late], rate_hz=200.0)
    assert s["runs"] == 3 and s["stood_up"] == 2
    assert s["runs_markers_p99_within_target"] == 2 and s["runs_command_p99_within_target"] == 2
    assert s["capture_to_command_p99_ms_median"] == 7.0 and s["capture_to_command_p99_ms_max"] == 19.0
    assert s["command_p99_target_ms"] == 8.0 and s["command_p99_median_vs_target"] == pytest.approx(7.0 / 8.0)
    assert summary([run], rate_hz=100.0)["runs_command_p99_within_target"] == 0, "7 ms misses 100 Hz's 5 ms"
