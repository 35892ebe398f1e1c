#!/usr/bin/env python3
"""Reads a landing-sim MCAP recording with stock Python readers and checks its structure.

Every message of every channel is decoded by the `mcap` package with mcap-protobuf-support's
decoder, from the schema embedded in the file. Every `foxglove.*` channel is also read with the
stock classes of the `foxglove-schemas-protobuf` package: its embedded schema must have their
fields, and the checks below run on the messages as those classes parse them, which is the proof
that Foxglove reads the channels as we mean them.

Usage: check_mcap.py RECORDING.mcap [--min-frames N] [--replay]
--replay: the file is a `landing replay --out` output and must also hold the answers.
Exits non-zero with a message on the first problem.
"""

import argparse
import struct
import sys
from collections import defaultdict

from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.SceneEntityDeletion_pb2 import SceneEntityDeletion
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

# Topics logged once per frame, all at the frame's log time.
FRAME_TOPICS = {
    "/frame": "landing.v1.FrameHeader",
    "/lidar/points": "foxglove.PointCloud",
    "/camera/image": "foxglove.CompressedImage",
    "/camera/calibration": "foxglove.CameraCalibration",
    "/tf": "foxglove.FrameTransforms",
    "/camera/labels": "foxglove.CompressedImage",
    "/ground_truth": "landing.v1.GroundTruth",
    "/ground_truth/scene": "foxglove.SceneUpdate",
}
# Topics a replay adds, once per answer, at the answered frame's log time.
REPLAY_TOPICS = {
    "/landing/results": "landing.v1.StreamLandingSitesResponse",
    "/landing/sites": "foxglove.SceneUpdate",
    "/camera/annotations": "foxglove.ImageAnnotations",
}
STOCK = {
    cls.DESCRIPTOR.full_name: cls
    for cls in (PointCloud, CompressedImage, CameraCalibration, FrameTransforms, SceneUpdate,
                ImageAnnotations)
}
WORLD, LIDAR, CAMERA = "world", "lidar", "camera"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def fail(msg):
    print(f"FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def fields_of(message):
    return {f.number: (f.name, f.type, f.is_repeated) for f in message.fields}


def values_of(enum):
    return {v.number: v.name for v in enum.values}


def schema_difference(embedded, stock, seen=None):
    """How the message descriptor `embedded` differs from `stock` (fields by number: name, type,
    repetition; nested messages and enums too), or None when they agree."""
    seen = set() if seen is None else seen
    if stock.full_name in seen:
        return None
    seen.add(stock.full_name)
    if embedded.full_name != stock.full_name:
        return f"{embedded.full_name} where {stock.full_name} is expected"
    if fields_of(embedded) != fields_of(stock):
        return f"{stock.full_name} fields {fields_of(embedded)}, stock {fields_of(stock)}"
    for f in stock.fields:
        e = embedded.fields_by_number[f.number]
        if f.enum_type is not None and values_of(e.enum_type) != values_of(f.enum_type):
            return f"{f.enum_type.full_name} values differ"
        if f.message_type is not None:
            why = schema_difference(e.message_type, f.message_type, seen)
            if why:
                return why
    return None


def png_header(data, what):
    """Width, height, bit depth and colour type of a PNG."""
    if not data.startswith(PNG_MAGIC) or data[12:16] != b"IHDR":
        fail(f"{what} is not PNG")
    width, height, depth, colour = struct.unpack_from(">IIBB", data, 16)
    return width, height, depth, colour


def unit(q):
    return abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0) <= 1e-6


