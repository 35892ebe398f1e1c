#!/usr/bin/env python3
"""Reads a landing-sim MCAP recording with the `mcap` package and its protobuf decoder (an
independent implementation of MCAP and protobuf) and checks its structure.

Usage: check_mcap.py RECORDING.mcap [--min-frames N]
Exits non-zero with a message on the first problem.
"""

import argparse
import struct
import sys

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

EXPECTED = {
    "/frame": "landing.v1.Frame",
    "/ground_truth": "landing.v1.GroundTruth",
    "/camera/labels": "landing.v1.CameraImage",
}
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
FLOAT32, UINT8 = 7, 1


def fail(msg):
    print(f"FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def check_frame(frame):
    pc = frame.point_cloud
    if pc.point_stride < 17:
        fail(f"frame {frame.sequence}: point_stride {pc.point_stride} < 17")
    fields = {f.name: (f.offset, f.type) for f in pc.fields}
    for name in ("x", "y", "z", "intensity"):
        if fields.get(name, (None, None))[1] != FLOAT32:
            fail(f"frame {frame.sequence}: field {name} missing or not FLOAT32: {fields}")
    if fields.get("class", (None, None))[1] != UINT8:
        fail(f"frame {frame.sequence}: field class missing or not UINT8")
    if len(pc.data) % pc.point_stride:
        fail(f"frame {frame.sequence}: data length {len(pc.data)} not a multiple of the stride")
    n = len(pc.data) // pc.point_stride
    if not 500 <= n <= 2000:
        fail(f"frame {frame.sequence}: {n} points, expected about 1,600")
    off = fields["class"][0]
    xo = fields["x"][0]
    for i in range(0, n, 97):
        base = i * pc.point_stride
        x, y, z = struct.unpack_from("<fff", pc.data, base + xo)
        cls = pc.data[base + off]
        if not 1 <= cls <= 14:
            fail(f"frame {frame.sequence}: point {i} class {cls}")
        if not (x * x + y * y + z * z) ** 0.5 <= 120.0:
            fail(f"frame {frame.sequence}: point {i} range too large")
    q = pc.pose.orientation
    if abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0) > 1e-6:
        fail(f"frame {frame.sequence}: LiDAR pose quaternion not unit")
    img = frame.image
    if img.compressed.format != "png" or not img.compressed.data.startswith(PNG_MAGIC):
        fail(f"frame {frame.sequence}: camera image is not PNG")
    cal = img.calibration
    if cal.width == 0 or cal.height == 0 or cal.fx <= 0 or cal.fy <= 0:
        fail(f"frame {frame.sequence}: bad calibration {cal}")
    return n


def check_truth(gt):
    if not gt.roofs:
        fail(f"ground truth {gt.sequence}: no roof in view")
    target = gt.roofs[0]
    if target.building != gt.target_building:
        fail(f"ground truth {gt.sequence}: first roof is not the target")
    if target.best_safe_radius_m <= 0.0:
        fail(f"ground truth {gt.sequence}: target roof has no safe radius")
    if len(target.outline.points) != 4:
        fail(f"ground truth {gt.sequence}: roof outline has {len(target.outline.points)} points")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("recording")
    ap.add_argument("--min-frames", type=int, default=10)
    args = ap.parse_args()
    counts = {t: 0 for t in EXPECTED}
    points = 0
    with open(args.recording, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        for ch in summary.channels.values():
            if ch.topic not in EXPECTED:
                fail(f"unexpected topic {ch.topic}")
            schema = summary.schemas[ch.schema_id]
            if schema.encoding != "protobuf" or schema.name != EXPECTED[ch.topic]:
                fail(f"{ch.topic}: schema {schema.name!r} encoding {schema.encoding!r}")
            if ch.message_encoding != "protobuf":
                fail(f"{ch.topic}: message encoding {ch.message_encoding!r}")
        for schema, channel, message, proto in reader.iter_decoded_messages():
            counts[channel.topic] += 1
            if channel.topic == "/frame":
                points += check_frame(proto)
            elif channel.topic == "/ground_truth":
                check_truth(proto)
            else:
                if not proto.compressed.data.startswith(PNG_MAGIC):
                    fail("label image is not PNG")
    for topic, n in counts.items():
        if n < args.min_frames:
            fail(f"{topic}: {n} messages, expected at least {args.min_frames}")
    if len(set(counts.values())) != 1:
        fail(f"topics have different message counts: {counts}")
    print(f"OK: {counts['/frame']} frames, {points} points, topics {sorted(counts)}")


if __name__ == "__main__":
    main()
