#!/usr/bin/env python3
"""A client that is not ours: calls landing.v1 DetectLandingSites from Python.

Stubs are generated from the repository's proto/ with grpcio-tools into a temporary directory
(nothing generated is committed), one frame is read from an MCAP recording with the `mcap`
package and mcap-protobuf-support's decoder, which uses the schemas embedded in the file (the
frame is put back together from its Foxglove channels, or taken whole from older recordings, and
cross-checked against the stubs), and the running server must answer it with at least one
landing site.

Usage:
    python client/examples/python/detect_one_frame.py \
        --server 127.0.0.1:50051 --recording samples/rooftops.mcap [--frame -1] [--token T]

Exit status: 0 when the server answered with sites, 1 otherwise.
"""

import argparse
import importlib
import json
import pathlib
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[3]
PROTO = ROOT / "proto"


def generate_stubs(out_dir: pathlib.Path) -> None:
    """Runs protoc (from grpcio-tools) on every .proto of the API."""
    protos = sorted(str(p.relative_to(PROTO)) for p in PROTO.rglob("*.proto"))
    cmd = [
        sys.executable, "-m", "grpc_tools.protoc",
        "-I", str(PROTO),
        f"--python_out={out_dir}",
        f"--grpc_python_out={out_dir}",
        *protos,
    ]
    subprocess.run(cmd, check=True)


def read_frame(path: pathlib.Path, index: int, pb, rec):
    """The `index`-th frame of the recording (negative counts from the end), as a landing.v1.Frame
    of the stubs `pb`, and how many frames the recording holds.

    A frame is put back together from the messages of one log time: the landing.v1.FrameHeader
    (stubs `rec`) on /frame, the foxglove.PointCloud on /lidar/points, the camera image on
    /camera/image (or /camera/image_raw), the foxglove.CameraCalibration on /camera/calibration,
    and the sensor poses from the foxglove.FrameTransforms on /tf. Whole landing.v1.Frame
    messages (older recordings, other tools) are taken as they are.
    """
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    frames = []  # a whole Frame, or the log time of a frame to put together
    moments = {}  # log time -> topic -> (raw bytes, message decoded with the file's schema)
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, proto_msg in reader.iter_decoded_messages():
            if schema is None:
                continue
            if schema.name == "landing.v1.Frame":
                frames.append(checked(pb.Frame, message.data, proto_msg))
                continue
            moment = moments.setdefault(message.log_time, {})
            starts = channel.topic in ("/frame", "/lidar/points")
            if starts and not ({"/frame", "/lidar/points"} & moment.keys()):
                frames.append(message.log_time)
            moment[channel.topic] = (message.data, proto_msg)
    if not frames:
        raise SystemExit(f"{path}: no frames (no /frame header, /lidar/points cloud or landing.v1.Frame)")
    frame = frames[index]
    if isinstance(frame, int):
        frame = assemble(moments[frame], pb, rec)
    return frame, len(frames)


def checked(cls, data: bytes, dynamic):
    """`data` parsed with our stubs' `cls`; the file's own schema and proto/ must agree on it."""
    msg = cls.FromString(data)
    if dynamic.sequence != msg.sequence or dynamic.drone_id != msg.drone_id:
        raise SystemExit(f"the recording's embedded schema and proto/ disagree on a {cls.__name__}")
    return msg


