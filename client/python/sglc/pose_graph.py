"""PoseGraph calls of sglc.Client: optimised poses, session frames, loops, and a watch on new solutions."""
from __future__ import annotations

import os
import re
from typing import Dict, List, Optional, Sequence, Tuple

import grpc

from ._args import integer
from ._stubs import pb2
from .errors import InternalError, SglcError
from .results import LoopEdge, MapEvent, ScanPose, SessionFrame


class MapWatch:
    """Iterator over a map's pose-graph solutions (MapEvent), as the server publishes them. Blocks until the
    next one; close() (or leaving a with-block) cancels the stream. Raises an SglcError subclass when the
    stream fails (CancelledError is not raised after close())."""

    METHOD = "PoseGraph.WatchMap"

    def __init__(self, call):
        self._call = call
        self._closed = False

    def __iter__(self) -> "MapWatch":
        return self

    def __next__(self) -> MapEvent:
        try:
            return MapEvent.from_proto(next(self._call))
        except grpc.RpcError as e:
            if self._closed and e.code() == grpc.StatusCode.CANCELLED:
                raise StopIteration from None
            raise SglcError.from_rpc(self.METHOD, e) from None

    def close(self) -> None:
        self._closed = True
        self._call.cancel()

    def __enter__(self) -> "MapWatch":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class PoseGraphCalls:
    """Mixed into sglc.Client (uses its _call, _metadata and _graph stub)."""

    def _pages(self, method: str, request, field: str, timeout: Optional[float]):
        while True:
            r = self._call(getattr(self._graph, method), "PoseGraph." + method, request, timeout)
            yield from getattr(r, field)
            if r.next_page_token == 0:
                return
            if r.next_page_token <= request.page_token:  # tokens only grow: do not page forever
                raise InternalError("PoseGraph." + method, grpc.StatusCode.INTERNAL,
                                    f"the server's next_page_token {r.next_page_token} does not follow "
                                    f"{request.page_token}")
            request.page_token = r.next_page_token

    def poses(self, map: str, robot: str = "", session: str = "", page_size: int = 1000,
              timeout: Optional[float] = None) -> List[ScanPose]:
        """Every graph node's pose (scans ingested with an odometry pose), in scan-id order, all pages."""
        request = pb2.GetPosesRequest(map=map, robot=robot, session=session, page_size=integer("page_size", page_size))
        return [ScanPose.from_proto(p) for p in self._pages("GetPoses", request, "poses", timeout)]

    def session_frames(self, map: str, timeout: Optional[float] = None) -> List[SessionFrame]:
        """Each session's odometry frame in the map frame."""
        r = self._call(self._graph.GetSessionFrames, "PoseGraph.GetSessionFrames",
                       pb2.GetSessionFramesRequest(map=map), timeout)
        return [SessionFrame.from_proto(s) for s in r.sessions]

    def loops(self, map: str, robot: str = "", page_size: int = 1000,
              timeout: Optional[float] = None) -> List[LoopEdge]:
        """The verified loops of the map's pose graph (with at least one end in `robot`'s scans if given)."""
        request = pb2.GetLoopsRequest(map=map, robot=robot, page_size=integer("page_size", page_size))
        return [LoopEdge.from_proto(e) for e in self._pages("GetLoops", request, "loops", timeout)]

    def export(self, map: str, format: str = "g2o", robots: Sequence[str] = (), out_dir=None,
               timeout: Optional[float] = None) -> Tuple[Dict[str, bytes], Dict[str, int]]:
        """The map's pose graph as the server weighs it (PoseGraph.ExportGraph; client/README.md "export"):
        ({file name: contents}, summary counts). format "g2o" gives graph.g2o, graph.ids.csv and
        graph.left_out.csv, "json" graph.json, "mcap" graph.mcap (Foxglove). robots: only their scans
        (default every robot). With out_dir the files are also written there (created)."""
        request = pb2.ExportGraphRequest(map=map, format=format, robots=list(robots))
        files: Dict[str, bytes] = {}
        summary: Dict[str, int] = {}
        try:
            for chunk in self._graph.ExportGraph(request, timeout=self.timeout if timeout is None else timeout,
                                                 metadata=self._metadata):
                if chunk.HasField("summary"):
                    summary = {f.name: getattr(chunk.summary, f.name) for f in chunk.summary.DESCRIPTOR.fields}
                files[chunk.file] = files.get(chunk.file, b"") + chunk.data
        except grpc.RpcError as e:
            raise SglcError.from_rpc("PoseGraph.ExportGraph", e) from None
        for name in files:  # names from the wire: plain file names only
            if not re.fullmatch(r"[A-Za-z0-9_-][A-Za-z0-9._-]{0,63}", name):
                raise InternalError("PoseGraph.ExportGraph", grpc.StatusCode.INTERNAL,
                                    f"the server sent an export file named {name[:64]!r}")
        if out_dir is not None:
            os.makedirs(out_dir, exist_ok=True)
            for name, data in files.items():
                with open(os.path.join(out_dir, name), "wb") as f:
                    f.write(data)
        return files, summary

    def watch(self, map: str, after_version: int = 0, timeout: Optional[float] = None) -> MapWatch:
        """A MapWatch yielding each new pose-graph solution above after_version. timeout: of the whole stream
        (default none). Deleting the map ends the watch with NotFoundError."""
        call = self._graph.WatchMap(pb2.WatchMapRequest(map=map, after_version=integer("after_version", after_version)), timeout=timeout,
                                    metadata=self._metadata)
        return MapWatch(call)

