"""The stand-up graph's frames as ROS tools see them: one live stand-up (CAD robot, elderly demonstration) recorded,
then its /tf, /tf_static and /robot_description checked against Pinocchio, and the frame id of every stamped topic
checked against the frame its numbers are in."""

import re
import subprocess
import sys
from bisect import bisect_left
from functools import cache
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import rerun_entities

from sit2stand.io.bag import BagReader
from sit2stand.io.topics import HUMAN_ROOT_FRAME, LAB_FRAME, WORLD_FRAME, sole_world_aligned_frame
from sit2stand.robot.model import controller_model
from sit2stand.robot.profile import load_profile

TALOS = load_profile("talos")

pytestmark = pytest.mark.graph
ROOT = Path(__file__).resolve().parents[1]
SIDES = ("left", "right")
LEG_LINKS = [f"leg_{s}_{i}_link" for s in SIDES for i in range(1, 7)]
# The frame each stamped topic's numbers are in. Joint-space messages (joint angles of the chain rooted at the
# base) say base_link; those carrying a base pose as root_* / pelvis_* entries say where that pose is given.
EXPECTED_FRAME = {
    "/mocap/markers": LAB_FRAME, "/force_plate/chair": LAB_FRAME, "/force_plate/feet": LAB_FRAME,
    "/human/com": LAB_FRAME, "/human/joint_states": HUMAN_ROOT_FRAME, "/human/model_cop": LAB_FRAME,
    "/human/pelvis_pose": LAB_FRAME, "/viz/human": LAB_FRAME,
    "/human/measured_cop": LAB_FRAME, "/ground_truth/com": LAB_FRAME, "/ground_truth/joint_states": LAB_FRAME,
    "/robot/base_pose": WORLD_FRAME, "/robot/cop": WORLD_FRAME, "/robot/planned_com": WORLD_FRAME,
    "/robot/planned_zmp": WORLD_FRAME, "/robot/com_feedback": WORLD_FRAME, "/robot/retarget/ik": WORLD_FRAME,
    "/robot/ft/left": sole_world_aligned_frame("left"), "/robot/ft/right": sole_world_aligned_frame("right"),
    "/robot/joint_states": TALOS.root_link, "/robot/joint_command": TALOS.root_link, "/viz/markers": WORLD_FRAME,
}
# /tf samples of a stand-up at least (50 Hz: the robot's 6 s, seated, rising and standing, at the human's timing)
MIN_SAMPLES = 300
# Stamped, but with no single frame: per-link parameters (masses, COMs in each link's own frame, scale factors), the
# subject (stature, mass)
NO_SINGLE_FRAME = {"/human/scaling", "/ground_truth/inertial_parameters", "/human/subject"}


@pytest.fixture(scope="module")
def run(elderly_standup):
    """The shared stand-up (conftest): bags/elderly, the CAD plant: (bag path, launcher stdout)."""
    folder, result = elderly_standup
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    return folder / "run", result.stdout


@pytest.fixture(scope="module")
def bag(run):
    reader = BagReader(run[0])
    yield cache(reader.read), reader
    reader.close()


def _ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _se3(transform) -> pin.SE3:
    t, r = transform.translation, transform.rotation
    return pin.SE3(pin.Quaternion(r.w, r.x, r.y, r.z).normalized().toRotationMatrix(), np.array([t.x, t.y, t.z]))


def _edges(*messages) -> dict[str, tuple[str, pin.SE3]]:
    """child -> (parent, placement in parent) of the transforms of TFMessages."""
    return {tr.child_frame_id: (tr.header.frame_id, _se3(tr.transform)) for m in messages for tr in m.transforms}


def _in(edges, frame: str, root: str = WORLD_FRAME) -> pin.SE3:
    """The pose of ``frame`` in ``root``, composed along the tree as tf2 does."""
    X = pin.SE3.Identity()
    while frame != root:
        frame, Xp = edges[frame]
        X = Xp * X
    return X


