"""``sit2stand view``: a run's :class:`~sit2stand.view.scene.Scene` as a Rerun recording with its own layout.

The recording carries everything it shows, the robot's meshes included (``Asset3D`` with the mesh file's bytes),
so a saved ``.rrd`` opens the same in the native viewer, in the browser viewer and on another machine, with nothing
to set up. Entities:

* ``/world``: lab frame, z up (REP-103). ``floor``, ``chair`` (the robot's), ``robot/<visual>`` (one per URDF visual:
  its placement over time; ``mesh`` under it), ``robot/com`` (measured, from the sensed joints and base with the
  URDF's inertias) and ``com_floor`` (its floor projection), ``robot/planned_com``, ``robot/planned_zmp``,
  ``robot/cop``, ``robot/support`` (the soles' convex hull).
* ``/world/human``: the human's side, :data:`HUMAN_BESIDE_M` to the robot's left unless overlaid: ``skeleton``,
  ``markers``, ``com`` and ``com_floor``, ``cop``, ``plates/<name>`` (outline) and ``plates/<name>/force``.
* ``/plots``: time series, human against robot: COM forward and height, COP and ZMP forward, knee, hip, trunk
  flexion and ankle dorsiflexion.

Time is the bag's own (timeline ``time``, seconds of bag time).
"""

from __future__ import annotations

import ctypes.util
import os
import socket
import sys
import tempfile
import time
import urllib.parse
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from rerun.experimental import ViewerClient

from ..errors import Sit2StandError
from ..robot.meshes import shown_rgba
from .scene import PointSeries, Scene

TIMELINE = "time"
WEB_PORT = 9090
"""The port of Rerun's web viewer (``view --web``): its default."""


class ViewError(Sit2StandError, RuntimeError):
    """The viewer cannot run here; the message says what is missing."""

HUMAN_BESIDE_M = 1.0
"""The human is drawn this far to the robot's left (+y) [m], so that neither hides the other; ``overlay``: 0."""
FORCE_SCALE_M_PER_N = 1e-3
"""Plate forces are drawn as arrows this long per newton [m/N] (a 700 N body weight: 0.7 m)."""
PLOTS = {"com_x": "COM forward [m]", "com_z": "COM height [m]", "cop_x": "COP / ZMP forward [m]",
         "knee": "knee flexion [deg]", "hip": "hip flexion [deg]", "trunk": "trunk flexion [deg]",
         "ankle": "ankle dorsiflexion [deg]"}
"""The time-series views: entity under ``/plots`` -> title."""
COLOURS = {"human": (220, 120, 40), "robot": (40, 110, 220), "plan": (120, 200, 255), "zmp": (150, 60, 200),
           "cop": (200, 30, 30), "chair": (140, 90, 50), "floor": (200, 200, 200), "plate": (90, 90, 90)}


def log_scene(scene: Scene, rec: rr.RecordingStream, overlay: bool = False) -> None:
    """Log ``scene`` to ``rec`` (see the module docstring)."""
    rec.log("/world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log("/world/floor", rr.Boxes3D(centers=[[0.2, 0.5, -0.002]], half_sizes=[[1.2, 1.4, 0.002]],
                                       colors=[COLOURS["floor"]], fill_mode="solid"), static=True)
    rec.log("/world/human", rr.Transform3D(translation=[0.0, 0.0 if overlay else HUMAN_BESIDE_M, 0.0]), static=True)
    if scene.chair is not None:
        rec.log("/world/chair", rr.Boxes3D(centers=[scene.chair.centre], half_sizes=[scene.chair.half_size],
                                           colors=[COLOURS["chair"]], fill_mode="solid"), static=True)
    if scene.human_chair is not None:
        rec.log("/world/human/chair", rr.Boxes3D(centers=[scene.human_chair.centre],
                                                 half_sizes=[scene.human_chair.half_size], colors=[COLOURS["chair"]],
                                                 fill_mode="solid"), static=True)
    if scene.robot is not None:
        _log_robot(scene, rec)
    if scene.human is not None:
        _log_human(scene, rec)
    _log_points(scene, rec)
    _log_plates(scene, rec)
    if scene.markers is not None:
        t, xyz = scene.markers
        seen = [p[np.isfinite(p).all(axis=1)] for p in xyz]
        rr.send_columns("/world/human/markers", indexes=[_time(t)], columns=rr.Points3D.columns(
            positions=np.concatenate(seen)).partition([len(p) for p in seen]), recording=rec)
        rec.log("/world/human/markers", rr.Points3D.from_fields(radii=0.008, colors=[(250, 200, 0)]), static=True)
    _log_plots(scene, rec)


