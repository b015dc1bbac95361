"""What the service answers, as dataclasses with numpy matrices (built from the sglc.v1 messages).

Transforms are 4x4 float64 arrays (row-major rigid motions); information matrices 6x6 float64 arrays
(translation then rotation, for a right perturbation in the candidate's frame), or None when not refined.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional

import numpy as np

from ._stubs import pb2

LABEL_SOURCES = {pb2.LABEL_SOURCE_UNSPECIFIED: "unspecified", pb2.LABELS_PROVIDED: "provided",
                 pb2.LABELS_COMPUTED: "computed", pb2.LABELS_COMPLETED: "completed"}


def matrix(transform) -> np.ndarray:
    """A Transform message (or 16 values) -> 4x4 float64 array; identity when the message is empty."""
    values = list(transform.m) if hasattr(transform, "m") else list(transform)
    if not values:
        return np.eye(4)
    if len(values) != 16:
        raise ValueError(f"transform has {len(values)} values, expected 16 (row-major 4x4)")
    return np.array(values, dtype=np.float64).reshape(4, 4)


def information(values) -> Optional[np.ndarray]:
    """36 values -> 6x6 float64 array; None when empty (the loop was not refined)."""
    values = list(values)
    if not values:
        return None
    if len(values) != 36:
        raise ValueError(f"information has {len(values)} values, expected 36 (row-major 6x6)")
    return np.array(values, dtype=np.float64).reshape(6, 6)


def _stamp(message) -> Optional[float]:
    return message.stamp if message.HasField("stamp") else None


@dataclass
class Timing:
    fingerprint_ms: float = 0.0
    store_ms: float = 0.0
    search_ms: float = 0.0
    verify_ms: float = 0.0
    refine_ms: float = 0.0
    total_ms: float = 0.0

    @classmethod
    def from_proto(cls, m) -> "Timing":
        return cls(m.fingerprint_ms, m.store_ms, m.search_ms, m.verify_ms, m.refine_ms, m.total_ms)


EVIDENCE_SOURCES = {pb2.EVIDENCE_SOURCE_NONE: "none", pb2.EVIDENCE_SOURCE_LANDMARKS: "landmarks",
                    pb2.EVIDENCE_SOURCE_CONSENSUS: "consensus", pb2.EVIDENCE_SOURCE_WALLS: "walls",
                    pb2.EVIDENCE_SOURCE_VIEW: "view"}


@dataclass
class Evidence:
    """What the loop model measured at a candidate's pose (sglc.proto's Evidence; docs/METHOD.md section 8).
    source: "landmarks", "consensus", "walls", "view" or "none" (where the pose hypothesis came from)."""
    source: str
    landmarks: int
    landmark_similarity: float
    field_deg: float
    agreement: float
    wide_agreement: float
    pin: float
    plane_overlap: float
    plane_rmse_m: float
    constraint: float
    context_similarity: float
    translation_m: float

    @classmethod
    def from_proto(cls, m) -> "Evidence":
        return cls(EVIDENCE_SOURCES.get(m.source, str(m.source)), m.landmarks, m.landmark_similarity, m.field_deg,
                   m.agreement, m.wide_agreement, m.pin, m.plane_overlap, m.plane_rmse_m, m.constraint,
                   m.context_similarity, m.translation_m)


def _probability(m) -> Optional[float]:
    """The loop model's probability, or None when the message has none (an older server, an older loop)."""
    return m.probability if m.HasField("probability") else None


@dataclass
class Loop:
    """A loop candidate: a stored scan and the transform that maps its points into the query's frame."""
    scan_id: int
    robot: str
    session: str
    seq: int
    score: float
    verified: bool
    refined: bool
    inliers: int
    fitness: float
    rmse: float
    T: np.ndarray                      # 4x4, maps the candidate into the query
    information: Optional[np.ndarray]  # 6x6, or None when not refined
    descriptor_distance: float
    probability: Optional[float] = None  # the loop model's probability (0..1); None from an older server
    evidence: Optional[Evidence] = None  # with query_options(include_evidence=True)
    reason: str = ""                     # why a rejected candidate is not a loop (empty for loops)

    @classmethod
    def from_proto(cls, m) -> "Loop":
        return cls(m.scan_id, m.robot, m.session, m.seq, m.score, m.verified, m.refined, m.inliers, m.fitness,
                   m.rmse, matrix(m.t_query_candidate), information(m.information), m.descriptor_distance,
                   _probability(m), Evidence.from_proto(m.evidence) if m.HasField("evidence") else None, m.reason)


