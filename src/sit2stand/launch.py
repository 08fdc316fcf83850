"""`sit2stand launch GRAPH.yaml`: start a graph of ROS 2 node processes (ros2 launch is not on PyPI).

A graph file::

    name: roundtrip
    arguments:                       # defaults of $(var NAME); override with NAME:=VALUE on the command line
      bag: ../bags/natural
      out: ../bags/generated/copy
    nodes:
      - name: recorder
        executable: recorder         # a sit2stand node (python -m sit2stand.nodes.<executable>) or a program on PATH
        parameters:                  # ROS parameter YAML files (relative to the graph file, or a packaged
          - recorder                 # parameter file's name: recorder, replayer, human_com) and/or inline maps
          - {output: $(var out)}
        remappings: {/in: /out}
        arguments: []                # extra command-line arguments before --ros-args
        env: {ROS_LOG_DIR: /tmp}
        scheduling: {policy: fifo, priority: 50}   # or {nice: 10}; default: the launcher's own (see below)
        delay_s: 0.0                 # start this long after the graph
        host: robot                  # a label: `sit2stand launch GRAPH --host robot` starts only these nodes
        on_exit: ignore              # "ignore": a clean exit leaves the graph running, a failure stops it;
                                     # "shutdown": when this node ends, stop the whole graph; "continue": the graph
                                     # runs on whatever its exit (the recorder's default: its crash must not stop
                                     # the robot), a failure still fails the job
        grace_s: 10.0                # SIGINT to SIGTERM at shutdown; default the launcher's --grace (recorder: 60)
      - name: replayer
        executable: replayer
        parameters: [{bag: $(var bag), wait_for_subscribers: 1}]
        on_exit: shutdown

A graph spread over several machines is launched once per machine, each starting its share: ``--host NAME``
(the nodes labelled ``host: NAME``) or ``--only a,b`` (these nodes by name). The shares find each other through
DDS discovery (same ``ROS_DOMAIN_ID``; see docs/method.md, "Live capture", for multicast and static peers).

Substitutions: ``$(var NAME)``, ``$(env NAME)`` / ``$(env NAME default)``, ``$(dirname)`` (the graph file's folder).

The graph itself is a file or a packaged graph's name (``standup``: ``sit2stand/data/graphs/standup.yaml``, see
:mod:`sit2stand.data`); a packaged graph names its parameter files and plant by name, so a copy of it runs anywhere.

``scheduling`` sets a node's Linux scheduling class before it starts (every thread it makes inherits it):
``policy`` ``other`` (the default time-sharing scheduler) with an optional ``nice`` (-20..19), or ``fifo`` / ``rr``
(real-time) with a ``priority`` (1..99). A latency-critical node in real time is what ROS 2 control stacks do
(ros2_control's controller manager asks for SCHED_FIFO 50); it needs root, CAP_SYS_NICE or an ``rtprio`` limit.
Where that is not permitted the node still starts, under the default scheduler, and the launcher says so.

Each node's output is printed line by line with a ``[name]`` prefix. SIGINT/SIGTERM to the launcher are forwarded
as SIGINT to every node; nodes still alive after their ``grace_s`` get SIGTERM, then SIGKILL. Recorders (``on_exit:
continue``) are stopped last, once every other node has ended, so that they take all that was published and their
shutdown is only their own drain and close. Every child gets PR_SET_PDEATHSIG, so even a launcher killed with SIGKILL
leaves no orphan process.

The launcher exits 0 only when the job succeeded: every node exited 0 (or on the SIGINT it was sent). A node that
failed (a robot that fell: the driver exits 3; a recorder killed, or one that lost messages: exit 1) makes it exit 1,
naming the nodes.
"""

from __future__ import annotations

import ctypes
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from .data import DataFileNotFound, graph_path
from .data import folder as data_folder
from .data import names as data_names
from .errors import Sit2StandError
from .io.topics import NODE_RESULT, RUN_ID_ENV
from .scheduling import POLICIES, Scheduling

OUR_NODES = {"replayer", "recorder", "human_com", "driver", "identification", "retargeter", "mocap_bridge",
             "foxglove"}
ON_EXIT = ("ignore", "shutdown", "continue")
# The recorder's shutdown: its drain (up to 30 s while a backlog keeps arriving) and its close (the last chunk and the
# bag's summary); an 11-minute recording took longer than 10 s and was sent SIGTERM
RECORDER_GRACE_S = 60.0
SUBST = re.compile(r"\$\((var|env|dirname)(?:\s+([^)\s]+))?(?:\s+([^)]*))?\)")


class LaunchError(Sit2StandError, ValueError):
    """A graph file that cannot be launched; the message names the file and the field."""