@pytest.fixture(scope="module")
def frames(bag):
    """Per /tf stamp: the tree (with /tf_static), the recorded joint state and base pose of that stamp."""
    read, _ = bag
    static = [m for _, m in read("/tf_static")]
    js = {_ns(m.header): m for _, m in read("/robot/joint_states")}
    base = {_ns(m.header): m for _, m in read("/robot/base_pose")}
    tf = {}
    for m in _robot_tf(read):
        stamp = {_ns(tr.header) for tr in m.transforms}
        assert len(stamp) == 1, "one stamp per /tf message (one state sample)"
        tf[stamp.pop()] = m
    # each state sample gives /tf, /robot/joint_states and /robot/base_pose of one stamp. Where the recorder has all
    # three topics (it may match one of them a sample before the others: DDS discovery's timing, not asserted),
    # every /tf stamp has its joint state and base pose
    first = max(min(tf), min(js), min(base))
    last = min(max(tf), max(js), max(base))
    both = [s for s in tf if first <= s <= last]
    assert [s for s in both if s not in js or s not in base] == [], "a /tf sample without its state"
    return {s: (_edges(*static, tf[s]), js[s], base[s]) for s in both}


def _robot_tf(read) -> list:
    """The driver's /tf messages (world -> base_link first); the human_com node's start with lab -> pelvis."""
    return [m for _, m in read("/tf") if m.transforms[0].header.frame_id == WORLD_FRAME]


@cache
def _model():
    return controller_model()


def _pin_q(js, base) -> np.ndarray:
    """The controller model's configuration of a recorded joint state and base pose."""
    model = _model()
    q = pin.neutral(model)
    p, o = base.pose.position, base.pose.orientation
    q[:7] = p.x, p.y, p.z, o.x, o.y, o.z, o.w
    for name, value in zip(js.name, js.position):
        q[model.joints[model.getJointId(name)].idx_q] = value
    return q


# --- /tf, /tf_static, /robot_description ------------------------------------------------------------------------------
def test_the_robot_stands_up_and_the_bag_holds_tf_and_the_description(run, bag):
    out, stdout = run
    read, reader = bag
    topics = reader.topics()
    assert "upright" in stdout and "FALLEN" not in stdout, stdout[-3000:]
    z = np.array([m.pose.position.z for _, m in read("/robot/base_pose")])
    assert z[0] < 0.65 and z[-1] > 0.85, f"pelvis from {z[0]:.2f} m to {z[-1]:.2f} m: did not stand up"
    robot_tf = _robot_tf(read)
    assert topics["/tf"].msgtype == "tf2_msgs/msg/TFMessage" and len(robot_tf) > MIN_SAMPLES
    assert topics["/tf_static"].count == 1 and topics["/robot_description"].count == 1
    for latched in ("/tf_static", "/robot_description"):
        assert [q.durability.name for q in reader.qos(latched)] == ["TRANSIENT_LOCAL"], latched
    [(_, desc)] = read("/robot_description")
    urdf = desc.data
    assert urdf.startswith("<?xml") and '<robot name="talos"' in urdf
    for link in ["base_link", "torso_2_link", "left_sole_link", *LEG_LINKS]:
        assert f'<link name="{link}"' in urdf
    # the driver measures what /tf costs it; the recorder has every /tf sample from the first it took (when it
    # matched the driver's /tf is DDS discovery's timing, not asserted): consecutive state samples, 20 ms apart
    cost = re.search(r"/tf at 50 Hz: (\d+) messages of 35 transforms, (\d+) us median, (\d+) us p99", stdout)
    assert cost and len(robot_tf) <= int(cost.group(1)), stdout[-2000:]
    gaps = np.diff([_ns(m.transforms[0].header) for m in robot_tf])
    assert np.all(np.abs(gaps - 20_000_000) < 1_000), f"/tf samples lost: gaps up to {gaps.max() * 1e-6:.1f} ms"


