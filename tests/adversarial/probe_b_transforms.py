"""B. Transforms: an odometry_pose that is not a rigid motion is INVALID_ARGUMENT ("rigid"), on every ingest path;
float rounding is accepted; the all-zero rotation that used to abort the server (and every restart) is refused."""
import os
import time

import numpy as np

import adv_harness as h

CLASS = "B"
TITLE = "odometry poses that are not rigid motions"


def rotation(rz=0.3, rx=0.1):
    cz, sz, cx, sx = np.cos(rz), np.sin(rz), np.cos(rx), np.sin(rx)
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return Rz @ Rx


def homogeneous(R, t=(1.0, -2.0, 0.5)):
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def values(T):
    return [float(v) for v in np.asarray(T).reshape(-1)]


def bad_poses():
    R = rotation()
    last_row = homogeneous(R)
    last_row[3] = [0, 0, 0, 2]
    last_row2 = homogeneous(R)
    last_row2[3] = [0.1, 0, 0, 1]
    nan = homogeneous(R)
    nan[0, 3] = np.nan
    inf = homogeneous(R)
    inf[1, 1] = np.inf
    return [
        ("zero_rotation", [0.0] * 12 + [0.0, 0.0, 0.0, 1.0]),
        ("diag_1e-300", values(np.diag([1e-300, 1e-300, 1e-300, 1.0]))),
        ("scaled_2R", values(homogeneous(2 * R))),
        ("sheared", values(homogeneous(R @ np.array([[1, 0.3, 0], [0, 1, 0], [0, 0, 1]])))),
        ("reflection_det_-1", values(homogeneous(R @ np.diag([1.0, 1.0, -1.0])))),
        ("last_row_0002", values(last_row)),
        ("last_row_not_zero", values(last_row2)),
        ("15_values", values(homogeneous(R))[:15]),
        ("17_values", values(homogeneous(R)) + [0.0]),
        ("nan_value", values(nan)),
        ("inf_value", values(inf)),
    ]


