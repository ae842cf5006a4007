"""The vplayground node with each Python thread's name given to its OS thread (Linux
PR_SET_NAME, "vplayground-" dropped: `physics`, `publisher`, `recorder`; the main thread is
`main`), so /proc/<pid>/task/*/comm tells node_overhead.py which thread used the CPU. Threads of
native code (ROS middleware, the Foxglove server) keep the names their libraries give them.

    python bench/named_node.py <vplayground arguments>
"""
import ctypes
import sys
import threading

from vplayground_ros import cli

PR_SET_NAME = 15
COMM_LENGTH = 15  # bytes of a thread name the kernel keeps
libc = ctypes.CDLL(None, use_errno=True)


def name_os_thread(name):
    libc.prctl(PR_SET_NAME, name.removeprefix("vplayground-").encode()[:COMM_LENGTH], 0, 0, 0)


def run_named(thread, run=threading.Thread.run):
    name_os_thread(thread.name)
    run(thread)


if __name__ == "__main__":
    threading.Thread.run = run_named
    name_os_thread("main")
    sys.exit(cli.main())
