#!/usr/bin/env python3
"""An independent client of Foxglove's WebSocket protocol (foxglove.websocket.v1, spec:
https://github.com/foxglove/ws-protocol/blob/main/docs/spec.md) for llrp-gateway's live view.

Usage: foxglove_client.py ws://HOST:PORT READS TIMEOUT_S [NEED]

Built on `websockets` (17.4) and `mcap-ros2-support` (0.6.0, which decodes the CDR messages
from the `ros2msg` schemas the server advertises); none of llrp-gateway's code.

1. A handshake without the subprotocol: the HTTP status it is refused with.
2. A hostile client: garbage, an unsupported op, a subscription to a channel that does not
   exist, a binary message; the status messages it gets back. It then subscribes to every
   channel and never reads again (a stalled client), staying connected to the end.
3. A well-behaved client: serverInfo, the advertised channels; prints the line `READY` once
   it has subscribed to every channel advertised so far (and subscribes to later ones as
   they come), then decodes every message until it holds READS tag reads and at least one
   message of each kind NEED names (comma-separated among poses, tf, tags, events, scenes,
   estimate_scenes: scenes that draw at least one estimate;
   default the first four), or TIMEOUT_S pass.

Prints ONE JSON object after READY:
  {"refused_status": n, "hostile_status": [{"level", "message"}],
   "server_info": {...}, "channels": [{"id", "topic", "encoding", "schemaName",
   "schemaEncoding"}], "counts": {topic: n},
   "reads": [{"topic", "epc", "reader", "antenna", "rssi_dbm", "log_time", "frame_id"}],
   "poses": n, "tf": n, "tags": n, "events": n, "scenes": n, "estimate_scenes": n, "scene_ids": [the entity ids of
   the newest SceneUpdate], "bad_subscription_ids": n}
"""

import asyncio
import json
import struct
import sys

import websockets
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory

SUBPROTOCOL = "foxglove.websocket.v1"
READ = "llrp_gateway_msgs/msg/TagRead"
POSE = "foxglove_msgs/msg/PoseInFrame"
TF = "tf2_msgs/msg/TFMessage"
TAG = "llrp_gateway_msgs/msg/TagPosition"
EVENT = "llrp_gateway_msgs/msg/ReaderEvent"
SCENE = "foxglove_msgs/msg/SceneUpdate"


async def refused_status(url):
    try:
        async with websockets.connect(url, open_timeout=10):
            return 101
    except websockets.exceptions.InvalidStatus as e:
        return e.response.status_code


async def next_json(ws, timeout=10):
    """The next text message (binary ones skipped), parsed."""
    while True:
        m = await asyncio.wait_for(ws.recv(), timeout)
        if isinstance(m, str):
            return json.loads(m)


async def hostile(url):
    """Misbehaves, collects the status replies; returns them and the open socket."""
    ws = await websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None,
                                  close_timeout=1)
    info = await next_json(ws)
    assert info["op"] == "serverInfo", info
    adv = await next_json(ws)
    assert adv["op"] == "advertise", adv
    await ws.send("{this is not json")
    await ws.send(json.dumps({"op": "setParameters", "parameters": []}))
    await ws.send(json.dumps({"op": "subscribe",
                              "subscriptions": [{"id": 1, "channelId": 999999}]}))
    await ws.send(b"\x01\x00\x00\x00\x00garbage")
    statuses = []
    while len(statuses) < 4:
        m = await next_json(ws)
        if m["op"] == "status":
            statuses.append({"level": m["level"], "message": m["message"]})
    # Stalled from now on: subscribed to everything, reading nothing.
    subs = [{"id": i, "channelId": c["id"]} for i, c in enumerate(adv["channels"])]
    await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
    return statuses, ws


async def good(url, want_reads, timeout, need):
    out = {"counts": {}, "reads": [], "poses": 0, "tf": 0, "tags": 0, "events": 0,
           "scenes": 0, "estimate_scenes": 0, "scene_ids": [], "channels": [],
           "bad_subscription_ids": 0}
    factory = DecoderFactory()
    channels, decoders, by_sub = {}, {}, {}
    async with websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None) as ws:
        assert ws.subprotocol == SUBPROTOCOL, ws.subprotocol
        out["server_info"] = await next_json(ws)
        ready = False
        loop = asyncio.get_running_loop()
        until = loop.time() + timeout

        async def subscribe(new):
            for c in new:
                sid = len(by_sub) + 100
                by_sub[sid] = c["id"]
                schema = Schema(id=c["id"], name=c["schemaName"],
                                encoding=c["schemaEncoding"], data=c["schema"].encode())
                decoders[c["id"]] = factory.decoder_for(c["encoding"], schema)
            subs = [{"id": s, "channelId": ch} for s, ch in by_sub.items()
                    if ch in {c["id"] for c in new}]
            if subs:
                await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

        while loop.time() < until:
            if len(out["reads"]) >= want_reads and all(out[k] for k in need):
                break
            try:
                m = await asyncio.wait_for(ws.recv(), max(0.1, until - loop.time()))
            except asyncio.TimeoutError:
                break
            if isinstance(m, str):
                j = json.loads(m)
                if j["op"] == "advertise":
                    new = [c for c in j["channels"] if c["id"] not in channels]
                    for c in new:
                        channels[c["id"]] = c
                        out["channels"].append({k: c[k] for k in (
                            "id", "topic", "encoding", "schemaName", "schemaEncoding")})
                    await subscribe(new)
                    if not ready:
                        ready = True
                        print("READY", flush=True)
                continue
            opcode = m[0]
            if opcode != 1:
                continue
            sid, log_time = struct.unpack_from("<IQ", m, 1)
            if sid not in by_sub:
                out["bad_subscription_ids"] += 1
                continue
            c = channels[by_sub[sid]]
            topic = c["topic"]
            out["counts"][topic] = out["counts"].get(topic, 0) + 1
            msg = decoders[c["id"]](m[13:])
            if c["schemaName"] == READ:
                out["reads"].append({
                    "topic": topic, "epc": msg.epc, "reader": msg.reader,
                    "antenna": msg.antenna, "rssi_dbm": msg.rssi_dbm,
                    "log_time": log_time, "frame_id": msg.header.frame_id})
            elif c["schemaName"] == POSE:
                out["poses"] += 1
            elif c["schemaName"] == TF:
                out["tf"] += 1
            elif c["schemaName"] == TAG:
                out["tags"] += len(msg.epc) > 0
            elif c["schemaName"] == EVENT:
                out["events"] += 1
            elif c["schemaName"] == SCENE:
                out["scenes"] += 1
                out["scene_ids"] = sorted(e.id for e in msg.entities)
                if any(i.startswith("estimate/") for i in out["scene_ids"]):
                    out["estimate_scenes"] += 1
    return out


async def main():
    url, want_reads, timeout = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    need = (sys.argv[4] if len(sys.argv) > 4 else "poses,tf,tags,events").split(",")
    need = [k for k in need if k]
    status = await refused_status(url)
    statuses, stalled = await hostile(url)
    out = await good(url, want_reads, timeout, need)
    out["refused_status"] = status
    out["hostile_status"] = statuses
    await stalled.close()
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    asyncio.run(main())
