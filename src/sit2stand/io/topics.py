"""Every topic and service name of the sit2stand graph, with the message types and frame ids that go with them.

The one home of these names: nodes, offline tools, the importer and the synthesiser take them from here. Names are
written as a bag stores them and as a graph in the root namespace sees them (``/mocap/markers``). Nodes subscribe and
publish them relative (:func:`ros_name`: ``mocap/markers``), so ``--ros-args -r __ns:=/robot2`` (or ``sit2stand
launch --namespace robot2``) moves a whole graph to ``/robot2/mocap/markers``; a recorder in ``/robot2`` writes that
topic into its bag as ``/mocap/markers`` again (:func:`bag_name`), so a bag never depends on the namespace it was
recorded in. Node-private services (``~/pause``, ``~/status``) stay with their nodes. Frames follow REP-103 (x
forward, y left, z up). ``lab`` is the capture volume's frame, in which markers, plates and the human COM are given;
``world`` is the robot simulation's frame; ``lab`` -> ``world`` is one static transform (the driver's /tf_static).
"""

from __future__ import annotations

import re

# --- frames -------------------------------------------------------------------------------------------------------
LAB_FRAME = "lab"
WORLD_FRAME = "world"
HUMAN_ROOT_FRAME = "pelvis"    # the human skeleton's floating base (its URDF's root link; lab -> pelvis in /tf)

# --- message types of our interface package -----------------------------------------------------------------------
MOCAP_TYPE = "sit2stand_msgs/msg/MocapFrame"
PLATE_TYPE = "sit2stand_msgs/msg/ForcePlateSample"
COM_TYPE = "sit2stand_msgs/msg/CenterOfMass"
SUBJECT_TYPE = "sit2stand_msgs/msg/Subject"
MARKER_ARRAY_TYPE = "visualization_msgs/msg/MarkerArray"

# --- capture: replayer (from a bag) or a capture-system bridge ------------------------------------------------------
MARKERS_TOPIC = "/mocap/markers"                     # sit2stand_msgs/MocapFrame, lab frame
MODEL_POINTS_TOPIC = "/mocap/model_points"           # MocapFrame: the capture software's modelled points
REFERENCE_COM_TOPIC = "/mocap/reference_com"         # CenterOfMass: the capture software's own COM
FORCE_PLATE_PREFIX = "/force_plate/"                 # + plate name: ForcePlateSample, lab axes
CLOCK_TOPIC = "/clock"                               # rosgraph_msgs/Clock
GRAPH_TOPIC = "/sit2stand/graph"                     # std_msgs/String (transient local, JSON): each node's run id
RUN_ID_ENV = "SIT2STAND_RUN_ID"                      # the launcher's run id, given to every node of a graph
FELL_EXIT_CODE = 3                                   # the driver's exit status when the robot fell: the graph failed
# A node's last words before its DDS teardown (``nodes.runtime``), which the launcher reads: its result. Teardown can
# hang inside the middleware holding Python's lock; a node that said its result and then died in teardown is judged
# by what it said.
NODE_RESULT = re.compile(r"^\[(?P<name>[\w.-]+)\] result: exit (?P<code>-?\d+); tearing down DDS$")


def node_result_line(name: str, code: int) -> str:
    """The line a node prints with its result, just before its DDS teardown (:data:`NODE_RESULT`)."""
    return f"[{name}] result: exit {code}; tearing down DDS"


# --- human COM estimator ------------------------------------------------------------------------------------------
HUMAN_COM_TOPIC = "/human/com"                       # CenterOfMass, lab frame
HUMAN_MODEL_COP_TOPIC = "/human/model_cop"           # geometry_msgs/PointStamped
HUMAN_MEASURED_COP_TOPIC = "/human/measured_cop"     # geometry_msgs/PointStamped
HUMAN_JOINTS_TOPIC = "/human/joint_states"           # sensor_msgs/JointState: the fitted skeleton's joints, pelvis
HUMAN_PELVIS_POSE_TOPIC = "/human/pelvis_pose"       # geometry_msgs/PoseStamped: the skeleton's base, lab frame
HUMAN_SCALING_TOPIC = "/human/scaling"               # sit2stand_msgs/InertialParameters
HUMAN_DESCRIPTION_TOPIC = "/human/robot_description"   # std_msgs/String (transient local): the skeleton's URDF
HUMAN_MARKERS_TOPIC = "/viz/human"                   # visualization_msgs/MarkerArray: markers, COM, COPs in lab
SUBJECT_TOPIC = "/human/subject"                     # sit2stand_msgs/Subject (transient local): stature, mass, sex

