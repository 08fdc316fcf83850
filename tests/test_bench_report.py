"""sit2stand.bench.report: the generated tables of docs/results.md come from the benchmarks' JSON, stamped."""

import json

from sit2stand.bench import write_result
from sit2stand.bench.report import rewrite

DOC = """# results

## Live

<!-- generated: live -->
old live table
<!-- end: live -->

hand-written text stays

<!-- generated: driver -->
old driver table
<!-- end: driver -->
"""


def test_a_table_is_rewritten_from_its_json_and_one_without_json_is_kept(tmp_path):
    summary = {"runs": 5.0, "stood_up": 5.0, "com_tracking_rms_cm_median": 1.2, "com_tracking_rms_cm_max": 1.3,
               "capture_to_markers_p99_ms_median": 0.8, "capture_to_markers_p99_ms_max": 0.9,
               "capture_to_human_com_p99_ms_median": 2.5, "capture_to_human_com_p99_ms_max": 3.2,
               "capture_to_command_p50_ms_median": 2.4, "capture_to_command_p99_ms_median": 3.9,
               "capture_to_command_p99_ms_max": 5.1, "runs_command_p99_within_target": 4.0,
               "command_p99_target_ms": 5.0}
    write_result(tmp_path / "live.json", {"protocol": "qtm", "marker_rate_hz": 100.0, "runs": [], "summary": summary},
                 "make bench-live")
    text, kept = rewrite(DOC, tmp_path)
    assert "old live table" not in text and "3.90 ms (5.10)" in text and "4 of 5 within 5 ms" in text
    stamp = json.loads((tmp_path / "live.json").read_text())["measured"]
    assert f"{stamp['date']}, code at {stamp['commit']}, `make bench-live`" in text
    assert "old driver table" in text and "hand-written text stays" in text
    assert len(kept) == 1 and kept[0].startswith("driver:")
    again, _ = rewrite(text, tmp_path)
    assert again == text, "rewriting twice changes nothing"
