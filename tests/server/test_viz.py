#!/usr/bin/env python3
"""End-to-end tests of the live view (sglc-server --viz-listen): Foxglove's own WebSocket client
(@foxglove/ws-protocol), the page in Debian's Chromium (playwright-core), tokens, hostile viewers.

Usage: test_viz.py SERVER_BINARY PYTHON_STUB_DIR SIM_BINARY SGLC_CLI ARTEFACT_DIR
The page's screenshot is kept as ARTEFACT_DIR/viz_page.png. Exit 77 when grpcio/numpy are missing."""
import json
import os
import shutil
import subprocess
import sys
import urllib.request

try:
    import grpc  # noqa: F401
except ImportError as e:
    print(f"SKIP: {e} (needs Debian's python3-grpcio; run with /usr/bin/python3)")
    sys.exit(77)

SERVER, STUBS, SIM, CLI, ARTEFACTS = sys.argv[1:6]
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402
from harness import Server  # noqa: E402

pb, rpc = harness.configure(SERVER, STUBS)
INTEROP = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "interop")
sys.path.insert(0, INTEROP)
from stalled_viewer import stalled_viewer  # noqa: E402


def node(script, *args, timeout=240, check=True):
    """Runs one of tests/interop's scripts; returns (exit code, its JSON output)."""
    assert shutil.which("node") and os.path.isdir(os.path.join(INTEROP, "node_modules", "@foxglove", "ws-protocol")), \
        "node or tests/interop/node_modules is missing: run scripts/install-deps.sh"
    r = subprocess.run(["node", os.path.join(INTEROP, script), *map(str, args)], capture_output=True, text=True,
                       timeout=timeout)
    out = r.stdout.strip().splitlines()
    assert out, f"{script} printed nothing (exit {r.returncode}): {r.stderr[-2000:]}"
    if check:
        assert r.returncode == 0, f"{script} exit {r.returncode}: {out[-1][:3000]} {r.stderr[-2000:]}"
    return r.returncode, json.loads(out[-1])


def simulate(tmp):
    seq = os.path.join(tmp, "seq")
    subprocess.run([SIM, "--route", "loop", "--frames", "::8", "--odom-noise", "0.02", "--out", seq], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=300)
    return seq


def ingest(s, seq, robot, frames, m="m", token=None, extra=()):
    cmd = [CLI, "ingest", "--server", s.addr, "--map", m, "--robot", robot, "--session", robot, "--frames", frames,
           "--query", "--no-progress", *extra, seq]
    if token:
        cmd += ["--token", token]
    subprocess.run(cmd, check=True, capture_output=True, timeout=600)


def server_counts(s, m="m"):
    poses = s.graph.GetPoses(pb.GetPosesRequest(map=m, page_size=10000)).poses
    loops = s.graph.GetLoops(pb.GetLoopsRequest(map=m, page_size=10000)).loops
    return len(poses), len(loops)


