"""Writes spot_reflector.stl: a faceted paraboloid reflector cup as a CAD program exports it
(binary STL, millimetres, an 80-byte header starting with "solid"), for scenes/spotlight.toml.

The cup is z = -r^2 / (4 f) with focal length f = 20 mm, from the apex (z = 0) to a rim of
radius 60 mm (z = -45 mm), opening downward; 48 facets around, 12 rings. Each facet's front,
(b - a) x (c - a), faces into the cup, toward the lamp at the focus (0, 0, -20). Run: python3 make_spot_reflector.py (no dependencies).
"""

import math
import struct

F, RIM, AROUND, RINGS = 20.0, 60.0, 48, 12


def point(ring, k):
    r = RIM * ring / RINGS
    phi = 2 * math.pi * k / AROUND
    return (r * math.cos(phi), r * math.sin(phi), -r * r / (4 * F))


def triangles():
    for ring in range(RINGS):
        for k in range(AROUND):
            a, b = point(ring, k), point(ring, k + 1)
            c, d = point(ring + 1, k), point(ring + 1, k + 1)
            # (b - a) x (c - a) points down into the cup, toward the lamp.
            if ring > 0:
                yield (a, b, c)
            yield (b, d, c)


def normal(t):
    u = [t[1][i] - t[0][i] for i in range(3)]
    v = [t[2][i] - t[0][i] for i in range(3)]
    n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
    length = math.sqrt(sum(x * x for x in n)) or 1.0
    return [x / length for x in n]


tris = list(triangles())
with open("spot_reflector.stl", "wb") as f:
    f.write(b"solid spot_reflector (binary; photon's scenes/meshes/make_spot_reflector.py)".ljust(80, b" "))
    f.write(struct.pack("<I", len(tris)))
    for t in tris:
        f.write(struct.pack("<3f", *normal(t)))
        for p in t:
            f.write(struct.pack("<3f", *p))
        f.write(b"\0\0")
print(len(tris), "triangles")
