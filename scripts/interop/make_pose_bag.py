#!/usr/bin/env python3
"""Makes a ROS 2 bag (rosbag2 directory, MCAP storage) of a robot's poses, as a robot records
it, from a pose file of one antenna's poses (JSON Lines, `t_us, x, y, z, yaw_deg`, as
`sim --truth` and the localizer's pose files have them): the robot's pose is the antenna's
less the antenna's offset in the robot frame (`--offset x,y,z,yaw_deg`), stamped at
`t_us + --shift-us` (the robot's clock).

    make_pose_bag.py POSES.jsonl OUTDIR --kind amcl|pose|odom|tf [--offset X,Y,Z,YAW_DEG]
                     [--shift-us N]

--kind amcl: /amcl_pose, geometry_msgs/msg/PoseWithCovarianceStamped, frame map;
--kind pose: /robot_pose, geometry_msgs/msg/PoseStamped, frame map;
--kind odom: /odom, nav_msgs/msg/Odometry, frame odom, child base_link;
--kind tf:   /tf, tf2_msgs/msg/TFMessage: map -> odom (a fixed transform, yaw 30 degrees,
             sent once a second as amcl does) and odom -> base_link (every pose), so that
             map -> odom -> base_link is the robot's pose.

Types come from rosbags' ROS 2 Humble store, as rosbag2 records them. Run with the venv of
scripts/venv-mcap.sh (rosbags 0.11.9). tests/mcap_in.rs runs it.
"""

import argparse
import json
import math
from pathlib import Path

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

MAP_ODOM = (1.0, -2.0, math.radians(30.0))


def quat(yaw):
    return math.cos(yaw / 2), math.sin(yaw / 2)  # w, z


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("poses")
    ap.add_argument("out")
    ap.add_argument("--kind", default="amcl", choices=["amcl", "pose", "odom", "tf"])
    ap.add_argument("--offset", default="0,0,0,0")
    ap.add_argument("--shift-us", type=int, default=0)
    a = ap.parse_args()
    ox, oy, oz, oyaw = (float(v) for v in a.offset.split(","))
    oyaw = math.radians(oyaw)
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    P, Pt, Q = T["geometry_msgs/msg/Pose"], T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Quaternion"]

    def header(t_ns, frame):
        return Header(stamp=Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id=frame)

    def pose(x, y, z, yaw):
        w, qz = quat(yaw)
        return P(position=Pt(x=x, y=y, z=z), orientation=Q(x=0.0, y=0.0, z=qz, w=w))

    def transform(t_ns, parent, child, x, y, z, yaw):
        w, qz = quat(yaw)
        V3 = T["geometry_msgs/msg/Vector3"]
        tf = T["geometry_msgs/msg/Transform"](
            translation=V3(x=x, y=y, z=z), rotation=Q(x=0.0, y=0.0, z=qz, w=w)
        )
        return T["geometry_msgs/msg/TransformStamped"](
            header=header(t_ns, parent), child_frame_id=child, transform=tf
        )

    samples = [json.loads(l) for l in Path(a.poses).read_text().splitlines() if l.strip()]
    topic, msgtype = {
        "amcl": ("/amcl_pose", "geometry_msgs/msg/PoseWithCovarianceStamped"),
        "pose": ("/robot_pose", "geometry_msgs/msg/PoseStamped"),
        "odom": ("/odom", "nav_msgs/msg/Odometry"),
        "tf": ("/tf", "tf2_msgs/msg/TFMessage"),
    }[a.kind]
    with Writer(Path(a.out), version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection(topic, msgtype, typestore=ts)
        for i, s in enumerate(samples):
            yaw = math.radians(s["yaw_deg"]) - oyaw
            c, sn = math.cos(yaw), math.sin(yaw)
            x = s["x"] - (c * ox - sn * oy)
            y = s["y"] - (sn * ox + c * oy)
            z = s["z"] - oz
            t_ns = (s["t_us"] + a.shift_us) * 1000
            if a.kind == "amcl":
                cov = T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=pose(x, y, z, yaw), covariance=__import__("numpy").zeros(36)
                )
                msg = T[msgtype](header=header(t_ns, "map"), pose=cov)
            elif a.kind == "pose":
                msg = T[msgtype](header=header(t_ns, "map"), pose=pose(x, y, z, yaw))
            elif a.kind == "odom":
                np = __import__("numpy")
                cov = T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=pose(x, y, z, yaw), covariance=np.zeros(36)
                )
                V3 = T["geometry_msgs/msg/Vector3"]
                tw = T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](
                        linear=V3(x=0.1, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=0.0)
                    ),
                    covariance=np.zeros(36),
                )
                msg = T[msgtype](
                    header=header(t_ns, "odom"), child_frame_id="base_link", pose=cov, twist=tw
                )
            else:
                mx, my, myaw = MAP_ODOM
                dx, dy = x - mx, y - my
                cm, sm = math.cos(myaw), math.sin(myaw)
                ex, ey = cm * dx + sm * dy, -sm * dx + cm * dy
                tfs = [transform(t_ns, "odom", "base_link", ex, ey, z, yaw - myaw)]
                if i % 10 == 0 or i == len(samples) - 1:
                    tfs.insert(0, transform(t_ns, "map", "odom", mx, my, 0.0, myaw))
                msg = T[msgtype](transforms=tfs)
            w.write(conn, t_ns, ts.serialize_cdr(msg, msgtype))


if __name__ == "__main__":
    main()