def _time(t_s: np.ndarray) -> rr.TimeColumn:
    return rr.TimeColumn(TIMELINE, duration=np.asarray(t_s, float))


def _log_robot(scene: Scene, rec: rr.RecordingStream) -> None:
    robot = scene.robot
    t = _time(robot.t_s)
    for v in robot.visuals:
        path = f"/world/robot/{v.name}"
        rr.send_columns(path, indexes=[t], columns=rr.Transform3D.columns(translation=v.translation,
                                                                            mat3x3=v.rotation), recording=rec)
        if not np.allclose(v.scale, 1.0):
            rec.log(f"{path}/mesh", rr.Transform3D(scale=v.scale), static=True)
        rgba = shown_rgba(v.rgba)
        rec.log(f"{path}/mesh", rr.Asset3D(path=v.mesh, albedo_factor=(rgba * 255).astype(np.uint8)), static=True)
    rr.send_columns("/world/robot/com", indexes=[t], columns=rr.Points3D.columns(positions=robot.com), recording=rec)
    floor = robot.com * [1.0, 1.0, 0.0]
    rr.send_columns("/world/robot/com_floor", indexes=[t], columns=rr.LineStrips3D.columns(
        strips=np.stack([robot.com, floor], axis=1)), recording=rec)
    hulls = [_hull(s.reshape(-1, 3)) for s in robot.soles]
    rr.send_columns("/world/robot/support", indexes=[t], columns=rr.LineStrips3D.columns(
        strips=hulls), recording=rec)
    rec.log("/world/robot/com", rr.Points3D.from_fields(radii=0.025, colors=[COLOURS["robot"]]), static=True)
    rec.log("/world/robot/com_floor", rr.LineStrips3D.from_fields(colors=[COLOURS["robot"]], radii=0.003),
            static=True)
    rec.log("/world/robot/support", rr.LineStrips3D.from_fields(colors=[(30, 160, 60)], radii=0.004), static=True)


def _turn(a, b, c) -> float:
    """The z of (b - a) x (c - a): positive when a, b, c turn left."""
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _hull(points: np.ndarray) -> np.ndarray:
    """The closed outline of the convex hull of points' x, y (monotone chain), at floor height + 1 mm."""
    pts = sorted(map(tuple, np.round(points[:, :2], 6)))
    def half(seq):
        out: list = []
        for p in seq:
            while len(out) >= 2 and _turn(out[-2], out[-1], p) <= 0:
                out.pop()
            out.append(p)
        return out[:-1]
    ring = half(pts) + half(pts[::-1])
    ring.append(ring[0])
    return np.column_stack([np.array(ring), np.full(len(ring), 0.001)])


def _log_human(scene: Scene, rec: rr.RecordingStream) -> None:
    human = scene.human
    n, b = human.bones.shape[:2]
    rr.send_columns("/world/human/skeleton", indexes=[_time(human.t_s)], columns=rr.LineStrips3D.columns(
        strips=human.bones.reshape(n * b, 2, 3)).partition([b] * n), recording=rec)
    rec.log("/world/human/skeleton", rr.LineStrips3D.from_fields(colors=[COLOURS["human"]], radii=0.015),
            static=True)


POINT_ENTITIES = {"human COM": ("/world/human/com", "human", 0.025), "human measured COP": ("/world/human/cop", "cop",
                                                                                             0.015),
                  "robot planned COM": ("/world/robot/planned_com", "plan", 0.02),
                  "robot planned ZMP": ("/world/robot/planned_zmp", "zmp", 0.015),
                  "robot COP": ("/world/robot/cop", "cop", 0.015)}
"""Scene point label -> (entity, colour, radius [m])."""


