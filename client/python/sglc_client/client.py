"""Python client of the SGLC loop-closure service (sglc.v1: LoopClosure and MapAdmin)."""
import collections
import queue

import grpc

from . import packing
from ._stubs import load_stubs

DEFAULT_CHUNK_BYTES = 3_000_000
SCOPES = {"all": 1, "same": 2, "other": 3, "sessions": 4}  # sglc.v1.Scope values


class SglcError(Exception):
    """A failed call. ``code`` is the grpc.StatusCode, ``code_name`` its name (e.g. "NOT_FOUND"),
    ``details`` the server's message, ``method`` the RPC."""

    def __init__(self, method, code, details):
        self.method = method
        self.code = code
        self.code_name = code.name if code is not None else "UNKNOWN"
        self.details = details or ""
        super().__init__(f"{self.code_name}: {self.details} ({method})" if self.details else f"{self.code_name} ({method})")

    @classmethod
    def from_rpc(cls, method, error):
        code = error.code() if hasattr(error, "code") else grpc.StatusCode.UNKNOWN
        details = error.details() if hasattr(error, "details") else str(error)
        return cls(method, code, details)


class Client:
    """Connects to an SGLC server.

    address: "host:port". token: bearer token, sent as ``authorization: Bearer <token>``.
    tls_root_certs: PEM bytes (or a str path to a PEM file) to use TLS; None for plain TCP.
    timeout: default deadline of each call in seconds (None: none). chunk_bytes: scans whose packed size
    exceeds this are sent with IngestChunked. stubs_path: where the generated stubs are (see _stubs.py).

    Every call raises SglcError on failure and ValueError on input it rejects before sending.
    Usable as a context manager (closes the channel).
    """

    def __init__(self, address="127.0.0.1:50051", token=None, tls_root_certs=None, timeout=30.0,
                 chunk_bytes=DEFAULT_CHUNK_BYTES, stubs_path=None):
        self.pb2, pb2_grpc = load_stubs(stubs_path)
        if chunk_bytes < packing.POINT_BYTES + packing.LABEL_BYTES:
            raise ValueError("chunk_bytes must hold at least one point (16 bytes)")
        self.address = address
        self.timeout = timeout
        self.chunk_bytes = chunk_bytes
        self._metadata = (("authorization", f"Bearer {token}"),) if token else None
        options = [("grpc.max_receive_message_length", -1), ("grpc.max_send_message_length", -1)]
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

    def close(self):
        self._channel.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------------------------------------
    # helpers

    def _call(self, stub_method, name, request, timeout):
        try:
            return stub_method(request, timeout=self.timeout if timeout is None else timeout, metadata=self._metadata)
        except grpc.RpcError as e:
            raise SglcError.from_rpc(name, e) from None

    def query_options(self, scope="all", top_k=0, exclude_recent=None, exclude_seconds=0.0, sessions=(), candidates=0,
                      refine=None, include_rejected=False, min_score=None, verify_scan_ids=(), known_loops=False):
        """Builds a QueryOptions message. scope: "all", "same", "other" or "sessions" (with sessions=["robot/session"]).
        verify_scan_ids: check exactly these stored scans instead of searching; known_loops: they are known to be
        loops, so a pose is estimated for rejected ones too (see QueryOptions in sglc.proto). exclude_recent=None
        leaves the server's default (50 scans of the same session), as every other client does."""
        if scope not in SCOPES:
            raise ValueError(f"unknown scope {scope!r} (expected same, other, all or sessions)")
        o = self.pb2.QueryOptions(scope=SCOPES[scope], exclude_seconds=float(exclude_seconds), top_k=int(top_k), candidates=int(candidates),
                                  include_rejected=bool(include_rejected), known_loops=bool(known_loops))
        if exclude_recent is not None:
            o.exclude_recent = int(exclude_recent)
        o.sessions.extend(sessions)
        o.verify_scan_ids.extend(int(i) for i in verify_scan_ids)
        if refine is not None:
            o.refine = bool(refine)
            o.refine_set = True
        if min_score is not None:
            o.min_score = float(min_score)
        return o

    def ingest_request(self, map, robot, session, seq, points, labels=None, stamp=None, odometry_pose=None, store_raw=False,
                       query=False, query_options=None, **query_kwargs):
        """Builds an IngestRequest. points/labels: numpy arrays or packed bytes (see packing); labels None: the
        server labels the scan (its labeller mode permitting).
        odometry_pose: 4x4 array-like. query_options: a QueryOptions message, or keyword arguments of query_options()."""
        p, l = packing.pack_scan(points, labels)
        r = self.pb2.IngestRequest(key=self.pb2.ScanKey(map=map, robot=robot, session=session, seq=int(seq)),
                                   scan=self.pb2.Scan(points=p, labels=l), store_raw=store_raw, query=query)
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
        points, labels = request.scan.points, request.scan.labels
        header = self.pb2.IngestRequest()
        header.CopyFrom(request)
        header.scan.Clear()
        yield self.pb2.IngestChunk(header=header)
        per = max(1, self.chunk_bytes // (packing.POINT_BYTES + packing.LABEL_BYTES))
        n = len(points) // packing.POINT_BYTES
        for begin in range(0, n, per):
            end = min(n, begin + per)
            yield self.pb2.IngestChunk(points=points[begin * 12:end * 12],
                                       labels=labels[begin * 4:end * 4] if labels else b"")

    # ------------------------------------------------------------------------------------------------
    # LoopClosure

    def ingest(self, map, robot, session, seq, points, labels=None, timeout=None, **kwargs):
        """Stores one scan; returns the IngestResponse (scan_id, loops when query=True, timing, seq).

        Keyword arguments as for ingest_request(). Scans above chunk_bytes go through IngestChunked.
        """
        return self.ingest_message(self.ingest_request(map, robot, session, seq, points, labels, **kwargs), timeout)

    def ingest_message(self, request, timeout=None):
        """Sends a prepared IngestRequest (chunked when large)."""
        if len(request.scan.points) + len(request.scan.labels) > self.chunk_bytes:
            return self.ingest_chunked(request, timeout)
        return self._call(self._loop.Ingest, "LoopClosure.Ingest", request, timeout)

    def ingest_chunked(self, request, timeout=None):
        """Always sends the request with IngestChunked, in chunks of at most chunk_bytes."""
        return self._call(self._loop.IngestChunked, "LoopClosure.IngestChunked", self._chunks(request), timeout)

    def open_session(self, timeout=None):
        """An IngestSession (IngestStream) for one robot's run. timeout: for the whole stream (default none)."""
        return IngestSession(self, timeout)

    def query(self, map, scan_id=None, points=None, labels=None, robot="", session="", seq=0, stamp=None,
              options=None, timeout=None, **option_kwargs):
        """Queries with a stored scan (scan_id) or a scan that is not stored (points + labels).
        options: a QueryOptions message, or keyword arguments of query_options(). Returns the QueryResponse."""
        if (scan_id is None) == (points is None and labels is None):
            raise ValueError("give either scan_id or points and labels")
        r = self.pb2.QueryRequest(map=map, robot=robot, session=session, seq=int(seq))
        if scan_id is not None:
            r.scan_id = int(scan_id)
        else:
            if points is None or labels is None:
                raise ValueError("points and labels go together")
            p, l = packing.pack_scan(points, labels)
            r.scan.points, r.scan.labels = p, l
        if stamp is not None:
            r.stamp = float(stamp)
        r.options.CopyFrom(options if options is not None else self.query_options(**option_kwargs))
        return self._call(self._loop.Query, "LoopClosure.Query", r, timeout)

    # ------------------------------------------------------------------------------------------------
    # MapAdmin

    def create_map(self, name, timeout=None):
        return self._call(self._admin.CreateMap, "MapAdmin.CreateMap", self.pb2.CreateMapRequest(name=name), timeout)

    def ensure_map(self, name, timeout=None):
        """Creates the map unless it exists (CreateMap is idempotent; ALREADY_EXISTS means the map exists with
        another descriptor layout, i.e. another engine configuration, and is raised)."""
        self.create_map(name, timeout)

    def list_maps(self, timeout=None):
        return list(self._call(self._admin.ListMaps, "MapAdmin.ListMaps", self.pb2.ListMapsRequest(), timeout).maps)

    def list_robots(self, map, timeout=None):
        r = self._call(self._admin.ListRobots, "MapAdmin.ListRobots", self.pb2.ListRobotsRequest(map=map), timeout)
        return list(r.robots)

    def list_sessions(self, map, robot="", timeout=None):
        r = self._call(self._admin.ListSessions, "MapAdmin.ListSessions",
                       self.pb2.ListSessionsRequest(map=map, robot=robot), timeout)
        return list(r.sessions)

    def get_scan(self, scan_id, include_graph=False, timeout=None):
        return self._call(self._admin.GetScan, "MapAdmin.GetScan",
                          self.pb2.GetScanRequest(scan_id=int(scan_id), include_graph=include_graph), timeout)

    def delete_session(self, map, robot, session, timeout=None):
        """Returns the number of scans removed."""
        return self._call(self._admin.DeleteSession, "MapAdmin.DeleteSession",
                          self.pb2.DeleteSessionRequest(map=map, robot=robot, session=session), timeout).scans_removed

    def delete_robot(self, map, robot, timeout=None):
        """Returns the number of scans removed."""
        return self._call(self._admin.DeleteRobot, "MapAdmin.DeleteRobot",
                          self.pb2.DeleteRobotRequest(map=map, robot=robot), timeout).scans_removed

    def stats(self, map="", timeout=None):
        """GetStatsResponse of one map, or of the whole database (map="")."""
        return self._call(self._admin.GetStats, "MapAdmin.GetStats", self.pb2.GetStatsRequest(map=map), timeout)

    def server_info(self, timeout=None):
        """GetServerInfoResponse: version, label preset and the full label map (node_classes, road, building,
        fence, vegetation, moving), labeller mode, engine configuration (YAML), descriptor_dim and limits
        (max_points, max_message_bytes, ...). Check it before sending: labels the map does not know give no
        loops; unlabelled scans need labeller_mode "auto" or "always"."""
        return self._call(self._admin.GetServerInfo, "MapAdmin.GetServerInfo", self.pb2.GetServerInfoRequest(), timeout)

    def backup(self, path, timeout=None):
        """Online backup to a new file on the server's machine. Returns BackupResponse (path, bytes)."""
        return self._call(self._admin.Backup, "MapAdmin.Backup", self.pb2.BackupRequest(path=path), timeout)


_END = object()


class IngestSession:
    """One robot's run over IngestStream: responses come in request order.

    send() queues a scan without waiting; next() returns the oldest outstanding response; finish() closes
    the stream and returns the responses still outstanding. A scan above the client's chunk_bytes is sent
    with IngestChunked after the outstanding stream responses arrive (order kept). When the server rejects
    a scan it ends the stream: next() returns the earlier responses, then raises SglcError.
    Use as a context manager: leaving the block without finish() cancels the stream.
    """

    METHOD = "LoopClosure.IngestStream"

    def __init__(self, client, timeout=None):
        self._client = client
        self._requests = queue.Queue()
        self._outstanding = collections.deque()  # None: from the stream; else a known response
        self._error = None
        self._closed = False
        self._responses = client._loop.IngestStream(iter(self._requests.get, _END), timeout=timeout,
                                                    metadata=client._metadata)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if not self._closed:
            self._closed = True
            self._requests.put(_END)
            self._responses.cancel()

    def __len__(self):
        return len(self._outstanding)

    def _fail(self, error):
        self._error = error if isinstance(error, SglcError) else SglcError.from_rpc(self.METHOD, error)
        if not self._closed:
            self._requests.put(_END)  # release gRPC's request-reading thread
        self._closed = True
        # Scans still waiting for an answer from the stream were not stored.
        self._outstanding = collections.deque(r for r in self._outstanding if r is not None)
        raise self._error

    def _read(self):
        try:
            return next(self._responses)
        except grpc.RpcError as e:
            self._fail(e)
        except StopIteration:
            self._fail(SglcError(self.METHOD, grpc.StatusCode.INTERNAL, "the server closed the stream early"))

    def send(self, *args, **kwargs):
        """send(map, robot, session, seq, points, labels, **ingest options) or send(IngestRequest)."""
        if self._error is not None:
            raise self._error
        if self._closed:
            raise RuntimeError("IngestSession: send() after finish()")
        request = args[0] if len(args) == 1 and not kwargs else self._client.ingest_request(*args, **kwargs)
        if len(request.scan.points) + len(request.scan.labels) > self._client.chunk_bytes:
            for i, r in enumerate(self._outstanding):  # everything sent before is processed first
                if r is None:
                    self._outstanding[i] = self._read()
            try:
                response = self._client.ingest_chunked(request, timeout=None)
            except SglcError as e:
                self._error = e
                raise
            self._outstanding.append(response)
            return
        self._requests.put(request)
        self._outstanding.append(None)

    def next(self):
        if not self._outstanding:
            if self._error is not None:
                raise self._error
            raise RuntimeError("IngestSession: next() with no scan outstanding")
        head = self._outstanding[0]
        response = self._read() if head is None else head
        self._outstanding.popleft()
        return response

    def finish(self):
        if self._error is not None:
            raise self._error
        rest = []
        if not self._closed:
            self._requests.put(_END)
            while self._outstanding:
                rest.append(self.next())
            self._closed = True
            try:
                for _ in self._responses:  # the final status: raises if the server failed the stream
                    pass
            except grpc.RpcError as e:
                self._error = SglcError.from_rpc(self.METHOD, e)
                raise self._error from None
        return rest
