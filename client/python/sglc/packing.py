"""Scans and transforms in the sglc.v1 wire format.

Scan.points: float32 little-endian x, y, z per point (12 bytes). Scan.labels: uint32 little-endian per point.
Scan.point_times: float32 little-endian per point (s after the stamp), for the server to de-skew the scan.
Transform.m: 16 doubles, row-major 4x4.

Points: any (N, 3+) numeric array (KITTI's (N, 4) x, y, z, reflectance included: columns past the third are
dropped), or packed bytes. Labels: any (N,) integer array with values in 0..2^32-1, or packed bytes.
Malformed input raises ValueError saying what is wrong.
"""
from __future__ import annotations

import math
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

POINT_BYTES = 12
LABEL_BYTES = 4

ArrayOrBytes = Union[np.ndarray, Sequence, bytes, bytearray, memoryview]


def _is_bytes(x) -> bool:
    """Packed bytes: bytes, bytearray, or a memoryview of bytes (a memoryview over an array of numbers is an
    array, not packed bytes)."""
    if isinstance(x, memoryview):
        return x.format in ("B", "b", "c")
    return isinstance(x, (bytes, bytearray))


def as_points(points) -> np.ndarray:
    """(N, 3+) array-like -> C-contiguous float32 (N, 3) array (columns past the third dropped)."""
    a = np.asarray(points)
    if a.ndim != 2 or a.shape[1] < 3:
        raise ValueError(f"points must have shape (N, 3) or (N, C >= 3), got {a.shape}")
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise ValueError(f"points must be numeric, got dtype {a.dtype}")
    with np.errstate(over="ignore", invalid="ignore"):  # values beyond float32 become inf: reported below
        out = np.ascontiguousarray(a[:, :3], dtype=np.float32)
    if out.size and not np.isfinite(out).all():
        bad = int(np.argwhere(~np.isfinite(out).all(axis=1))[0][0])
        raise ValueError(f"points: point {bad} has a non-finite coordinate (NaN, inf, or beyond float32's range)")
    return out


def as_labels(labels) -> np.ndarray:
    """(N,) integer array-like -> C-contiguous uint32 array (values checked to fit)."""
    a = np.asarray(labels)
    if a.ndim != 1:
        raise ValueError(f"labels must have shape (N,), got {a.shape}")
    if a.size == 0:
        return np.zeros(0, dtype=np.uint32)
    if not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"labels must be integers, got dtype {a.dtype}")
    if int(a.min()) < 0 or int(a.max()) > 0xFFFFFFFF:
        raise ValueError("labels must fit in uint32 (0 .. 4294967295)")
    return np.ascontiguousarray(a, dtype=np.uint32)


def pack_points(points: ArrayOrBytes) -> bytes:
    """Points (array or packed bytes) -> bytes (float32 LE x, y, z per point)."""
    if _is_bytes(points):
        data = bytes(points)
        if len(data) % POINT_BYTES:
            raise ValueError(f"points: {len(data)} bytes is not a multiple of 12 (float32 x, y, z per point)")
        return data
    return as_points(points).astype("<f4", copy=False).tobytes()


def pack_labels(labels: ArrayOrBytes) -> bytes:
    """Labels (array or packed bytes) -> bytes (uint32 LE per point)."""
    if _is_bytes(labels):
        data = bytes(labels)
        if len(data) % LABEL_BYTES:
            raise ValueError(f"labels: {len(data)} bytes is not a multiple of 4 (uint32 per point)")
        return data
    return as_labels(labels).astype("<u4", copy=False).tobytes()


def pack_scan(points: ArrayOrBytes, labels: Optional[ArrayOrBytes] = None) -> Tuple[bytes, bytes]:
    """(points_bytes, labels_bytes), checked to hold the same number of points. labels None: no labels (the
    server's labeller labels the scan)."""
    p = pack_points(points)
    if labels is None:
        return p, b""
    lab = pack_labels(labels)
    if len(p) // POINT_BYTES != len(lab) // LABEL_BYTES:
        raise ValueError(f"scan has {len(p) // POINT_BYTES} points but {len(lab) // LABEL_BYTES} labels")
    return p, lab


TIME_BYTES = 4  # float32 per point


def pack_point_times(times: ArrayOrBytes, count: int) -> bytes:
    """Per-point times (s after the stamp; (N,) array or packed float32 bytes) -> float32 little-endian bytes,
    checked to be one per point, finite and within 1 s of the stamp."""
    if _is_bytes(times):
        data = bytes(times)
        if len(data) % TIME_BYTES:
            raise ValueError(f"point_times: {len(data)} bytes is not a multiple of 4 (float32 per point)")
        t = np.frombuffer(data, dtype="<f4")
    else:
        t = np.asarray(times, dtype=np.float64).reshape(-1)
    if len(t) != count:
        raise ValueError(f"scan has {count} points but {len(t)} point times")
    if len(t) and not (np.all(np.isfinite(t)) and np.max(np.abs(t)) <= 1.0):
        bad = int(np.flatnonzero(~np.isfinite(t) | (np.abs(np.nan_to_num(t, nan=2.0)) > 1.0))[0])
        raise ValueError(f"point_times[{bad}] is {t[bad]} s, not within 1 s of the stamp")
    return t.astype("<f4").tobytes()


