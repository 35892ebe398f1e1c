#!/usr/bin/env python3
"""The plain Python pipeline that issue 42 times the unary model-mode frame against.

The same parts as the service's single-frame method, at one input size and with nothing else:
PIL decodes the camera PNG and resizes it to the model's 320x240, one ONNX Runtime inference
gives the class mask, NumPy moves the scan into the world and projects it into the mask, the
rooftop points go to Polylidar3D (the paper's library, the point-cloud path) with the service's
default parameters, and shapely's polylabel finds each polygon's safest point.

Every frame of every recording given is read first (MCAP, Foxglove schemas); then each frame is
timed from its PNG bytes and packed points to its polylabel results, `--rounds` times over the
whole set. Prints the per-frame time's p50 / p95 and what the frames found, and with `--json` writes
them with the per-frame times.

Usage: pipeline.py MODEL.onnx RECORDING.mcap... [--rounds N] [--threads N] [--json OUT]
"""

import argparse
import io
import json
import statistics
import sys
import time

import numpy as np
import onnxruntime as ort
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from mcap.reader import make_reader
from PIL import Image
from polylidar import MatrixDouble, Polylidar3D
from shapely.geometry import Polygon
from shapely.ops import polylabel

# The service's defaults (`landing info`): max_triangle_edge_m, min_region_triangles,
# max_triangle_height_m, min_normal_dot, polylabel_precision_m, landable_classes.
LMAX = 4.0
MIN_TRIANGLES = 10
Z_THRESH = 0.1
NORM_THRESH = 0.96
POLYLABEL_PRECISION = 0.5
ROOFTOP = 4
# The one size the model runs at: the camera's.
INPUT_SIZE = (320, 240)
MEAN = np.array([0.485, 0.456, 0.406], dtype=np.float32)
STD = np.array([0.229, 0.224, 0.225], dtype=np.float32)
TOPICS = {
    "/lidar/points": PointCloud,
    "/camera/image": CompressedImage,
    "/camera/calibration": CameraCalibration,
    "/tf": FrameTransforms,
}


def rotation(q):
    """The rotation matrix of a unit quaternion."""
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def read_frames(paths):
    """Each frame's PNG bytes, packed points, calibration and poses, as the recording holds them."""
    frames = []
    for path in paths:
        moments = {}
        with open(path, "rb") as f:
            for _, channel, message in make_reader(f).iter_messages(topics=list(TOPICS)):
                proto = TOPICS[channel.topic].FromString(message.data)
                moments.setdefault(message.log_time, {})[channel.topic] = proto
        for at in sorted(moments):
            m = moments[at]
            if set(m) != set(TOPICS):
                sys.exit(f"{path}: frame at {at} lacks {set(TOPICS) - set(m)}")
            poses = {t.child_frame_id: (rotation(t.rotation),
                                        np.array([t.translation.x, t.translation.y, t.translation.z]))
                     for t in m["/tf"].transforms}
            cloud = m["/lidar/points"]
            fields = {f.name: f.offset for f in cloud.fields}
            frames.append({
                "png": m["/camera/image"].data,
                "points": cloud.data,
                "stride": cloud.point_stride,
                "x_offset": fields["x"],
                "k": list(m["/camera/calibration"].K),
                "size": (m["/camera/calibration"].width, m["/camera/calibration"].height),
                "lidar": poses[cloud.frame_id],
                "camera": poses[m["/camera/image"].frame_id],
            })
    return frames


