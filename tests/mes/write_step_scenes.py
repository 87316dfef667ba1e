#!/usr/bin/python3
"""Writes user scenes (devices/sim/specimen.h scene.json) of a step between two textured planes on
a slight common tilt, for inspectd --scene-dir: NAME.json, NAME_height.png (16-bit, 1 nm per
unit above 195 um) and a shared log-normal texture (fine grain plus mottling, like the built-in
specimens'). Standard library only (zlib, struct): Debian's python3 without numpy.

Usage: write_step_scenes.py DIR WIDTHxHEIGHT PIXEL_UM NAME=STEP_UM [NAME=STEP_UM ...]
The step rises at the middle column (right half higher); the planes tilt by 0.3 deg along x and
0.5 deg along y.
"""
import math
import os
import random
import struct
import sys
import zlib


def write_png16(path, width, height, rows):
    raw = b"".join(b"\x00" + struct.pack(">%dH" % width, *row) for row in rows)

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 16, 0, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 6)))
        f.write(chunk(b"IEND", b""))


def box_blur(img, w, h, r):
    out = [[0.0] * w for _ in range(h)]
    for y in range(h):
        row = img[y]
        acc = sum(row[min(max(i, 0), w - 1)] for i in range(-r, r + 1))
        for x in range(w):
            out[y][x] = acc / (2 * r + 1)
            acc += row[min(x + r + 1, w - 1)] - row[max(x - r, 0)]
    res = [[0.0] * w for _ in range(h)]
    for x in range(w):
        acc = sum(out[min(max(i, 0), h - 1)][x] for i in range(-r, r + 1))
        for y in range(h):
            res[y][x] = acc / (2 * r + 1)
            acc += out[min(y + r + 1, h - 1)][x] - out[max(y - r, 0)][x]
    return res


def normalised(img):
    vals = [v for row in img for v in row]
    m = sum(vals) / len(vals)
    s = math.sqrt(sum((v - m) ** 2 for v in vals) / len(vals)) or 1.0
    return [[(v - m) / s for v in row] for row in img]


def main():
    if len(sys.argv) < 5:
        raise SystemExit(__doc__)
    out, size, pixel_um = sys.argv[1], sys.argv[2], float(sys.argv[3])
    w, h = (int(v) for v in size.split("x"))
    os.makedirs(out, exist_ok=True)
    rng = random.Random(20261202)
    fine = normalised(box_blur([[rng.gauss(0, 1) for _ in range(w)] for _ in range(h)], w, h, 1))
    coarse = normalised(box_blur([[rng.gauss(0, 1) for _ in range(w)] for _ in range(h)], w, h, 8))
    tex = [[math.exp(0.35 * fine[y][x] + 0.15 * coarse[y][x]) for x in range(w)] for y in range(h)]
    mean = sum(v for row in tex for v in row) / (w * h)
    write_png16(os.path.join(out, "step_texture.png"), w, h,
                [[min(65535, int(20000 * v / mean)) for v in row] for row in tex])
    tx, ty = math.tan(math.radians(0.3)), math.tan(math.radians(0.5))
    for spec in sys.argv[4:]:
        name, step = spec.split("=")
        step = float(step)
        rows = []
        for y in range(h):
            row = []
            for x in range(w):
                z_um = 5.0 + tx * (x + 0.5) * pixel_um + ty * (y + 0.5) * pixel_um + (step if x >= w // 2 else 0.0)
                row.append(int(round(z_um * 1000.0)))
            rows.append(row)
        write_png16(os.path.join(out, name + "_height.png"), w, h, rows)
        with open(os.path.join(out, name + ".json"), "w") as f:
            f.write('{"height": "%s_height.png", "height_scale_um": 0.001, "height_offset_um": 195, '
                    '"texture": "step_texture.png"}\n' % name)
        print(f"{name}: step {step} um, {w}x{h} px of {pixel_um} um")


if __name__ == "__main__":
    main()
