"""A live-view viewer that subscribes and then never reads again: what a frozen laptop or a viewer on a dead
link looks like to sglc-server --viz-listen. Plain sockets (RFC 6455 framing by hand), so that nothing
reads on its behalf."""
import json
import os
import socket
import struct


def _frame(text):
    """A masked text frame, as a client must send."""
    data, mask = text.encode(), os.urandom(4)
    head = bytes([0x81]) + (bytes([0x80 | len(data)]) if len(data) < 126 else bytes([0x80 | 126]) + struct.pack("!H", len(data)))
    return head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data))


def _read_exact(sock, n):
    out = b""
    while len(out) < n:
        part = sock.recv(n - len(out))
        if not part:
            raise ConnectionError("the server closed the connection")
        out += part
    return out


def _read_message(sock):
    """One whole message (fragments joined): (opcode, data)."""
    opcode, data = None, b""
    while True:
        b0, b1 = _read_exact(sock, 2)
        n = b1 & 0x7F
        if n == 126:
            n = struct.unpack("!H", _read_exact(sock, 2))[0]
        elif n == 127:
            n = struct.unpack("!Q", _read_exact(sock, 8))[0]
        if opcode is None:
            opcode = b0 & 0x0F
        data += _read_exact(sock, n)
        if b0 & 0x80:  # FIN
            return opcode, data


def _read_text(sock):
    opcode, data = _read_message(sock)
    return json.loads(data) if opcode == 1 else None


def stalled_viewer(port, prefix="", token=None):
    """Connects, subscribes to every channel of the first advertisement whose topic starts with `prefix`, and
    returns the socket (with a small receive buffer) without reading again. Returns (socket, channels)."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=60)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    target = "/" + (f"?token={token}" if token else "")
    sock.sendall(f"GET {target} HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                 "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
                 "Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n".encode())
    head = b""
    while b"\r\n\r\n" not in head:
        head += _read_exact(sock, 1)
    if b" 101 " not in head.split(b"\r\n")[0]:
        raise ConnectionError(head.split(b"\r\n")[0].decode())
    channels = []
    while not channels:
        m = _read_text(sock)
        if m and m.get("op") == "advertise":
            channels = [c for c in m["channels"] if c["topic"].startswith(prefix)]
    subs = [{"id": i, "channelId": c["id"]} for i, c in enumerate(channels)]
    sock.sendall(_frame(json.dumps({"op": "subscribe", "subscriptions": subs})))
    return sock, channels
