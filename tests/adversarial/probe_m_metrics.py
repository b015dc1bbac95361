"""M. The metrics port under abuse. 100,000 calls to unknown gRPC method paths (up to 6 KB each, sent without a
token to a server that wants one) count under method="unknown": the exposition stays small and the server's
memory flat. Idle, half-sent, TLS and oversized connections to the metrics port do not keep a scrape from being
answered, also when idle connections from many addresses hold every slot."""
import os
import re
import socket
import time

import adv_harness as h

CLASS = "M"
TITLE = "metrics: unknown-method flood, idle and garbage connections"

TOKEN = "token-M-mmmmmmmmmmmm"
FLOOD = 100_000
WARM = 20_000
IN_FLIGHT = 256
GROWTH_LIMIT_MB = 32
SANITIZED = os.environ.get("SGLC_SANITIZED") == "1"


def scrape(port, source="127.0.0.1", timeout=30):
    """(status line, body, seconds) of GET /metrics from a given loopback source address."""
    t0 = time.monotonic()
    with socket.socket() as s:
        s.settimeout(timeout)
        s.bind((source, 0))
        s.connect(("127.0.0.1", port))
        s.sendall(b"GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n")
        data = b""
        while chunk := s.recv(65536):
            data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    return head.split(b"\r\n")[0].decode(errors="replace"), body.decode(errors="replace"), time.monotonic() - t0


def unknown_total(body):
    return sum(float(m.group(1)) for m in
               re.finditer(r'^sglc_rpc_requests_total\{service="unknown",method="unknown",code="[A-Z_]+"\} (\S+)$',
                           body, re.M))


def flood(s, start, count):
    """`count` unary calls to distinct unknown method paths, IN_FLIGHT at a time; returns their status codes."""
    codes = {}
    pending = []
    for i in range(start, start + count):
        path = f"/evil.Svc{i}/M" + "x" * (100 + (i * 7919) % 6000)
        pending.append(s.channel.unary_unary(path, request_serializer=lambda b: b,
                                             response_deserializer=lambda b: b).future(b"", timeout=60))
        if len(pending) >= IN_FLIGHT or i == start + count - 1:
            for f in pending:
                code = f.code().name
                codes[code] = codes.get(code, 0) + 1
            pending = []
    return codes


def label_flood(tmp):
    tokens = os.path.join(tmp, "tokens.txt")
    with open(tokens, "w") as f:
        f.write(f"{TOKEN} *\n")
    mport = h.free_port()
    s = h.Server(os.path.join(tmp, "flood.db"), ["--tokens", tokens, "--metrics-listen", f"127.0.0.1:{mport}"],
                 token=TOKEN)
    try:
        codes = flood(s, 0, WARM)
        time.sleep(1)
        before = s.rss_kb()["VmRSS"]
        codes2 = flood(s, WARM, FLOOD - WARM)
        for k, v in codes2.items():
            codes[k] = codes.get(k, 0) + v
        time.sleep(1)
        after = s.rss_kb()["VmRSS"]
        status, body, secs = scrape(mport)
        s.assert_alive()
    finally:
        s.stop()
    h.note(f"{FLOOD} unknown-method calls: {codes}; RSS {before / 1024:.0f} -> {after / 1024:.0f} MB over the last "
           f"{FLOOD - WARM}; scrape {len(body)} bytes in {secs:.2f} s")
    assert sum(codes.values()) == FLOOD and "OK" not in codes, f"expected {FLOOD} failed calls, got {codes}"
    assert status.startswith("HTTP/1.1 200"), f"expected a 200 scrape, got '{status}'"
    assert unknown_total(body) == FLOOD, f"expected {FLOOD} calls under method=\"unknown\", got {unknown_total(body)}"
    assert "evil.Svc" not in body, "a client's method path became a label value"
    assert len(body) < 256 * 1024, f"expected an exposition under 256 KB, got {len(body)} bytes"
    if SANITIZED:
        h.note("sanitized build: the RSS figures are reported, not checked")
    else:
        assert after - before < GROWTH_LIMIT_MB * 1024, \
            f"expected RSS to grow by under {GROWTH_LIMIT_MB} MB, grew {(after - before) / 1024:.0f} MB"


def held_connections(tmp):
    mport = h.free_port()
    s = h.Server(os.path.join(tmp, "held.db"), ["--metrics-listen", f"127.0.0.1:{mport}"])
    held = []
    try:
        for i in range(40):  # idle, from one peer (the server keeps 16 of them, and closes the rest at once)
            held.append(socket.create_connection(("127.0.0.1", mport)))
        for i in range(8):  # a slow sender's first bytes, from another peer
            c = socket.socket()
            c.bind(("127.0.0.2", 0))
            c.connect(("127.0.0.1", mport))
            c.sendall(b"GET /metrics HTTP/1.1\r\nHost: x")
            held.append(c)
        for payload in (b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03", b"GET /metrics HTTP/1.1\n\n",
                        b"GET /metrics HTTP/1.1\r\nX: " + b"a" * 20000):
            c = socket.socket()
            c.bind(("127.0.0.3", 0))
            c.connect(("127.0.0.1", mport))
            c.sendall(payload)
            held.append(c)
        status, body, secs = scrape(mport, source="127.0.0.4")
        h.note(f"scrape with 51 idle, slow and garbage connections open: {status} in {secs:.2f} s")
        assert status.startswith("HTTP/1.1 200"), f"expected a 200 scrape, got '{status}'"
        assert "sglc_metrics_read_age_seconds" in body and "sglc_maps " in body, "expected the gauges"
        for payload_sock, want in zip(held[-3:], ("400", "400", "431")):
            payload_sock.settimeout(30)
            answer = payload_sock.recv(200).decode(errors="replace")
            assert answer.startswith(f"HTTP/1.1 {want}"), f"expected {want}, got '{h.short(answer)}'"
        # Every slot held by idle connections from 16 addresses (16 each: the per-peer and the total limit): a
        # scrape from another address takes the oldest idle one's slot.
        for a in range(16):
            for _ in range(16):
                c = socket.socket()
                c.bind((f"127.0.1.{a + 1}", 0))
                c.connect(("127.0.0.1", mport))
                held.append(c)
        status, body, secs = scrape(mport, source="127.0.0.5")
        h.note(f"scrape with every slot held by idle connections from 16 addresses: {status} in {secs:.2f} s")
        assert status.startswith("HTTP/1.1 200"), f"expected a 200 scrape on a full server, got '{status}'"
        s.assert_alive()
    finally:
        for c in held:
            c.close()
        s.stop()


def run(tmp):
    h.probe("M.unknown_method_flood_keeps_memory_and_exposition_flat", label_flood, tmp)
    h.probe("M.idle_and_garbage_connections_do_not_hold_a_scrape", held_connections, tmp)