def test_tf_has_world_to_base_link_and_every_leg_link_at_50_hz(bag, frames):
    read, _ = bag
    stamps = sorted(frames)
    period_ms = np.median(np.diff(stamps)) * 1e-6
    assert period_ms == pytest.approx(20.0, abs=0.5), "tf_rate_hz 50 of a 200 Hz state"
    edges = frames[stamps[0]][0]
    assert edges[TALOS.root_link][0] == WORLD_FRAME and edges[WORLD_FRAME][0] == LAB_FRAME
    for link in LEG_LINKS + ["left_sole_link", "right_sole_link", "sole_left", "sole_right", "arm_left_7_link",
                             "head_2_link", sole_world_aligned_frame("left")]:
        assert _in(edges, link, LAB_FRAME) is not None
    assert len(_robot_tf(read)[0].transforms) == 35


def test_the_sole_tf_is_where_pinocchio_puts_it_for_the_recorded_state(frames):
    """Every /tf message: world -> base_link -> leg links -> left_sole_link (and both soles), composed as tf2 does,
    against the controller's Pinocchio model (built from MuJoCo's compiled MJCF, not the URDF the driver reads) at
    the recorded joint state and base pose of the same stamp: within 1 mm (and 1e-6 rad)."""
    model = _model()
    data = model.createData()
    worst_m, worst_rad = 0.0, 0.0
    for edges, js, base in frames.values():
        pin.framesForwardKinematics(model, data, _pin_q(js, base))
        for side in SIDES:
            ref = data.oMf[model.getFrameId(f"sole_{side}")]
            for frame in (f"{side}_sole_link", f"sole_{side}"):
                X = _in(edges, frame)
                worst_m = max(worst_m, np.linalg.norm(X.translation - ref.translation))
                worst_rad = max(worst_rad, np.linalg.norm(pin.log3(ref.rotation.T @ X.rotation)))
    assert len(frames) > MIN_SAMPLES
    assert worst_m < 1e-3 and worst_rad < 1e-6, f"sole off by {worst_m * 1e3:.3g} mm, {worst_rad:.2g} rad"


# --- frame labels ----------------------------------------------------------------------------------------------------
def test_the_description_names_mesh_files_that_rerun_opens_with_no_ros_environment(run, bag, monkeypatch):
    """A bag alone shows the robot: /robot_description's meshes are file:// paths that exist, and Rerun's own MCAP
    reader (the one its viewer uses) turns them into meshes with no ROS_PACKAGE_PATH or AMENT_PREFIX_PATH."""
    read, _ = bag
    [(_, desc)] = read("/robot_description")
    uris = re.findall(r'<mesh filename="([^"]+)"', desc.data)
    assert uris and all(u.startswith("file:///") and Path(u[len("file://"):]).is_file() for u in uris)
    for var in ("ROS_PACKAGE_PATH", "AMENT_PREFIX_PATH"):
        monkeypatch.delenv(var, raising=False)
    [mcap] = Path(run[0]).glob("*.mcap")
    meshes = [e for e, cols in rerun_entities(mcap).items() if any(c.startswith("Asset3D:") for c in cols)]
    assert len(meshes) >= 20, f"{len(meshes)} meshes from the bag"


