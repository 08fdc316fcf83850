"""sit2stand.nodes.runtime: a node process leaves with its own result even when DDS teardown blocks."""

import subprocess
import sys
import textwrap
from types import SimpleNamespace

from sit2stand.nodes.qos import publisher_names

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


# a teardown that blocks in native code holding Python's lock (ctypes.PyDLL keeps it): no Python thread runs, the
# bound's timer neither; faulthandler's native thread ends the process after printing where it hung
GIL_HELD_TEARDOWN = BLOCKED_TEARDOWN.replace("time.sleep(60.0)", "import ctypes; ctypes.PyDLL(None).sleep(60)") \
    .replace("runtime.TEARDOWN_LIMIT_S = 0.5", "runtime.TEARDOWN_LIMIT_S = 0.5; runtime.TEARDOWN_HARD_LIMIT_S = 1.0")


def test_a_teardown_blocked_holding_pythons_lock_still_ends_after_saying_its_result():
    result = subprocess.run([sys.executable, "-c", GIL_HELD_TEARDOWN], capture_output=True, text=True, timeout=30)
    assert result.returncode == 1, result.stderr
    assert "[stuck] result: exit 3; tearing down DDS" in result.stdout
    assert "destroy_node" in result.stderr          # faulthandler's traceback: where it hung


def test_publishers_discovery_has_not_named_read_as_another_publisher():
    def info(ns, name):
        return SimpleNamespace(node_namespace=ns, node_name=name)

    unnamed = info("_NODE_NAMESPACE_UNKNOWN_", "_NODE_NAME_UNKNOWN_")
    assert publisher_names([info("/", "replayer"), unnamed]) == ["/replayer", "another publisher"]
    assert publisher_names([info("/", "replayer"), unnamed, unnamed]) == ["/replayer", "2 other publishers"]
    assert publisher_names([info("/robot2", "replayer"), info("/", "replayer")]) == ["/replayer", "/robot2/replayer"]
