"""Finding the package's shared files (config/, meshes/) wherever it was installed from."""
import os
import sys
import sysconfig
from pathlib import Path

PACKAGE = "vplayground_ros"


def is_file(path):
    """Path.is_file, and False too where the system refuses the name (a component longer than
    it allows: Path.is_file raises that one)."""
    try:
        return Path(path).is_file()
    except OSError:
        return False


def share_directories():
    """Candidate share roots, most specific first: a ROS install (ament_index), a source tree
    (editable install, tests), then pip's data_files under the interpreter's prefix or the
    user base (pip install --user)."""
    roots = []
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
        try:
            roots.append(Path(get_package_share_directory(PACKAGE)))
        except (PackageNotFoundError, OSError):  # not in an ament index, or none is set up
            pass
    except ImportError:
        pass
    roots.append(Path(__file__).resolve().parent.parent)
    roots.append(Path(sys.prefix) / "share" / PACKAGE)
    # pip install --user puts data_files under the user base (its scheme's "data" path).
    roots.append(Path(sysconfig.get_path("data", f"{os.name}_user")) / "share" / PACKAGE)
    return roots


def find_shared(relative):
    """Path of a shared file such as 'config/default_scene.yaml', or None."""
    for root in share_directories():
        candidate = root / relative
        if is_file(candidate):
            return candidate
    return None
