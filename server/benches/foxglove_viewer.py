#!/usr/bin/env python3
"""A Foxglove viewer for the live view's benchmark (BENCHMARKS.md, "Live view"): connects to
`landing-server serve --foxglove-listen`, subscribes to every channel and reads what it is sent,
or with --stall subscribes and then reads nothing (a viewer that has fallen behind).

Usage: foxglove_viewer.py ws://127.0.0.1:8765 [--seconds 30] [--stall]
Needs `websockets` (server/benches/requirements.txt). Prints messages and bytes received.
"""

import argparse
import asyncio
import json
import time

import websockets


async def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("url")
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--stall", action="store_true")
    args = ap.parse_args()
    async with websockets.connect(
        args.url, subprotocols=["foxglove.sdk.v1"], max_size=None, max_queue=1
    ) as ws:
        channels = []
        while not channels:
            msg = json.loads(await ws.recv())
            if msg.get("op") == "advertise":
                channels = msg["channels"]
        subs = [{"id": i, "channelId": c["id"]} for i, c in enumerate(channels)]
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        print(f"subscribed to {[c['topic'] for c in channels]}", flush=True)
        end = time.monotonic() + args.seconds
        if args.stall:
            await asyncio.sleep(args.seconds)
            return
        count = size = 0
        while (left := end - time.monotonic()) > 0:
            try:
                data = await asyncio.wait_for(ws.recv(), left)
            except asyncio.TimeoutError:
                break
            if isinstance(data, bytes) and data[:1] == b"\x01":
                count += 1
                size += len(data)
        print(f"received {count} messages, {size / 1e6:.1f} MB in {args.seconds:.0f} s")


asyncio.run(main())
