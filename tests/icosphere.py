#!/usr/bin/env python3
"""Writes an icosphere (a closed mesh of a sphere) as OFF, for the tests'
mesh checks: the icosahedron's 20 faces split in four, each new vertex
pushed out to the sphere, SUBDIV times (20 * 4^SUBDIV triangles).
Usage: icosphere.py OUT.off RADIUS SUBDIV"""
import math
import sys

out, radius, subdiv = sys.argv[1], float(sys.argv[2]), int(sys.argv[3])
t = (1 + 5 ** 0.5) / 2
v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
     (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
v = [tuple(c / math.sqrt(sum(x * x for x in p)) for c in p) for p in v]
f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6),
     (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7),
     (9, 8, 1)]
for _ in range(subdiv):
    mid, nf = {}, []

    def m(a, b):
        k = (min(a, b), max(a, b))
        if k not in mid:
            p = [(x + y) / 2 for x, y in zip(v[a], v[b])]
            n = math.sqrt(sum(x * x for x in p))
            v.append(tuple(x / n for x in p))
            mid[k] = len(v) - 1
        return mid[k]

    for a, b, c in f:
        ab, bc, ca = m(a, b), m(b, c), m(c, a)
        nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
    f = nf
with open(out, "w") as o:
    o.write("OFF\n%d %d 0\n" % (len(v), len(f)))
    for p in v:
        o.write("%.7f %.7f %.7f\n" % tuple(radius * x for x in p))
    for a, b, c in f:
        o.write("3 %d %d %d\n" % (a, b, c))
