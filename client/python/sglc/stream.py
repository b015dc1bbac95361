"""Streaming ingest over LoopClosure.IngestStream: IngestSession (send/next/finish) and ScanInput, the item
type of Client.ingest_stream()."""
from __future__ import annotations

import collections
import queue
from dataclasses import dataclass
from typing import Any, Dict, List, Optional

import grpc

from . import packing
from .errors import InternalError, SglcError
from .results import IngestResult

_END = object()


@dataclass
class ScanInput:
    """One scan for Client.ingest_stream(): the arguments of Client.ingest()."""
    map: str
    robot: str
    session: str
    seq: int
    points: Any
    labels: Any = None
    stamp: Optional[float] = None
    odometry_pose: Any = None
    store_raw: bool = False
    query: bool = False
    query_options: Optional[Dict[str, Any]] = None  # keyword arguments of Client.query_options()
    point_times: Any = None  # (N,) s after the stamp, for the server to de-skew the scan
    twist: Any = None        # (linear, angular) over the sweep; else the server's constant velocity

    def as_kwargs(self) -> Dict[str, Any]:
        kw = dict(map=self.map, robot=self.robot, session=self.session, seq=self.seq, points=self.points,
                  labels=self.labels, stamp=self.stamp, odometry_pose=self.odometry_pose, store_raw=self.store_raw,
                  query=self.query, point_times=self.point_times, twist=self.twist)
        kw.update(self.query_options or {})
        return kw


class IngestSession:
    """One robot's run over IngestStream: results come in request order.

    send() queues a scan without waiting; next() returns the oldest outstanding result; finish() closes the
    stream and returns the results still outstanding. A scan above the client's chunk_bytes goes through
    IngestChunked once the results sent before it have arrived (order kept). When the server rejects a scan it
    ends the stream: next() returns the earlier results, then raises the SglcError.
    Use as a context manager: leaving the block without finish() cancels the stream.
    """

    METHOD = "LoopClosure.IngestStream"

    def __init__(self, client, timeout: Optional[float] = None):
        self._client = client
        self._timeout = timeout
        self._requests: "queue.Queue" = queue.Queue()
        self._outstanding: collections.deque = collections.deque()  # None: from the stream; else a known result
        self._error: Optional[SglcError] = None
        self._closed = False
        self._ended = False  # the request side is closed
        self._responses = client._loop.IngestStream(iter(self._requests.get, _END), timeout=timeout,
                                                    metadata=client._metadata)

    def __enter__(self) -> "IngestSession":
        return self

    def __exit__(self, *exc) -> None:
        if not self._closed:
            self._closed = True
            self.end_requests()
            self._responses.cancel()

    def __del__(self) -> None:
        # A session dropped without finish() or a with-block: release gRPC's request thread and the server's
        # stream slot.
        try:
            self.__exit__(None, None, None)
        except Exception:  # noqa: BLE001 - nothing can be reported from a finalizer
            pass

    def __len__(self) -> int:
        return len(self._outstanding)

    def _fail(self, error) -> None:
        self._error = error if isinstance(error, SglcError) else SglcError.from_rpc(self.METHOD, error)
        if not self._closed:
            self.end_requests()  # release gRPC's request-reading thread
        self._closed = True
        # Scans still waiting for an answer from the stream were not stored.
        self._outstanding = collections.deque(r for r in self._outstanding if r is not None)
        raise self._error

    def _read(self) -> IngestResult:
        try:
            return IngestResult.from_proto(next(self._responses))
        except grpc.RpcError as e:
            self._fail(e)
        except StopIteration:
            self._fail(InternalError(self.METHOD, grpc.StatusCode.INTERNAL, "the server closed the stream early"))
        raise AssertionError("unreachable")

    def send(self, *args, **kwargs) -> None:
        """send(map, robot, session, seq, points, labels=None, **ingest options) or send(IngestRequest)."""
        if self._error is not None:
            raise self._error
        if self._closed or self._ended:
            raise RuntimeError("IngestSession: send() after finish() or end_requests()")
        request = args[0] if len(args) == 1 and not kwargs else self._client.ingest_request(*args, **kwargs)
        if packing.packed_size(request.scan) > self._client.chunk_bytes:
            for i, r in enumerate(self._outstanding):  # everything sent before is processed first
                if r is None:
                    self._outstanding[i] = self._read()
            try:
                result = self._client.ingest_chunked(request, timeout=self._timeout)
            except SglcError as e:
                self._error = e
                raise
            self._outstanding.append(result)
            return
        self._requests.put(request)
        self._outstanding.append(None)

    def next(self) -> IngestResult:
        """The oldest outstanding scan's result (blocks until it arrives)."""
        if not self._outstanding:
            if self._error is not None:
                raise self._error
            raise RuntimeError("IngestSession: next() with no scan outstanding")
        head = self._outstanding[0]
        result = self._read() if head is None else head
        self._outstanding.popleft()
        return result

    def end_requests(self) -> None:
        """Tells the server no more scans follow; the outstanding results can still be read with next()."""
        if not self._ended:
            self._ended = True
            self._requests.put(_END)

    def finish(self) -> List[IngestResult]:
        """Closes the stream; returns the outstanding results and raises if the server failed the stream."""
        if self._error is not None:
            raise self._error
        rest = []
        if not self._closed:
            self.end_requests()
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