def _log_points(scene: Scene, rec: rr.RecordingStream) -> None:
    for label, series in scene.points.items():
        path, colour, radius = POINT_ENTITIES[label]
        ok = np.isfinite(series.xyz).all(axis=1)
        rr.send_columns(path, indexes=[_time(series.t_s)], columns=rr.Points3D.columns(
            positions=series.xyz[ok]).partition(ok.astype(int)), recording=rec)
        rec.log(path, rr.Points3D.from_fields(radii=radius, colors=[COLOURS[colour]]), static=True)
    com = scene.points.get("human COM")
    if com is not None:
        rr.send_columns("/world/human/com_floor", indexes=[_time(com.t_s)], columns=rr.LineStrips3D.columns(
            strips=np.stack([com.xyz, com.xyz * [1.0, 1.0, 0.0]], axis=1)), recording=rec)
        rec.log("/world/human/com_floor", rr.LineStrips3D.from_fields(colors=[COLOURS["human"]], radii=0.003),
                static=True)


def _log_plates(scene: Scene, rec: rr.RecordingStream) -> None:
    for plate in scene.plates:
        path = f"/world/human/plates/{plate.name}"
        if plate.corners is not None:
            rec.log(path, rr.LineStrips3D([np.vstack([plate.corners, plate.corners[:1]])],
                                          colors=[COLOURS["plate"]], radii=0.004), static=True)
        ok = np.isfinite(plate.cop).all(axis=1)
        rr.send_columns(f"{path}/force", indexes=[_time(plate.t_s)], columns=rr.Arrows3D.columns(
            origins=plate.cop[ok], vectors=plate.force[ok] * FORCE_SCALE_M_PER_N).partition(ok.astype(int)),
            recording=rec)
        rec.log(f"{path}/force", rr.Arrows3D.from_fields(colors=[COLOURS["cop"]], radii=0.006), static=True)


def _series(rec: rr.RecordingStream, path: str, t_s: np.ndarray, values: np.ndarray, name: str, colour) -> None:
    ok = np.isfinite(values)
    if not ok.any():
        return
    rr.send_columns(path, indexes=[_time(t_s[ok])], columns=rr.Scalars.columns(scalars=values[ok]), recording=rec)
    rec.log(path, rr.SeriesLines(names=name, colors=[colour], widths=2.0), static=True)


def _log_plots(scene: Scene, rec: rr.RecordingStream) -> None:
    p: dict[str, PointSeries] = scene.points
    for axis, col in (("com_x", 0), ("com_z", 2)):
        if "human COM" in p:
            _series(rec, f"/plots/{axis}/human", p["human COM"].t_s, p["human COM"].xyz[:, col], "human",
                    COLOURS["human"])
        if "robot planned COM" in p:
            _series(rec, f"/plots/{axis}/robot_planned", p["robot planned COM"].t_s, p["robot planned COM"].xyz[:, col],
                    "robot planned", COLOURS["plan"])
        if scene.robot is not None:
            _series(rec, f"/plots/{axis}/robot_measured", scene.robot.t_s, scene.robot.com[:, col], "robot measured",
                    COLOURS["robot"])
    for label, name, colour in (("human measured COP", "human COP", "human"), ("robot COP", "robot COP", "cop"),
                                ("robot planned ZMP", "robot planned ZMP", "zmp")):
        if label in p:
            _series(rec, f"/plots/cop_x/{name.replace(' ', '_')}", p[label].t_s, p[label].xyz[:, 0], name,
                    COLOURS[colour])
    for who, body in (("human", scene.human), ("robot", scene.robot)):
        for angle, deg in (body.angles_deg.items() if body is not None else ()):
            _series(rec, f"/plots/{angle}/{who}", body.t_s, deg, who, COLOURS[who])


def blueprint(scene: Scene) -> rrb.Blueprint:
    """A large 3D view of the lab beside the time series (see :data:`PLOTS`), the whole run on screen."""
    eye = rrb.EyeControls3D(position=[1.6, 3.2, 1.4], look_target=[-0.1, 0.5, 0.55], eye_up=[0, 0, 1])
    three_d = rrb.Spatial3DView(origin="/world", name="stand-up (lab frame)", eye_controls=eye,
                                line_grid=rrb.LineGrid3D(visible=False))
    plots = [rrb.TimeSeriesView(origin=f"/plots/{key}", name=title) for key, title in PLOTS.items()]
    return rrb.Blueprint(rrb.Horizontal(three_d, rrb.Vertical(*plots), column_shares=[3, 2]),
                         collapse_panels=True)