@dataclass
class IngestResult:
    scan_id: int
    seq: int
    already_stored: bool   # the identical request was stored before (a retry)
    label_source: str      # provided, computed or completed
    loops: List[Loop]
    warnings: List[str]
    timing: Timing
    deskewed: bool = False  # the scan's points were moved by their point_times
    place_id: int = 0       # lifelong maps: the scan's place (0 with the policy off)
    kept: bool = False      # ... and whether the map keeps it as a version (else it retires with its session)

    @classmethod
    def from_proto(cls, m) -> "IngestResult":
        return cls(m.scan_id, m.seq, m.already_stored, LABEL_SOURCES.get(m.label_source, "unspecified"),
                   [Loop.from_proto(c) for c in m.loops], list(m.warnings), Timing.from_proto(m.timing), m.deskewed,
                   m.place_id, m.kept)


@dataclass
class QueryResult:
    candidates: List[Loop]
    label_source: str
    warnings: List[str]
    timing: Timing
    deskewed: bool = False  # the query scan was de-skewed by its point_times and twist

    @classmethod
    def from_proto(cls, m) -> "QueryResult":
        return cls([Loop.from_proto(c) for c in m.candidates], LABEL_SOURCES.get(m.label_source, "unspecified"),
                   list(m.warnings), Timing.from_proto(m.timing), m.deskewed)


@dataclass
class MapInfo:
    name: str
    scans: int
    robots: int
    sessions: int
    descriptor_dim: int

    @classmethod
    def from_proto(cls, m) -> "MapInfo":
        return cls(m.name, m.scans, m.robots, m.sessions, m.descriptor_dim)


@dataclass
class RobotInfo:
    name: str
    scans: int
    sessions: int

    @classmethod
    def from_proto(cls, m) -> "RobotInfo":
        return cls(m.name, m.scans, m.sessions)


@dataclass
class SessionInfo:
    robot: str
    name: str
    scans: int
    first_seq: int
    last_seq: int

    @classmethod
    def from_proto(cls, m) -> "SessionInfo":
        return cls(m.robot, m.name, m.scans, m.first_seq, m.last_seq)


@dataclass
class GraphNode:
    cls: str
    center: np.ndarray  # x, y, z (m)
    size: np.ndarray    # length, width, height (m)


@dataclass
class ScanInfo:
    scan_id: int
    map: str
    robot: str
    session: str
    seq: int
    stamp: Optional[float]
    odometry_pose: Optional[np.ndarray]
    fingerprint_bytes: int
    has_raw: bool
    nodes: List[GraphNode]            # with include_graph
    descriptor: Optional[np.ndarray]  # with include_graph

    @classmethod
    def from_proto(cls, m) -> "ScanInfo":
        nodes = [GraphNode(n.cls, np.array([n.x, n.y, n.z]), np.array([n.length, n.width, n.height])) for n in m.nodes]
        return cls(m.scan_id, m.key.map, m.key.robot, m.key.session, m.key.seq, _stamp(m),
                   matrix(m.odometry_pose) if m.odometry_pose.m else None, m.fingerprint_bytes, m.has_raw, nodes,
                   np.array(m.scan_descriptor, dtype=np.float32) if m.scan_descriptor else None)


@dataclass
class Compaction:
    """What MapAdmin.Compact did (docs/LIFELONG.md)."""
    policy_on: bool
    placed: int
    retired: int
    retired_bytes: int
    loops_moved: int
    loops_dropped: int
    open_sessions: int
    places: int
    versions: int
    promoted: int = 0  # surplus scans made versions (places left with too few, or replacing an unused version)
    demoted: int = 0   # versions made surplus (places that held too many, or replaced)

    @classmethod
    def from_proto(cls, m) -> "Compaction":
        return cls(m.policy_on, m.placed, m.retired, m.retired_bytes, m.loops_moved, m.loops_dropped,
                   m.open_sessions, m.places, m.versions, m.promoted, m.demoted)


