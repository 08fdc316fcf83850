"""sit2stand.launch: graph files, substitutions, and supervising real processes (signals, prefixes, orphans)."""

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import pytest
import yaml

import sit2stand.nodes as nodes_pkg
from sit2stand.launch import LaunchError, load_graph, parse_overrides

CHILD = textwrap.dedent("""\
    #!{python}
    import os, signal, sys, time
    name = sys.argv[1]
    def on_int(*_):
        print(name, "got SIGINT", flush=True)
        time.sleep(float(os.environ.get("STOP_S", "0")))     # a node that takes this long to close
        sys.exit(0)
    signal.signal(signal.SIGINT, on_int)
    if {ignore_int!r}:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    print(name, "args", " ".join(sys.argv[2:]), flush=True)
    # NAME.pid says "ready": written (whole, by a rename) once the signal handling is set and the args printed
    pid_file = os.path.join({tmp!r}, name + ".pid")
    with open(pid_file + ".tmp", "w") as f:
        f.write(str(os.getpid()))
    os.replace(pid_file + ".tmp", pid_file)
    end = time.monotonic() + float(os.environ.get("LIFETIME", "60"))
    until = os.environ.get("UNTIL")          # a file: live until it exists (LIFETIME at most), not for a time
    while time.monotonic() < end and not (until and os.path.exists(until)):
        time.sleep(0.02 if until else max(0.0, end - time.monotonic()))
    print(name, "done", flush=True)
    """)


def child_script(tmp_path, ignore_int=False):
    path = tmp_path / ("stubborn.py" if ignore_int else "child.py")
    path.write_text(CHILD.format(python=sys.executable, tmp=str(tmp_path), ignore_int=ignore_int))
    path.chmod(0o755)
    return path


def graph_file(tmp_path, nodes, arguments=None):
    path = tmp_path / "graph.yaml"
    path.write_text(yaml.safe_dump({"name": "t", "arguments": arguments or {}, "nodes": nodes}))
    return path


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:  # a zombie is dead for our purpose
        return f.read().split()[2] != "Z"


def test_substitutions_and_parameters(tmp_path):
    (tmp_path / "p.yaml").write_text("/**:\n  ros__parameters:\n    a: 1\n")
    path = graph_file(tmp_path, [{"name": "n1", "executable": "recorder",
                                  "parameters": ["p.yaml", {"output": "$(var out)", "rate": "$(var rate)"}],
                                  "remappings": {"/a": "/b"}, "env": {"X": "$(env HOME)"}}],
                      arguments={"out": "default", "rate": "2.5"})
    graph = load_graph(path, {"out": "/tmp/o"})
    (node,) = graph.nodes
    assert node.command[1:3] == ["-m", "sit2stand.nodes.recorder"]
    assert ["-r", "__node:=n1"] == node.command[4:6]
    assert str(tmp_path / "p.yaml") in node.command and "/a:=/b" in node.command
    inline = yaml.safe_load(open(node.command[node.command.index("--params-file", 7) + 1]))
    assert inline == {"/**": {"ros__parameters": {"output": "/tmp/o", "rate": 2.5}}}  # typed substitution
    assert node.env["X"] == os.environ["HOME"]
    graph.discard()


@pytest.mark.parametrize("nodes, overrides, message", [
    ([{"name": "a", "executable": "recorder", "parameters": [{"x": "$(var missing)"}]}], {}, r"\$\(var missing\)"),
    ([{"name": "a", "executable": "no-such-program-xyz"}], {}, "neither a sit2stand node"),
    ([{"name": "a", "executable": "recorder"}, {"name": "a", "executable": "replayer"}], {}, "duplicate node name"),
    ([{"name": "a", "executable": "recorder", "parameters": ["nope.yaml"]}], {}, "does not exist"),
    ([{"name": "a", "executable": "recorder"}], {"typo": "1"}, "unknown argument"),
    ([{"name": "a", "executable": "recorder", "on_exit": "explode"}], {}, "on_exit must be one of ignore, shutdown"),
    ([{"name": "a", "executable": "recorder", "grace_s": "long"}], {}, "grace_s must be a positive number"),
    ([{"name": "a", "executable": "recorder", "scheduling": {"policy": "turbo"}}], {}, "scheduling.policy"),
    ([{"name": "a", "executable": "recorder", "scheduling": {"policy": "fifo"}}], {}, "scheduling.priority"),
    ([{"name": "a", "executable": "recorder", "scheduling": {"nice": 40}}], {}, "scheduling.nice"),
    ([{"name": "a", "executable": "recorder", "scheduling": {"priority": "high"}}], {}, "integers"),
    ([{"name": "a", "executable": "recorder", "parameters": [{"x": 1}], "on_exit": "explode"}], {}, "on_exit"),
])
def test_bad_graphs_name_the_problem(tmp_path, nodes, overrides, message, monkeypatch):
    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    with pytest.raises(LaunchError, match=message) as err:
        load_graph(graph_file(tmp_path, nodes), overrides)
    assert "graph.yaml" in str(err.value)
    assert not any(temp.iterdir())           # the inline parameters' folder goes with the failed load