def run_frame(frame, session, input_name):
    """One frame, PNG bytes to ranked safe circles: [(radius, x, y, z)], largest first."""
    width, height = INPUT_SIZE
    image = Image.open(io.BytesIO(frame["png"])).convert("RGB").resize(INPUT_SIZE, Image.BILINEAR)
    pixels = (np.asarray(image, dtype=np.float32) / 255.0 - MEAN) / STD
    tensor = np.ascontiguousarray(pixels.transpose(2, 0, 1)[None])
    mask = session.run(None, {input_name: tensor})[0][0]  # uint8 classes, [H, W]

    n = len(frame["points"]) // frame["stride"]
    packed = np.frombuffer(frame["points"], dtype=np.uint8).reshape(n, frame["stride"])
    local = packed[:, frame["x_offset"]:frame["x_offset"] + 12].copy().view(np.float32).astype(np.float64)
    r_lidar, t_lidar = frame["lidar"]
    world = local @ r_lidar.T + t_lidar
    r_camera, t_camera = frame["camera"]
    in_camera = (world - t_camera) @ r_camera  # the inverse rotation, row by row
    k = frame["k"]
    w, h = frame["size"]
    z = in_camera[:, 2]
    ahead = z > 0
    u = np.full(n, -1.0)
    v = np.full(n, -1.0)
    u[ahead] = k[0] * in_camera[ahead, 0] / z[ahead] + k[2]
    v[ahead] = k[4] * in_camera[ahead, 1] / z[ahead] + k[5]
    seen = ahead & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    classes = np.zeros(n, dtype=np.uint8)
    cols = (u[seen] * width / w).astype(np.int64)
    rows = (v[seen] * height / h).astype(np.int64)
    classes[seen] = mask[rows, cols]
    roof = world[classes == ROOFTOP]
    if len(roof) < 3:
        return []
    origin = roof.mean(axis=0)
    # MatrixDouble wraps the array's memory without copying: it must outlive the extraction.
    vertices = roof - origin
    polylidar = Polylidar3D(lmax=LMAX, min_triangles=MIN_TRIANGLES, z_thresh=Z_THRESH,
                            norm_thresh=NORM_THRESH, norm_thresh_min=NORM_THRESH)
    _, _, polygons = polylidar.extract_planes_and_polygons(MatrixDouble(vertices))
    sites = []
    for polygon in polygons:
        ring = vertices[np.asarray(polygon.shell)]
        shell = ring[:, :2]
        holes = [vertices[np.asarray(hole), :2] for hole in polygon.holes]
        shape = Polygon(shell, holes)
        if not shape.is_valid or shape.is_empty:
            continue
        centre = polylabel(shape, tolerance=POLYLABEL_PRECISION)
        radius = shape.exterior.distance(centre)
        for hole in shape.interiors:
            radius = min(radius, hole.distance(centre))
        sites.append((radius, centre.x + origin[0], centre.y + origin[1], ring[:, 2].mean() + origin[2]))
    sites.sort(reverse=True)
    return sites


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("model")
    ap.add_argument("recordings", nargs="+")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--threads", type=int, default=0, help="ONNX Runtime intra-op threads (0: its default)")
    ap.add_argument("--json")
    args = ap.parse_args()

    frames = read_frames(args.recordings)
    options = ort.SessionOptions()
    options.intra_op_num_threads = args.threads
    session = ort.InferenceSession(args.model, options, providers=["CPUExecutionProvider"])
    input_name = session.get_inputs()[0].name
    run_frame(frames[0], session, input_name)  # warm-up, not timed

    times = []
    found = []
    for _ in range(args.rounds):
        for frame in frames:
            start = time.perf_counter()
            sites = run_frame(frame, session, input_name)
            times.append((time.perf_counter() - start) * 1e3)
            found.append(sites)
    times_sorted = sorted(times)
    p50 = statistics.median(times)
    p95 = times_sorted[min(len(times) - 1, int(0.95 * len(times)))]
    with_site = sum(1 for s in found if s)
    print(f"{len(frames)} frames x {args.rounds} rounds: p50 {p50:.2f} ms, p95 {p95:.2f} ms, "
          f"mean {statistics.fmean(times):.2f} ms; frames with a site {with_site}, "
          f"sites {sum(len(s) for s in found)}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"frames": len(frames), "rounds": args.rounds, "p50_ms": p50, "p95_ms": p95,
                       "times_ms": times, "sites": found[:len(frames)]}, f)


if __name__ == "__main__":
    main()
