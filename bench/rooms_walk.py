#!/usr/bin/env python3
"""A TUM trajectory for `bitfuse synth --scene rooms:N`: the camera walks
down the row of rooms (camera +z is forward; synth places the first pose in
the first room looking along the row) and back to the start, still facing
down the row (a backward walk: on the way back it sees what it saw on the way
out, from the map streamed back in), looking left and right as it goes.

    rooms_walk.py OUT.txt ROOMS [STEP_M] [RATE_HZ] [SWAY_DEG]
"""
import math
import sys

out, rooms = sys.argv[1], int(sys.argv[2])
step = float(sys.argv[3]) if len(sys.argv) > 3 else 0.03
rate = float(sys.argv[4]) if len(sys.argv) > 4 else 30.0
sway_deg = float(sys.argv[5]) if len(sys.argv) > 5 else 15.0
length = (rooms - 1) * 4.0 + 1.0          # from the first room to the last
n_walk = int(round(length / step))


def sway(i):
    return math.radians(sway_deg) * math.sin(2 * math.pi * i / 120.0)


poses = [(i * step, sway(i)) for i in range(n_walk + 1)]
poses += [(length - i * step, sway(n_walk + i)) for i in range(1, n_walk + 1)]
with open(out, "w") as f:
    f.write("# rooms_walk.py %d rooms, %.3f m per frame, out and back\n" % (rooms, step))
    for i, (z, yaw) in enumerate(poses):
        # Yaw about the camera's y axis (down): a rotation in the x-z plane.
        qy, qw = math.sin(yaw / 2), math.cos(yaw / 2)
        f.write("%.6f 0 0 %.6f 0 %.9f 0 %.9f\n" % (1305031100.0 + i / rate, z, qy, qw))
print("%d poses" % len(poses))
