"""MapAdmin calls of sglc.Client: maps, robots, sessions, scans, statistics, server info, backups."""
from __future__ import annotations

from typing import List, Optional

from ._args import integer
from ._stubs import pb2
from .results import Backup, Compaction, MapInfo, RobotInfo, ScanInfo, ServerInfo, SessionInfo, Stats


class AdminCalls:
    """Mixed into sglc.Client (uses its _call and _admin stub)."""

    def _admin_call(self, method: str, request, timeout: Optional[float]):
        return self._call(getattr(self._admin, method), "MapAdmin." + method, request, timeout)

    def create_map(self, name: str, timeout: Optional[float] = None) -> MapInfo:
        """Creates a map, or answers the existing one (idempotent). AlreadyExistsError only when it exists with
        another descriptor layout (another engine configuration)."""
        return MapInfo.from_proto(self._admin_call("CreateMap", pb2.CreateMapRequest(name=name), timeout))

    ensure_map = create_map

    def list_maps(self, timeout: Optional[float] = None) -> List[MapInfo]:
        return [MapInfo.from_proto(m) for m in self._admin_call("ListMaps", pb2.ListMapsRequest(), timeout).maps]

    def list_robots(self, map: str, timeout: Optional[float] = None) -> List[RobotInfo]:
        r = self._admin_call("ListRobots", pb2.ListRobotsRequest(map=map), timeout)
        return [RobotInfo.from_proto(x) for x in r.robots]

    def list_sessions(self, map: str, robot: str = "", timeout: Optional[float] = None) -> List[SessionInfo]:
        r = self._admin_call("ListSessions", pb2.ListSessionsRequest(map=map, robot=robot), timeout)
        return [SessionInfo.from_proto(x) for x in r.sessions]

    def get_scan(self, scan_id: int, include_graph: bool = False, timeout: Optional[float] = None) -> ScanInfo:
        r = self._admin_call("GetScan", pb2.GetScanRequest(scan_id=integer("scan_id", scan_id), include_graph=include_graph), timeout)
        return ScanInfo.from_proto(r)

    def delete_session(self, map: str, robot: str, session: str, timeout: Optional[float] = None) -> int:
        """Deletes one session's scans; returns how many were removed."""
        r = self._admin_call("DeleteSession", pb2.DeleteSessionRequest(map=map, robot=robot, session=session), timeout)
        return r.scans_removed

    def delete_robot(self, map: str, robot: str, timeout: Optional[float] = None) -> int:
        """Deletes one robot's scans; returns how many were removed."""
        return self._admin_call("DeleteRobot", pb2.DeleteRobotRequest(map=map, robot=robot), timeout).scans_removed

    def delete_map(self, map: str, timeout: Optional[float] = None) -> int:
        """Deletes the whole map (scans, robots, sessions, loops, poses), irreversibly; returns how many scans
        were removed. NotFoundError for an unknown map."""
        return self._admin_call("DeleteMap", pb2.DeleteMapRequest(map=map), timeout).scans_removed

    def stats(self, map: str = "", timeout: Optional[float] = None) -> Stats:
        """Counts and sizes of one map, or of the whole database (map="")."""
        return Stats.from_proto(self._admin_call("GetStats", pb2.GetStatsRequest(map=map), timeout))

    def server_info(self, timeout: Optional[float] = None) -> ServerInfo:
        """Version, label preset and label map, labeller mode, engine configuration and limits. Check it before
        sending: labels the server does not know give no loops; unlabelled scans need labeller_mode auto or
        always."""
        return ServerInfo.from_proto(self._admin_call("GetServerInfo", pb2.GetServerInfoRequest(), timeout))

    def backup(self, name: str, timeout: Optional[float] = None) -> Backup:
        """Online backup into a new file `name` (a plain file name) in the server's backup directory."""
        r = self._admin_call("Backup", pb2.BackupRequest(path=name), timeout)
        return Backup(r.path, r.bytes)

    def compact(self, map: str, timeout: Optional[float] = None) -> Compaction:
        """Applies the map's lifelong policy now (docs/LIFELONG.md): places for scans that have none, then the
        retirement of ended sessions' scans that are not versions of their places (none with the policy off)."""
        return Compaction.from_proto(self._admin_call("Compact", pb2.CompactRequest(map=map), timeout))
