#!/usr/bin/env python3
"""Reads an MCAP file of llrp-gateway with two independent readers and prints what it holds.

Usage: mcap_check.py FILE.mcap

1. Foxglove's `mcap` 1.6.0 with `mcap-ros2-support` 0.6.0: the header, every schema and
   channel (topic, schema name and encoding, message encoding, offered QoS), the summary's
   message count per channel, and every message decoded from the schemas in the file.
2. `rosbags` 0.11.9 (rosbags.highlevel.AnyReader over an EMPTY typestore, so every type comes
   from the definitions the file carries): the connections and every message deserialized
   from CDR.

Prints ONE JSON object:

  {"header": {"profile", "library"},
   "channels": [{"topic", "schema", "schema_encoding", "message_encoding", "count",
                 "qos"}],
   "mcap_ros2": DECODED, "rosbags": DECODED}

where DECODED is {"reads": [...], "frames": {topic: hex of the data concatenated},
"frame_count": {topic: n}, "events": [...], "logs": [...], "count": n, "poses": [...],
"tf": [...], "tags": [...]} (poses: PoseInFrame with topic, frame_id, stamp_ns and x, y, z,
qx, qy, qz, qw; tf: every transform of every TFMessage, parent, child, stamp_ns and the same
fields; phases: TagPhase's fields (topic, reader, epc, antenna, channel_index,
channel_frequency_hz, phase_rad, phase_unwrapped_rad, rssi_dbm, frame_id, t_us), in file
order; tags: TagPosition's epc, frame_id, stamp_ns, x, y, z; estimates: TagEstimate's
fields, position [x, y, z] and covariance with null for NaN; scenes: each SceneUpdate's
log_time, deleted ids and entities: id, frame_id, stamp_ns, metadata, arrows (position,
orientation, shaft_length), cubes, spheres and cylinders (position, orientation, size, color),
lines (type, points), texts). A read is the reads
file's fields (epc, reader, antenna, t_us from the header stamp, last_seen_us, phase_rad,
rssi_dbm, channel_index, channel_frequency_hz, doppler_hz; null for the message set's NaN
and 0 "none" values; the float64 fields as their IEEE 754 bits, an integer, so that no
decimal conversion stands between the file and the comparison) plus frame_id, topic, log_time and publish_time (ns; rosbags gives only
the log time). Exits 1 with a message on standard error when a reader fails.
"""

import json
import math
import struct
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

READ = "llrp_gateway_msgs/msg/TagRead"
PHASE = "llrp_gateway_msgs/msg/TagPhase"
FRAME = "llrp_gateway_msgs/msg/LlrpFrame"
EVENT = "llrp_gateway_msgs/msg/ReaderEvent"
LOG = "foxglove_msgs/msg/Log"
POSE = "foxglove_msgs/msg/PoseInFrame"
TF = "tf2_msgs/msg/TFMessage"
TAG = "llrp_gateway_msgs/msg/TagPosition"
ESTIMATE = "llrp_gateway_msgs/msg/TagEstimate"
SCENE = "foxglove_msgs/msg/SceneUpdate"


def pose_of(p):
    return {"x": p.position.x, "y": p.position.y, "z": p.position.z,
            "qx": p.orientation.x, "qy": p.orientation.y, "qz": p.orientation.z,
            "qw": p.orientation.w}


def ns(t):
    return t.sec * 1_000_000_000 + t.nanosec


def none_if(v, empty):
    return None if v == empty else v


def bits(v):
    """A float64 as its IEEE 754 bits (an integer, which JSON carries exactly); None for NaN."""
    if math.isnan(v):
        return None
    return struct.unpack("<Q", struct.pack("<d", v))[0]


def num(v):
    """A float, None for NaN (JSON has no NaN)."""
    return None if math.isnan(v) else v


def point(p):
    return [num(p.x), num(p.y), num(p.z)]


def quat(q):
    return [q.x, q.y, q.z, q.w]


def solid(s):
    return {"position": point(s.pose.position), "orientation": quat(s.pose.orientation),
            "size": point(s.size), "color": [s.color.r, s.color.g, s.color.b, s.color.a]}


def estimate_of(m, log_time):
    return {"epc": m.epc, "estimator": m.estimator, "state": m.state,
            "frame_id": m.header.frame_id, "stamp_ns": ns(m.header.stamp),
            "log_time": log_time, "position": point(m.position),
            "covariance": [num(v) for v in m.covariance], "samples": m.samples,
            "reads": m.reads, "pose_sigma_m": num(m.pose_sigma_m), "reason": m.reason}


def entity_of(e):
    return {"id": e.id, "frame_id": e.frame_id, "stamp_ns": ns(e.timestamp),
            "metadata": {kv.key: kv.value for kv in e.metadata},
            "arrows": [{"position": point(a.pose.position),
                        "orientation": quat(a.pose.orientation),
                        "shaft_length": a.shaft_length} for a in e.arrows],
            "cubes": [solid(c) for c in e.cubes],
            "spheres": [solid(c) for c in e.spheres],
            "cylinders": [solid(c) for c in e.cylinders],
            "lines": [{"type": ln.type, "points": [point(p) for p in ln.points]}
                      for ln in e.lines],
            "texts": [t.text for t in e.texts]}