def save(scene: Scene, out: Path, overlay: bool = False) -> Path:
    """Write the scene's recording and its layout to ``out`` (``.rrd``)."""
    rec = rr.RecordingStream("sit2stand", recording_id=str(scene.source.resolve()))
    rec.save(out, default_blueprint=blueprint(scene))
    log_scene(scene, rec, overlay)
    rec.flush()
    rec.disconnect()
    return out


def _viewer_on_path() -> None:
    """Put the ``rerun`` viewer that rerun-sdk installs beside this Python on ``PATH`` (where the SDK looks for it),
    for a virtual environment that is not activated."""
    here = str(Path(sys.executable).parent)
    if (Path(here) / "rerun").exists() and here not in os.environ.get("PATH", "").split(os.pathsep):
        os.environ["PATH"] = here + os.pathsep + os.environ.get("PATH", "")


def show(scene: Scene, web: bool = False, overlay: bool = False) -> str | None:
    """Open the scene in Rerun's native viewer, or (``web``) serve it to the browser viewer on :data:`WEB_PORT`; the
    web viewer's address."""
    _viewer_on_path()
    rec = rr.RecordingStream("sit2stand", recording_id=str(scene.source.resolve()))
    url = None
    if web:
        grpc = rec.serve_grpc(default_blueprint=blueprint(scene))
        rr.serve_web_viewer(web_port=WEB_PORT, connect_to=grpc, open_browser=False)
        url = f"http://localhost:{WEB_PORT}/?url={urllib.parse.quote(grpc, safe='')}"
    else:
        rec.spawn(default_blueprint=blueprint(scene))
    log_scene(scene, rec, overlay)
    rec.flush()
    return url


SCREENSHOT_WAIT_S = 60.0
"""How long a screenshot waits for the headless viewer to settle [s]: loaded, meshes drawn, notices gone."""
SCREENSHOT_SIZE_PX = 1600
"""The picture's longer side [px]."""
SETTLED_FRAMES = 3
"""A screenshot is saved once this many pictures taken a second apart are the same."""


def screenshot(rrd: Path, png: Path, at_s: float) -> Path:
    """A PNG of Rerun's own viewer showing ``rrd`` at bag time ``at_s`` [s]: the viewer runs headless (no window, no
    X server) on Vulkan; on a machine without a GPU that is Mesa's software renderer (Debian:
    ``mesa-vulkan-drivers``).

    Raises:
        ViewError: no Vulkan here.
        TimeoutError: the picture did not settle within :data:`SCREENSHOT_WAIT_S`.
    """
    if ctypes.util.find_library("vulkan") is None:
        raise ViewError("Rerun's headless viewer draws with Vulkan and this machine has no Vulkan loader: install "
                        "one with a driver (Debian, Ubuntu: `apt-get install mesa-vulkan-drivers`, Mesa's software "
                        "renderer)")
    os.environ.setdefault("WGPU_BACKEND", "vulkan")      # llvmpipe's OpenGL lacks a texture format Rerun draws to
    if not os.environ.get("XDG_RUNTIME_DIR"):
        os.environ["XDG_RUNTIME_DIR"] = tempfile.mkdtemp(prefix="rerun-xdg-")
    _viewer_on_path()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    viewer = ViewerClient.spawn(headless=True, port=port, hide_welcome_screen=True)
    try:
        viewer.open(str(Path(rrd).resolve()))
        deadline = time.monotonic() + SCREENSHOT_WAIT_S
        while viewer.get_state().loading and time.monotonic() < deadline:
            time.sleep(0.2)
        viewer.set_time(TIMELINE, duration=float(at_s), play_state="paused")
        same, last = 0, b""
        while same < SETTLED_FRAMES:
            if time.monotonic() > deadline:
                raise TimeoutError(f"{rrd}: Rerun's picture still changing after {SCREENSHOT_WAIT_S:.0f} s")
            time.sleep(1.0)
            picture = viewer.take_screenshot(max_size=SCREENSHOT_SIZE_PX)
            same, last = (same + 1 if picture == last else 1), picture
        Path(png).write_bytes(last)
    finally:
        viewer.quit()
    return png
