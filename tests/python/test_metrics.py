"""sglc-server --metrics-listen: a real server scraped over HTTP while real scans go through it.

Every line of the exposition is checked against the text format's grammar; the counts must match the calls
made (per method and status code), histogram buckets must be cumulative and end in their _count.
"""
import math
import re
import subprocess
import time
import urllib.error
import urllib.request

import pytest

import sglc
from conftest import _binary, _free_port, start_server

SAMPLE = re.compile(r'^([a-zA-Z_:][a-zA-Z0-9_:]*)(\{(?:[a-zA-Z_][a-zA-Z0-9_]*="(?:[^"\\\n]|\\[\\"n])*",?)*\})? '
                    r'(-?[0-9.eE+-]+|[+-]Inf|NaN)$')
LABEL = re.compile(r'([a-zA-Z_][a-zA-Z0-9_]*)="((?:[^"\\]|\\.)*)"')


def parse(text):
    """{(name, frozenset(labels)): value}, with every line checked; TYPE of each family."""
    samples, types = {}, {}
    for line in text.splitlines():
        if line.startswith("# HELP "):
            continue
        if line.startswith("# TYPE "):
            _, _, name, kind = line.split(" ")
            assert kind in ("counter", "gauge", "histogram"), line
            types[name] = kind
            continue
        m = SAMPLE.match(line)
        assert m, f"not a valid sample line: {line!r}"
        labels = frozenset(LABEL.findall(m.group(2) or ""))
        key = (m.group(1), labels)
        assert key not in samples, f"duplicate series {line!r}"
        samples[key] = float(m.group(3))
    return samples, types


def value(samples, name, **labels):
    return samples.get((name, frozenset(labels.items())), 0.0)


@pytest.fixture(scope="module")
def metrics_server(tmp_path_factory):
    proc, address, args = start_server(tmp_path_factory.mktemp("metrics"),
                                       ["--metrics-listen", "127.0.0.1:{port}", "--viz-listen", "127.0.0.1:0"])
    yield address, f"http://{args[1]}/metrics"
    proc.terminate()
    proc.wait(timeout=60)


def scrape(url):
    with urllib.request.urlopen(url, timeout=30) as r:
        assert r.status == 200 and r.headers["Content-Type"].startswith("text/plain; version=0.0.4")
        return parse(r.read().decode())


