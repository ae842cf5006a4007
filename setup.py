"""vplayground_ros: installable by pip (make run / make test) and by colcon (ament_python).

rclpy and the message packages are deliberately not pip requirements: inside a ROS install colcon
resolves them from package.xml; without one, `make` installs the Jazzy wheels from PyPI.
"""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "vplayground_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "bench"]),
    package_data={PACKAGE: ["msg_definitions/README.md", "msg_definitions/*/msg/*.msg", "msg_definitions/*/srv/*.srv"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*")),
        (f"share/{PACKAGE}/meshes", glob("meshes/*.obj")),
    ],
    python_requires=">=3.10",
    # mcap-ros2-support: CDR from message definitions (interfaces.py); foxglove-sdk: the built-in
    # Foxglove WebSocket server (--foxglove); zlib-ng: the bag's chunk checksums (recorder.py,
    # which falls back on zlib without it); scipy: the convex hulls of convex bodies (qhull);
    # yourdfpy: robots from URDF (urdf_import.py).
    install_requires=["numpy>=1.24", "numba>=0.59", "pyyaml>=6", "trimesh>=4", "mcap>=1.1",
                      "zstandard>=0.22", "regex>=2022.1", "mcap-ros2-support>=0.5",
                      "foxglove-sdk>=0.30,<0.31", "zlib-ng>=0.4", "scipy>=1.10", "yourdfpy>=0.0.60"],
    extras_require={
        # pybullet for the real robot descriptions its pybullet_data ships (Husky, KUKA iiwa);
        # xacro expands the Husky's $(optenv ...) (urdf_import expands xacro where installed).
        # pytest-xdist: make test runs the suite on a worker per core (it mostly waits on nodes).
        "test": ["pytest>=7", "pytest-xdist>=3", "hypothesis>=6.80", "websockets>=13", "pybullet>=3.2",
                 "xacro>=2.0"],
        "xacro": ["xacro>=2.0"],
        # The ROS 2 Jazzy Python wheels, for machines without a ROS install (make does this).
        "ros": ["ros-jazzy-rclpy[fastrtps]", "ros-jazzy-common-interfaces"],
        # Peers and plots for bench/compare.py only; never needed to run the simulator.
        "bench": ["pybullet", "mujoco", "matplotlib"],
    },
    zip_safe=False,
    entry_points={"console_scripts": [f"vplayground = {PACKAGE}.cli:main",
                                      f"vplayground-recover = {PACKAGE}.recorder:recover_main"]},
)