def parse_scheduling(raw, where: str) -> Scheduling | None:
    """A graph node's ``scheduling`` map; errors name the field."""
    if raw is None:
        return None
    if not isinstance(raw, dict) or set(raw) - {"policy", "priority", "nice"}:
        raise LaunchError(f"{where}: scheduling must be a map with policy, priority and/or nice")
    policy = str(raw.get("policy", "other")).lower()
    if policy not in POLICIES:
        raise LaunchError(f"{where}: scheduling.policy must be one of {', '.join(POLICIES)}, not {policy!r}")
    try:
        priority, nice = int(raw.get("priority", 0)), int(raw.get("nice", 0))
    except (TypeError, ValueError):
        raise LaunchError(f"{where}: scheduling.priority and scheduling.nice must be integers") from None
    if policy == "other":
        if not -20 <= nice <= 19:
            raise LaunchError(f"{where}: scheduling.nice must be in -20..19, not {nice}")
        return Scheduling("other", 0, nice)
    if not 1 <= priority <= 99:
        raise LaunchError(f"{where}: scheduling.priority must be in 1..99 for policy {policy}, not {priority}")
    return Scheduling(policy, priority, 0)       # nice applies to policy other only: a graph gives both, one switch


@dataclass
class NodeSpec:
    """One process of a graph."""

    name: str
    command: list[str]
    env: dict[str, str] = field(default_factory=dict)
    delay_s: float = 0.0
    shutdown_on_exit: bool = False
    scheduling: Scheduling | None = None
    host: str = ""
    continue_on_failure: bool = False   # on_exit: continue
    grace_s: float | None = None        # None: the launcher's


@dataclass
class Graph:
    name: str
    nodes: list[NodeSpec]
    tmpdir: Path | None = None          # the inline parameters' files (made at the first); removed by :meth:`discard`

    def inline_parameters_file(self, node: str, index: int, parameters: dict) -> Path:
        """A ROS parameters file holding ``parameters``, node ``node``'s ``index``-th entry, in the graph's temp
        folder."""
        if self.tmpdir is None:
            self.tmpdir = Path(tempfile.mkdtemp(prefix="sit2stand-launch-"))
        file = self.tmpdir / f"{node}_{index}.yaml"
        file.write_text(yaml.safe_dump({"/**": {"ros__parameters": parameters}}))
        return file

    def discard(self) -> None:
        """Remove the inline parameters' temp folder (the launcher does, once the graph has stopped; a graph
        loaded and never run should too)."""
        if self.tmpdir is not None:
            shutil.rmtree(self.tmpdir, ignore_errors=True)
            self.tmpdir = None


def _substitute(value, variables: dict[str, str], graph_dir: Path, where: str):
    if isinstance(value, str):
        def repl(m: re.Match) -> str:
            kind, name, default = m.group(1), m.group(2), m.group(3)
            if kind == "dirname":
                return str(graph_dir)
            if kind == "env":
                if name in os.environ:
                    return os.environ[name]
                if default is not None:
                    return default
                raise LaunchError(f"{where}: environment variable {name} is not set")
            if name not in variables:
                raise LaunchError(f"{where}: $(var {name}) has no value: give {name}:=VALUE or add it to 'arguments'")
            return str(variables[name])
        new = SUBST.sub(repl, value)
        if new != value and SUBST.fullmatch(value) and new.strip():   # an empty value stays an empty string
            try:
                return yaml.safe_load(new)  # a whole-value substitution keeps its YAML type (numbers, bools)
            except yaml.YAMLError:
                return new
        return new
    if isinstance(value, list):
        return [_substitute(v, variables, graph_dir, where) for v in value]
    if isinstance(value, dict):
        return {k: _substitute(v, variables, graph_dir, where) for k, v in value.items()}
    return value


