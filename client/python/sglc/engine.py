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

    def fingerprint(self, points, labels=None) -> "Fingerprint":
        """Fingerprint of one scan. points: (N, 3+) numeric array (x, y, z first); labels: (N,) integer array in
        the configured label set, or None for the built-in labeller. ValueError on invalid input."""
        p = packing.as_points(points)
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