def run(tmp):
    pb, C = h.pb, h.C
    fx = h.Fixture(tmp, "b", prepare=lambda s: s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30))
    by = h.Bystander(fx.server())
    scan = h.synthetic_scan(3000, seed=11)

    # Each probe gets its own session, so that a pose wrongly accepted never meets another in one session's graph.
    # A translation the contract calls absurd (1e8 m or longer): refused, any wording.
    far = pb.IngestRequest(key=h.key("r", 0, session="b-far"), scan=scan,
                           odometry_pose=pb.Transform(m=values(homogeneous(rotation(), (1e9, 0.0, 0.0)))))
    h.probe("B.ingest_translation_1e9_m", lambda: h.expect_error(
        fx.server(), lambda t: fx.server().loop.Ingest(far, timeout=t), C.INVALID_ARGUMENT))

    # A matrix of the wrong size is named as such ("must have 16 values"); the others as not rigid.
    for name, m in bad_poses():
        req = pb.IngestRequest(key=h.key("r", 0, session=f"b-{name}"), scan=scan, odometry_pose=pb.Transform(m=m))
        words = ("16 values",) if len(m) != 16 else ("rigid",)
        h.probe(f"B.ingest_{name}", lambda req=req, words=words: h.expect_error(
            fx.server(), lambda t: fx.server().loop.Ingest(req, timeout=t), C.INVALID_ARGUMENT, words=words))

    zero = pb.Transform(m=[0.0] * 12 + [0.0, 0.0, 0.0, 1.0])
    reflection = pb.Transform(m=values(homogeneous(rotation() @ np.diag([1.0, 1.0, -1.0]))))

    def chunked(t):
        pts, lab = scan.points, scan.labels
        head = pb.IngestRequest(key=h.key("r", 0, session="b-chunked"), odometry_pose=zero)
        chunks = [pb.IngestChunk(header=head, points=pts[:12 * 1000], labels=lab[:4 * 1000]),
                  pb.IngestChunk(points=pts[12 * 1000:], labels=lab[4 * 1000:])]
        return fx.server().loop.IngestChunked(iter(chunks), timeout=t)
    h.probe("B.ingestchunked_zero_rotation", lambda: h.expect_error(fx.server(), chunked, C.INVALID_ARGUMENT,
                                                                     words=("rigid",)))

    def streamed(t):
        reqs = [pb.IngestRequest(key=h.key("r", 0, session="b-stream"), scan=scan, odometry_pose=reflection)]
        return list(fx.server().loop.IngestStream(iter(reqs), timeout=t))
    h.probe("B.ingeststream_reflection", lambda: h.expect_error(fx.server(), streamed, C.INVALID_ARGUMENT,
                                                                 words=("rigid",)))

    # Rigid motions, including ones whose rotation is off by float rounding, are stored (the server may
    # re-orthonormalise the rotation: the stored pose is the one sent up to rounding).
    R = rotation()
    good = [("rigid_pose_accepted", values(homogeneous(R))),
            ("identity_accepted", values(np.eye(4))),
            ("rotation_off_by_1e-6_accepted", values(homogeneous(R + 1e-6 * np.array([[0, 1, 0], [0, 0, 0],
                                                                                       [0, 0, 0]])))),
            ("float32_rounded_rotation_accepted", values(homogeneous(R.astype(np.float32).astype(np.float64))))]
    for i, (name, m) in enumerate(good):
        def accept(m=m, i=i):
            s = fx.server()
            req = pb.IngestRequest(key=h.key("r", i, session="b-good"), scan=scan, odometry_pose=pb.Transform(m=m))
            r = h.expect_ok(s, lambda t: s.loop.Ingest(req, timeout=t), stored=1)
            back = s.admin.GetScan(pb.GetScanRequest(scan_id=r.scan_id), timeout=30).odometry_pose.m
            assert len(back) == 16 and np.allclose(list(back), m, rtol=0, atol=1e-5), \
                f"expected the pose stored as sent (up to rounding), got {list(back)}"
        h.probe(f"B.{name}", accept)
    h.probe("B.other_clients_unaffected", by.finish)
    fx.stop()

    # The exact regression: two zero-rotation poses in one session, with queries (so a loop joins the graph).
    db = os.path.join(tmp, "regression.db")
    state = {}

    def rejected():
        s = state["s"] = h.Server(db)
        s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30)
        got = []
        frame = h.realistic_scan("000052", seed=12)
        for seq in (0, 1):
            req = pb.IngestRequest(key=h.key("r", seq, session="s"), scan=frame, odometry_pose=zero, query=True)
            try:
                r = s.loop.Ingest(req, timeout=30)
                got.append(f"seq {seq}: OK ({len(r.loops)} loops)")
            except h.grpc.RpcError as e:
                h.record(e)
                got.append(f"seq {seq}: {e.code().name} '{h.short(e.details(), 80)}'")
                if e.code() == C.INVALID_ARGUMENT and "rigid" in (e.details() or "").lower():
                    got[-1] = None
        bad = [g for g in got if g]
        assert not bad, f"expected both INVALID_ARGUMENT mentioning 'rigid', got {'; '.join(bad)}"

    def stays_up():
        s = state["s"]
        time.sleep(3)  # the old server aborted ~0.5 s after the second call
        s.assert_alive()
        st = s.admin.GetStats(pb.GetStatsRequest(map="m"), timeout=30)
        assert st.scans == 0, f"expected nothing stored, the map has {st.scans} scans"

    def restart_serves():
        s = state.pop("s")
        rc = s.stop()
        if rc is not None and rc < 0:
            h.note(f"the first server had died before the restart ({s.exit_reason()})")
        s = state["s"] = h.Server(db)
        time.sleep(3)
        s.assert_alive()
        s.admin.GetStats(pb.GetStatsRequest(map="m"), timeout=30)
        req = pb.IngestRequest(key=h.key("r", 2, session="s"), scan=scan, query=True)
        s.loop.Ingest(req, timeout=30)
        time.sleep(1)
        s.assert_alive()

    h.probe("B.zero_rotation_regression_rejected", rejected)
    if "s" in state:
        h.probe("B.zero_rotation_regression_server_stays_up_3s", stays_up)
        h.probe("B.zero_rotation_regression_restart_serves", restart_serves)
    if "s" in state:
        state["s"].stop()
