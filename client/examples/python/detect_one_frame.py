#!/usr/bin/env python3
"""A client that is not ours: calls landing.v1 DetectLandingSites from Python.

Stubs are generated from the repository's proto/ with grpcio-tools into a temporary directory
(nothing generated is committed), one frame is read from an MCAP recording with the `mcap`
package (and cross-checked with mcap-protobuf-support's decoder, which uses the schema embedded in
the file), and the running server must answer it with at least one landing site.

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


def read_frame(path: pathlib.Path, index: int, frame_cls):
    """The `index`-th landing.v1.Frame of the recording (negative counts from the end)."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        decoded = [
            (message.data, proto_msg)
            for schema, _channel, message, proto_msg in reader.iter_decoded_messages()
            if schema is not None and schema.name == "landing.v1.Frame"
        ]
    if not decoded:
        raise SystemExit(f"{path}: no landing.v1.Frame messages")
    data, dynamic = decoded[index]
    frame = frame_cls.FromString(data)
    # The file's own schema and our generated stubs must agree on the frame.
    if dynamic.sequence != frame.sequence or dynamic.drone_id != frame.drone_id:
        raise SystemExit("the recording's embedded schema and proto/ disagree")
    return frame, len(decoded)


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

        frame, count = read_frame(pathlib.Path(args.recording), args.frame, pb.Frame)
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
