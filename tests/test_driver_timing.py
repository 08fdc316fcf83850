"""The driver's time bases, command queue and fall policy (robot/driver_timing.py), without ROS."""

import numpy as np
import pytest

from sit2stand.robot.model import PlantConfig
from sit2stand.robot.plant import Plant
from sit2stand.robot.driver_timing import (AS_FAST_AS_POSSIBLE_STEP_S, MAX_STEP_PER_TICK_S, SIM_EPOCH_S, CommandQueue,
                                           SimulationClock, respond_to_fall)


def test_on_the_wall_clock_a_state_stands_for_the_ros_time_scaled_by_the_real_time_factor():
    clock = SimulationClock(sim_time=False, publish_clock=False, real_time_factor=0.5)
    clock.start(sim_s=2.0, wall_s=10.0, ros_ns=5_000_000_000)
    assert clock.ros_ns(3.0) == 7_000_000_000                  # 1 s simulated at 0.5x: 2 s of ROS time
    assert clock.target_s(2.0, None, wall_s=10.01) == pytest.approx(2.005)
    assert clock.target_s(2.0, None, wall_s=20.0) == pytest.approx(2.0 + MAX_STEP_PER_TICK_S), "behind: a slice"
    assert clock.real_time_factor(3.0, 12.0) == pytest.approx(0.5)


def test_under_use_sim_time_the_simulation_waits_for_the_first_clock_then_follows_it():
    clock = SimulationClock(sim_time=True, publish_clock=False, real_time_factor=1.0)
    clock.start(2.0, 0.0, 0)
    assert clock.target_s(2.0, 0, 1.0) is None and clock.ros_ns(2.0) is None, "no /clock yet: wait seated"
    assert clock.follow(101_000_000_000, 2.0) and not clock.follow(102_000_000_000, 2.0), "the first /clock only"
    assert clock.ros_ns(2.5) == 101_500_000_000
    assert clock.target_s(2.0, 101_010_000_000, 99.0) == pytest.approx(2.01)
    clock.start(7.0, 50.0, 200_000_000_000)                     # a reset: from the clock's time now
    assert clock.ros_ns(7.0) == 200_000_000_000


def test_as_the_time_source_and_unpaced():
    source = SimulationClock(sim_time=False, publish_clock=True, real_time_factor=1.0)
    source.start(2.0, 0.0, 0)
    assert source.ros_ns(2.0) == int((SIM_EPOCH_S + 2.0) * 1e9)
    free = SimulationClock(sim_time=False, publish_clock=False, real_time_factor=0.0)
    free.start(2.0, 0.0, 0)
    assert free.ros_ns(3.0) is None and free.target_s(3.0, None, 0.0) == 3.0 + AS_FAST_AS_POSSIBLE_STEP_S


def test_commands_wait_for_their_stamps_in_order_and_one_too_far_ahead_is_due_at_once():
    queue = CommandQueue()
    assert queue.add(2_000, ("b",), graph_now_ns=1_000) and queue.add(3_000, ("c",), graph_now_ns=1_000)
    assert not queue.add(10**10, ("far",), graph_now_ns=1_000)          # 10 s ahead: due now (after the others)
    assert list(queue.due(1_500)) == [] and len(queue) == 3
    assert list(queue.due(2_500)) == [("b",)]
    assert list(queue.due(None)) == [("c",), ("far",)] and len(queue) == 0
    queue.add(5, ("x",), None)
    queue.clear()
    assert len(queue) == 0


def test_a_fallen_robot_goes_limp_or_holds_the_posture_it_fell_into():
    plant = Plant(PlantConfig.load("g1_cad"))
    plant.data.qpos[plant.qadr] += 0.1                 # somewhere else than its reference
    respond_to_fall(plant, "hold")
    assert np.allclose(plant.q_ref, plant.data.qpos[plant.qadr]) and not plant.limp
    respond_to_fall(plant, "limp")
    assert plant.limp