def test_live_view(tmp):
    # Two robots drive the loop route (a frames 0-129, b 110-238): the page, open before they start, draws the
    # map as it grows (with the newest keyframe); then Foxglove's client and the page agree with the server.
    seq = simulate(tmp)
    # With the lifelong policy on (two versions per place; nothing retires within the test), so that the page and
    # the client show places.
    s = Server(os.path.join(tmp, "viz.db"), extra=["--viz-listen", "127.0.0.1:0", "--metrics-listen", "127.0.0.1:0",
                                                   "--viz-interval-s", "0.2", "--set", "map.max_versions_per_place=2"])
    try:
        port = s.logged_port("viz")
        url = f"http://127.0.0.1:{port}/"
        page = urllib.request.urlopen(url, timeout=30)
        assert page.headers["Content-Type"].startswith("text/html")
        html = page.read().decode()
        assert "foxglove.websocket.v1" in html and "<script src" not in html  # nothing fetched from elsewhere
        os.makedirs(ARTEFACTS, exist_ok=True)
        shot = os.path.join(ARTEFACTS, "viz_page.png")
        browser = subprocess.Popen(["node", os.path.join(INTEROP, "viz_browser.mjs"), url, shot, "--poses", "20",
                                    "--robots", "1", "--keyframe", "--timeout", "300", "--then-stdin"],
                                   stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        ingest(s, seq, "a", "0:130")
        ingest(s, seq, "b", "110:239")
        live = json.loads(browser.stdout.readline())["live"]
        assert live["connected"] and live["drawn"]["points"] > 100, live  # the newest keyframe, drawn live
        poses, loops = server_counts(s)
        assert poses == 259 and loops > 100, (poses, loops)
        # The page settles on exactly the server's poses and loops.
        out, err = browser.communicate(json.dumps({"poses": poses, "loops": loops, "robots": 2, "exact": True}) + "\n",
                                       timeout=300)
        drawn = json.loads(out.strip().splitlines()[-1])
        assert browser.returncode == 0, (drawn, err[-2000:])
        assert drawn["errors"] == [], drawn["errors"]
        assert drawn["maps"] == ["m"] and drawn["counts"]["inter"] > 0 and drawn["counts"]["intra"] > 0, drawn
        # The map's statistics, as GetStats gives them: places and their versions (robot b's second pass over a's
        # frames 110-129 and the route's own revisits put scans in places that hold their versions).
        stats = s.admin.GetStats(pb.GetStatsRequest(map="m"))
        assert 0 < stats.places and stats.versions < stats.scans == 259, stats
        assert drawn["mapStats"] == {"scans": 259, "places": stats.places, "versions": stats.versions,
                                     "retired_scans": 0, "retired_bytes": 0}, drawn["mapStats"]
        assert f"places {stats.places} ({stats.versions} versions)" in drawn["stats"], drawn["stats"]
        # It is on the canvas: pixels in the first robot's colour and in both loop colours (loops are drawn over
        # the trajectories, and the solve's timing moves them a little: bounds well below the ~900-7000 seen).
        px = drawn["pixels"]
        assert px["trajectory"] > 300 and px["intra"] > 50 and px["inter"] > 50, px
        assert os.path.getsize(shot) > 10000

        # Foxglove's client: every topic in Foxglove's schemas, and the same poses and loops as the server's.
        _, got = node("viz_client.mjs", f"ws://127.0.0.1:{port}/", "--poses", poses, "--loops", loops)
        schemas = {c["topic"]: c["schemaName"] for c in got["channels"]}
        assert schemas == {"/sglc/m/trajectory/a": "foxglove.PosesInFrame", "/sglc/m/trajectory/b": "foxglove.PosesInFrame",
                           "/sglc/m/odometry/a": "foxglove.PosesInFrame", "/sglc/m/odometry/b": "foxglove.PosesInFrame",
                           "/sglc/m/loops": "foxglove.SceneUpdate", "/sglc/m/loop_list": "sglc.LoopList",
                           "/sglc/m/keyframe": "foxglove.PointCloud", "/sglc/m/events": "sglc.MapEvent",
                           "/sglc/m/map_stats": "sglc.MapStats"}, schemas
        assert all(c["encoding"] == "json" and c["schemaEncoding"] == "jsonschema" for c in got["channels"])
        t = got["topics"]
        assert t["/sglc/m/trajectory/a"]["last"]["poses"] == 130 and t["/sglc/m/trajectory/b"]["last"]["poses"] == 129
        scene = t["/sglc/m/loops"]["last"]["entities"]
        assert sum(e["points"] for e in scene) == 2 * loops
        assert t["/sglc/m/loop_list"]["last"]["loops"] == loops
        assert t["/sglc/m/events"]["last"]["graph_version"] >= 1
        assert t["/sglc/m/map_stats"]["last"]["places"] == stats.places, t["/sglc/m/map_stats"]
        # The server's optimised pose of b's last scan is the trajectory's last pose.
        last_b = [p for p in s.graph.GetPoses(pb.GetPosesRequest(map="m", page_size=10000)).poses if p.robot == "b"][-1]
        T = last_b.t_map_scan.m
        end = t["/sglc/m/trajectory/b"]["last"]["last"]
        assert max(abs(end["x"] - T[3]), abs(end["y"] - T[7]), abs(end["z"] - T[11])) < 1e-6

        metrics = urllib.request.urlopen(f"http://127.0.0.1:{s.logged_port('metrics')}/metrics", timeout=30).read()
        text = metrics.decode()
        assert 'sglc_viz_connections_total{result="accepted"}' in text and "sglc_viz_viewers" in text
        assert 'sglc_viz_messages_total{result="sent"}' in text

        # A deleted map's topics are unadvertised: a new viewer is offered none of them.
        s.admin.DeleteMap(pb.DeleteMapRequest(map="m"))
        s.admin.CreateMap(pb.CreateMapRequest(name="other"))
        ingest(s, seq, "c", "0:3", m="other", extra=["--store-raw"])
        _, got = node("viz_client.mjs", f"ws://127.0.0.1:{port}/", "--poses", 3)
        assert all(c["topic"].startswith("/sglc/other/") for c in got["channels"]), got["channels"]

        # The MCAP export has the live view's topics, and the keyframes' points of scans stored with --store-raw.
        out = os.path.join(tmp, "export")
        done = subprocess.run([CLI, "export", "--server", s.addr, "--map", "other", "--format", "mcap", "--out", out],
                              check=True, capture_output=True, text=True, timeout=120)
        assert "3 keyframes' points" in done.stderr, done.stderr
        r = subprocess.run(["node", os.path.join(INTEROP, "read_mcap.mjs"), os.path.join(out, "graph.mcap")],
                           check=True, capture_output=True, text=True, timeout=120)
        mcap = json.loads(r.stdout)
        clouds = [m["data"] for m in mcap["messages"]["/sglc/keyframes/c"]]
        assert len(clouds) == 3 and all(c["point_stride"] == 12 and len(c["data"]) > 1000 for c in clouds)
        assert "foxglove.PointCloud" in mcap["indexed"]["schemas"]
    finally:
        assert s.stop() == 0


def test_tokens_and_hostile_viewers(tmp):
    seq = simulate(tmp)
    tokens = os.path.join(tmp, "tokens.txt")
    with open(tokens, "w") as f:
        f.write("admin-token-123 *\nfleet-token-456 m\n")
    s = Server(os.path.join(tmp, "auth.db"), extra=["--viz-listen", "127.0.0.1:0", "--tokens", tokens])
    try:
        admin = [("authorization", "Bearer admin-token-123")]
        for m in ("m", "secret"):
            s.admin.CreateMap(pb.CreateMapRequest(name=m), metadata=admin)
            ingest(s, seq, "r", "0:5", m=m, token="admin-token-123")
        ws = f"ws://127.0.0.1:{s.logged_port('viz')}/"
        # No token, a wrong one: refused before the WebSocket opens.
        assert node("viz_client.mjs", ws, "--timeout", 60, check=False) == (2, {"error": "HTTP 401"})
        assert node("viz_client.mjs", ws, "--token", "wrong-token", "--timeout", 60, check=False)[0] == 2
        # A token sees the maps it grants, by header or (as a browser must) in the URL.
        for args in (["--token", "fleet-token-456"], []):
            url = ws if args else ws + "?token=fleet-token-456"
            _, got = node("viz_client.mjs", url, *args, "--poses", 5)
            assert got["channels"] and all(c["topic"].startswith("/sglc/m/") for c in got["channels"]), got
        _, got = node("viz_client.mjs", ws + "?token=admin-token-123", "--poses", 10)
        assert {c["topic"].split("/")[2] for c in got["channels"]} == {"m", "secret"}

        # Bad messages get a status each and the connection goes on; another map's channel (never advertised to
        # this token) is refused as one that does not exist.
        _, admin_view = node("viz_raw.mjs", ws + "?token=admin-token-123")
        assert admin_view["serverInfo"]["name"].startswith("sglc-server")
        secret_channel = next(c["id"] for c in admin_view["channels"] if c["topic"].startswith("/sglc/secret/"))
        url = ws + "?token=fleet-token-456"
        _, got = node("viz_raw.mjs", url, "not json", "[1,2]", '{"op":"advertise"}', '{"op":"subscribe"}',
                      '{"op":"subscribe","subscriptions":[{"id":-1,"channelId":1}]}',
                      '{"op":"subscribe","subscriptions":[{"id":1,"channelId":%d}]}' % secret_channel,
                      '{"op":"unsubscribe","subscriptionIds":[77]}', "hex:01000000000000")
        assert not got["closed"] and len(got["statuses"]) == 8, got
        messages = " | ".join(st["message"] for st in got["statuses"])
        for words in ("JSON object", "unsupported op 'advertise'", "subscribe needs", "unsigned 32-bit",
                      f"no channel {secret_channel}", "no subscription 77", "binary messages"):
            assert words in messages, (words, messages)
        code, got = node("viz_raw.mjs", ws + "?token=admin-token-123", "--protocol", "json", check=False)
        assert code == 2 and got["error"] == "HTTP 400" and "foxglove.websocket.v1" in got["body"]

        # A viewer that stops reading never holds up ingest: the drive is stored, and a new viewer sees it all.
        stalled, subscribed = stalled_viewer(s.logged_port("viz"), "/sglc/m/", token="admin-token-123")
        assert len(subscribed) == 7, subscribed  # keyframe, events, trajectory, odometry, loops, loop_list, map_stats
        ingest(s, seq, "r2", "0:239", m="m", token="admin-token-123")
        _, got = node("viz_client.mjs", ws + "?token=admin-token-123", "--prefix", "/sglc/m/", "--poses", 244)
        assert got["topics"]["/sglc/m/trajectory/r2"]["last"]["poses"] == 239
        stalled.close()
    finally:
        assert s.stop() == 0


if __name__ == "__main__":
    harness.run([test_live_view, test_tokens_and_hostile_viewers], "sglc-viz-test-")
