#!/usr/bin/env python3
"""Compares two 8-bit RGB PNGs pixel by pixel (zlib only: no imaging
library among the test machine's packages).
Usage: png_compare.py A.png B.png MAX_DIFF MAX_FRACTION
Passes (exit 0) when the images have the same size and at most
MAX_FRACTION of the pixels differ by more than MAX_DIFF in any channel, and
A is not all black; prints the counts either way. read_png is also
imported by the tests that look at one image."""
import struct
import sys
import zlib



def read_png(path):
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        sys.exit("%s: not a PNG" % path)
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, colour = struct.unpack(">IIBB", body[:10])
            if depth != 8 or colour != 2:
                sys.exit("%s: not 8-bit RGB (depth %d, colour type %d)" % (path, depth, colour))
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw, stride = zlib.decompress(idat), 3 * w
    rows, up = [], bytearray(stride)
    for y in range(h):  # the PNG filters (PNG spec, section 9)
        f, line = raw[y * (stride + 1)], raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)]
        row = bytearray(stride)
        for x in range(stride):
            a = row[x - 3] if x >= 3 else 0
            b, c = up[x], (up[x - 3] if x >= 3 else 0)
            if f == 0:
                p = 0
            elif f == 1:
                p = a
            elif f == 2:
                p = b
            elif f == 3:
                p = (a + b) // 2
            else:
                pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                p = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
            row[x] = (line[x] + p) & 255
        rows.append(row)
        up = row
    return w, h, b"".join(rows)


def main():
    (wa, ha, a), (wb, hb, b) = read_png(sys.argv[1]), read_png(sys.argv[2])
    max_diff, max_frac = int(sys.argv[3]), float(sys.argv[4])
    if (wa, ha) != (wb, hb):
        sys.exit("sizes differ: %dx%d and %dx%d" % (wa, ha, wb, hb))
    n, bad, worst, lit = wa * ha, 0, 0, 0
    for i in range(n):
        d = max(abs(a[3 * i + k] - b[3 * i + k]) for k in range(3))
        worst = max(worst, d)
        bad += d > max_diff
        lit += max(a[3 * i:3 * i + 3]) > 0
    print("%d of %d pixels differ by more than %d (max %d); %d lit" % (bad, n, max_diff, worst, lit))
    sys.exit(0 if bad <= max_frac * n and lit > 0 else 1)


if __name__ == "__main__":
    main()
