"""Writes the committed seed corpus of the fuzz targets (fuzz/corpus/TARGET/): a few small, valid
inputs each, so that libFuzzer starts from the formats' happy paths. Standard library only, except
the JPEG, which needs Pillow (skipped without it). Run from the repository root:
python3 fuzz/seeds.py"""

import io
import struct
import zlib
from pathlib import Path

root = Path("fuzz/corpus")


def write(target, name, data):
    d = root / target
    d.mkdir(parents=True, exist_ok=True)
    (d / name).write_bytes(data)


def png(width, height, colour, pixels):
    """A PNG of 8-bit grey (colour 0) or RGB (colour 2) rows."""
    chunk = lambda kind, body: (
        struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    )
    channels = 1 if colour == 0 else 3
    rows = b"".join(
        b"\x00" + bytes(pixels[y * width * channels:(y + 1) * width * channels]) for y in range(height)
    )
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, colour, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(rows))
        + chunk(b"IEND", b"")
    )


# Protobuf wire format, enough for a request.
def varint(n):
    out = bytearray()
    while True:
        b, n = n & 0x7F, n >> 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)


def field(number, wire, body):
    key = varint(number << 3 | wire)
    if wire == 0:
        return key + varint(body)
    if wire == 1:
        return key + struct.pack("<d", body)
    if wire == 5:
        return key + struct.pack("<I", body)
    return key + varint(len(body)) + body


def request(points, classes):
    fields = b"".join(
        field(5, 2, field(1, 2, name.encode()) + field(2, 5, offset) + field(3, 0, ty))
        for name, offset, ty in [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("class", 12, 1)]
    )
    data = b"".join(struct.pack("<fffB", *p, c) for p, c in zip(points, classes))
    pose = field(1, 2, field(3, 1, 40.0)) + field(2, 2, field(4, 1, 1.0))
    cloud = field(3, 2, pose) + field(4, 5, 13) + fields + field(6, 2, data)
    frame = field(1, 2, b"d1") + field(2, 0, 7) + field(4, 2, cloud)
    options = field(11, 0, 2) + field(1, 1, 1.5)
    return field(1, 2, frame) + field(2, 2, options)


grid = [(x * 0.5, y * 0.5, -40.0) for x in range(6) for y in range(6)]
write("request", "grid", request(grid, [4] * len(grid)))
write("request", "tiny", request(grid[:3], [4, 8, 2]))

write("image", "grey.png", png(8, 8, 0, [4] * 64))
write("image", "rgb.png", png(4, 3, 2, list(range(36))))
try:
    from PIL import Image

    out = io.BytesIO()
    Image.new("RGB", (8, 8), (120, 130, 140)).save(out, "JPEG")
    write("image", "rgb.jpg", out.getvalue())
except ImportError:
    pass

header = "ply\nformat {}\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty uchar class\nend_header\n"
write("ply", "ascii.ply", (header.format("ascii 1.0") + "0 0 1 4\n1 0 1 4\n0 1 1 8\n").encode())
write(
    "ply",
    "binary.ply",
    header.format("binary_little_endian 1.0").encode()
    + b"".join(struct.pack("<fffB", *p, 4) for p in grid[:3]),
)

# The start of the sample recording: its magic, header and first records.
write("recording", "sample-head.mcap", Path("samples/rooftops.mcap").read_bytes()[:4096])

# Points on a 10 cm grid (13 bytes each after 8 parameter bytes), a plane with a bump.
params = bytes([40, 200, 30, 60, 2, 3, 1, 0])
pts = b"".join(
    struct.pack("<fffB", x * 0.1, y * 0.1, 0.3 if (x, y) == (5, 5) else 0.0, 4) for x in range(12) for y in range(12)
)
write("detect", "plane", params + pts)

# Two drones' frames, a reset and a step back in time (17-byte header, 4 bytes a point, 0xFE between).
def frame(drone, reset, dt_ms, position, heading, classes):
    head = bytes([drone, reset]) + struct.pack("<h", dt_ms) + struct.pack("<fff", *position) + bytes([heading])
    body = b"".join(bytes([x & 0xFF, y & 0xFF, 0, c]) for x in range(-8, 8, 2) for y in range(-8, 8, 2) for c in [classes])
    return head + body


write(
    "stream",
    "approach",
    b"\xfe".join(
        [
            frame(0x80, 0, 100, (0.0, 0.0, 40.0), 0, 4),
            frame(0x80, 0, 100, (0.2, 0.0, 39.0), 0, 4),
            frame(0x81, 0, 100, (0.2, 0.0, 39.0), 0, 8),
            frame(0x81, 1, -50, (5.0e6, 0.0, 30.0), 9, 4),
        ]
    ),
)
