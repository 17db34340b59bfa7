#!/usr/bin/env python3
"""Writes the two small images of the primitives scene (standard library only):
sky.hdr  - 64x32 lat-long environment (Radiance RGBE, flat scanlines): blue-to-white sky,
           dark ground, a small bright sun; top row = +Y (see docs/scene-format.md).
checker.png - 64x64 sRGB checkerboard (8x8 squares) for the textured material."""
import math, struct, zlib

def rgbe(r, g, b):
    m = max(r, g, b)
    if m < 1e-32:
        return bytes((0, 0, 0, 0))
    mant, e = math.frexp(m)  # m = mant * 2^e, mant in [0.5, 1)
    f = mant * 256.0 / m
    return bytes((int(r * f), int(g * f), int(b * f), e + 128))

def sky(w=64, h=32):
    out = bytearray(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n" % (h, w))
    for y in range(h):
        theta = (y + 0.5) / h * math.pi          # from +Y
        for x in range(w):
            phi = (x + 0.5) / w * 2 * math.pi
            if theta < math.pi / 2:
                t = theta / (math.pi / 2)         # 0 at zenith, 1 at horizon
                c = (0.35 + 0.65 * t, 0.55 + 0.45 * t, 1.0)
            else:
                c = (0.15, 0.12, 0.10)
            # Sun: 2x2 texels near phi = 0.8 rad, 35 degrees above the horizon.
            if x in (8, 9) and y in (9, 10):
                c = (40.0, 36.0, 30.0)
            out += rgbe(*c)
    return bytes(out)

def png(w=64, h=64):
    raw = bytearray()
    for y in range(h):
        raw.append(0)
        for x in range(w):
            on = ((x // 8) + (y // 8)) % 2 == 0
            raw += bytes((230, 200, 60) if on else (40, 60, 160))
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(bytes(raw), 9)) + chunk(b"IEND", b""))

if __name__ == "__main__":
    open("sky.hdr", "wb").write(sky())
    open("checker.png", "wb").write(png())
