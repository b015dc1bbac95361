"""sglc_client: Python client of the SGLC LiDAR loop-closure service (gRPC, sglc.v1).

    import sglc_client
    with sglc_client.Client("127.0.0.1:50051", token="...") as c:
        c.ensure_map("campus")
        r = c.ingest("campus", "robot1", "run1", 42, points, labels, query=True, scope="other")
        for loop in r.loops:
            print(loop.scan_id, loop.robot, sglc_client.to_matrix(loop.t_query_candidate))

The generated stubs (sglc_pb2, sglc_pb2_grpc) come from the build tree: set SGLC_PYTHON_STUBS to
<build dir>/python or pass stubs_path=... (see sglc_client/_stubs.py for the lookup order).
"""
from ._stubs import ENV_VAR as STUBS_ENV_VAR, load_stubs
from .client import DEFAULT_CHUNK_BYTES, SCOPES, Client, IngestSession, SglcError
from .packing import (information_matrix, pack_labels, pack_points, pack_scan, read_kitti_scan,
                      rigid_motion_error, to_matrix, transform_values, unpack_labels, unpack_points, unpack_scan)

__all__ = [
    "Client", "IngestSession", "SglcError", "DEFAULT_CHUNK_BYTES", "SCOPES", "STUBS_ENV_VAR", "load_stubs",
    "pack_points", "pack_labels", "pack_scan", "unpack_points", "unpack_labels", "unpack_scan", "read_kitti_scan",
    "to_matrix", "transform_values", "rigid_motion_error", "information_matrix",
]
