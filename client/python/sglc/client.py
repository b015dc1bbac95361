"""sglc.Client: the SGLC loop-closure service over gRPC (sglc.v1: LoopClosure, MapAdmin, PoseGraph)."""
from __future__ import annotations

import json
import os
from typing import Iterable, Iterator, Optional, Sequence, Union

import grpc

from . import packing
from ._args import integer
from ._stubs import pb2, pb2_grpc
from .admin import AdminCalls
from .errors import SglcError
from .pose_graph import PoseGraphCalls
from .results import IngestResult, QueryResult
from .stream import IngestSession, ScanInput

DEFAULT_CHUNK_BYTES = 3_000_000
SCOPES = {"all": pb2.SCOPE_WHOLE_MAP, "same": pb2.SCOPE_SAME_ROBOT, "other": pb2.SCOPE_OTHER_ROBOTS,
          "sessions": pb2.SCOPE_SESSIONS}
_HEALTH_CHECK = "/grpc.health.v1.Health/Check"


def _scan(points, labels=None, point_times=None, twist=None):
    """A sglc.v1.Scan: points, labels, and the per-point times and twist for de-skew."""
    p, lab = packing.pack_scan(points, labels)
    scan = pb2.Scan(points=p, labels=lab)
    if point_times is not None:
        scan.point_times = packing.pack_point_times(point_times, len(p) // packing.POINT_BYTES)
    if twist is not None:
        if point_times is None:
            raise ValueError("a twist needs point_times: it moves each point by its time")
        linear, angular = packing.twist_values(twist)
        scan.twist.linear.extend(linear)
        scan.twist.angular.extend(angular)
    return scan


def _retry_service_config(max_attempts: int) -> str:
    """gRPC's retry policy for every service of ours (and health checks): UNAVAILABLE only."""
    # Not the deletes or Backup: a delete whose answer was lost would be repeated, a backup would dump again.
    names = [{"service": s} for s in ("sglc.v1.LoopClosure", "sglc.v1.PoseGraph", "grpc.health.v1.Health")]
    names += [{"service": "sglc.v1.MapAdmin", "method": m} for m in (
        "GetServerInfo", "CreateMap", "ListMaps", "ListRobots", "ListSessions", "GetScan", "GetStats")]
    return json.dumps({"methodConfig": [{
        "name": names,
        "retryPolicy": {"maxAttempts": max_attempts, "initialBackoff": "0.2s", "maxBackoff": "5s",
                        "backoffMultiplier": 2, "retryableStatusCodes": ["UNAVAILABLE"]}}]})


class Client(AdminCalls, PoseGraphCalls):
    """Connects to an SGLC server.

    address: "host:port" (default: $SGLC_SERVER, else 127.0.0.1:50051, as for the sglc command).
    token: bearer token, sent as ``authorization: Bearer <token>``.
    tls_root_certs: PEM bytes, or a path to a PEM file, to use TLS; None for plain TCP.
    timeout: default deadline of each call in seconds (None: none). chunk_bytes: scans whose packed size
    exceeds this are sent with IngestChunked. max_attempts (1..5): a call that fails with UNAVAILABLE (the
    server restarting, or a replica behind a balancer going away) is retried by gRPC after 0.2 s, doubling up to
    5 s, until this many attempts; safe for every call, as each reads or is idempotent (a stream only before its
    first answer).

    Every call raises an SglcError subclass on failure (NotFoundError, AlreadyExistsError, ...; see
    sglc.errors) and ValueError on input it rejects before sending. Use it as a context manager to close
    the channel.
    """

    def __init__(self, address: Optional[str] = None, token: Optional[str] = None,
                 tls_root_certs: Union[bytes, str, None] = None, timeout: Optional[float] = 30.0,
                 chunk_bytes: int = DEFAULT_CHUNK_BYTES, max_attempts: int = 5):
        if chunk_bytes < packing.POINT_BYTES + packing.LABEL_BYTES:
            raise ValueError("chunk_bytes must hold at least one point (16 bytes)")
        if not 1 <= max_attempts <= 5:
            raise ValueError("max_attempts must be 1..5")
        if address is None:
            address = os.environ.get("SGLC_SERVER") or "127.0.0.1:50051"
        self.address = address
        self.timeout = timeout
        self.chunk_bytes = chunk_bytes
        self._metadata = (("authorization", f"Bearer {token}"),) if token else None
        options = [("grpc.max_receive_message_length", -1), ("grpc.max_send_message_length", -1)]
        if max_attempts > 1:
            options += [("grpc.service_config", _retry_service_config(max_attempts)),
                        ("grpc.per_rpc_retry_buffer_size", min(chunk_bytes + (1 << 20), 1 << 30))]
        if tls_root_certs is not None:
            if isinstance(tls_root_certs, str):
                with open(tls_root_certs, "rb") as f:
                    tls_root_certs = f.read()
            creds = grpc.ssl_channel_credentials(root_certificates=tls_root_certs)
            self._channel = grpc.secure_channel(address, creds, options=options)
        else:
            self._channel = grpc.insecure_channel(address, options=options)
        self._loop = pb2_grpc.LoopClosureStub(self._channel)
        self._admin = pb2_grpc.MapAdminStub(self._channel)
        self._graph = pb2_grpc.PoseGraphStub(self._channel)

    def close(self) -> None:
        self._channel.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _call(self, stub_method, name: str, request, timeout: Optional[float]):
        try:
            return stub_method(request, timeout=self.timeout if timeout is None else timeout, metadata=self._metadata)
        except grpc.RpcError as e:
            raise SglcError.from_rpc(name, e) from None

    def serving(self, timeout: float = 5.0) -> bool:
        """grpc.health.v1 Check of the whole server: True when it answers SERVING (needs no token)."""
        check = self._channel.unary_unary(_HEALTH_CHECK, request_serializer=lambda _: b"",
                                          response_deserializer=lambda data: data)
        try:
            reply = check(None, timeout=timeout)
        except grpc.RpcError:
            return False
        return reply == b"\x08\x01"  # HealthCheckResponse{status: SERVING}

    # ------------------------------------------------------------------------------------------------
    # Requests

    def query_options(self, scope: str = "all", top_k: int = 0, exclude_recent: Optional[int] = None,
                      exclude_seconds: float = 0.0, sessions: Sequence[str] = (), candidates: int = 0,
                      refine: Optional[bool] = None, include_rejected: bool = False, min_score: Optional[float] = None,
                      verify_scan_ids: Sequence[int] = (), known_loops: bool = False,
                      include_evidence: bool = False):
        """A QueryOptions message. scope: "all", "same", "other" or "sessions" (with sessions=["robot/session"]).
        exclude_recent None keeps the server's default (50 scans of the same session), as every client does.
        verify_scan_ids: check exactly these stored scans instead of searching; known_loops: they are known to
        be loops, so a pose is estimated for rejected ones too (see QueryOptions in sglc.proto). include_evidence:
        each answer's Loop.evidence holds what the loop model measured (rejected candidates' too)."""
        if scope not in SCOPES:
            raise ValueError(f"unknown scope {scope!r} (expected all, same, other or sessions)")
        o = pb2.QueryOptions(scope=SCOPES[scope], exclude_seconds=float(exclude_seconds), top_k=integer("top_k", top_k),
                             candidates=integer("candidates", candidates), include_rejected=bool(include_rejected),
                             known_loops=bool(known_loops), include_evidence=bool(include_evidence))
        if exclude_recent is not None:
            o.exclude_recent = integer("exclude_recent", exclude_recent)
        o.sessions.extend(sessions)
        o.verify_scan_ids.extend(integer("verify_scan_ids[]", i) for i in verify_scan_ids)
        if refine is not None:
            o.refine = bool(refine)
            o.refine_set = True
        if min_score is not None:
            o.min_score = float(min_score)
        return o

    def ingest_request(self, map: str, robot: str, session: str, seq: int, points, labels=None,
                       stamp: Optional[float] = None, odometry_pose=None, store_raw: bool = False, query: bool = False,
                       query_options=None, point_times=None, twist=None, **query_kwargs):
        """An IngestRequest. points: (N, 3+) array or packed bytes; labels: (N,) integer array, packed bytes, or
        None (the server labels the scan, its labeller mode permitting). odometry_pose: 4x4 array-like.
        query_options: a QueryOptions message, or keyword arguments of query_options().
        point_times: (N,) seconds after the stamp at which each point was measured, for the server to de-skew the
        scan; twist: the sensor's (linear, angular) velocity over the sweep, else the server takes the constant
        velocity from the session's previous scan (both need stamp and odometry_pose)."""
        r = pb2.IngestRequest(key=pb2.ScanKey(map=map, robot=robot, session=session, seq=integer("seq", seq)),
                              scan=_scan(points, labels, point_times, twist), store_raw=store_raw, query=query)
        if stamp is not None:
            r.stamp = float(stamp)
        if odometry_pose is not None:
            r.odometry_pose.m.extend(packing.transform_values(odometry_pose))
        if query:
            r.query_options.CopyFrom(query_options if query_options is not None else self.query_options(**query_kwargs))
        elif query_options is not None or query_kwargs:
            raise ValueError("query options given without query=True")
        return r

    def _chunks(self, request):
        points, labels, times = request.scan.points, request.scan.labels, request.scan.point_times
        header = pb2.IngestRequest()
        header.CopyFrom(request)
        header.scan.ClearField("points")
        header.scan.ClearField("labels")
        header.scan.ClearField("point_times")
        yield pb2.IngestChunk(header=header)
        per = max(1, self.chunk_bytes // (packing.POINT_BYTES + packing.LABEL_BYTES + (packing.TIME_BYTES if times else 0)))
        n = len(points) // packing.POINT_BYTES
        for begin in range(0, n, per):
            end = min(n, begin + per)
            yield pb2.IngestChunk(points=points[begin * 12:end * 12], labels=labels[begin * 4:end * 4] if labels else b"",
                                  point_times=times[begin * 4:end * 4] if times else b"")

    # ------------------------------------------------------------------------------------------------
    # LoopClosure

    def ingest(self, map: str, robot: str, session: str, seq: int, points, labels=None,
               timeout: Optional[float] = None, **kwargs) -> IngestResult:
        """Stores one scan (and looks for loops first with query=True). Keyword arguments as for
        ingest_request(). Scans above chunk_bytes go through IngestChunked. Retrying the identical request is
        safe: it answers the stored scan with already_stored=True."""
        return self.ingest_message(self.ingest_request(map, robot, session, seq, points, labels, **kwargs), timeout)

    def ingest_message(self, request, timeout: Optional[float] = None) -> IngestResult:
        """Sends a prepared IngestRequest (chunked when large)."""
        if packing.packed_size(request.scan) > self.chunk_bytes:
            return self.ingest_chunked(request, timeout)
        return IngestResult.from_proto(self._call(self._loop.Ingest, "LoopClosure.Ingest", request, timeout))

    def ingest_chunked(self, request, timeout: Optional[float] = None) -> IngestResult:
        """Sends the request with IngestChunked, in chunks of at most chunk_bytes."""
        return IngestResult.from_proto(
            self._call(self._loop.IngestChunked, "LoopClosure.IngestChunked", self._chunks(request), timeout))

    def open_session(self, timeout: Optional[float] = None) -> IngestSession:
        """An IngestSession (IngestStream) for one robot's run. timeout: for the whole stream (default none)."""
        return IngestSession(self, timeout)

    def ingest_stream(self, scans: Iterable[Union[ScanInput, dict]], window: int = 16,
                      timeout: Optional[float] = None) -> Iterator[IngestResult]:
        """Streams scans over one IngestStream and yields their results in order, keeping at most `window`
        scans in flight. Each item is a ScanInput or a dict of ingest() arguments. Stopping early (break,
        close()) cancels the stream; scans answered before were stored."""
        if window < 1:
            raise ValueError("window must be at least 1")
        with self.open_session(timeout) as session:
            for i, item in enumerate(scans):
                if isinstance(item, dict):
                    session.send(**item)
                elif isinstance(item, ScanInput):
                    session.send(**item.as_kwargs())
                else:
                    raise TypeError(f"ingest_stream: item {i} is a {type(item).__name__}; expected a sglc.ScanInput "
                                    f"or a dict of ingest() arguments")
                while len(session) >= window:
                    yield session.next()
            session.end_requests()
            while len(session):
                yield session.next()
            session.finish()  # the stream's final status

    def query(self, map: str, scan_id: Optional[int] = None, points=None, labels=None, robot: str = "",
              session: str = "", seq: int = 0, stamp: Optional[float] = None, options=None,
              timeout: Optional[float] = None, point_times=None, twist=None, **option_kwargs) -> QueryResult:
        """Queries with a stored scan (scan_id) or with a scan that is not stored (points, labels optional:
        relocalization; point_times with a twist de-skew it). options: a QueryOptions message, or keyword
        arguments of query_options()."""
        if (scan_id is None) == (points is None):
            raise ValueError("give either scan_id or points (with optional labels)")
        r = pb2.QueryRequest(map=map, robot=robot, session=session, seq=integer("seq", seq))
        if scan_id is not None:
            if labels is not None or point_times is not None or twist is not None:
                raise ValueError("labels, point_times and twist go with points, not with scan_id")
            r.scan_id = integer("scan_id", scan_id)
        else:
            r.scan.CopyFrom(_scan(points, labels, point_times, twist))
        if stamp is not None:
            r.stamp = float(stamp)
        r.options.CopyFrom(options if options is not None else self.query_options(**option_kwargs))
        return QueryResult.from_proto(self._call(self._loop.Query, "LoopClosure.Query", r, timeout))