# --- robot: driver (the simulated robot of a profile) -------------------------------------------------------------
ROBOT_JOINT_STATES_TOPIC = "/robot/joint_states"     # sensor_msgs/JointState
ROBOT_BASE_POSE_TOPIC = "/robot/base_pose"           # geometry_msgs/PoseStamped, world frame
ROBOT_COP_TOPIC = "/robot/cop"                       # geometry_msgs/PointStamped, world frame
ROBOT_FT_LEFT_TOPIC = "/robot/ft/left"               # geometry_msgs/WrenchStamped
ROBOT_FT_RIGHT_TOPIC = "/robot/ft/right"             # geometry_msgs/WrenchStamped
ROBOT_STATUS_TOPIC = "/robot/status"                 # diagnostic_msgs/DiagnosticStatus
ROBOT_JOINT_COMMAND_TOPIC = "/robot/joint_command"   # trajectory_msgs/JointTrajectory (one point)
ROBOT_JOINT_STATE_COMMAND_TOPIC = "/robot/joint_state_command"   # sensor_msgs/JointState (positions only)

# --- robot: frames and description (driver; what robot_state_publisher gives on a full ROS install) ---------------
TF_TOPIC = "/tf"                                     # tf2_msgs/TFMessage: world -> root link, each moving joint
TF_STATIC_TOPIC = "/tf_static"                       # tf2_msgs/TFMessage (transient local): fixed frames, lab -> world
ROBOT_DESCRIPTION_TOPIC = "/robot_description"       # std_msgs/String (transient local): the URDF
TF_TYPE = "tf2_msgs/msg/TFMessage"

# --- robot: retargeter --------------------------------------------------------------------------------------------
ROBOT_PLANNED_COM_TOPIC = "/robot/planned_com"       # CenterOfMass, world frame
ROBOT_PLANNED_ZMP_TOPIC = "/robot/planned_zmp"       # geometry_msgs/PointStamped, world frame
ROBOT_COM_FEEDBACK_TOPIC = "/robot/com_feedback"     # geometry_msgs/Vector3Stamped [m], world frame
ROBOT_RETARGET_IK_TOPIC = "/robot/retarget/ik"       # sensor_msgs/JointState: the raw IK pose per frame
VIZ_MARKERS_TOPIC = "/viz/markers"                   # visualization_msgs/MarkerArray: plan's COM, ZMP, support

# --- robot: identification service --------------------------------------------------------------------------------
IDENTIFY_COM_SERVICE = "/robot/identify_com"         # sit2stand_msgs/srv/IdentifyCom
ROBOT_INERTIAL_PARAMETERS_TOPIC = "/robot/inertial_parameters"   # InertialParameters (transient local)

# --- ground truth written by simulations (synthesised humans, the plant) --------------------------------------------
GROUND_TRUTH_COM_TOPIC = "/ground_truth/com"
GROUND_TRUTH_JOINTS_TOPIC = "/ground_truth/joint_states"
GROUND_TRUTH_PARAMETERS_TOPIC = "/ground_truth/inertial_parameters"
GROUND_TRUTH_ROBOT_COM_TOPIC = "/ground_truth/robot_com"


