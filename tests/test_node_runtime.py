"""sit2stand.nodes.runtime: a node process leaves with its own result even when DDS teardown blocks."""

import subprocess
import sys
import textwrap

# A node whose destroy_node never returns (the DDS teardown hang a CI run saw), bounded at 0.5 s
BLOCKED_TEARDOWN = textwrap.dedent("""\
    import time
    from sit2stand.nodes import runtime
    runtime.TEARDOWN_LIMIT_S = 0.5

    class Node:
        def get_name(self):
            return "stuck"

        def destroy_node(self):
            time.sleep(60.0)

    runtime._bounded_teardown(Node(), 3)
    raise SystemExit(0)
""")


def test_a_blocked_teardown_leaves_with_the_nodes_code_and_says_so():
    result = subprocess.run([sys.executable, "-c", BLOCKED_TEARDOWN], capture_output=True, text=True, timeout=30)
    assert result.returncode == 3, result.stderr
    assert "[stuck] DDS teardown did not finish" in result.stderr


def test_a_quick_teardown_returns_to_the_caller():
    quick = BLOCKED_TEARDOWN.replace("time.sleep(60.0)", "pass")
    result = subprocess.run([sys.executable, "-c", quick], capture_output=True, text=True, timeout=30)
    assert result.returncode == 0, result.stderr
    assert "DDS teardown" not in result.stderr
