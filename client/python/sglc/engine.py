"""sglc.Engine: the SGLC engine in-process, without a server (the compiled module sglc._engine).

    engine = sglc.Engine()
    a = engine.fingerprint(points_a, labels_a)   # labels optional: the built-in labeller labels the scan
    b = engine.fingerprint(points_b)
    m = engine.match(a, b)                       # m.is_loop, m.score, m.T (maps b into a), m.information

Results are those of the C++ engine (sglc-pair and the server run the same code). Thread-safe: the GIL is
released while the engine works.
"""
from __future__ import annotations

import os
from typing import Optional, Union

import numpy as np

from . import packing
from .results import Evidence, MatchResult

try:
    from . import _engine
except ImportError as e:  # pragma: no cover - depends on the build
    _engine = None
    _IMPORT_ERROR: Optional[ImportError] = e
else:
    _IMPORT_ERROR = None

Fingerprint = _engine.Fingerprint if _engine is not None else object
"""A scan's fingerprint: .nodes (landmarks), .num_points, .label_source (provided, computed or completed),
.warnings (what may keep it from closing loops), .descriptor (float32 array, the retrieval key)."""


def _require_engine(what: str) -> None:
    if _engine is None:
        raise ImportError(f"{what} needs the compiled module sglc._engine, which this installation lacks "
                          f"(sanitizer builds do not build it): {_IMPORT_ERROR}")


def deskew(points, point_times, twist) -> np.ndarray:
    """A spinning LiDAR's scan moved into the sensor's frame at its stamp, as the server and the CLI do it.
    points: (N, 3+) array; point_times: (N,) seconds after the stamp at which each point was measured (within
    1 s); twist: the sensor's velocity over the sweep, (linear m/s, angular rad/s as axis times rate) in its
    frame at the stamp, e.g. from twist_between(). Returns a float32 (N, 3) array; ValueError on bad input."""
    _require_engine("sglc.deskew")
    p = packing.as_points(points)
    t = np.frombuffer(packing.pack_point_times(point_times, len(p)), dtype="<f4").astype(np.float32)
    linear, angular = packing.twist_values(twist)
    return _engine.deskew(p, t, linear, angular)


def twist_between(pose_from, pose_to, dt: float):
    """The constant twist (linear, angular) that moves the sensor from pose_from to pose_to (4x4, sensor to
    world) in dt seconds: for a sweep that starts at pose_from, the motion on to the next pose."""
    _require_engine("sglc.twist_between")
    a = np.ascontiguousarray(pose_from, dtype=np.float64)
    b = np.ascontiguousarray(pose_to, dtype=np.float64)
    linear, angular = _engine.twist_between(a, b, float(dt))
    return np.asarray(linear), np.asarray(angular)


class Engine:
    """The engine with its default configuration, or one read from YAML.

    config: None (defaults), a path to a YAML file, or YAML text (as `sglc-pair --dump-config` prints; keys
    not given keep their defaults). Invalid configuration raises ValueError.
    """

    def __init__(self, config: Union[str, os.PathLike, None] = None):
        if _engine is None:
            raise ImportError(f"sglc.Engine needs the compiled module sglc._engine, which this installation lacks "
                              f"(sanitizer builds do not build it): {_IMPORT_ERROR}")
        text = ""
        if config is not None:
            path = os.fspath(config)
            if os.path.isfile(path):
                with open(path, encoding="utf-8") as f:
                    text = f.read()
            elif "\n" in path or ":" in path:
                text = path
            else:
                raise ValueError(f"config: {path!r} is neither a file nor YAML text")
        self._engine = _engine.Engine(text)

    def config(self) -> str:
        """The effective configuration, as YAML."""
        return self._engine.config()

    def fingerprint(self, points, labels=None, point_times=None, twist=None) -> "Fingerprint":
        """Fingerprint of one scan. points: (N, 3+) numeric array (x, y, z first); labels: (N,) integer array in
        the configured label set, or None for the built-in labeller. point_times and twist: de-skew the scan
        first (see deskew()). ValueError on invalid input."""
        p = packing.as_points(points)
        if point_times is not None or twist is not None:
            if point_times is None or twist is None:
                raise ValueError("de-skew needs both point_times and twist")
            p = deskew(p, point_times, twist)
        lab = None if labels is None else packing.as_labels(labels)
        if lab is not None and len(lab) != len(p):
            raise ValueError(f"scan has {len(p)} points but {len(lab)} labels")
        return self._engine.fingerprint(p, lab)

    def match(self, a: "Fingerprint", b: "Fingerprint", known_loop: bool = False) -> MatchResult:
        """Whether b (the candidate) closes a loop with a (the query), and T mapping b's points into a's frame.
        known_loop: the scans are known to show one place; estimate T even when verification rejects them
        (is_loop keeps the decision, refined says whether a pose was found)."""
        if not isinstance(a, _engine.Fingerprint) or not isinstance(b, _engine.Fingerprint):
            raise TypeError("match() takes two fingerprints from Engine.fingerprint()")
        d = self._engine.match(a, b, bool(known_loop))
        d["evidence"] = Evidence(**d["evidence"])
        return MatchResult(**d)