@dataclass
class Stats:
    maps: int
    robots: int
    sessions: int
    scans: int
    index_entries: int
    db_bytes: int
    fingerprint_bytes: int
    cache_mb: float
    pose_graph_failed: bool
    pose_graph_error: str
    # Lifelong maps (docs/LIFELONG.md): places, their kept versions, scans retired so far and their bytes.
    places: int = 0
    versions: int = 0
    retired_scans: int = 0
    retired_bytes: int = 0

    @classmethod
    def from_proto(cls, m) -> "Stats":
        return cls(m.maps, m.robots, m.sessions, m.scans, m.index_entries, m.db_bytes, m.fingerprint_bytes,
                   m.cache_mb, m.pose_graph_failed, m.pose_graph_error, m.places, m.versions, m.retired_scans,
                   m.retired_bytes)


@dataclass
class ServerInfo:
    version: str
    label_preset: str
    node_classes: List[str]   # landmark classes, in descriptor order
    label_ids: dict           # class or role name -> list of label ids (node classes, road, building, ...)
    labeller_mode: str        # off, auto or always
    engine_config: str        # YAML
    descriptor_dim: int
    max_points: int
    max_message_bytes: int
    max_streams_per_client: int
    stream_idle_timeout_s: float
    max_inflight_bytes: int
    loop_model: str           # the loop model's version
    min_probability: float    # the probability a loop needs

    @classmethod
    def from_proto(cls, m) -> "ServerInfo":
        ids = {c.name: list(c.ids) for c in m.node_classes}
        for role in ("road", "building", "fence", "vegetation", "moving"):
            ids[role] = list(getattr(m, role))
        return cls(m.version, m.label_preset, [c.name for c in m.node_classes], ids, m.labeller_mode,
                   m.engine_config, m.descriptor_dim, m.max_points, m.max_message_bytes, m.max_streams_per_client,
                   m.stream_idle_timeout_s, m.max_inflight_bytes, m.loop_model, m.min_probability)


@dataclass
class ScanPose:
    scan_id: int
    robot: str
    session: str
    seq: int
    T: np.ndarray          # 4x4, maps the scan into the map frame (or its session's frame when not connected)
    connected: bool
    optimised: bool
    stamp: Optional[float]

    @classmethod
    def from_proto(cls, m) -> "ScanPose":
        return cls(m.scan_id, m.robot, m.session, m.seq, matrix(m.t_map_scan), m.connected, m.optimised, _stamp(m))


@dataclass
class SessionFrame:
    robot: str
    session: str
    T: np.ndarray   # 4x4, maps the session's odometry frame into the map frame
    connected: bool

    @classmethod
    def from_proto(cls, m) -> "SessionFrame":
        return cls(m.robot, m.session, matrix(m.t_map_session), m.connected)


@dataclass
class LoopEnd:
    scan_id: int
    robot: str
    session: str
    seq: int

    @classmethod
    def from_proto(cls, m) -> "LoopEnd":
        return cls(m.scan_id, m.robot, m.session, m.seq)


@dataclass
class LoopEdge:
    """A verified loop of the map's pose graph."""
    id: int
    query: LoopEnd
    candidate: LoopEnd
    T: np.ndarray                      # maps the candidate's points into the query's frame
    score: float
    inliers: int
    fitness: float
    rmse: float
    information: Optional[np.ndarray]
    probability: Optional[float] = None  # None: recorded before the loop model (unknown)

    @classmethod
    def from_proto(cls, m) -> "LoopEdge":
        return cls(m.id, LoopEnd.from_proto(m.query), LoopEnd.from_proto(m.candidate), matrix(m.t_query_candidate),
                   m.score, m.inliers, m.fitness, m.rmse, information(m.information), _probability(m))


@dataclass
class MapEvent:
    """A new pose-graph solution of a map."""
    graph_version: int
    loops: int
    nodes: int
    rejected_loops: int
    optimise_ms: float
    converged: bool
    failed: bool
    error: str

    @classmethod
    def from_proto(cls, m) -> "MapEvent":
        return cls(m.graph_version, m.loops, m.nodes, m.rejected_loops, m.optimise_ms, m.converged, m.failed, m.error)


@dataclass
class Backup:
    path: str
    bytes: int


@dataclass
class MatchResult:
    """sglc.Engine.match: whether two scans close a loop, and the pose that maps b into a."""
    is_loop: bool
    score: float
    T: np.ndarray               # 4x4: p_a = T @ p_b
    information: np.ndarray     # 6x6 (zeros when not refined)
    refined: bool
    inliers: int
    matches: int
    graph_similarity: float
    background_similarity: float
    fitness: float
    rmse: float
    reason: str = ""            # why it is not a loop
    probability: float = 0.0    # the loop model's probability that this is a true loop
    evidence: Optional[Evidence] = None  # what it was computed from
