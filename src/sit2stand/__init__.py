"""sit2stand: a humanoid robot stands up from a chair the way a recorded human did.

Algorithms live in plain modules that never import rclpy (io/, and later human/, robot/, retarget/, gap/);
the ROS 2 nodes in nodes/ are thin wrappers around them. Units are SI, axes REP-103 (x forward, y left, z up).
"""

from .scheduling import openmp_threads_sleep_when_idle

__version__ = "0.1.0"

openmp_threads_sleep_when_idle()     # before anything loads the OpenMP runtime