def load_graph(path: str | Path, overrides: dict[str, str] | None = None, namespace: str = "") -> Graph:
    """Parse a graph file, or a packaged graph's name, into :class:`Graph` (commands resolved, inline parameters
    written to a temp folder). ``namespace`` (e.g. ``robot2``): every node runs in it (``-r __ns:=/robot2``), and
    with them every topic, /clock included, so two graphs run side by side on one ROS domain."""
    try:
        path = graph_path(path)
    except DataFileNotFound as err:
        raise LaunchError(str(err)) from None
    try:
        doc = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as err:
        raise LaunchError(f"{path}: not valid YAML: {err}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("nodes"), list) or not doc["nodes"]:
        raise LaunchError(f"{path}: needs a non-empty 'nodes' list")
    graph_dir = path.resolve().parent
    # argument defaults may use $(dirname) and $(env ...) themselves
    variables = {str(k): str(_substitute(str(v), {}, graph_dir, f"{path}: arguments.{k}"))
                 for k, v in (doc.get("arguments") or {}).items()}
    variables.update(overrides or {})
    unknown = set(overrides or {}) - set(doc.get("arguments") or {})
    if unknown:
        raise LaunchError(f"{path}: unknown argument(s) {', '.join(sorted(unknown))}; "
                          f"it takes {', '.join(sorted(doc.get('arguments') or {})) or 'none'}")
    graph = Graph(str(doc.get("name", path.stem)), [])
    names = set()
    try:
        for i, raw in enumerate(doc["nodes"]):
            where = f"{path}: nodes[{i}]"
            if not isinstance(raw, dict) or "name" not in raw:
                raise LaunchError(f"{where}: each node needs a 'name'")
            spec = _substitute(raw, variables, graph_dir, where)
            name = str(spec["name"])
            if name in names:
                raise LaunchError(f"{where}: duplicate node name {name!r}")
            names.add(name)
            graph.nodes.append(_node_spec(spec, name, where, graph_dir, graph, _namespace(namespace)))
    except BaseException:
        graph.discard()
        raise
    return graph


def select_nodes(graph: Graph, only: list[str] | None = None, host: str | None = None) -> Graph:
    """The share of ``graph`` one machine runs: the nodes named in ``only`` and/or labelled ``host: <host>``.

    Raises:
        LaunchError: a name no node has, or a host label no node carries (the message lists what there is).
    """
    nodes = graph.nodes
    if only:
        unknown = sorted(set(only) - {n.name for n in nodes})
        if unknown:
            raise LaunchError(f"graph {graph.name}: no node {', '.join(unknown)} (it has "
                              f"{', '.join(n.name for n in nodes)})")
        nodes = [n for n in nodes if n.name in only]
    if host:
        hosts = sorted({n.host for n in graph.nodes if n.host})
        if host not in hosts:
            raise LaunchError(f"graph {graph.name}: no node is labelled host: {host} (labels: "
                              f"{', '.join(hosts) or 'none'})")
        nodes = [n for n in nodes if n.host == host]
    if not nodes:
        raise LaunchError(f"graph {graph.name}: --only and --host leave no node to start")
    return Graph(graph.name, nodes, graph.tmpdir)


def _namespace(namespace: str) -> str:
    """``robot2`` or ``/robot2`` as ``/robot2`` ('' for none); names the rule a ROS namespace breaks."""
    ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
    if ns and not re.fullmatch(r"(/[A-Za-z_][A-Za-z0-9_]*)+", ns):
        raise LaunchError(f"namespace {namespace!r}: ROS names are letters, digits and _ (not starting with a digit), "
                          f"separated by /")
    return ns


def _node_spec(spec: dict, name: str, where: str, graph_dir: Path, graph: Graph, namespace: str = "") -> NodeSpec:
    exe = spec.get("executable")
    if exe is None:
        raise LaunchError(f"{where} ({name}): needs 'executable'")
    if exe in OUR_NODES:
        command = [sys.executable, "-m", f"sit2stand.nodes.{exe}"]
    else:
        found = shutil.which(str(exe)) or shutil.which(str(exe), path=str(Path(sys.executable).parent))
        if found is None:
            raise LaunchError(f"{where} ({name}): executable {exe!r} is neither a sit2stand node "
                              f"({', '.join(sorted(OUR_NODES))}) nor on PATH")
        command = [found]
    command += [str(a) for a in spec.get("arguments", []) or []]
    command += ["--ros-args", "-r", f"__node:={name}"] + (["-r", f"__ns:={namespace}"] if namespace else [])
    for j, entry in enumerate(spec.get("parameters", []) or []):
        if isinstance(entry, str):
            file = Path(entry) if Path(entry).is_absolute() else graph_dir / entry
            if not file.is_file():      # else a packaged parameter file's name ("recorder")
                packaged = data_folder("params") / (entry if entry.endswith(".yaml") else f"{entry}.yaml")
                if Path(entry).name != entry or not packaged.is_file():
                    raise LaunchError(f"{where} ({name}): parameter file {file} does not exist, nor is {entry!r} a "
                                      f"packaged one ({', '.join(data_names('params'))})")
                file = packaged
            command += ["--params-file", str(file)]
        elif isinstance(entry, dict):
            command += ["--params-file", str(graph.inline_parameters_file(name, j, entry))]
        else:
            raise LaunchError(f"{where} ({name}): parameters[{j}] must be a file name or a map")
    for src, dst in (spec.get("remappings") or {}).items():
        command += ["-r", f"{src}:={dst}"]
    recorder = exe == "recorder"
    on_exit = spec.get("on_exit", "continue" if recorder else "ignore")
    if on_exit not in ON_EXIT:
        raise LaunchError(f"{where} ({name}): on_exit must be one of {', '.join(ON_EXIT)}, not {on_exit!r}")
    grace = spec.get("grace_s", RECORDER_GRACE_S if recorder else None)
    if grace is not None and (isinstance(grace, bool) or not isinstance(grace, (int, float)) or grace <= 0):
        raise LaunchError(f"{where} ({name}): grace_s must be a positive number of seconds, not {grace!r}")
    env = {str(k): str(v) for k, v in (spec.get("env") or {}).items()}
    return NodeSpec(name, command, env, float(spec.get("delay_s", 0.0)), on_exit == "shutdown",
                    parse_scheduling(spec.get("scheduling"), f"{where} ({name})"), str(spec.get("host", "")),
                    on_exit == "continue", None if grace is None else float(grace))


def _set_parent_death_signal() -> None:
    """In the child: get SIGTERM when the launcher dies, however it dies (Linux prctl PR_SET_PDEATHSIG)."""
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    except OSError:
        pass


def _child_setup(scheduling: Scheduling | None) -> None:
    """In the child, before exec: the parent death signal, and the scheduling class if permitted (the launcher
    checks afterwards whether it took)."""
    _set_parent_death_signal()
    if scheduling is not None:
        scheduling.try_apply(0)


class Launcher:
    """Runs a :class:`Graph` until its nodes end, a shutdown node exits, a signal, or ``timeout_s``."""

    def __init__(self, graph: Graph, grace_s: float = 10.0, out=None) -> None:
        self.graph = graph
        self.grace_s = grace_s
        self.out = out or sys.stdout
        self.procs: dict[str, subprocess.Popen] = {}
        self.reported: dict[str, int] = {}       # node -> the result it said before its teardown (NODE_RESULT)
        self._stop = threading.Event()
        self._print_lock = threading.Lock()
        self._readers: dict[str, threading.Thread] = {}     # node -> the thread reading its output
        self.width = max(len(n.name) for n in graph.nodes)
        # one id for this run of the graph, given to every node: a node of another run with the same name (a second
        # graph on the domain) stops itself (sit2stand.nodes.graph_guard.GraphGuard); the recorder stores it in the bag
        self.run_id = os.environ.get(RUN_ID_ENV) or uuid.uuid4().hex[:8]

    def _emit(self, name: str, line: str) -> None:
        with self._print_lock:
            self.out.write(f"[{name:<{self.width}}] {line}")
            if not line.endswith("\n"):
                self.out.write("\n")
            self.out.flush()

    def _pump(self, name: str, stream) -> None:
        for raw in iter(stream.readline, b""):
            line = raw.decode(errors="replace")
            said = NODE_RESULT.match(line.strip())
            if said:
                self.reported[name] = int(said["code"])
            self._emit(name, line)
        stream.close()

    def _failed(self, name: str, returncode: int, sent_sigint: bool = False) -> bool:
        """Whether a node that ended with ``returncode`` failed: by its code, or, when it said its result and then
        died in DDS teardown (killed, or its teardown bound expired), by what it said. Its last lines may still be in
        the pipe when it has ended: they are read first."""
        self._readers[name].join(timeout=2.0)
        said = self.reported.get(name)
        if said is not None and returncode != said:
            self._emit("launch", f"{name} said exit {said}, then its DDS teardown ended it with {returncode}: "
                                 f"judged by what it said")
            return said != 0
        return returncode not in ((0, -signal.SIGINT) if sent_sigint else (0,))

    def _start(self, spec: NodeSpec) -> None:
        env = dict(os.environ)
        env.update({"PYTHONUNBUFFERED": "1", "RCUTILS_COLORIZED_OUTPUT": "0", "RCUTILS_LOGGING_BUFFERED_STREAM": "0"})
        env.update(spec.env)
        env[RUN_ID_ENV] = self.run_id
        proc = subprocess.Popen(spec.command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL,
                                env=env, start_new_session=True,
                                preexec_fn=lambda: _child_setup(spec.scheduling))
        self.procs[spec.name] = proc
        reader = threading.Thread(target=self._pump, args=(spec.name, proc.stdout), daemon=True)
        reader.start()
        self._readers[spec.name] = reader
        note = ""
        if spec.scheduling is not None:
            try:
                took = spec.scheduling.holds_for(proc.pid)
            except OSError:          # it already ended
                took = True
            note = f", {spec.scheduling}" if took else \
                (f"; {spec.scheduling} was not permitted (needs root, CAP_SYS_NICE or an rtprio limit): it runs "
                 "under the default scheduler")
        self._emit("launch", f"started {spec.name} (pid {proc.pid}){note}")

    def request_stop(self, *_args) -> None:
        self._stop.set()

    def run(self, timeout_s: float | None = None) -> int:
        """Start the graph and supervise it; returns 0 when the job succeeded (every node ended cleanly), else 1."""
        old = {s: signal.signal(s, self.request_stop) for s in (signal.SIGINT, signal.SIGTERM)}
        t0 = time.monotonic()
        self._emit("launch", f"run {self.run_id}: graph {self.graph.name}")
        pending = sorted(self.graph.nodes, key=lambda n: n.delay_s)
        failed: list[str] = []
        try:
            while not self._stop.is_set():
                now = time.monotonic() - t0
                while pending and pending[0].delay_s <= now:
                    self._start(pending.pop(0))
                failed += self._check_exits()
                if not pending and all(p.poll() is not None for p in self.procs.values()):
                    break
                if timeout_s is not None and now > timeout_s:
                    self._emit("launch", f"timeout after {timeout_s:g} s: stopping the graph")
                    break
                time.sleep(0.05)
        finally:
            failed += self._shutdown()
            for s, handler in old.items():
                signal.signal(s, handler)
            for reader in self._readers.values():
                reader.join(timeout=2.0)
            self.graph.discard()
        if failed:
            self._emit("launch", "the job failed: " + ", ".join(
                f"{n} exited with code {self.procs[n].returncode}" for n in dict.fromkeys(failed)))
        return 1 if failed else 0

    def _check_exits(self) -> list[str]:
        """Report the nodes that ended since the last look, stop the graph where their ``on_exit`` says so; returns
        the names of those that failed."""
        failed = []
        for spec in self.graph.nodes:
            proc = self.procs.get(spec.name)
            if proc is None or proc.returncode is not None or proc.poll() is None:
                continue
            self._emit("launch", f"{spec.name} exited with code {proc.returncode}")
            bad = self._failed(spec.name, proc.returncode)
            if bad:
                failed.append(spec.name)
            if spec.shutdown_on_exit or (bad and not spec.continue_on_failure):
                self._emit("launch", f"stopping the graph ({spec.name} ended)")
                self._stop.set()
            elif bad:
                self._emit("launch", f"the graph goes on without {spec.name} (on_exit: continue); the job has failed")
        return failed

    def _shutdown(self) -> list[str]:
        """Stop every node still alive, recorders (``on_exit: continue``) once the others have ended; returns the
        names of the nodes that failed."""
        last = {s.name for s in self.graph.nodes if s.continue_on_failure}
        bad = self._stop_nodes([n for n in self.procs if n not in last])
        return bad + self._stop_nodes([n for n in self.procs if n in last])

    def _stop_nodes(self, names: list[str]) -> list[str]:
        """SIGINT these nodes, SIGTERM each one alive after its grace, SIGKILL 5 s later; returns the names of those
        that failed (an exit code other than 0, or death by a signal other than the SIGINT they were sent)."""
        t0 = time.monotonic()
        alive = {n: self.procs[n] for n in names if self.procs[n].poll() is None}
        grace = {s.name: self.grace_s if s.grace_s is None else s.grace_s for s in self.graph.nodes}
        escalation = {n: [(grace[n], signal.SIGTERM), (grace[n] + 5.0, signal.SIGKILL)] for n in alive}
        for proc in alive.values():
            _send(proc, signal.SIGINT)
        bad = []
        while alive:
            for name, proc in list(alive.items()):
                if proc.poll() is not None:
                    self._emit("launch", f"{name} exited with code {proc.returncode}")
                    if self._failed(name, proc.returncode, sent_sigint=True):
                        bad.append(name)
                    del alive[name]
                elif escalation[name] and time.monotonic() - t0 > escalation[name][0][0]:
                    sig = escalation[name].pop(0)[1]
                    self._emit("launch", f"sending {sig.name} to {name}")
                    _send(proc, sig)
            time.sleep(0.05)
        return bad


def _send(proc: subprocess.Popen, sig: int) -> None:
    try:
        proc.send_signal(sig)
    except ProcessLookupError:
        pass


def parse_overrides(items: list[str]) -> dict[str, str]:
    """``NAME:=VALUE`` command-line arguments to a dict."""
    out = {}
    for item in items:
        if ":=" not in item:
            raise LaunchError(f"argument {item!r} is not NAME:=VALUE")
        key, value = item.split(":=", 1)
        out[key] = value
    return out
