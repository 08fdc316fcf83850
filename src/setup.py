"""colcon's ament_python build runs this file; everything else about the package is in pyproject.toml.

It adds the two files an ament package installs besides its Python code: the marker in the ament index (so that
`ros2 pkg` and `ros2 run` know the package) and package.xml. pip installs them too (<prefix>/share/...), which
registers the package for tools that search AMENT_PREFIX_PATH.
"""
from setuptools import setup

setup(
    python_requires=">=3.11,<3.13",   # ros-jazzy-* wheels: 3.10-3.12; the pinned numpy, scipy, mujoco: 3.11+
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/sit2stand"]),
        ("share/sit2stand", ["package.xml"]),
    ],
)
