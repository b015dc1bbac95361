"""Reading what robots record, in-process (the compiled module sglc._engine, the readers `sglc ingest` uses):

    points, labels = sglc.read_scan("000123.bin", "000123.label")     # .bin, .npy, .pcd, .ply (labels optional)
    for scan in sglc.read_bag("drive.mcap", "/points", odom_topic="/odom"):
        scan.stamp, scan.pose, scan.points                              # pose: 4x4 sensor pose, or None

A bag is an MCAP file, a rosbag2 .db3 file or directory, or a ROS 1 .bag; its clouds (sensor_msgs/PointCloud2,
any field layout) become keyframes as `sglc ingest` makes them (client/README.md, "Bags"): poses from an
Odometry topic or from /tf, a keyframe every keyframe_m metres or keyframe_deg degrees, clouds with per-point
times de-skewed. Bad input raises ValueError naming the file, topic and message.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Iterator, List, Optional, Tuple, Union

from .engine import _IMPORT_ERROR, _engine


def _module():
    if _engine is None:
        raise ImportError(f"sglc.read_scan and sglc.read_bag need the compiled module sglc._engine: {_IMPORT_ERROR}")
    return _engine


def read_scan(path: Union[str, os.PathLike], labels: Union[str, os.PathLike, None] = None,
              label_field: str = "label") -> Tuple["numpy.ndarray", Optional["numpy.ndarray"]]:  # noqa: F821
    """A scan file of any format the CLI reads: (points (N, 3) float32, labels (N,) uint32 or None). Labels come
    from `labels` (a .label or .npy file) or, for PCD and PLY, from the field `label_field` when there is one."""
    return _module().read_scan(os.fspath(path), os.fspath(labels) if labels else "", label_field)


@dataclass
class BagScan:
    """One keyframe of a bag: its cloud's index on the topic, stamp (s), sensor pose (4x4, or None without
    poses), points (N, 3) float32 (NaN points dropped, de-skewed when the cloud had per-point times),
    intensities and per-point times (s after the stamp) when the cloud has them."""
    index: int
    stamp: float
    stamp_ns: int
    frame_id: str
    pose: Optional["numpy.ndarray"]  # noqa: F821
    points: "numpy.ndarray"  # noqa: F821
    intensities: Optional["numpy.ndarray"]  # noqa: F821
    times: Optional["numpy.ndarray"]  # noqa: F821
    deskewed: bool
    dropped: int


class Bag:
    """The keyframes of a bag's drive, by index or in order; each cloud is read when asked for."""

    def __init__(self, path: Union[str, os.PathLike], points_topic: str, odom_topic: str = "", tf: str = "",
                 keyframe_m: float = 1.0, keyframe_deg: float = 10.0, deskew: bool = True):
        self._bag = _module().Bag(os.fspath(path), points_topic, odom_topic, tf, keyframe_m, keyframe_deg, deskew)

    def __len__(self) -> int:
        return len(self._bag)

    def __getitem__(self, i: int) -> BagScan:
        if i < 0:
            i += len(self)
        if not 0 <= i < len(self):
            raise IndexError(f"keyframe {i} of {len(self)}")
        return BagScan(**self._bag[i])

    def __iter__(self) -> Iterator[BagScan]:
        return (self[i] for i in range(len(self)))

    @property
    def clouds(self) -> int:
        """Clouds on the topic, before keyframes were chosen."""
        return self._bag.clouds

    @property
    def warnings(self) -> List[str]:
        return list(self._bag.warnings)


def read_bag(path: Union[str, os.PathLike], points_topic: str, odom_topic: str = "", tf: str = "",
             keyframe_m: float = 1.0, keyframe_deg: float = 10.0, deskew: bool = True) -> Bag:
    """A bag's keyframes (see Bag): `for scan in sglc.read_bag(...)`, `len(...)`, `bag[i]`."""
    return Bag(path, points_topic, odom_topic, tf, keyframe_m, keyframe_deg, deskew)