def test_a_loaded_graph_discards_its_inline_parameters(tmp_path, monkeypatch):
    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    graph = load_graph(graph_file(tmp_path, [{"name": "n", "executable": "recorder", "parameters": [{"a": 1}]}]))
    assert graph.tmpdir.parent == temp and any(graph.tmpdir.iterdir())
    graph.discard()
    assert not any(temp.iterdir())


def test_overrides_syntax():
    assert parse_overrides(["a:=1", "b:=x:=y"]) == {"a": "1", "b": "x:=y"}
    with pytest.raises(LaunchError):
        parse_overrides(["a=1"])


def run_launch(tmp_path, nodes, *extra):
    path = graph_file(tmp_path, nodes)
    return subprocess.Popen([sys.executable, "-m", "sit2stand.cli", "launch", str(path), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def wait_for_pids(tmp_path, names, timeout=10.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        files = [tmp_path / f"{n}.pid" for n in names]
        if all(f.exists() and f.read_text() for f in files):
            return [int(f.read_text()) for f in files]
        time.sleep(0.05)
    raise AssertionError(f"children {names} did not start")


def wait_until(condition, message: str, timeout: float = 10.0) -> None:
    """Poll ``condition`` until it holds; fail with ``message`` if it still does not ``timeout`` s later."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, message
        time.sleep(0.05)


def test_sigint_is_forwarded_and_output_prefixed(tmp_path):
    script = child_script(tmp_path)
    proc = run_launch(tmp_path, [{"name": "alpha", "executable": str(script), "arguments": ["alpha"]},
                                 {"name": "beta", "executable": str(script), "arguments": ["beta"]}])
    pids = wait_for_pids(tmp_path, ["alpha", "beta"])     # both ready: their SIGINT handlers are set
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, out
    assert "[alpha] alpha got SIGINT" in out and "[beta ] beta got SIGINT" in out
    assert "[alpha] alpha args --ros-args -r __node:=alpha" in out
    assert not any(alive(p) for p in pids)


def test_stubborn_node_gets_sigterm_after_grace(tmp_path):
    script = child_script(tmp_path, ignore_int=True)
    proc = run_launch(tmp_path, [{"name": "stub", "executable": str(script), "arguments": ["stub"]}],
                      "--grace", "0.5")
    (pid,) = wait_for_pids(tmp_path, ["stub"])
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=30)
    assert "sending SIGTERM to stub" in out
    assert proc.returncode == 1  # a node that had to be terminated counts as a failure
    assert not alive(pid)


def test_shutdown_node_ends_the_graph(tmp_path):
    script = child_script(tmp_path)
    # short ends once long is ready (its SIGINT handler set), not after a time long might still be starting in
    nodes = [{"name": "short", "executable": str(script), "arguments": ["short"],
              "env": {"UNTIL": str(tmp_path / "long.pid")}, "on_exit": "shutdown"},
             {"name": "long", "executable": str(script), "arguments": ["long"]}]
    proc = run_launch(tmp_path, nodes)
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, out
    assert "stopping the graph (short ended)" in out and "[long ] long got SIGINT" in out


def test_a_crashed_recorder_fails_the_job_but_does_not_stop_the_graph(tmp_path):
    script = child_script(tmp_path)
    # the robot ends when told, once its recorder has died (not after a time the start-up might take)
    nodes = [{"name": "rec", "executable": str(script), "arguments": ["rec"], "on_exit": "continue"},
             {"name": "robot", "executable": str(script), "arguments": ["robot"],
              "env": {"UNTIL": str(tmp_path / "end-robot")}, "on_exit": "shutdown"}]
    proc = run_launch(tmp_path, nodes)
    rec_pid, _ = wait_for_pids(tmp_path, ["rec", "robot"])
    os.kill(rec_pid, signal.SIGKILL)
    wait_until(lambda: not alive(rec_pid), "rec outlived SIGKILL")
    (tmp_path / "end-robot").touch()
    out, _ = proc.communicate(timeout=30)
    assert "[robot] robot done" in out, "the robot must run on without its recorder"
    assert "the graph goes on without rec (on_exit: continue)" in out
    assert proc.returncode == 1 and "the job failed: rec exited with code -9" in out


def test_recorders_stop_last_and_have_their_own_grace(tmp_path):
    script = child_script(tmp_path)
    # the closing times are the scenario: the recorder takes longer to close than the graph's grace (2 s) and less
    # than its own (10 s), the robot well within the graph's; the margins (1.5 s, 7 s) leave a loaded host room
    nodes = [{"name": "rec", "executable": str(script), "arguments": ["rec"], "on_exit": "continue",
              "env": {"STOP_S": "3"}, "grace_s": 10},
             {"name": "robot", "executable": str(script), "arguments": ["robot"], "env": {"STOP_S": "0.5"}}]
    proc = run_launch(tmp_path, nodes, "--grace", "2")
    wait_for_pids(tmp_path, ["rec", "robot"])       # both ready: their SIGINT handlers are set
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, out
    assert out.index("robot exited with code 0") < out.index("[rec  ] rec got SIGINT")
    assert "SIGTERM" not in out


def test_no_orphans_when_the_launcher_is_killed(tmp_path):
    script = child_script(tmp_path)
    proc = run_launch(tmp_path, [{"name": "a", "executable": str(script), "arguments": ["a"]},
                                 {"name": "b", "executable": str(script), "arguments": ["b"]}])
    pids = wait_for_pids(tmp_path, ["a", "b"])
    proc.kill()
    proc.wait(10)
    wait_until(lambda: not any(alive(p) for p in pids), "children outlived a SIGKILLed launcher")


SCHED_CHILD = textwrap.dedent("""\
    #!{python}
    import os, sys
    policy = {{os.SCHED_OTHER: "other", os.SCHED_FIFO: "fifo", os.SCHED_RR: "rr"}}[os.sched_getscheduler(0)]
    print(sys.argv[1], "runs", policy, os.sched_getparam(0).sched_priority, os.getpriority(os.PRIO_PROCESS, 0),
          flush=True)
    """)


def _sched_graph(tmp_path):
    script = tmp_path / "sched.py"
    script.write_text(SCHED_CHILD.format(python=sys.executable))
    script.chmod(0o755)
    return [{"name": "low", "executable": str(script), "arguments": ["low"], "scheduling": {"nice": 5}},
            {"name": "rt", "executable": str(script), "arguments": ["rt"],
             "scheduling": {"policy": "fifo", "priority": 10}}]


def _check_sched(out: str, permitted: bool | None) -> None:
    assert "[low] low runs other 0 5" in out and "started low" in out and "SCHED_OTHER nice 5" in out
    took = "[rt ] rt runs fifo 10 0" in out
    if permitted is not None:
        assert took == permitted, out
    if took:
        assert "SCHED_FIFO priority 10" in out, out
    else:   # not permitted: the node still ran, under the default scheduler, and the launcher said so
        assert "[rt ] rt runs other 0 0" in out and "was not permitted" in out, out


def test_scheduling_is_applied_or_reported(tmp_path):
    proc = run_launch(tmp_path, _sched_graph(tmp_path))
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, out
    _check_sched(out, None)


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("setpriv"),
                    reason="needs root and setpriv to drop a capability")
def test_real_time_refused_without_cap_sys_nice(tmp_path):
    """As root, run the launcher without CAP_SYS_NICE: the real-time node must still start, and be reported."""
    path = graph_file(tmp_path, _sched_graph(tmp_path))
    cmd = ["setpriv", "--inh-caps=-sys_nice", "--bounding-set=-sys_nice", sys.executable, "-m", "sit2stand.cli",
           "launch", str(path)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    if "setpriv:" in proc.stderr:
        pytest.skip(f"setpriv cannot drop capabilities here: {proc.stderr.strip()}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    _check_sched(proc.stdout, False)


def test_every_node_module_launches_as_a_sit2stand_node(tmp_path):
    """Each nodes/ module with ``main = node_main(...)`` is a sit2stand node a graph runs as ``python -m``."""
    folder = Path(nodes_pkg.__file__).parent
    modules = {p.stem for p in folder.glob("*.py") if "\nmain = node_main(" in p.read_text()}
    assert "foxglove" in modules
    for exe in sorted(modules):
        (node,) = load_graph(graph_file(tmp_path, [{"name": "n", "executable": exe}]), {}).nodes
        assert node.command[1:3] == ["-m", f"sit2stand.nodes.{exe}"]


def test_a_node_that_said_its_result_and_died_in_teardown_is_judged_by_what_it_said(tmp_path):
    """A node prints its result before DDS teardown (io.topics.NODE_RESULT); teardown may hang and the process end by a
    signal or exit 1 (two CI runs: a good stand-up failed by the driver's exit -15). The job is judged by the result
    said; a node that said a failure still fails it."""
    said = tmp_path / "said.py"
    said.write_text(textwrap.dedent(f"""\
        #!{sys.executable}
        import sys
        print("[{{}}] result: exit {{}}; tearing down DDS".format(sys.argv[1], sys.argv[2]), flush=True)
        sys.exit(1)                 # the teardown's end, not the node's result
        """))
    said.chmod(0o755)
    for told, job in (("0", 0), ("2", 1)):
        proc = run_launch(tmp_path, [{"name": "node", "executable": str(said), "arguments": ["node", told],
                                      "on_exit": "shutdown"}])
        out, _ = proc.communicate(timeout=30)
        assert proc.returncode == job, out
        assert f"node said exit {told}, then its DDS teardown ended it with 1: judged by what it said" in out