def test_sit2stand_view_shows_robot_human_chair_com_and_cop_in_one_recording(run, tmp_path):
    rrd = tmp_path / "run.rrd"
    done = subprocess.run([sys.executable, "-m", "sit2stand.cli", "view", str(run[0]), "--save", str(rrd)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    entities = rerun_entities(rrd)
    meshes = [e for e, cols in entities.items() if e.startswith("/world/robot/")
              and any(c.startswith("Asset3D:") for c in cols)]
    assert len(meshes) >= 20
    for needed in ("/world/chair", "/world/human/skeleton", "/world/human/com",
                   "/world/human/cop", "/world/robot/com", "/world/robot/planned_com", "/world/robot/planned_zmp",
                   "/world/robot/cop", "/world/robot/support", "/plots/knee/human", "/plots/knee/robot"):
        assert needed in entities, f"{needed} missing"
    assert any(c.startswith("LineStrips3D:") for c in entities["/world/human/skeleton"])


def test_every_stamped_topic_says_a_known_frame(bag):
    """Each stamped topic is in this module's table (a new topic needs its frame stated) and says that frame."""
    read, reader = bag
    for topic in sorted(reader.topics()):
        [(_, first)] = read(topic)[:1]
        if topic in ("/tf", "/tf_static") or not hasattr(first, "header") and not hasattr(first, "markers"):
            continue
        ids = {m.header.frame_id for _, msg in read(topic) for m in getattr(msg, "markers", [msg])}
        if topic in NO_SINGLE_FRAME:
            continue
        assert topic in EXPECTED_FRAME, f"{topic}: stamped, frame {ids}, but not in EXPECTED_FRAME"
        assert ids == {EXPECTED_FRAME[topic]}, f"{topic} says {ids}, its numbers are in {EXPECTED_FRAME[topic]}"


def _nearest(stamps: list[int], s: int) -> int:
    i = min(bisect_left(stamps, s), len(stamps) - 1)
    return stamps[i] if i == 0 or abs(stamps[i] - s) < abs(stamps[i - 1] - s) else stamps[i - 1]


def test_the_base_pose_is_in_world(frames):
    """/robot/base_pose (world) is the transform world -> base_link of the same stamp, and the pelvis's height."""
    for edges, _, base in frames.values():
        p, o = base.pose.position, base.pose.orientation
        X = _in(edges, TALOS.root_link)
        np.testing.assert_allclose(X.translation, [p.x, p.y, p.z], atol=1e-12)
        np.testing.assert_allclose(X.rotation, pin.Quaternion(o.w, o.x, o.y, o.z).toRotationMatrix(), atol=1e-12)


def test_the_feet_wrenches_are_in_the_world_aligned_sole_frames(bag, frames):
    """/robot/ft/<side>: force in world axes, torque about the sole point. With the numbers taken as they are in
    sole_<side>_world_aligned (world axes at the sole, from /tf), each loaded foot's own COP lies on its sole plate,
    and both feet's moments carried to the world origin give the /robot/cop (world) of the same sample. (Seated, the
    feet rock on their heel edges; the F/T sensor's static foot-weight compensation then puts the COP up to ~1 cm
    past the edge, measured. A torque about the world origin would put it ~8.5 cm off sideways.)"""
    read, _ = bag
    wrench = {s: {_ns(m.header): m.wrench for _, m in read(f"/robot/ft/{s}")} for s in SIDES}
    cop = {_ns(m.header): m.point for _, m in read("/robot/cop")}
    half_x, half_y = TALOS.sole.half_size_m[0], TALOS.sole.half_size_m[1]
    outside, compared = [], 0
    for stamp, (edges, _, _) in frames.items():
        force, moment = np.zeros(3), np.zeros(3)
        for side in SIDES:
            X = _in(edges, sole_world_aligned_frame(side))
            np.testing.assert_allclose(X.rotation, np.eye(3), atol=1e-12)
            sole = _in(edges, f"sole_{side}")
            np.testing.assert_allclose(X.translation, sole.translation, atol=1e-12)
            w = wrench[side][stamp]
            f = np.array([w.force.x, w.force.y, w.force.z])
            tau = np.array([w.torque.x, w.torque.y, w.torque.z])
            force += f
            moment += tau + np.cross(X.translation, f)
            if f[2] > 100.0:        # this foot's COP in its world-aligned sole frame, against the sole plate
                local = sole.rotation.T @ np.array([-tau[1] / f[2], tau[0] / f[2], 0.0])
                outside.append(max(abs(local[0] - TALOS.sole.centre_x_m) - half_x, abs(local[1]) - half_y))
        c = cop[stamp]
        if np.isfinite(c.x):
            np.testing.assert_allclose([c.x, c.y], [-moment[1] / force[2], moment[0] / force[2]], atol=2e-3)
            assert c.z == 0.0
            compared += 1
    outside = np.array(outside)
    assert len(outside) > MIN_SAMPLES and compared > MIN_SAMPLES
    assert outside.max() < 0.02 and np.mean(outside > 0.005) < 0.01, f"feet COPs up to {outside.max():.3f} m off"


def test_the_plans_com_zmp_and_feedback_are_in_world(bag, frames):
    """The plan's last COM is the robot's measured COM (Pinocchio, world) within 3 cm; its ZMP lies on the floor
    between the soles' heels and toes (world, from /tf); the COM feedback's shift is horizontal."""
    read, _ = bag
    tf_stamps = sorted(frames)
    coms = read("/robot/planned_com")
    model = _model()
    data = model.createData()
    err = []
    for _, m in coms[-100:]:                       # the last second of the plan: standing
        edges, js, base = frames[_nearest(tf_stamps, _ns(m.header))]
        measured = pin.centerOfMass(model, data, _pin_q(js, base))
        err.append(np.linalg.norm(measured - [m.position.x, m.position.y, m.position.z]))
    assert np.mean(err) < 0.03, f"planned COM {np.mean(err) * 100:.1f} cm from the robot's"
    edges = frames[tf_stamps[-1]][0]
    soles = np.array([_in(edges, f"sole_{s}").translation for s in SIDES])
    heel = soles[:, 0].min() + TALOS.sole.centre_x_m - TALOS.sole.half_size_m[0]
    toe = soles[:, 0].max() + TALOS.sole.centre_x_m + TALOS.sole.half_size_m[0]
    zmp = np.array([[m.point.x, m.point.y, m.point.z] for _, m in read("/robot/planned_zmp")[-100:]])
    assert np.all(zmp[:, 2] == 0.0) and np.all((zmp[:, 0] > heel) & (zmp[:, 0] < toe))
    assert np.all(np.abs(zmp[:, 1]) < np.abs(soles[:, 1]).max() + TALOS.sole.half_size_m[1])
    assert all(m.vector.z == 0.0 for _, m in read("/robot/com_feedback"))


def test_the_ik_base_pose_is_in_world(bag, frames):
    """/robot/retarget/ik's root_* entries (world): the first IK pose is calibrated over the robot's measured seated
    base pose, so its base is where /tf has base_link then (within 5 cm)."""
    read, _ = bag
    [(_, first)] = read("/robot/retarget/ik")[:1]
    names = list(first.name)
    root = np.array([first.position[names.index(f"root_{c}")] for c in "xyz"])
    edges = frames[_nearest(sorted(frames), _ns(first.header))][0]
    assert np.linalg.norm(root - _in(edges, TALOS.root_link).translation) < 0.05


def _markers(msg, names):
    where = {n: i for i, n in enumerate(msg.marker_names)}
    return np.array([[msg.positions[where[n]].x, msg.positions[where[n]].y, msg.positions[where[n]].z]
                     for n in names])


def test_the_human_topics_are_in_lab(bag):
    """Markers, plates, the human's COM, COPs and pelvis pose agree with each other in lab: feet markers near the
    floor (z up), the feet plate's COP between the feet markers' heels and toes, the standing COM above the feet,
    the skeleton's pelvis at the pelvis markers, and the ground truth COM at the estimate."""
    read, _ = bag
    frames = read("/mocap/markers")
    feet = ["LHEE", "RHEE", "LTOE", "RTOE"]
    by_stamp = {_ns(m.header): m for _, m in frames}
    last = _markers(frames[-1][1], feet)
    z = np.array([_markers(m, feet)[:, 2] for _, m in frames])
    assert np.nanmin(z) > -0.01 and np.nanmax(z) < 0.15, "feet markers above the lab floor"
    heel, toe = np.nanmin(last[:, 0]) - 0.03, np.nanmax(last[:, 0]) + 0.03
    plate = [m for _, m in read("/force_plate/feet")[-500:] if m.cop_valid]
    assert plate and all(heel < m.cop.x < toe and abs(m.cop.z) < 0.01 for m in plate)
    for topic in ("/human/measured_cop", "/human/model_cop"):
        pts = np.array([[m.point.x, m.point.y, m.point.z] for _, m in read(topic)[-30:]])
        assert np.all(np.abs(pts[:, 2]) < 0.01) and np.all((pts[:, 0] > heel) & (pts[:, 0] < toe)), topic
    com = read("/human/com")[-1][1].position
    assert heel < com.x < toe and 0.8 < com.z < 1.2
    truth = {_ns(m.header): m.position for _, m in read("/ground_truth/com")}
    d = [np.linalg.norm([m.position.x - truth[s].x, m.position.y - truth[s].y, m.position.z - truth[s].z])
         for _, m in read("/human/com") if (s := _ns(m.header)) in truth]
    assert len(d) > 400 and np.median(d) < 0.05
    pelvis = ["LASI", "RASI", "LPSI", "RPSI"]
    for _, pose in read("/human/pelvis_pose")[::50]:
        p = np.array([pose.pose.position.x, pose.pose.position.y, pose.pose.position.z])
        centre = np.nanmean(_markers(by_stamp[_ns(pose.header)], pelvis), axis=0)
        assert np.linalg.norm(p - centre) < 0.15
    assert not any(n.startswith("pelvis_") for n in read("/human/joint_states")[0][1].name), "no pseudo-joints"


def test_the_plan_markers_are_recorded_in_world_at_the_plans_com_and_zmp(bag):
    """/viz/markers (every 5th command): the COM sphere at the planned COM and the ZMP disc at the planned ZMP of the
    same stamp; the support polygon holds the plan's ZMP once standing."""
    read, reader = bag
    markers = read("/viz/markers")
    commands = reader.topics()["/robot/joint_command"].count
    assert abs(len(markers) - commands / 5) <= 2
    # stamps are /clock time (1 ms ticks): a burst of commands can share one, so any of that stamp's will do
    com, zmp = {}, {}
    for _, m in read("/robot/planned_com"):
        com.setdefault(_ns(m.header), []).append((m.position.x, m.position.y, m.position.z))
    for _, m in read("/robot/planned_zmp"):
        zmp.setdefault(_ns(m.header), []).append((m.point.x, m.point.y))
    for _, msg in markers:
        by_id = {m.id: m for m in msg.markers}
        s = _ns(by_id[0].header)
        assert (by_id[0].pose.position.x, by_id[0].pose.position.y, by_id[0].pose.position.z) in com[s]
        assert (by_id[2].pose.position.x, by_id[2].pose.position.y) in zmp[s]
        z = by_id[2].pose.position
    polygon = np.array([[p.x, p.y] for p in by_id[3].points[:-1]])
    edges = np.roll(polygon, -1, axis=0) - polygon
    rel = np.array([z.x, z.y]) - polygon
    assert np.all(edges[:, 0] * rel[:, 1] - edges[:, 1] * rel[:, 0] > 0), "the last ZMP inside the support polygon"


# --- the human in 3D, one time base ------------------------------------------------------------------------------
def test_the_human_skeleton_is_in_tf_under_lab_with_its_description(bag):
    """/tf also holds lab -> pelvis -> segments (the fitted skeleton): the pelvis at /human/pelvis_pose of the same
    stamp, the feet near the lab floor once standing; /human/robot_description (latched) is the skeleton's URDF
    with a link per segment; /viz/human holds the markers, the COM at /human/com and both COPs."""
    read, reader = bag
    human_tf = [m for _, m in read("/tf") if m.transforms[0].child_frame_id == HUMAN_ROOT_FRAME]
    assert len(human_tf) > 250           # 50 Hz of a 5.3 s recording
    pelvis = {_ns(m.header): m.pose for _, m in read("/human/pelvis_pose")}
    for m in human_tf[::20]:
        edges = _edges(m)
        X = _in(edges, HUMAN_ROOT_FRAME, LAB_FRAME)
        p = pelvis[_ns(m.transforms[0].header)].position
        np.testing.assert_allclose(X.translation, [p.x, p.y, p.z], atol=1e-9)
    edges = _edges(human_tf[-1])
    for foot in ("foot_l", "foot_r"):
        assert -0.05 < _in(edges, foot, LAB_FRAME).translation[2] < 0.2, foot
    assert [q.durability.name for q in reader.qos("/human/robot_description")] == ["TRANSIENT_LOCAL"]
    urdf = read("/human/robot_description")[-1][1].data
    for link in ("pelvis", "torso", "head", "thigh_l", "shank_r", "foot_l", "toes_r"):
        assert f'<link name="{link}">' in urdf
    com = {_ns(m.header): m.position for _, m in read("/human/com")}
    viz = read("/viz/human")
    assert len(viz) > 250
    ids = set()
    for _, msg in viz:
        by_id = {m.id: m for m in msg.markers}
        ids |= set(by_id)
        if 1 in by_id:
            c, p = com[_ns(by_id[1].header)], by_id[1].pose.position
            assert (p.x, p.y, p.z) == (c.x, c.y, c.z)
    assert ids == {0, 1, 2, 3, 4} and len(viz[-1][1].markers[0].points) > 20


def test_one_time_base_header_stamps_within_the_log_times(bag):
    """Every header stamp of every topic lies within the bag's log-time span (from 0.5 s before its start to 50 ms
    after its end). Stamps and log times are read off one clock (the replayer's /clock), so their difference is a
    latency: the sources (replayed capture, the robot's state) are logged within a frame (10 ms) of their stamps
    whenever the recorder keeps up (10th percentile; on 2 cores the calibrating estimator and the real-time
    retargeter starve it at times), the robot's states and commands within a frame at the median and three at p99,
    and no stamp is more than half a second after its log time (each process sees /clock with its own delay);
    before, robot stamps were wall time, 56 years after the bag's."""
    read, reader = bag
    frame_ns = 10_000_000
    # each process takes /clock with its own delay: the robot's last state, stamped at the /clock it simulated, may
    # reach the recorder before that /clock does (the replayer's lockstep lets /clock lead the robot by 10 ms); the
    # first messages may be logged late (a full run: the chair plate's first sample, stamped at the bag's start, was
    # logged 232 ms after it, and so became the bag's start)
    span = (reader.start_ns - 50 * frame_ns, reader.end_ns + 5 * frame_ns)
    for topic in sorted(reader.topics()):
        lags, stamps = [], []
        for log_ns, msg in read(topic):
            for h in _headers(msg):
                s = _ns(h)
                assert span[0] <= s <= span[1], f"{topic}: stamp {s * 1e-9:.3f} s outside the log times " \
                    f"{span[0] * 1e-9:.3f}..{span[1] * 1e-9:.3f} s"
                lags.append(log_ns - s)
                stamps.append(s)
        if not lags:
            continue
        assert min(lags) > -50 * frame_ns, f"{topic}: a stamp {-min(lags) * 1e-6:.1f} ms after its log time"
        if topic.startswith(("/mocap/", "/force_plate/", "/robot/joint_states", "/robot/base_pose", "/robot/ft/")):
            p10 = np.percentile(lags, 10)
            assert abs(p10) < frame_ns, f"{topic}: logged {p10 * 1e-6:.1f} ms after its stamps (10th percentile)"
        if topic in ("/robot/joint_states", "/robot/joint_command"):
            # the replayer's lockstep keeps the robot with the clock within a frame (749 ms before it; 65 ms at p99
            # with a 50 ms lead; measured here at 10 ms: p50 0.2 ms, p99 10-15 ms; the same graph alone, 6 runs: p99
            # 6-15 ms and once 31.5 ms, and 30.0 ms once in a full run). It follows a topic from the first message it
            # gets: the states of the bag's first 0.5 s, before that, were seen 130 ms late. In full runs on 2 cores
            # the recorder is starved for a moment now and then (p99 86 and 129 ms, p50 0.0 ms): the p99 bound is
            # the one that still catches a graph out of lockstep (749 ms), the p95 one the steady state
            steady = np.asarray(lags)[np.asarray(stamps) > reader.start_ns + 500_000_000]
            p50, p95, p99 = np.percentile(steady, [50, 95, 99])
            assert p50 < frame_ns and p95 < 5 * frame_ns and p99 < 25 * frame_ns, \
                f"{topic}: logged {p50 * 1e-6:.1f} ms (median), {p95 * 1e-6:.1f} ms (p95), {p99 * 1e-6:.1f} ms " \
                "(p99) after its stamps"


def _headers(msg):
    """The headers of a message: its own, each transform's, each marker's."""
    if hasattr(msg, "header"):
        return [msg.header]
    return [m.header for m in getattr(msg, "transforms", [])] + [m.header for m in getattr(msg, "markers", [])]
