#!/usr/bin/python3
"""Writes a ROS 1 bag with Debian's python3-rosbag (and its sensor_msgs, nav_msgs, tf2_msgs), from the JSON
description write_bag.mjs takes (tests/io/bag_writer.hpp): {"compression": "none" | "bz2" | "lz4", "messages":
[...]}. The bag tests' ROS 1 bags come from here, never from this project's own code.

    /usr/bin/python3 write_ros1_bag.py SPEC.json OUT.bag
"""
import json
import math
import struct
import sys

import genpy
import rosbag
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import PointCloud2, PointField
from tf2_msgs.msg import TFMessage

FORMATS = {1: "b", 2: "B", 3: "h", 4: "H", 5: "i", 6: "I", 7: "f", 8: "d"}


def stamp(ns):
    ns = int(ns)
    return genpy.Time(ns // 1000000000, ns % 1000000000)


def cloud(m):
    msg = PointCloud2()
    msg.header.stamp = stamp(m["stamp_ns"])
    msg.header.frame_id = m["frame_id"]
    msg.height, msg.width = m["height"], m["width"]
    msg.fields = [PointField(name=f["name"], offset=f["offset"], datatype=f["datatype"], count=f["count"])
                  for f in m["fields"]]
    msg.is_bigendian = m["is_bigendian"]
    msg.point_step = m["point_step"]
    msg.row_step = m["width"] * m["point_step"]
    order = ">" if m["is_bigendian"] else "<"
    data = bytearray(m["width"] * m["height"] * m["point_step"])
    for i, p in enumerate(m["points"]):
        for f, v in zip(m["fields"], p):
            struct.pack_into(order + FORMATS[f["datatype"]], data, i * m["point_step"] + f["offset"],
                             math.nan if v is None else v)
    msg.data = bytes(data)
    msg.is_dense = False
    return msg


def odometry(m):
    msg = Odometry()
    msg.header.stamp = stamp(m["stamp_ns"])
    msg.header.frame_id = m["frame_id"]
    msg.child_frame_id = m["child_frame_id"]
    p, q = m["position"], m["orientation"]
    msg.pose.pose.position.x, msg.pose.pose.position.y, msg.pose.pose.position.z = p
    o = msg.pose.pose.orientation
    o.x, o.y, o.z, o.w = q
    return msg


def tf(m):
    msg = TFMessage()
    for t in m["transforms"]:
        ts = TransformStamped()
        ts.header.stamp = stamp(t["stamp_ns"])
        ts.header.frame_id = t["frame_id"]
        ts.child_frame_id = t["child_frame_id"]
        tr, q = ts.transform.translation, ts.transform.rotation
        tr.x, tr.y, tr.z = t["position"]
        q.x, q.y, q.z, q.w = t["orientation"]
        msg.transforms.append(ts)
    return msg


def main():
    spec = json.load(open(sys.argv[1]))
    make = {"pointcloud2": cloud, "odometry": odometry, "tf": tf}
    with rosbag.Bag(sys.argv[2], "w", compression=spec.get("compression") or "none") as bag:
        for m in spec["messages"]:
            bag.write(m["topic"], make[m["type"]](m), t=stamp(m["log_time_ns"]))


if __name__ == "__main__":
    main()
