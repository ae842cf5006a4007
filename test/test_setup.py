"""make's choice of Python (tools/choose_python, issue 35): a sourced ROS install's rclpy imports
only in its own Python (Jazzy: 3.12), the PyPI Jazzy wheels exist only for 3.11. Run against
stub interpreters on a PATH made here; the Makefile runs in a copy of its inputs, so its venv is
made in tmp_path and never touches the checkout's .venv."""
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOOL = ROOT / "tools" / "choose_python"


def stub(bin_dir, name, version, rclpy, venv=False):
    """A fake interpreter: answers choose_python's probe (its version, whether it is a venv's,
    its path; exit status 0 where rclpy imports), and `-m venv [--system-site-packages] DIR` by
    writing DIR/pyvenv.cfg's two lines the Makefile reads and a DIR/bin/python that logs its
    arguments to DIR/calls (rclpy imports there if the venv sees the system's packages)."""
    bin_dir.mkdir(parents=True, exist_ok=True)
    path = bin_dir / name
    path.write_text(f"""#!/bin/sh
if [ "$1" = -m ] && [ "$2" = venv ]; then
    shift 2; site=false
    [ "$1" = --system-site-packages ] && {{ site=true; shift; }}
    mkdir -p "$1/bin"
    printf 'home = /stub\\ninclude-system-site-packages = %s\\nexecutable = %s\\n' $site "$0" > "$1/pyvenv.cfg"
    rclpy=1; [ $site = true ] && rclpy=0
    printf '#!/bin/sh\\necho "$*" >> "%s/calls"\\ncase "$*" in *"import rclpy"*) exit %s;; esac\\n' \\
        "$(cd "$1" && pwd)" $rclpy > "$1/bin/python"
    chmod +x "$1/bin/python"
    exit 0
fi
echo "{version} {int(venv)} $0"
exit {0 if rclpy else 1}
""")
    path.chmod(0o755)
    return path


def sourced_ros(tmp_path):
    """What sourcing a ROS install does to the environment: ROS_DISTRO, and its rclpy on
    PYTHONPATH."""
    site = tmp_path / "ros" / "lib" / "python3.12" / "site-packages"
    (site / "rclpy").mkdir(parents=True)
    return {"ROS_DISTRO": "jazzy", "PYTHONPATH": str(site)}


def choose(path, **env):
    """choose_python with only PATH (the stubs) and the given variables."""
    return subprocess.run(["/bin/sh", str(TOOL)], env={"PATH": str(path), **env},
                          capture_output=True, text=True, timeout=30)


def test_sourced_ros_picks_the_python_that_imports_its_rclpy(tmp_path):
    bin_dir = tmp_path / "bin"
    python3 = stub(bin_dir, "python3", "3.12", rclpy=True)
    stub(bin_dir, "python3.11", "3.11", rclpy=False)
    run = choose(bin_dir, **sourced_ros(tmp_path))
    assert run.returncode == 0, run.stderr
    assert run.stdout == f"ros {python3}\n"
    assert run.stderr == f"make: Python: python3 = {python3} (3.12), which imports rclpy (ROS jazzy sourced)\n"


def test_sourced_ros_finds_its_python_behind_another_python3(tmp_path):
    # pyenv's python3 (3.11) ahead of the system's; an activated venv's python3 imports the
    # wheels' rclpy from that venv, and a pyenv shim of a version not selected does not run.
    bin_dir = tmp_path / "bin"
    stub(bin_dir, "python3", "3.11", rclpy=False)
    stub(bin_dir, "python3.11", "3.11", rclpy=False)
    venv_bin = tmp_path / "venv" / "bin"
    stub(venv_bin, "python3", "3.12", rclpy=True, venv=True)
    shim = tmp_path / "shims" / "python3.12"
    shim.parent.mkdir()
    shim.write_text("#!/bin/sh\necho 'pyenv: python3.12: command not found' >&2\nexit 127\n")
    shim.chmod(0o755)
    system_bin = tmp_path / "usr_bin"
    python312 = stub(system_bin, "python3.12", "3.12", rclpy=True)
    run = choose(f"{venv_bin}:{bin_dir}:{shim.parent}:{system_bin}", **sourced_ros(tmp_path))
    assert run.returncode == 0, run.stderr
    assert run.stdout == f"ros {python312}\n"


def test_without_ros_the_wheels_python_311(tmp_path):
    bin_dir = tmp_path / "bin"
    stub(bin_dir, "python3", "3.12", rclpy=False)
    stub(bin_dir, "python3.12", "3.12", rclpy=False)
    python311 = stub(bin_dir, "python3.11", "3.11", rclpy=False)
    run = choose(bin_dir)
    assert run.returncode == 0, run.stderr
    assert run.stdout == f"wheels {python311}\n"
    assert run.stderr == (f"make: Python: python3.11 = {python311} (3.11), for the ROS 2 Jazzy wheels "
                          "from PyPI (no ROS sourced)\n")


def test_an_explicit_python_wins(tmp_path):
    bin_dir = tmp_path / "bin"
    stub(bin_dir, "python3", "3.12", rclpy=True)
    python311 = stub(bin_dir, "python3.11", "3.11", rclpy=False)
    run = choose(bin_dir, ROS_DISTRO="jazzy", PYTHON="python3.11")
    assert run.returncode == 0, run.stderr
    assert run.stdout == f"wheels {python311}\n"
    assert "PYTHON=python3.11" in run.stderr
    other = stub(tmp_path / "elsewhere", "python3.12", "3.12", rclpy=True)
    run = choose(bin_dir, PYTHON=str(other))
    assert run.stdout == f"ros {other}\n"