def assemble(moment: dict, pb, rec):
    """A landing.v1.Frame from the Foxglove messages and header of one log time."""
    frame = pb.Frame()
    if "/frame" in moment:
        header = checked(rec.FrameHeader, *moment["/frame"])
        frame.drone_id = header.drone_id
        frame.sequence = header.sequence
        if header.HasField("timestamp"):
            frame.timestamp.CopyFrom(header.timestamp)
        if header.HasField("geodetic_origin"):
            frame.geodetic_origin.CopyFrom(header.geodetic_origin)
        if header.HasField("class_image"):
            frame.class_image.CopyFrom(header.class_image)
    transforms = moment["/tf"][1].transforms if "/tf" in moment else []
    if "/lidar/points" in moment:
        cloud = moment["/lidar/points"][1]
        pc = frame.point_cloud
        copy_time(pc, cloud)
        pc.frame_id = cloud.frame_id
        set_pose(pc, transforms, cloud.frame_id, pb)
        pc.point_stride = cloud.point_stride
        pc.fields.extend(
            pb.PackedElementField(name=f.name, offset=f.offset, type=f.type) for f in cloud.fields
        )
        pc.data = cloud.data
    image = next((moment[t][1] for t in ("/camera/image", "/camera/image_raw") if t in moment), None)
    if image is not None:
        img = frame.image
        copy_time(img, image)
        img.frame_id = image.frame_id
        set_pose(img, transforms, image.frame_id, pb)
        if image.DESCRIPTOR.full_name == "foxglove.CompressedImage":
            img.compressed.data = image.data
            img.compressed.format = image.format
        else:
            img.raw.CopyFrom(pb.RawImage(width=image.width, height=image.height,
                                         encoding=image.encoding, step=image.step, data=image.data))
        if "/camera/calibration" in moment:
            cal = moment["/camera/calibration"][1]
            img.calibration.CopyFrom(pb.CameraCalibration(
                width=cal.width, height=cal.height, fx=cal.K[0], fy=cal.K[4], cx=cal.K[2], cy=cal.K[5]))
    return frame


def copy_time(dst, src) -> None:
    """dst.timestamp = src.timestamp, between messages of different descriptor pools."""
    if src.HasField("timestamp"):
        dst.timestamp.seconds = src.timestamp.seconds
        dst.timestamp.nanos = src.timestamp.nanos


def set_pose(dst, transforms, frame_id: str, pb) -> None:
    """dst.pose = the transform world → frame_id, if the frame has one (unset means identity)."""
    for t in transforms:
        if t.parent_frame_id == "world" and t.child_frame_id == frame_id:
            p, q = t.translation, t.rotation
            dst.pose.CopyFrom(pb.Pose(position=pb.Vector3(x=p.x, y=p.y, z=p.z),
                                      orientation=pb.Quaternion(x=q.x, y=q.y, z=q.z, w=q.w)))
            return


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--server", default="127.0.0.1:50051", help="host:port of a plain-text server")
    parser.add_argument("--recording", default=str(ROOT / "samples" / "rooftops.mcap"))
    parser.add_argument("--frame", type=int, default=-1, help="frame index; -1 is the last (closest) one")
    parser.add_argument("--token", default=None, help="bearer token, if the server requires one")
    parser.add_argument("--segmentation", default="POINT_CLASSES",
                        choices=["UNSPECIFIED", "MODEL", "POINT_CLASSES", "NONE"])
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="landing-stubs-") as out:
        generate_stubs(pathlib.Path(out))
        sys.path.insert(0, out)
        import grpc

        pb = importlib.import_module("landing.v1.landing_pb2")
        pb_grpc = importlib.import_module("landing.v1.landing_pb2_grpc")
        rec = importlib.import_module("landing.v1.recording_pb2")

        frame, count = read_frame(pathlib.Path(args.recording), args.frame, pb, rec)
        mode = getattr(pb, f"SEGMENTATION_MODE_{args.segmentation}")
        request = pb.DetectLandingSitesRequest(frame=frame, options=pb.PipelineOptions(segmentation_mode=mode))
        metadata = [("authorization", f"Bearer {args.token}")] if args.token else None
        with grpc.insecure_channel(args.server) as channel:
            stub = pb_grpc.LandingServiceStub(channel)
            info = stub.GetServiceInfo(pb.GetServiceInfoRequest(), timeout=30, metadata=metadata)
            response = stub.DetectLandingSites(request, timeout=120, metadata=metadata)

    result = response.result
    summary = {
        "server_version": info.version,
        "recording_frames": count,
        "sequence": result.sequence,
        "points": result.point_count,
        "sites": [
            {
                "rank": s.rank,
                "safe_radius_m": round(s.safe_radius_m, 3),
                "center": [round(s.center.x, 3), round(s.center.y, 3), round(s.center.z, 3)],
                "holes": len(s.polygon.holes),
            }
            for s in result.sites
        ],
    }
    print(json.dumps(summary, indent=2))
    if result.sequence != frame.sequence:
        print(f"answer is for frame {result.sequence}, sent {frame.sequence}", file=sys.stderr)
        return 1
    if not result.sites:
        print("the server found no landing site", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