def twist_values(twist) -> Tuple[List[float], List[float]]:
    """(linear, angular) from a twist given as a pair of 3-vectors (m/s; rad/s, axis times rate, in the sensor's
    frame at the stamp) or a 6-vector (linear first)."""
    v = np.asarray(twist, dtype=np.float64).reshape(-1)
    if v.shape != (6,) or not np.all(np.isfinite(v)):
        raise ValueError("twist: expected 6 finite values (linear m/s, then angular rad/s)")
    return [float(x) for x in v[:3]], [float(x) for x in v[3:]]


def packed_size(scan) -> int:
    """Bytes of a sglc.v1.Scan's payload (points, labels and point times), as the chunking limit counts them."""
    return len(scan.points) + len(scan.labels) + len(scan.point_times)


def unpack_points(data: bytes) -> np.ndarray:
    """bytes -> float32 array of shape (N, 3)."""
    data = bytes(data)
    if len(data) % POINT_BYTES:
        raise ValueError(f"points: {len(data)} bytes is not a multiple of 12 (float32 x, y, z per point)")
    return np.frombuffer(data, dtype="<f4").astype(np.float32).reshape(-1, 3)


def unpack_labels(data: bytes) -> np.ndarray:
    """bytes -> uint32 array of shape (N,)."""
    data = bytes(data)
    if len(data) % LABEL_BYTES:
        raise ValueError(f"labels: {len(data)} bytes is not a multiple of 4 (uint32 per point)")
    return np.frombuffer(data, dtype="<u4").astype(np.uint32)


def read_kitti_scan(bin_path: str, label_path: Optional[str] = None) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """A KITTI .bin (x, y, z, reflectance float32) and, optionally, a SemanticKITTI .label (uint32 per point).

    Returns (points (N, 3) float32, labels (N,) uint32 or None)."""
    raw = np.fromfile(bin_path, dtype="<f4")
    if raw.size % 4:
        raise ValueError(f"{bin_path}: size {raw.size * 4} is not a multiple of 16 (x, y, z, reflectance float32)")
    points = np.ascontiguousarray(raw.reshape(-1, 4)[:, :3], dtype=np.float32)
    if label_path is None:
        return points, None
    labels = np.fromfile(label_path, dtype="<u4")
    if labels.size * 4 != _size(label_path):
        raise ValueError(f"{label_path}: size is not a multiple of 4 (uint32 per point)")
    if labels.size != len(points):
        raise ValueError(f"{label_path}: {labels.size} labels for {len(points)} points in {bin_path}")
    return points, labels.astype(np.uint32)


def _size(path: str) -> int:
    with open(path, "rb") as f:
        return f.seek(0, 2)


RIGID_TOLERANCE = 1e-3  # the server's tolerance on |R'R - I| and |det R - 1|


def rigid_motion_error(values: Sequence[float]) -> Optional[str]:
    """Why 16 row-major values are not a rigid motion (the server's checks), or None when they are one."""
    if not all(math.isfinite(v) for v in values):
        return "has a non-finite value (NaN or inf)"
    m = np.array(values, dtype=np.float64).reshape(4, 4)
    if np.abs(m[3] - (0.0, 0.0, 0.0, 1.0)).max() > 1e-9:
        return "last row is not 0 0 0 1"
    ortho = float(np.abs(m[:3, :3].T @ m[:3, :3] - np.eye(3)).max())
    if not ortho <= RIGID_TOLERANCE:
        return f"rotation block is not orthonormal (max |R'R - I| = {ortho:.3g}): not a rigid motion"
    det = float(np.linalg.det(m[:3, :3]))
    if not abs(det - 1.0) <= RIGID_TOLERANCE:
        return f"rotation block has determinant {det:.3g}, not +1: a reflection, not a rigid motion"
    return None


def transform_values(matrix) -> list:
    """4x4 array-like (a row-major rigid motion) -> 16 floats; ValueError when it is not a rigid motion."""
    a = np.asarray(matrix, dtype=np.float64)
    if a.shape != (4, 4):
        raise ValueError(f"a transform must be a 4x4 matrix, got shape {a.shape}")
    values = [float(v) for v in a.ravel()]
    error = rigid_motion_error(values)
    if error:
        raise ValueError("transform is not a rigid motion: " + error)
    return values
