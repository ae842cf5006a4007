"""Generates playground.obj, the default playground (SPEC 3 `playground`): a ramp up to a
platform, a half-pipe, a flight of steps and a wall around the yard. Z up, metres, triangles
wound counter-clockwise seen from outside (outward normals).

    python meshes/make_playground.py [OUTPUT]
"""
import sys
from pathlib import Path

import numpy as np


class MeshBuilder:
    def __init__(self):
        self.vertices, self.triangles = [], []

    def quad(self, a, b, c, d):
        """Corners counter-clockwise seen from the side the face looks at."""
        base = len(self.vertices)
        self.vertices += [tuple(map(float, p)) for p in (a, b, c, d)]
        self.triangles += [(base, base + 1, base + 2), (base, base + 2, base + 3)]

    def box(self, lo, hi):
        x0, y0, z0 = lo
        x1, y1, z1 = hi
        self.quad((x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1))  # top
        self.quad((x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0))  # bottom
        self.quad((x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1))  # -y
        self.quad((x1, y1, z0), (x0, y1, z0), (x0, y1, z1), (x1, y1, z1))  # +y
        self.quad((x0, y1, z0), (x0, y0, z0), (x0, y0, z1), (x0, y1, z1))  # -x
        self.quad((x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1))  # +x

    def prism(self, profile, y0, y1):
        """A convex x-z profile (counter-clockwise seen from -y) extruded from y0 to y1."""
        n = len(profile)
        for k in range(n):
            (xa, za), (xb, zb) = profile[k], profile[(k + 1) % n]
            self.quad((xa, y1, za), (xb, y1, zb), (xb, y0, zb), (xa, y0, za))
        base = len(self.vertices)  # the two end caps as fans
        self.vertices += [(x, y0, z) for x, z in profile] + [(x, y1, z) for x, z in profile]
        self.triangles += [(base, base + k, base + k + 1) for k in range(1, n - 1)]
        self.triangles += [(base + n, base + n + k + 1, base + n + k) for k in range(1, n - 1)]

    def half_pipe(self, x0, x1, y_center, radius, segments, sections):
        """The inside of a half cylinder along x, lowest line on the ground at y_center; split
        into `sections` along x so no triangle is a long sliver (the octree indexes each)."""
        angles = np.linspace(-np.pi / 2, np.pi / 2, segments + 1)
        ys = y_center + radius * np.sin(angles)
        zs = radius - radius * np.cos(angles)
        xs = np.linspace(x0, x1, sections + 1)
        for j in range(sections):
            for k in range(segments):
                # Seen from inside (above the curve), +x then +y runs counter-clockwise.
                self.quad((xs[j], ys[k], zs[k]), (xs[j + 1], ys[k], zs[k]),
                          (xs[j + 1], ys[k + 1], zs[k + 1]), (xs[j], ys[k + 1], zs[k + 1]))

    def write_obj(self, path):
        lines = ["# vplayground_ros default playground, made by meshes/make_playground.py",
                 "# Z up, metres"]
        lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in self.vertices]
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in self.triangles]
        Path(path).write_text("\n".join(lines) + "\n", encoding="ascii")


def build():
    mesh = MeshBuilder()
    # Ramp (slope 1:4) up to a 2 m platform, east of the origin.
    mesh.prism([(8.0, 0.0), (20.0, 0.0), (20.0, 2.0), (16.0, 2.0)], -3.0, 3.0)
    # Half-pipe of radius 4 m, south-west.
    mesh.half_pipe(-20.0, -8.0, -12.0, 4.0, 24, 6)
    # Five steps of 0.2 m rise and 0.8 m going, north.
    for k in range(5):
        mesh.box((-4.0, 10.0 + 0.8 * k, 0.0), (4.0, 10.0 + 0.8 * (k + 1), 0.2 * (k + 1)))
    # A 3 m wall around the 50 x 50 m yard: above the car's 3D lidar (1.77 m), so its upper rings
    # see something. With a 1 m wall a flat floor filled most of each scan and KISS-ICP, fed the
    # default scene's clouds, drifted 10.6 % of the way driven and 13.5 degrees (3 m: 1.1 %, 0.7).
    WALL = 3.0
    for lo, hi in [((-25.0, -25.0, 0.0), (25.0, -24.5, WALL)), ((-25.0, 24.5, 0.0), (25.0, 25.0, WALL)),
                   ((-25.0, -24.5, 0.0), (-24.5, 24.5, WALL)), ((24.5, -24.5, 0.0), (25.0, 24.5, WALL))]:
        mesh.box(lo, hi)
    return mesh


if __name__ == "__main__":
    build().write_obj(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).with_name("playground.obj"))
