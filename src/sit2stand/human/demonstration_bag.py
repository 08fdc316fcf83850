"""A synthesised demonstration (:mod:`sit2stand.human.synth`) written as a bag: what a lab would record (markers,
plates, the subject's stature and mass in the metadata) plus the truth on ``/ground_truth/*``.
"""

from __future__ import annotations

import numpy as np

from ..io import messages as M
from ..io.bag import BagWriter, reliable_qos
from ..forceplate import PLATE_CORNERS_KEY, plate_corners_json
from ..io.topics import (COM_TYPE, GROUND_TRUTH_COM_TOPIC, GROUND_TRUTH_JOINTS_TOPIC, GROUND_TRUTH_PARAMETERS_TOPIC,
                         MARKERS_TOPIC, MOCAP_TYPE, PLATE_TYPE, SUBJECT_TOPIC, SUBJECT_TYPE, plate_topic)
from ..io.typestore import typestore
from .skeleton import SEGMENTS, HumanModel
from .synth import Demonstration


START_TIME_S = 100.0
"""Bag time of the trial's first sample [s] (not 0: ROS nodes on /clock read time 0 as "not set yet")."""


def truth_parameters(human: HumanModel) -> tuple[list[str], list[float]]:
    """Names and values of the true segment masses [kg] and COMs [m, joint frame], extra masses included."""
    names, values = [], []
    for seg in SEGMENTS:
        names.append(f"{seg}.mass")
        values.append(float(human.segment_mass[seg]))
        for axis, v in zip("xyz", human.segment_com[seg]):
            names.append(f"{seg}.com_{axis}")
            values.append(float(v))
    for i, extra in enumerate(human.subject.extra):
        names += [f"extra{i}.{extra.segment}.mass"] + [f"extra{i}.{extra.segment}.offset_{a}" for a in "xyz"]
        values += [extra.mass_kg, *map(float, extra.offset_m)]
    return names, values


def _to_ns(t_s: float) -> int:
    """Bag time [ns] of a trial time [s] (the trial starts at :data:`START_TIME_S`)."""
    return int(round((START_TIME_S + t_s) * 1e9))


def write_demonstration_bag(demo: Demonstration, out) -> dict[str, int]:
    """Write a :class:`Demonstration` as a bag: what a lab would record, plus the truth on /ground_truth/*.

    The bag's metadata carries what a lab knows (stature, body mass from a scale, sex, seat height, events); the
    hidden extra masses appear only on the ground-truth topics, which estimators must not read. The body mass is the
    true one (extra masses included) times ``config.declared_mass_factor`` (1: a scale that weighs right).
    """
    cfg = demo.config
    declared_kg = demo.human.total_mass * cfg.declared_mass_factor
    store = typestore().types
    custom = {
        "source": "sit2stand synth-human", "style": cfg.style, "seed": str(cfg.seed),
        "height_m": f"{cfg.height_m:g}", "body_mass_kg": f"{declared_kg:.3f}", "sex": cfg.sex,
        "seat_height_m": f"{demo.seat_height_m:.3f}", "plates": "chair, feet",
        PLATE_CORNERS_KEY: plate_corners_json(demo.plates),
        "events": (f"rise_start@{START_TIME_S + demo.rise_start_s:.3f}s;"
                   f" seat_off@{START_TIME_S + demo.seat_off_s:.3f}s;"
                   f" rise_end@{START_TIME_S + demo.rise_end_s:.3f}s"),
        "lab_axes": "REP-103 (synthetic): x forward, y left, z up; origin between the ankles",
    }
    joint_names = demo.human.joint_names()
    with BagWriter(out, custom_data=custom) as bag:
        bag.add_topic(MARKERS_TOPIC, MOCAP_TYPE)
        # the subject in the stream too (latched): a conversion that drops custom_data (ROS 1) keeps it
        bag.add_topic(SUBJECT_TOPIC, SUBJECT_TYPE, [reliable_qos(1, transient_local=True)])
        bag.write(SUBJECT_TOPIC, _to_ns(0.0), M.subject(_to_ns(0.0), cfg.height_m, declared_kg, cfg.sex))
        for name in ("chair", "feet"):
            bag.add_topic(plate_topic(name), PLATE_TYPE)
        bag.add_topic(GROUND_TRUTH_COM_TOPIC, COM_TYPE)
        bag.add_topic(GROUND_TRUTH_JOINTS_TOPIC, "sensor_msgs/msg/JointState")
        bag.add_topic(GROUND_TRUTH_PARAMETERS_TOPIC, "sit2stand_msgs/msg/InertialParameters")
        names, values = truth_parameters(demo.human)
        bag.write(GROUND_TRUTH_PARAMETERS_TOPIC, _to_ns(0.0), store["sit2stand_msgs/msg/InertialParameters"](
            header=M.header(_to_ns(0.0)), model="human_truth", names=names, values=np.array(values),
            std_devs=np.zeros(len(values)), yaml_path=""))
        step = int(round(cfg.plate_rate_hz / cfg.marker_rate_hz))
        for i, ts in enumerate(demo.marker_t_s):
            t_ns = _to_ns(ts)
            bag.write(MARKERS_TOPIC, t_ns, M.mocap_frame(t_ns, demo.marker_names, demo.markers_m[i],
                                                         demo.marker_valid[i]))
            k = i * step
            bag.write(GROUND_TRUTH_COM_TOPIC, t_ns, M.center_of_mass(t_ns, demo.com_m[k], demo.com_vel[k],
                                                                     demo.com_acc[k], source="ground_truth",
                                                                     n_markers=0))
            q = demo.q[k]
            bag.write(GROUND_TRUTH_JOINTS_TOPIC, t_ns, store["sensor_msgs/msg/JointState"](
                header=M.header(t_ns), name=["pelvis_x", "pelvis_y", "pelvis_z", "pelvis_qx", "pelvis_qy",
                                                       "pelvis_qz", "pelvis_qw"] + joint_names,
                position=q.astype(float), velocity=np.zeros(0), effort=np.zeros(0)))
        for plate in demo.plates:
            for t_ns, msg in M.plate_messages(plate, START_TIME_S):
                bag.write(plate_topic(plate.name), t_ns, msg)
        return dict(bag.counts)
