#!/usr/bin/env python3
"""A reflection client that is not ours: the stock grpcio-reflection client against a running server.

grpcio-reflection speaks only the v1alpha reflection protocol, so this fails unless the server
serves it. Everything below comes from the server itself: the service list, the descriptors of
landing.v1.LandingService (and the files they import), and the message classes built from them,
with which it calls GetServiceInfo. No stubs are generated and proto/ is not read.

Usage:
    python client/examples/python/reflect.py --server 127.0.0.1:50051

Exit status: 0 when every check passed, 1 otherwise (the reason on stderr).
"""

import argparse
import json
import sys

import grpc
from google.protobuf import descriptor_pool, message_factory
from grpc_reflection.v1alpha.proto_reflection_descriptor_database import (
    ProtoReflectionDescriptorDatabase,
)

SERVICE = "landing.v1.LandingService"
EXPECTED_SERVICES = {SERVICE, "grpc.health.v1.Health"}
EXPECTED_METHODS = {"DetectLandingSites", "StreamLandingSites", "GetServiceInfo"}


def fail(message: str) -> int:
    print(f"reflect.py: {message}", file=sys.stderr)
    return 1


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--server", default="127.0.0.1:50051", help="host:port of a plain-text server")
    args = parser.parse_args()

    with grpc.insecure_channel(args.server) as channel:
        database = ProtoReflectionDescriptorDatabase(channel)
        try:
            services = set(database.get_services())
        except grpc.RpcError as e:
            return fail(f"v1alpha reflection (grpc.reflection.v1alpha.ServerReflection) failed: "
                        f"{e.code().name}: {e.details()}")
        missing = EXPECTED_SERVICES - services
        if missing:
            return fail(f"services {sorted(missing)} not listed; listed: {sorted(services)}")

        pool = descriptor_pool.DescriptorPool(database)
        service = pool.FindServiceByName(SERVICE)
        methods = {m.name for m in service.methods}
        if not EXPECTED_METHODS <= methods:
            return fail(f"{SERVICE} has methods {sorted(methods)}, expected {sorted(EXPECTED_METHODS)}")

        # Call the API with message classes made only from the reflected descriptors.
        method = service.methods_by_name["GetServiceInfo"]
        request_cls = message_factory.GetMessageClass(method.input_type)
        response_cls = message_factory.GetMessageClass(method.output_type)
        call = channel.unary_unary(
            f"/{SERVICE}/GetServiceInfo",
            request_serializer=lambda m: m.SerializeToString(),
            response_deserializer=response_cls.FromString,
        )
        info = call(request_cls(), timeout=30)

    classes = [c.name for c in info.classes]
    print(json.dumps({
        "services": sorted(services),
        "methods": sorted(methods),
        "server_version": info.version,
        "classes": len(classes),
    }, indent=2))
    if not info.version:
        return fail("GetServiceInfo answered without a version")
    if "building rooftop" not in classes:
        return fail(f"GetServiceInfo classes {classes} lack 'building rooftop'")
    return 0


if __name__ == "__main__":
    sys.exit(main())
