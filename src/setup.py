"""ament_python packaging of sit2stand: `pip install -e src` for development, `colcon build` for a ROS workspace.

Console scripts are the `sit2stand` command and one executable per node; on a ROS install (colcon) setup.cfg puts
them in lib/sit2stand/ so that `ros2 run sit2stand replayer` finds them.
"""
from setuptools import find_packages, setup

NODES = ["replayer", "recorder", "human_com", "driver", "identification", "retargeter"]

setup(
    name="sit2stand",
    version="0.1.0",
    packages=find_packages(include=["sit2stand", "sit2stand.*"]),
    package_data={"sit2stand.nodes": ["*.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/sit2stand"]),
        ("share/sit2stand", ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    description="Sit-to-stand from human demonstration on a humanoid robot (ROS 2 nodes and algorithms).",
    license="Apache-2.0",
    entry_points={
        "console_scripts": ["sit2stand = sit2stand.cli:main"]
        + [f"{n} = sit2stand.nodes.{n}:main" for n in NODES],
    },
)
