"""Scan and transform conversions for the sglc.v1 wire format.

Scan.points: float32 little-endian x, y, z per point (12 bytes). Scan.labels: uint32 little-endian per point.
Transform.m: 16 doubles, row-major 4x4.

Packing accepts numpy arrays (points of shape (N, 3), labels of shape (N,), any numeric dtype that converts
exactly) or already packed bytes. Unpacking and matrices need numpy; reading KITTI files does not.
Malformed input raises ValueError.
"""
import array
import math
import sys

POINT_BYTES = 12
LABEL_BYTES = 4


def _is_bytes(x):
    return isinstance(x, (bytes, bytearray, memoryview))


def _np():
    try:
        import numpy
    except ImportError as e:  # pragma: no cover - numpy is a Debian dependency of the tests
        raise ImportError("numpy is needed for arrays; pass packed bytes instead") from e
    return numpy


def pack_points(points):
    """(N, 3) array-like of coordinates, or packed bytes -> bytes (float32 LE x, y, z per point)."""
    if _is_bytes(points):
        data = bytes(points)
        if len(data) % POINT_BYTES:
            raise ValueError(f"points: {len(data)} bytes is not a multiple of 12 (float32 x, y, z per point)")
        return data
    np = _np()
    a = np.asarray(points)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {a.shape}")
    if not np.issubdtype(a.dtype, np.number):
        raise ValueError(f"points must be numeric, got dtype {a.dtype}")
    return np.ascontiguousarray(a, dtype="<f4").tobytes()


def pack_labels(labels):
    """(N,) array-like of uint32 labels, or packed bytes -> bytes (uint32 LE per point)."""
    if _is_bytes(labels):
        data = bytes(labels)
        if len(data) % LABEL_BYTES:
            raise ValueError(f"labels: {len(data)} bytes is not a multiple of 4 (uint32 per point)")
        return data
    np = _np()
    a = np.asarray(labels)
    if a.ndim != 1:
        raise ValueError(f"labels must have shape (N,), got {a.shape}")
    if a.size and not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"labels must be integers, got dtype {a.dtype}")
    if a.size and (a.min() < 0 or a.max() > 0xFFFFFFFF):
        raise ValueError("labels must fit in uint32")
    return np.ascontiguousarray(a, dtype="<u4").tobytes()


def pack_scan(points, labels=None):
    """Returns (points_bytes, labels_bytes), checked to hold the same number of points. labels None: no labels
    (the server's labeller labels the scan)."""
    p = pack_points(points)
    if labels is None:
        return p, b""
    l = pack_labels(labels)
    if len(p) // POINT_BYTES != len(l) // LABEL_BYTES:
        raise ValueError(f"scan has {len(p) // POINT_BYTES} points but {len(l) // LABEL_BYTES} labels")
    return p, l


def unpack_points(data):
    """bytes -> numpy float32 array of shape (N, 3)."""
    data = bytes(data)
    if len(data) % POINT_BYTES:
        raise ValueError(f"points: {len(data)} bytes is not a multiple of 12 (float32 x, y, z per point)")
    np = _np()
    return np.frombuffer(data, dtype="<f4").astype(np.float32).reshape(-1, 3)


def unpack_labels(data):
    """bytes -> numpy uint32 array of shape (N,)."""
    data = bytes(data)
    if len(data) % LABEL_BYTES:
        raise ValueError(f"labels: {len(data)} bytes is not a multiple of 4 (uint32 per point)")
    np = _np()
    return np.frombuffer(data, dtype="<u4").astype(np.uint32)


def unpack_scan(points_bytes, labels_bytes):
    """(points_bytes, labels_bytes) -> (points (N, 3) float32, labels (N,) uint32), counts checked."""
    p, l = unpack_points(points_bytes), unpack_labels(labels_bytes)
    if len(p) != len(l):
        raise ValueError(f"scan has {len(p)} points but {len(l)} labels")
    return p, l


def read_kitti_scan(bin_path, label_path):
    """Reads a KITTI .bin (x, y, z, reflectance float32) and a SemanticKITTI .label (uint32).

    Returns packed (points_bytes, labels_bytes) without needing numpy (reflectance is dropped).
    """
    with open(bin_path, "rb") as f:
        raw = f.read()
    with open(label_path, "rb") as f:
        labels = f.read()
    if len(raw) % 16:
        raise ValueError(f"{bin_path}: size {len(raw)} is not a multiple of 16 (x, y, z, reflectance float32)")
    if len(labels) % 4:
        raise ValueError(f"{label_path}: size {len(labels)} is not a multiple of 4 (uint32 per point)")
    if len(raw) // 16 != len(labels) // 4:
        raise ValueError(f"{label_path}: {len(labels) // 4} labels for {len(raw) // 16} points in {bin_path}")
    values = array.array("f")
    values.frombytes(raw)
    del values[3::4]  # drop reflectance
    if sys.byteorder == "big":  # the files and the wire are little-endian
        values.byteswap()
    return values.tobytes(), labels


RIGID_TOLERANCE = 1e-3  # the server's tolerance on |R'R - I| and |det R - 1|


def rigid_motion_error(values):
    """Why 16 row-major values are not a rigid motion (the server's checks), or None when they are one."""
    m = [values[4 * r:4 * r + 4] for r in range(4)]
    if not all(math.isfinite(v) for v in values):
        return "has a non-finite value (NaN or inf)"
    if any(abs(a - b) > 1e-9 for a, b in zip(m[3], (0.0, 0.0, 0.0, 1.0))):
        return "last row is not 0 0 0 1"
    ortho = max(abs(sum(m[k][i] * m[k][j] for k in range(3)) - (1.0 if i == j else 0.0))
                for i in range(3) for j in range(3))
    if not ortho <= RIGID_TOLERANCE:
        return f"rotation block is not orthonormal (max |R'R - I| = {ortho:.3g}): not a rigid motion"
    det = (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
    if not abs(det - 1.0) <= RIGID_TOLERANCE:
        return f"rotation block has determinant {det:.3g}, not +1: a reflection, not a rigid motion"
    return None


def transform_values(matrix):
    """4x4 array-like (row-major rigid motion) -> list of 16 floats; ValueError when it is not a rigid motion."""
    rows = [list(map(float, r)) for r in matrix]
    if len(rows) != 4 or any(len(r) != 4 for r in rows):
        raise ValueError("a transform must be a 4x4 matrix")
    values = [v for r in rows for v in r]
    error = rigid_motion_error(values)
    if error:
        raise ValueError("transform is not a rigid motion: " + error)
    return values


def to_matrix(transform):
    """A Transform message (or any sequence of 16 values) -> numpy 4x4 float64 array."""
    values = list(transform.m) if hasattr(transform, "m") else list(transform)
    if len(values) != 16:
        raise ValueError(f"transform has {len(values)} values, expected 16 (row-major 4x4)")
    np = _np()
    return np.array(values, dtype=np.float64).reshape(4, 4)


def information_matrix(candidate):
    """A Candidate's loop-pose information -> numpy 6x6 float64 array (translation then rotation, for a right
    perturbation in the candidate's frame), or None when the candidate was not refined."""
    values = list(candidate.information) if hasattr(candidate, "information") else list(candidate)
    if not values:
        return None
    if len(values) != 36:
        raise ValueError(f"information has {len(values)} values, expected 36 (row-major 6x6)")
    np = _np()
    return np.array(values, dtype=np.float64).reshape(6, 6)