def read_of(m, topic, log_time, publish_time):
    last = ns(m.last_seen)
    return {
        "epc": m.epc,
        "reader": m.reader,
        "antenna": m.antenna,
        "t_us": ns(m.header.stamp) // 1000,
        "last_seen_us": None if last == 0 else last // 1000,
        "phase_rad": bits(m.phase_rad),
        "rssi_dbm": bits(m.rssi_dbm),
        "channel_index": none_if(m.channel_index, 0),
        "channel_frequency_hz": none_if(m.channel_frequency_hz, 0),
        "doppler_hz": bits(m.doppler_hz),
        "frame_id": m.header.frame_id,
        "topic": topic,
        "log_time": log_time,
        "publish_time": publish_time,
    }


class Decoded:
    def __init__(self):
        self.reads, self.frames, self.frame_count = [], {}, {}
        self.events, self.logs, self.count = [], [], 0
        self.poses, self.tf, self.tags = [], [], []
        self.estimates, self.scenes = [], []
        self.phases = []

    def add(self, schema, topic, m, log_time, publish_time):
        self.count += 1
        if schema == READ:
            self.reads.append(read_of(m, topic, log_time, publish_time))
        elif schema == PHASE:
            self.phases.append({
                "topic": topic, "reader": m.reader, "epc": m.epc, "antenna": m.antenna,
                "channel_index": m.channel_index,
                "channel_frequency_hz": m.channel_frequency_hz,
                "phase_rad": m.phase_rad, "phase_unwrapped_rad": m.phase_unwrapped_rad,
                "rssi_dbm": num(m.rssi_dbm), "frame_id": m.header.frame_id,
                "t_us": ns(m.header.stamp) // 1000,
            })
        elif schema == FRAME:
            self.frames[topic] = self.frames.get(topic, "") + bytes(m.data).hex()
            self.frame_count[topic] = self.frame_count.get(topic, 0) + 1
        elif schema == EVENT:
            self.events.append({
                "topic": topic, "reader": m.reader, "connection": m.connection,
                "kind": m.kind, "detail": m.detail, "stamp_ns": ns(m.header.stamp),
                "frame_id": m.header.frame_id, "log_time": log_time,
                "publish_time": publish_time,
            })
        elif schema == POSE:
            self.poses.append({"topic": topic, "frame_id": m.frame_id,
                               "stamp_ns": ns(m.timestamp), "log_time": log_time,
                               **pose_of(m.pose)})
        elif schema == TF:
            for t in m.transforms:
                r, v = t.transform.rotation, t.transform.translation
                self.tf.append({"parent": t.header.frame_id, "child": t.child_frame_id,
                                "stamp_ns": ns(t.header.stamp), "x": v.x, "y": v.y,
                                "z": v.z, "qx": r.x, "qy": r.y, "qz": r.z, "qw": r.w})
        elif schema == TAG:
            self.tags.append({"epc": m.epc, "frame_id": m.header.frame_id,
                              "stamp_ns": ns(m.header.stamp), "x": m.position.x,
                              "y": m.position.y, "z": m.position.z})
        elif schema == ESTIMATE:
            self.estimates.append(estimate_of(m, log_time))
        elif schema == SCENE:
            self.scenes.append({"log_time": log_time,
                                "deletions": [d.id for d in m.deletions],
                                "entities": [entity_of(e) for e in m.entities]})
        elif schema == LOG:
            self.logs.append({"name": m.name, "level": m.level, "message": m.message,
                              "stamp_ns": ns(m.timestamp), "log_time": log_time})

    def json(self):
        return {"reads": self.reads, "frames": self.frames, "frame_count": self.frame_count,
                "events": self.events, "logs": self.logs, "count": self.count,
                "poses": self.poses, "tf": self.tf, "tags": self.tags,
                "estimates": self.estimates, "scenes": self.scenes, "phases": self.phases}


def with_mcap(path):
    out = Decoded()
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        summary = reader.get_summary()
        counts = summary.statistics.channel_message_counts
        channels = []
        for c in sorted(summary.channels.values(), key=lambda c: c.id):
            s = summary.schemas[c.schema_id]
            channels.append({
                "topic": c.topic, "schema": s.name, "schema_encoding": s.encoding,
                "message_encoding": c.message_encoding, "count": counts.get(c.id, 0),
                "qos": c.metadata.get("offered_qos_profiles", ""),
            })
        for schema, channel, message, decoded in reader.iter_decoded_messages(
                log_time_order=False):
            out.add(schema.name, channel.topic, decoded, message.log_time,
                    message.publish_time)
    return {"profile": header.profile, "library": header.library}, channels, out


def with_rosbags(path):
    from pathlib import Path
    out = Decoded()
    with AnyReader([Path(path)], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        for conn, timestamp, raw in reader.messages():
            m = reader.deserialize(raw, conn.msgtype)
            out.add(conn.msgtype, conn.topic, m, timestamp, None)
    return out


def main():
    path = sys.argv[1]
    try:
        header, channels, mine = with_mcap(path)
        theirs = with_rosbags(path)
    except Exception as e:  # noqa: BLE001 - any failure of a reader is the answer
        print(f"mcap_check.py: {type(e).__name__}: {e}", file=sys.stderr)
        sys.exit(1)
    print(json.dumps({"header": header, "channels": channels, "mcap_ros2": mine.json(),
                      "rosbags": theirs.json()}))


if __name__ == "__main__":
    main()
