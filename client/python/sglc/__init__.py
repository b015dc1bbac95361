"""sglc: Python package of the SGLC LiDAR loop-closure service.

    import sglc
    with sglc.Client("127.0.0.1:50051", token="...") as c:
        c.create_map("campus")
        r = c.ingest("campus", "robot1", "run1", 42, points, labels, query=True, scope="other")
        for loop in r.loops:
            print(loop.scan_id, loop.robot, loop.T)

    engine = sglc.Engine()                      # the engine in-process, no server
    m = engine.match(engine.fingerprint(pa, la), engine.fingerprint(pb, lb))
    print(m.is_loop, m.score, m.T)
"""
from ._stubs import pb2
from .client import DEFAULT_CHUNK_BYTES, SCOPES, Client
from .engine import Engine, deskew, twist_between
from .errors import (AbortedError, AlreadyExistsError, CancelledError, DataLossError, DeadlineExceededError,
                     FailedPreconditionError, InternalError, InvalidArgumentError, NotFoundError, OutOfRangeError,
                     PermissionDeniedError, ResourceExhaustedError, SglcError, UnauthenticatedError,
                     UnavailableError, UnimplementedError, UnknownError, error_class)
from .packing import pack_scan, read_kitti_scan, unpack_labels, unpack_points
from .pose_graph import MapWatch
from .readers import Bag, BagScan, read_bag, read_scan
from .results import (Backup, Evidence, GraphNode, IngestResult, Loop, LoopEdge, LoopEnd, MapEvent, MapInfo,
                      MatchResult, QueryResult, RobotInfo, ScanInfo, ScanPose, ServerInfo, SessionFrame, SessionInfo, Stats, Compaction,
                      Timing, information, matrix)
from .stream import IngestSession, ScanInput
from .version import __version__

__all__ = [
    "Client", "Engine", "IngestSession", "ScanInput", "MapWatch", "DEFAULT_CHUNK_BYTES", "SCOPES", "pb2",
    "SglcError", "error_class", "CancelledError", "UnknownError", "InvalidArgumentError", "DeadlineExceededError",
    "NotFoundError", "AlreadyExistsError", "PermissionDeniedError", "ResourceExhaustedError",
    "FailedPreconditionError", "AbortedError", "OutOfRangeError", "UnimplementedError", "InternalError",
    "UnavailableError", "DataLossError", "UnauthenticatedError",
    "Backup", "Evidence", "GraphNode", "IngestResult", "Loop", "LoopEdge", "LoopEnd", "MapEvent", "MapInfo",
    "MatchResult", "QueryResult", "RobotInfo", "ScanInfo", "ScanPose", "ServerInfo", "SessionFrame", "SessionInfo", "Stats", "Compaction",
    "Timing", "information", "matrix", "pack_scan", "read_kitti_scan", "unpack_points", "unpack_labels",
    "Bag", "BagScan", "read_bag", "read_scan", "deskew", "twist_between",
    "__version__",
]
