"""De-skew through the service: a scan sent with per-point times is moved to its stamp by the server, with the
sender's twist or the constant velocity from the session's previous scan, exactly as sglc.deskew does it
locally (the stored descriptor is the one the in-process engine computes for the de-skewed scan)."""
import numpy as np
import pytest

import sglc
from conftest import BUILD

try:
    from sglc import _engine  # noqa: F401
except ImportError as e:
    pytest.skip(f"sglc._engine is not built in {BUILD} (sanitizer builds do not build it): {e}",
                allow_module_level=True)


def sweep_times(points):
    """A spinning sensor's times: one turn of 0.1 s by azimuth, centred on the stamp."""
    az = np.arctan2(points[:, 1], points[:, 0])
    return ((az + np.pi) / (2 * np.pi) * 0.1 - 0.05).astype(np.float32)


def pose(x, yaw=0.0):
    T = np.eye(4)
    T[0, 3] = x
    T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    return T


@pytest.fixture(scope="module")
def engine():
    return sglc.Engine()


@pytest.fixture(scope="module")
def scan(kitti):
    p, lab = kitti("000052")
    return p[:, :3].astype(np.float32), lab


def stored_descriptor(client, scan_id):
    return client.get_scan(scan_id, include_graph=True).descriptor


def test_deskew_matches_the_local_engine(engine, scan):
    p, lab = scan
    t = sweep_times(p)
    twist = ([8.0, 0.5, 0.0], [0.0, 0.0, 0.4])
    moved = sglc.deskew(p, t, twist)
    assert moved.shape == p.shape and moved.dtype == np.float32
    # Points at the stamp stay; the late ones move by about their time times the speed.
    at_stamp = np.abs(t) < 1e-4
    assert np.allclose(moved[at_stamp], p[at_stamp], atol=2e-3)  # within 1e-4 s of it: under 1 mm at 8 m/s
    late = t > 0.04
    assert np.median(np.linalg.norm(moved[late] - p[late], axis=1)) > 0.3
    local = engine.fingerprint(p, lab, point_times=t, twist=twist).descriptor
    assert np.array_equal(local, engine.fingerprint(moved, lab).descriptor)
    assert not np.array_equal(local, engine.fingerprint(p, lab).descriptor)

    lin, ang = sglc.twist_between(pose(0.0), pose(1.0, 0.1), 0.1)
    assert np.allclose(lin, [10.0, 0, 0]) and np.allclose(ang, [0, 0, 1.0])
    with pytest.raises(ValueError, match="point times"):
        sglc.deskew(p, t[:-1], twist)
    bad = t.copy()
    bad[5] = 2.0
    with pytest.raises(ValueError, match=r"point_times\[5\]"):
        sglc.deskew(p, bad, twist)
    with pytest.raises(ValueError, match="twist"):
        sglc.deskew(p, t, [1.0, 2.0])
    with pytest.raises(ValueError, match="both"):
        engine.fingerprint(p, lab, point_times=t)


def test_server_deskews_as_the_engine_does(client, engine, scan):
    p, lab = scan
    t = sweep_times(p)
    client.create_map("deskew")
    twist = ([6.0, 0.0, 0.0], [0.0, 0.0, 0.3])
    # The sender's twist.
    r = client.ingest("deskew", "a", "run", 0, p, lab, stamp=100.0, odometry_pose=pose(0.0), point_times=t,
                      twist=twist)
    assert r.deskewed and not any("de-skew" in w for w in r.warnings)
    assert np.array_equal(stored_descriptor(client, r.scan_id),
                          engine.fingerprint(p, lab, point_times=t, twist=twist).descriptor)
    # No twist: the constant velocity from the previous stored scan (seq 0), 1.2 m and 0.06 rad in 0.2 s.
    r2 = client.ingest("deskew", "a", "run", 2, p, lab, stamp=100.2, odometry_pose=pose(1.2, 0.06), point_times=t)
    assert r2.deskewed, r2.warnings
    cv = sglc.twist_between(pose(0.0), pose(1.2, 0.06), 0.2)
    assert np.array_equal(stored_descriptor(client, r2.scan_id),
                          engine.fingerprint(p, lab, point_times=t, twist=cv).descriptor)
    # A retry is the same request and answers the stored scan.
    again = client.ingest("deskew", "a", "run", 2, p, lab, stamp=100.2, odometry_pose=pose(1.2, 0.06), point_times=t)
    assert again.already_stored and again.scan_id == r2.scan_id and again.deskewed

    # Chunked (small chunks): the same scan, the same descriptor.
    with sglc.Client(client.address, timeout=120, chunk_bytes=64 * 1024) as small:
        r3 = small.ingest("deskew", "b", "run", 0, p, lab, point_times=t, twist=twist)
    assert r3.deskewed
    assert np.array_equal(stored_descriptor(client, r3.scan_id), stored_descriptor(client, r.scan_id))

    # The first scan of a session without a twist: stored as sent, with the reason.
    r4 = client.ingest("deskew", "c", "run", 0, p, lab, stamp=5.0, odometry_pose=pose(0.0), point_times=t)
    assert not r4.deskewed
    assert any("not de-skewed" in w and "no earlier scan" in w for w in r4.warnings), r4.warnings
    assert np.array_equal(stored_descriptor(client, r4.scan_id), engine.fingerprint(p, lab).descriptor)

    # A query scan: de-skewed with its twist, else left with a warning.
    q = client.query("deskew", points=p, labels=lab, point_times=t, twist=twist, top_k=1)
    assert q.deskewed and q.candidates and q.candidates[0].descriptor_distance < 1e-4
    q2 = client.query("deskew", points=p, labels=lab, point_times=t, top_k=1)
    assert not q2.deskewed and any("the query has no twist" in w for w in q2.warnings)


def test_bad_sweeps_are_refused_with_the_reason(client, scan):
    p, lab = scan
    client.create_map("deskew-bad")
    t = sweep_times(p)
    with pytest.raises(ValueError, match="point times"):
        client.ingest("deskew-bad", "a", "s", 0, p, lab, point_times=t[:-1])
    with pytest.raises(ValueError, match="needs point_times"):
        client.ingest("deskew-bad", "a", "s", 0, p, lab, twist=([1, 0, 0], [0, 0, 0]))
    # What a client of another language might send: the server says what is wrong.
    req = client.ingest_request("deskew-bad", "a", "s", 0, p, lab)
    req.scan.point_times = t[:-1].tobytes()
    with pytest.raises(sglc.InvalidArgumentError, match="point times"):
        client.ingest_message(req)
    bad = t.copy()
    bad[3] = np.nan
    req.scan.point_times = bad.tobytes()
    with pytest.raises(sglc.InvalidArgumentError, match=r"point_times\[3\]"):
        client.ingest_message(req)
    req.scan.point_times = t.tobytes()
    req.scan.twist.linear.extend([1.0, 2.0])
    with pytest.raises(sglc.InvalidArgumentError, match="linear has 2 values"):
        client.ingest_message(req)
    assert client.stats("deskew-bad").scans == 0