def check_cloud(pc, seq):
    """A scan in the LiDAR frame with x, y, z, intensity and class; returns its point count."""
    if pc.frame_id != LIDAR or pc.HasField("pose"):
        fail(f"frame {seq}: cloud in frame {pc.frame_id!r} with pose set: {pc.HasField('pose')}")
    if pc.point_stride < 17:
        fail(f"frame {seq}: point_stride {pc.point_stride} < 17")
    fields = {f.name: (f.offset, f.type) for f in pc.fields}
    for name in ("x", "y", "z", "intensity"):
        if fields.get(name, (None, None))[1] != PackedElementField.FLOAT32:
            fail(f"frame {seq}: field {name} missing or not FLOAT32: {fields}")
    if fields.get("class", (None, None))[1] != PackedElementField.UINT8:
        fail(f"frame {seq}: field class missing or not UINT8")
    if len(pc.data) % pc.point_stride:
        fail(f"frame {seq}: data length {len(pc.data)} not a multiple of the stride")
    n = len(pc.data) // pc.point_stride
    if not 500 <= n <= 2000:
        fail(f"frame {seq}: {n} points, expected about 1,600")
    xo, co = fields["x"][0], fields["class"][0]
    for i in range(0, n, 97):
        base = i * pc.point_stride
        x, y, z = struct.unpack_from("<fff", pc.data, base + xo)
        cls = pc.data[base + co]
        if not 1 <= cls <= 14:
            fail(f"frame {seq}: point {i} class {cls}")
        if not (x * x + y * y + z * z) ** 0.5 <= 120.0:
            fail(f"frame {seq}: point {i} range too large")
    return n


def check_tf(tf, seq):
    """world → lidar and world → camera, with unit rotations."""
    children = sorted(t.child_frame_id for t in tf.transforms)
    if children != [CAMERA, LIDAR] or any(t.parent_frame_id != WORLD for t in tf.transforms):
        fail(f"frame {seq}: transforms {[(t.parent_frame_id, t.child_frame_id) for t in tf.transforms]}")
    for t in tf.transforms:
        if not unit(t.rotation):
            fail(f"frame {seq}: rotation of {t.child_frame_id} not a unit quaternion")


def check_camera(image, cal, labels, seq):
    """A PNG camera image, a pinhole calibration of its size, and a grayscale label PNG of the
    same size."""
    if image.frame_id != CAMERA or cal.frame_id != CAMERA or labels.frame_id != CAMERA:
        fail(f"frame {seq}: camera frame ids {image.frame_id!r} {cal.frame_id!r} {labels.frame_id!r}")
    if image.format != "png" or labels.format != "png":
        fail(f"frame {seq}: image formats {image.format!r} {labels.format!r}")
    size = png_header(image.data, f"frame {seq}: camera image")[:2]
    k = list(cal.K)
    if (len(k) != 9 or len(cal.P) != 12 or list(cal.R) != [1, 0, 0, 0, 1, 0, 0, 0, 1]
            or k[0] <= 0 or k[4] <= 0 or k[1] or k[3] or k[6:] != [0, 0, 1]
            or not 0 < k[2] < cal.width or not 0 < k[5] < cal.height
            or (cal.width, cal.height) != size):
        fail(f"frame {seq}: calibration {cal.width}x{cal.height} K={k} R={list(cal.R)} "
             f"P={list(cal.P)} for a {size[0]}x{size[1]} image")
    width, height, depth, colour = png_header(labels.data, f"frame {seq}: label image")
    if (width, height) != size or (depth, colour) != (8, 0):
        fail(f"frame {seq}: label PNG {width}x{height}, depth {depth}, colour type {colour}")


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


