// Sends the live view what a broken or hostile viewer might, over the `ws` package, and prints the server's
// answers as JSON: the serverInfo, the channels advertised and the status messages. It sends each MESSAGE once
// the first advertisement came (text; "hex:0102" is sent as binary bytes) and ends when every one has been
// answered by a status message, or the connection closed.
//   node viz_raw.mjs URL [--protocol P] [MESSAGE...]
// A refused handshake prints {"error": "HTTP 400"} and exits 2.
import WebSocket from "ws";

const args = process.argv.slice(2);
const url = args[0];
let protocol = "foxglove.websocket.v1";
const messages = [];
for (let i = 1; i < args.length; i++) {
  if (args[i] === "--protocol") protocol = args[++i];
  else messages.push(args[i]);
}
const out = { serverInfo: null, channels: [], statuses: [], closed: false };
const ws = new WebSocket(url, [protocol]);
ws.on("unexpected-response", (req, res) => {
  let body = "";
  res.on("data", (d) => (body += d));
  res.on("end", () => {
    console.log(JSON.stringify({ error: `HTTP ${res.statusCode}`, body }));
    process.exit(2);
  });
});
let sent = false;
const finish = () => {
  console.log(JSON.stringify(out));
  process.exit(0);
};
ws.on("message", (data, binary) => {
  if (binary) return;
  const m = JSON.parse(data.toString());
  if (m.op === "serverInfo") out.serverInfo = m;
  if (m.op === "advertise") out.channels.push(...m.channels.map((c) => ({ id: c.id, topic: c.topic })));
  if (m.op === "status") out.statuses.push(m);
  if (!sent && m.op === "advertise") {
    sent = true;
    for (const msg of messages)
      ws.send(msg.startsWith("hex:") ? Buffer.from(msg.slice(4), "hex") : msg, { binary: msg.startsWith("hex:") });
  }
  if (sent && out.statuses.length >= messages.length) finish();
});
ws.on("close", () => {
  out.closed = true;
  finish();
});