# --- every topic above with its type; the latched ones (transient local) --------------------------------------------
# The recorder subscribes to these before their publishers exist, so that a topic appearing mid-run is recorded from
# its first message (subscribing once a publisher is seen missed its first 0.14-0.38 s).
_POINT = "geometry_msgs/msg/PointStamped"
_POSE = "geometry_msgs/msg/PoseStamped"
_JOINTS = "sensor_msgs/msg/JointState"
_PARAMETERS = "sit2stand_msgs/msg/InertialParameters"
_STRING = "std_msgs/msg/String"
TOPIC_TYPES: dict[str, str] = {
    MARKERS_TOPIC: MOCAP_TYPE, MODEL_POINTS_TOPIC: MOCAP_TYPE, REFERENCE_COM_TOPIC: COM_TYPE,
    FORCE_PLATE_PREFIX + "chair": PLATE_TYPE, FORCE_PLATE_PREFIX + "feet": PLATE_TYPE,
    HUMAN_COM_TOPIC: COM_TYPE, HUMAN_MODEL_COP_TOPIC: _POINT, HUMAN_MEASURED_COP_TOPIC: _POINT,
    HUMAN_JOINTS_TOPIC: _JOINTS, HUMAN_PELVIS_POSE_TOPIC: _POSE, HUMAN_SCALING_TOPIC: _PARAMETERS,
    HUMAN_DESCRIPTION_TOPIC: _STRING, HUMAN_MARKERS_TOPIC: MARKER_ARRAY_TYPE, SUBJECT_TOPIC: SUBJECT_TYPE,
    ROBOT_JOINT_STATES_TOPIC: _JOINTS, ROBOT_BASE_POSE_TOPIC: _POSE, ROBOT_COP_TOPIC: _POINT,
    ROBOT_FT_LEFT_TOPIC: "geometry_msgs/msg/WrenchStamped", ROBOT_FT_RIGHT_TOPIC: "geometry_msgs/msg/WrenchStamped",
    ROBOT_STATUS_TOPIC: "diagnostic_msgs/msg/DiagnosticStatus",
    ROBOT_JOINT_COMMAND_TOPIC: "trajectory_msgs/msg/JointTrajectory", ROBOT_JOINT_STATE_COMMAND_TOPIC: _JOINTS,
    TF_TOPIC: TF_TYPE, TF_STATIC_TOPIC: TF_TYPE, ROBOT_DESCRIPTION_TOPIC: _STRING,
    ROBOT_PLANNED_COM_TOPIC: COM_TYPE, ROBOT_PLANNED_ZMP_TOPIC: _POINT,
    ROBOT_COM_FEEDBACK_TOPIC: "geometry_msgs/msg/Vector3Stamped", ROBOT_RETARGET_IK_TOPIC: _JOINTS,
    VIZ_MARKERS_TOPIC: MARKER_ARRAY_TYPE, ROBOT_INERTIAL_PARAMETERS_TOPIC: _PARAMETERS,
    GROUND_TRUTH_COM_TOPIC: COM_TYPE, GROUND_TRUTH_JOINTS_TOPIC: _JOINTS,
    GROUND_TRUTH_PARAMETERS_TOPIC: _PARAMETERS, GROUND_TRUTH_ROBOT_COM_TOPIC: COM_TYPE,
}
LATCHED_TOPICS = frozenset({HUMAN_SCALING_TOPIC, HUMAN_DESCRIPTION_TOPIC, SUBJECT_TOPIC, TF_STATIC_TOPIC,
                            ROBOT_DESCRIPTION_TOPIC, ROBOT_INERTIAL_PARAMETERS_TOPIC})
ESTIMATE_TOPICS = frozenset({HUMAN_COM_TOPIC, HUMAN_JOINTS_TOPIC, HUMAN_PELVIS_POSE_TOPIC, HUMAN_MODEL_COP_TOPIC,
                             HUMAN_MEASURED_COP_TOPIC})
"""The human COM estimator's stream, published transient local with a deep history (and so declared in the bags
that hold it): a subscriber that matches late, as a recorder still discovering the estimator when its first frames
come, still gets every estimate."""

def ros_name(topic: str) -> str:
    """The name a node uses for ``topic``: relative (no leading ``/``), so it resolves in the node's namespace."""
    return topic.lstrip("/")


def bag_name(namespace: str, resolved: str) -> str | None:
    """The bag's name of ``resolved`` (a fully qualified topic) seen from ``namespace``: the name relative to it with
    a leading ``/`` (``/robot2``, ``/robot2/mocap/markers`` -> ``/mocap/markers``); None for a topic outside it."""
    prefix = namespace.rstrip("/") + "/"
    return "/" + resolved[len(prefix):] if resolved.startswith(prefix) else None


def plate_topic(name: str) -> str:
    """Topic of the force plate called ``name`` (e.g. ``/force_plate/feet``)."""
    return FORCE_PLATE_PREFIX + name


CHAIR_PLATE_TOPIC = plate_topic("chair")
FEET_PLATE_TOPIC = plate_topic("feet")


def ft_topic(side: str) -> str:
    """Topic of the robot's ankle force/torque sensor on ``side`` (``left`` or ``right``)."""
    return {"left": ROBOT_FT_LEFT_TOPIC, "right": ROBOT_FT_RIGHT_TOPIC}[side]


def sole_world_aligned_frame(side: str) -> str:
    """The frame of the ground reaction under the foot on ``side`` (``/robot/ft/<side>``): origin at the sole
    point, world axes (a moving frame in ``/tf``, child of ``world``)."""
    return f"sole_{side}_world_aligned"
