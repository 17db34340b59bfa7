#!/usr/bin/env python3
"""Writes the shared procedural textures of the scene library (standard library only), 256x256
sRGB PNGs, deterministic:
checker-fine.png - 32x32 checker (8-px squares), cream/dark red: aliasing-prone fine detail
tiles.png        - 8x8 glazed tiles with thin dark grout lines
wood.png         - warm wood grain (rings distorted by value noise)
bricks.png       - running-bond bricks with mortar, per-brick tint
marble.png       - veined grey-white marble (turbulence)
dots.png         - dense polka dots (4-px dots every 12 px) on blue
Run from this folder: python3 make_textures.py"""
import math, random, struct, zlib

def png(name, w, h, pix):
    raw = bytearray()
    for y in range(h):
        raw.append(0)
        for x in range(w):
            raw += bytes(max(0, min(255, int(round(c * 255)))) for c in pix(x, y))
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    data = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    data += chunk(b"IDAT", zlib.compress(bytes(raw), 9)) + chunk(b"IEND", b"")
    open(name, "wb").write(data)

rng = random.Random(4)
LAT = [[rng.random() for _ in range(65)] for _ in range(65)]

def noise(x, y):
    """Periodic (64) value noise in [0, 1]."""
    xi, yi = int(math.floor(x)), int(math.floor(y))
    fx, fy = x - xi, y - yi
    sx, sy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    g = lambda i, j: LAT[j % 64][i % 64]
    a = g(xi, yi) + (g(xi + 1, yi) - g(xi, yi)) * sx
    b = g(xi, yi + 1) + (g(xi + 1, yi + 1) - g(xi, yi + 1)) * sx
    return a + (b - a) * sy

def turb(x, y, octaves=5):
    return sum(abs(noise(x * 2 ** o, y * 2 ** o) - 0.5) * 2 / 2 ** o for o in range(octaves)) / 2

def mix(a, b, t):
    return tuple(p + (q - p) * t for p, q in zip(a, b))

S = 256
png("checker-fine.png", S, S, lambda x, y: (0.93, 0.88, 0.75) if (x // 8 + y // 8) % 2 else (0.45, 0.06, 0.05))

def tiles(x, y):
    if x % 32 < 2 or y % 32 < 2:
        return (0.18, 0.17, 0.16)
    t = noise(x / 16.0, y / 16.0) * 0.15 + ((x // 32 * 7 + y // 32 * 3) % 5) * 0.03
    return mix((0.25, 0.55, 0.6), (0.85, 0.9, 0.88), t + 0.3)
png("tiles.png", S, S, tiles)

def wood(x, y):
    u, v = x / S * 4, y / S
    r = math.sin((u + 1.5 * noise(x / 32.0, y / 8.0)) * math.pi * 6) * 0.5 + 0.5
    g = noise(x / 2.0, y / 64.0) * 0.2
    return mix((0.55, 0.32, 0.14), (0.3, 0.15, 0.06), r ** 3 * 0.8 + g)
png("wood.png", S, S, wood)

def bricks(x, y):
    row = y // 16
    xo = x + (8 * 2 if row % 2 else 0)
    if y % 16 < 2 or xo % 32 < 2:
        return (0.7, 0.68, 0.62)
    k = (xo // 32 * 13 + row * 7) % 9
    base = mix((0.55, 0.2, 0.12), (0.75, 0.38, 0.22), k / 8.0)
    return mix(base, (0.3, 0.12, 0.08), noise(x / 3.0, y / 3.0) * 0.4)
png("bricks.png", S, S, bricks)

def marble(x, y):
    t = math.sin(x / S * 2 * math.pi * 3 + turb(x / 32.0, y / 32.0) * 12) * 0.5 + 0.5
    return mix((0.92, 0.92, 0.9), (0.35, 0.36, 0.4), t ** 6)
png("marble.png", S, S, marble)

def dots(x, y):
    dx, dy = x % 12 - 5.5, y % 12 - 5.5
    return (0.95, 0.85, 0.3) if dx * dx + dy * dy < 5 else (0.08, 0.15, 0.45)
png("dots.png", S, S, dots)