def check_scene(scene, topic, seq):
    """A drawing that replaces the previous one and lies in the world frame."""
    if not scene.deletions or scene.deletions[0].type != SceneEntityDeletion.ALL:
        fail(f"{topic} {seq}: does not start by deleting everything")
    for e in scene.entities:
        if e.frame_id != WORLD:
            fail(f"{topic} {seq}: entity {e.id!r} in frame {e.frame_id!r}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("recording")
    ap.add_argument("--min-frames", type=int, default=10)
    ap.add_argument("--replay", action="store_true", help="also require the answers")
    args = ap.parse_args()
    expected = FRAME_TOPICS | (REPLAY_TOPICS if args.replay else {})
    # log time -> topic -> message (stock class for foxglove.*, embedded schema otherwise).
    moments = defaultdict(dict)
    times = defaultdict(list)
    with open(args.recording, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        compressions = {c.compression for c in summary.chunk_indexes}
        if compressions != {"zstd"}:
            fail(f"chunk compression {compressions}, expected zstd")
        for ch in summary.channels.values():
            if ch.topic not in expected:
                fail(f"unexpected topic {ch.topic}")
            schema = summary.schemas.get(ch.schema_id)
            name, encoding = (schema.name, schema.encoding) if schema else (None, None)
            if encoding != "protobuf" or name != expected[ch.topic]:
                fail(f"{ch.topic}: schema {name!r} encoding {encoding!r}")
            if ch.message_encoding != "protobuf":
                fail(f"{ch.topic}: message encoding {ch.message_encoding!r}")
        compared = set()
        for schema, channel, message, proto in reader.iter_decoded_messages():
            topic, at = channel.topic, message.log_time
            if schema.name in STOCK:
                stock = STOCK[schema.name]
                if channel.id not in compared:
                    why = schema_difference(proto.DESCRIPTOR, stock.DESCRIPTOR)
                    if why:
                        fail(f"{topic}: embedded schema is not Foxglove's: {why}")
                    compared.add(channel.id)
                proto = stock.FromString(message.data)
            if topic in moments[at]:
                fail(f"{topic}: two messages at log time {at}")
            moments[at][topic] = proto
            times[topic].append(at)

    frame_times = times["/frame"]
    if len(frame_times) < args.min_frames:
        fail(f"/frame: {len(frame_times)} messages, expected at least {args.min_frames}")
    for topic in expected:
        if topic != "/camera/annotations" and times[topic] != frame_times:
            fail(f"{topic}: {len(times[topic])} messages, not one at each of the "
                 f"{len(frame_times)} frames' log times")
    points = 0
    answered = 0
    sites_drawn = False
    for at in frame_times:
        m = moments[at]
        seq = m["/frame"].sequence
        if m["/ground_truth"].sequence != seq:
            fail(f"frame {seq}: ground truth is for frame {m['/ground_truth'].sequence}")
        points += check_cloud(m["/lidar/points"], seq)
        check_tf(m["/tf"], seq)
        check_camera(m["/camera/image"], m["/camera/calibration"], m["/camera/labels"], seq)
        check_truth(m["/ground_truth"])
        check_scene(m["/ground_truth/scene"], "/ground_truth/scene", seq)
        if not m["/ground_truth/scene"].entities:
            fail(f"frame {seq}: ground truth scene draws nothing")
        if not args.replay:
            continue
        response = m["/landing/results"]
        if response.sequence != seq:
            fail(f"frame {seq}: answer is for frame {response.sequence}")
        check_scene(m["/landing/sites"], "/landing/sites", seq)
        has_result = response.WhichOneof("outcome") == "result"
        # The answer is drawn over the camera image exactly when it has a result.
        if has_result != ("/camera/annotations" in m):
            fail(f"frame {seq}: outcome {response.WhichOneof('outcome')} but annotations "
                 f"{'present' if '/camera/annotations' in m else 'missing'}")
        if has_result and response.result.sites and not sites_drawn:
            entities = {e.id: e for e in m["/landing/sites"].entities}
            first = entities.get(f"site-{response.result.sites[0].rank}")
            if first is None or not any(t.points for t in first.triangles):
                fail(f"frame {seq}: first site is not drawn filled: {sorted(entities)}")
            annotations = m["/camera/annotations"]
            if not (annotations.points or annotations.circles):
                fail(f"frame {seq}: the sites are not drawn over the camera image")
            sites_drawn = True
        answered += has_result
    if args.replay and not sites_drawn:
        fail("no answer has a landing site")
    if args.replay and len(times["/camera/annotations"]) != answered:
        fail(f"/camera/annotations: {len(times['/camera/annotations'])} messages for {answered} results")
    extra = f", {answered} answers with a result" if args.replay else ""
    print(f"OK: {len(frame_times)} frames, {points} points{extra}, topics {sorted(expected)}")


if __name__ == "__main__":
    main()