def test_scrape_counts_calls_stages_and_sizes(metrics_server, kitti):
    address, url = metrics_server
    with sglc.Client(address, timeout=120) as c:
        c.create_map("gone")
        c.delete_map("gone")  # a deletion is no pose-graph solve
        before, _ = scrape(url)
        assert not any(v for (n, _), v in before.items() if n == "sglc_pose_graph_solve_seconds_count"), before
        c.create_map("m")
        c.ingest("m", "a", "s", 52, *kitti("000052"), odometry_pose=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
        r = c.ingest("m", "b", "s", 4501, *kitti("004501"), query=True, scope="other",
                     odometry_pose=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
        assert r.loops
        with pytest.raises(sglc.AlreadyExistsError):
            c.ingest("m", "a", "s", 52, *kitti("000088"))
        with pytest.raises(sglc.NotFoundError):
            c.list_robots("nosuch")
        c.query("m", scan_id=r.scan_id)
        with c.watch("m") as w:  # the loop is solved: one solve time recorded
            next(w)
    samples, types = scrape(url)

    rpc = "sglc_rpc_requests_total"
    assert types[rpc] == "counter" and types["sglc_rpc_duration_seconds"] == "histogram"
    svc = "sglc.v1.LoopClosure"
    assert value(samples, rpc, service=svc, method="Ingest", code="OK") == 2
    assert value(samples, rpc, service=svc, method="Ingest", code="ALREADY_EXISTS") == 1
    assert value(samples, rpc, service="sglc.v1.MapAdmin", method="ListRobots", code="NOT_FOUND") == 1
    assert value(samples, rpc, service=svc, method="Query", code="OK") == 1
    assert value(samples, "sglc_rpc_duration_seconds_count", service=svc, method="Ingest", code="OK") == 2

    # Histograms: cumulative buckets ending at _count.
    for (name, labels), count in samples.items():
        if not name.endswith("_count") or types.get(name[:-6]) != "histogram":
            continue
        base = name[:-6]
        buckets = sorted(((float(dict(l)["le"]) if dict(l)["le"] != "+Inf" else math.inf, v)
                          for (n, l), v in samples.items()
                          if n == base + "_bucket" and l - {("le", dict(l)["le"])} == labels))
        assert buckets[-1] == (math.inf, count), (base, labels)
        assert all(a[1] <= b[1] for a, b in zip(buckets, buckets[1:])), (base, labels)

    # Stage timings: fingerprints of the 3 ingests (the refused one is fingerprinted before the key check or
    # not: at least the 2 stored), 2 stores, searches of the ingest query and the query.
    stage = "sglc_stage_duration_seconds_count"
    assert value(samples, stage, stage="fingerprint") >= 2
    assert value(samples, stage, stage="store") == 2
    assert value(samples, stage, stage="search") == 2 and value(samples, stage, stage="verify") >= 1
    assert sum(v for (n, _), v in samples.items() if n == "sglc_pose_graph_solve_seconds_count") >= 1

    # Sizes and queues, read at the scrape.
    assert value(samples, "sglc_map_scans", map="m") == 2 and value(samples, "sglc_maps") == 1
    assert value(samples, "sglc_index_entries") == 2 and value(samples, "sglc_db_bytes") > 0
    # The policy of lifelong maps is off by default: no places, nothing retired.
    assert value(samples, "sglc_places") == 0 and value(samples, "sglc_retired_scans") == 0
    assert value(samples, "sglc_place_versions") == 0 and value(samples, "sglc_retired_bytes") == 0
    assert value(samples, "sglc_compute_queue_depth") == 0 and value(samples, "sglc_inflight_bytes") == 0
    assert value(samples, "sglc_inflight_bytes_limit") > 0 and value(samples, "process_resident_memory_bytes") > 0
    assert value(samples, "sglc_build_info", version=sglc.__version__) == 1

    # What the operators graph: scans by label source (the refused retry is not counted), loop candidates by
    # outcome (the ingest query and the stored-scan query each verified the other robot's scan), the pose
    # graph's loops per map.
    ingested = "sglc_scans_ingested_total"
    assert types[ingested] == "counter" and value(samples, ingested, label_source="provided") == 2
    assert sum(v for (n, _), v in samples.items() if n == ingested) == 2
    cands = "sglc_loop_candidates_total"
    assert value(samples, cands, result="verified", reason="") == 2
    refused = {dict(l)["reason"] for (n, l), v in samples.items() if n == cands and dict(l)["result"] == "refused"}
    assert refused <= {"low_probability", "no_pose", "narrow_view", "landmarks", "translation"}, refused
    assert value(samples, "sglc_pose_graph_loops", map="m", state="accepted") == 1
    assert value(samples, "sglc_pose_graph_loops", map="m", state="rejected") == 0


def test_dashboard_and_alerts_name_only_metrics_the_server_exports(metrics_server):
    """Every metric the Grafana dashboard and the alert rules query is one the server declares, with the
    labels they use; the rules pass promtool's own checks and unit tests."""
    import json
    import os
    import shutil
    from conftest import REPO
    _, url = metrics_server
    with urllib.request.urlopen(url, timeout=30) as r:
        text = r.read().decode()
    declared = {line.split(" ")[2]: line.split(" ")[3] for line in text.splitlines() if line.startswith("# TYPE ")}
    labels_seen = {}
    for line in text.splitlines():
        m = SAMPLE.match(line)
        if m:
            labels_seen.setdefault(m.group(1), set()).update(k for k, _ in LABEL.findall(m.group(2) or ""))
    dashboard = json.load(open(os.path.join(REPO, "deploy", "grafana", "sglc-dashboard.json")))
    exprs = [t["expr"] for p in dashboard["panels"] for t in p["targets"]]
    rules_path = os.path.join(REPO, "deploy", "prometheus", "sglc-alerts.yml")
    exprs += re.findall(r"expr: >?\s*(.+?)(?=\n\s+(?:for|labels):)", open(rules_path).read(), re.S)
    assert len(exprs) >= 20, exprs
    for expr in exprs:
        for name in re.findall(r"\b((?:sglc|process)_[a-z_]+)", expr):
            base = re.sub(r"_(bucket|count|sum)$", "", name) if name.endswith(("_bucket", "_count", "_sum")) else name
            assert base in declared, f"{name} in {expr!r} is no metric of the server"
            if name != base:
                assert declared[base] == "histogram", name
    promtool = shutil.which("promtool")
    assert promtool, "promtool is missing (Debian's prometheus package: run scripts/install-deps.sh)"
    for args in (["check", "rules", rules_path], ["test", "rules", os.path.join(REPO, "tests", "deploy", "sglc-alerts.test.yml")]):
        done = subprocess.run([promtool, *args], capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, f"promtool {' '.join(args)}: {done.stdout}{done.stderr}"


def test_other_paths_and_methods(metrics_server):
    _, url = metrics_server
    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.urlopen(url.replace("/metrics", "/"), timeout=30)
    assert e.value.code == 404
    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.urlopen(urllib.request.Request(url, data=b"x", method="POST"), timeout=30)
    assert e.value.code == 405


def test_promtool_accepts_the_exposition(metrics_server):
    """Prometheus' own checker (promtool, from Debian's prometheus package) reads a real scrape: no parse
    error, no lint finding. Taken after calls to unknown method paths, which count under method="unknown"."""
    import shutil
    import grpc
    promtool = shutil.which("promtool")
    assert promtool, "promtool is missing (Debian's prometheus package: run scripts/install-deps.sh)"
    address, url = metrics_server
    with grpc.insecure_channel(address) as ch:
        for path in ("/no.such.Service/Call", "/sglc.v1.LoopClosure/NoSuchMethod", "/" + "x" * 3000):
            call = ch.unary_unary(path, request_serializer=lambda b: b, response_deserializer=lambda b: b)
            with pytest.raises(grpc.RpcError) as e:
                call(b"", timeout=30)
            assert e.value.code() == grpc.StatusCode.UNIMPLEMENTED
    with urllib.request.urlopen(url, timeout=30) as r:
        text = r.read().decode()
    samples, _ = parse(text)
    unknown = [labels for (name, labels) in samples if name == "sglc_rpc_requests_total"
               and ("method", "unknown") in labels]
    assert unknown and all(("service", "unknown") in labels for labels in unknown), unknown
    assert "NoSuchMethod" not in text and "no.such" not in text
    done = subprocess.run([promtool, "check", "metrics"], input=text, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, f"promtool: {done.stdout}{done.stderr}"


def test_bad_metrics_address_stops_the_server(tmp_path):
    binary = _binary("SGLC_SERVER_BIN", "sglc-server")
    if binary is None:
        pytest.skip("sglc-server is not built")
    done = subprocess.run([binary, "--db", str(tmp_path / "x.db"), "--listen", f"127.0.0.1:{_free_port()}",
                           "--metrics-listen", "127.0.0.1"], capture_output=True, text=True, timeout=120)
    assert done.returncode != 0 and "metrics address '127.0.0.1' is not host:port" in done.stderr


def test_log_lines_are_json_objects(tmp_path, kitti):
    """Every line the server writes (start, calls that fail with hostile names, shutdown) is one JSON object."""
    import json
    import signal
    binary = _binary("SGLC_SERVER_BIN", "sglc-server")
    if binary is None:
        pytest.skip("sglc-server is not built")
    address = f"127.0.0.1:{_free_port()}"
    with open(tmp_path / "log", "wb") as log:
        proc = subprocess.Popen([binary, "--db", str(tmp_path / "x.db"), "--listen", address], stdout=log,
                                stderr=subprocess.STDOUT)
        try:
            deadline = time.monotonic() + 120
            with sglc.Client(address, timeout=30) as c:
                while not c.serving(timeout=2) and time.monotonic() < deadline and proc.poll() is None:
                    time.sleep(0.05)
                c.create_map("m")
                with pytest.raises(sglc.NotFoundError):
                    c.list_robots('no "such"\nmap\\')
                c.ingest("m", "r", "s", 1, *kitti("000052"))
        finally:
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(timeout=60) == 0
    lines = (tmp_path / "log").read_text().splitlines()
    assert len(lines) >= 5
    for line in lines:
        obj = json.loads(line)
        assert isinstance(obj, dict) and list(obj)[:2] == ["ts", "level"], line
    events = [json.loads(line) for line in lines]
    assert events[-1]["event"] == "stopped"
    assert any(e.get("method") == "ListRobots" and e.get("code") == "NOT_FOUND" and e["level"] == "warning"
               for e in events)
    assert any(e.get("method") == "Ingest" and e.get("code") == "OK" for e in events)