def test_no_python_for_either_route_is_one_clear_error(tmp_path):
    bin_dir = tmp_path / "bin"
    stub(bin_dir, "python3", "3.12", rclpy=False)
    run = choose(bin_dir)
    assert run.returncode == 1
    assert run.stdout == ""
    assert run.stderr.count("\n") == 1
    assert run.stderr.startswith("make: no python3.11 on PATH for the ROS 2 Jazzy wheels")


def test_a_sourced_rclpy_no_python_imports_is_an_error(tmp_path):
    # The wheels' rclpy would sit behind the sourced one on PYTHONPATH and never load.
    bin_dir = tmp_path / "bin"
    stub(bin_dir, "python3", "3.12", rclpy=False)
    stub(bin_dir, "python3.11", "3.11", rclpy=False)
    env = sourced_ros(tmp_path)
    run = choose(bin_dir, **env)
    assert run.returncode == 1 and run.stdout == ""
    assert env["PYTHONPATH"] in run.stderr and "make PYTHON=" in run.stderr


def test_an_explicit_python_without_rclpy_or_wheels_is_an_error(tmp_path):
    bin_dir = tmp_path / "bin"
    stub(bin_dir, "python3.12", "3.12", rclpy=False)
    run = choose(bin_dir, PYTHON="python3.12")
    assert run.returncode == 1 and run.stdout == ""
    assert "wheels are for Python 3.11 only" in run.stderr
    run = choose(bin_dir, PYTHON="python3.9")
    assert run.returncode == 1 and run.stderr == "make: PYTHON=python3.9 does not run\n"


def test_make_builds_the_venv_with_the_chosen_python_and_remakes_it_when_the_choice_changes(tmp_path):
    repo = tmp_path / "repo"
    for name in ("Makefile", "setup.py", "setup.cfg", "package.xml", "tools/choose_python", "tools/build_interfaces.py",
                 "interfaces/simulation_interfaces/package.xml", "interfaces/tf2_msgs/package.xml"):
        (repo / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / name, repo / name)
    bin_dir = tmp_path / "bin"
    python3 = stub(bin_dir, "python3", "3.12", rclpy=True)
    python311 = stub(bin_dir, "python3.11", "3.11", rclpy=False)
    # The tools the recipes and stubs use, without the real interpreters beside them.
    tools = tmp_path / "tools"
    tools.mkdir()
    for tool in ("sh", "grep", "sed", "rm", "touch", "mkdir", "chmod"):
        (tools / tool).symlink_to(shutil.which(tool))
    path = f"{bin_dir}:{tools}"
    venv = repo / ".venv"

    def make(**env):
        return subprocess.run([shutil.which("make"), "setup"], cwd=repo, capture_output=True, text=True,
                              env={"PATH": path, **env}, timeout=60)

    def calls():
        return (venv / "calls").read_text().splitlines()

    ros = sourced_ros(tmp_path)
    run = make(**ros)
    assert run.returncode == 0, run.stdout + run.stderr
    assert f"make: Python: python3 = {python3} (3.12), which imports rclpy (ROS jazzy sourced)" in run.stderr
    assert f"{python3} -m venv --system-site-packages .venv" in run.stdout
    assert f"executable = {python3}" in (venv / "pyvenv.cfg").read_text()
    assert '-m pip install --quiet -e .[test]' in calls()
    assert not any(".[ros]" in call for call in calls())
    # simulation_interfaces: the distro's package is looked for, nothing is built.
    assert "-c import simulation_interfaces, tf2_msgs" in calls() and "tools/build_interfaces.py" not in calls()
    assert (venv / ".installed").exists()

    made = calls()
    run = make(**ros)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "make: Python: python3" in run.stderr
    assert "-m venv" not in run.stdout and calls() == made

    # ROS no longer sourced: that venv's rclpy is gone, the wheels' Python makes it again.
    run = make()
    assert run.returncode == 0, run.stdout + run.stderr
    assert f"make: .venv was made by {python3} for a sourced rclpy: making it again" in run.stdout
    assert f"{python311} -m venv .venv" in run.stdout
    cfg = (venv / "pyvenv.cfg").read_text()
    assert f"executable = {python311}" in cfg and "include-system-site-packages = false" in cfg
    assert "-m pip install --quiet -e .[ros]" in calls()
    assert "tools/build_interfaces.py" in calls()  # the wheels' venv builds the types
    assert "-c from vplayground_ros.physics import World; World()" in calls()  # the engine beside them


def test_the_wheels_venv_has_the_vendored_interface_types():
    """On the PyPI wheels make builds simulation_interfaces and tf2_msgs into the venv
    (tools/build_interfaces.py): their tests would otherwise skip, hiding a failed build."""
    import importlib.util
    if importlib.util.find_spec("ros_wheels_bootstrapper") is None:
        pytest.skip("not the PyPI wheels' venv: a ROS install brings its own package")
    for package in ("simulation_interfaces", "tf2_msgs"):
        assert importlib.util.find_spec(package) is not None, (
            f"{package} does not import: make's build failed (make interfaces says why)")
