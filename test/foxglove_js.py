"""Foxglove's own JavaScript packages, installed once with npm into a cache the tests share
(VPLAYGROUND_NPM_CACHE, default ~/.cache/vplayground_ros/npm); tests using them skip where node
or npm is missing."""
import fcntl
import os
import shutil
import subprocess
from pathlib import Path

import pytest

# @mcap/support: the decompressors Foxglove's own MCAP reading loads (its wasm zstd grows its
# memory; zstd-codec, used before, has a fixed 16 MB heap, which one 8 MiB chunk and its
# compressed bytes can already overflow).
PACKAGES = ["@mcap/core@2", "@mcap/support@1", "@foxglove/rosmsg@5", "@foxglove/rosmsg2-serialization@2"]

needs_node = pytest.mark.skipif(shutil.which("node") is None or shutil.which("npm") is None,
                                reason="Foxglove's JavaScript stack needs node and npm")


def run_script(name, source, *args, timeout=120):
    """Writes the script next to the installed packages, runs it with node; returns stdout."""
    cache = Path(os.environ.get("VPLAYGROUND_NPM_CACHE", Path.home() / ".cache" / "vplayground_ros" / "npm"))
    cache.mkdir(parents=True, exist_ok=True)
    # One install at a time (make test's workers may run two files that need them at once; npm
    # installs into one prefix are not safe side by side, and half-written packages look there).
    with open(cache / ".install.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not all((cache / "node_modules" / package.rpartition("@")[0]).exists() for package in PACKAGES):
            subprocess.run(["npm", "install", "--prefix", str(cache), "--no-audit", "--no-fund", "--silent",
                            *PACKAGES], check=True, timeout=300)
    script = cache / name
    script.write_text(source)
    result = subprocess.run(["node", str(script), *map(str, args)], capture_output=True, text=True, timeout=timeout)
    assert result.returncode == 0, result.stderr
    return result.stdout
