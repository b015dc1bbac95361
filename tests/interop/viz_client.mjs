// A live-view viewer built on @foxglove/ws-protocol's FoxgloveClient (Foxglove's own client library, over the
// `ws` package), as Foxglove itself connects: it subscribes to every channel advertised (or those whose topic
// starts with --prefix) and keeps the newest message of each. Prints what it saw as JSON.
//   node viz_client.mjs URL [--token T] [--prefix P] [--poses N] [--loops K] [--keyframe] [--timeout S]
//   node viz_client.mjs URL --hold [--viewers N]   (stay subscribed until SIGTERM, then print counts)
// Without --hold it ends when the trajectories under the prefix hold N poses in all, loop_list K loops,
// (--keyframe) a keyframe has points, and the map_stats topics (where advertised) count N scans in all; on timeout
// it prints what it had and exits 1. A refused connection (HTTP 401, 400) prints {"error": ...} and exits 2.
import wsProtocol from "@foxglove/ws-protocol";
const { FoxgloveClient } = wsProtocol;
import WebSocket from "ws";

const args = process.argv.slice(2);
const url = args[0];
const opt = (name, fallback) => {
  const i = args.indexOf(name);
  return i < 0 ? fallback : args[i + 1];
};
const token = opt("--token", null);
const prefix = opt("--prefix", "");
const wantPoses = Number(opt("--poses", "0"));
const wantLoops = Number(opt("--loops", "0"));
const wantKeyframe = args.includes("--keyframe");
const hold = args.includes("--hold");
const viewers = Number(opt("--viewers", "1"));
const timeoutS = Number(opt("--timeout", "120"));

function summary(schemaName, data) {
  if (schemaName === "foxglove.PosesInFrame") return { poses: data.poses.length, frame_id: data.frame_id,
                                                       last: data.poses.at(-1)?.position ?? null };
  if (schemaName === "sglc.LoopList") return { loops: data.loops.length, graph_version: data.graph_version,
                                               first: data.loops[0] ?? null };
  if (schemaName === "foxglove.SceneUpdate")
    return { entities: data.entities.map((e) => ({ id: e.id, points: e.lines[0].points.length,
                                                   metadata: e.metadata })) };
  if (schemaName === "foxglove.PointCloud")
    return { points: Buffer.from(data.data, "base64").length / data.point_stride, stride: data.point_stride,
             fields: data.fields.map((f) => f.name) };
  return data;
}

function connect(index) {
  const state = { serverInfo: null, channels: new Map(), topics: {}, statuses: [], messages: 0, closed: null };
  const headers = token ? { Authorization: `Bearer ${token}` } : {};
  const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL], { headers });
  ws.on("unexpected-response", (req, res) => {
    console.log(JSON.stringify({ error: `HTTP ${res.statusCode}` }));
    process.exit(2);
  });
  const client = new FoxgloveClient({ ws });
  client.on("serverInfo", (info) => (state.serverInfo = info));
  client.on("status", (s) => state.statuses.push(s));
  client.on("close", () => (state.closed = true));
  client.on("error", (e) => (state.error = String(e)));
  client.on("advertise", (channels) => {
    for (const c of channels) {
      state.channels.set(c.id, c);
      if (c.topic.startsWith(prefix)) client.subscribe(c.id);
    }
  });
  client.on("unadvertise", (ids) => ids.forEach((id) => state.channels.delete(id)));
  const bySubscription = new Map();
  client.on("message", ({ subscriptionId, timestamp, data }) => {
    state.messages++;
    if (hold) return;
    const channelId = bySubscription.get(subscriptionId);
    const c = state.channels.get(channelId);
    if (!c) return;
    const json = JSON.parse(new TextDecoder().decode(data));
    const t = (state.topics[c.topic] ??= { schemaName: c.schemaName, messages: 0 });
    t.messages++;
    t.timestamp = timestamp.toString();
    t.last = summary(c.schemaName, json);
    check();
  });
  // FoxgloveClient numbers subscriptions from 0 in the order subscribe() is called: keep the map alongside.
  const subscribe = client.subscribe.bind(client);
  client.subscribe = (channelId) => {
    const id = subscribe(channelId);
    bySubscription.set(id, channelId);
    return id;
  };
  state.client = client;
  return state;
}

const states = Array.from({ length: viewers }, (_, i) => connect(i));
const report = (s) => ({
  serverInfo: s.serverInfo && { name: s.serverInfo.name, capabilities: s.serverInfo.capabilities },
  channels: [...s.channels.values()].map((c) => ({ topic: c.topic, schemaName: c.schemaName,
                                                   encoding: c.encoding, schemaEncoding: c.schemaEncoding })),
  topics: s.topics, statuses: s.statuses, messages: s.messages, closed: s.closed });

function done(s) {
  let poses = 0, loops = 0, keyframe = false, scans = 0;
  for (const [topic, t] of Object.entries(s.topics)) {
    if (!topic.startsWith(prefix)) continue;
    if (topic.includes("/trajectory/")) poses += t.last.poses;
    if (topic.endsWith("/loop_list")) loops = t.last.loops;
    if (topic.endsWith("/keyframe") && t.last.points > 0) keyframe = true;
    if (topic.endsWith("/map_stats")) scans += t.last.scans;
  }
  // An update's map statistics follow its trajectories: when advertised, wait for those of as many scans.
  const stats = [...s.channels.values()].some((c) => c.topic.startsWith(prefix) && c.topic.endsWith("/map_stats"));
  return s.serverInfo && poses >= wantPoses && loops >= wantLoops && (!wantKeyframe || keyframe) &&
         (!stats || scans >= wantPoses);
}
function check() {
  if (hold || !done(states[0])) return;
  console.log(JSON.stringify(report(states[0])));
  process.exit(0);
}
if (hold) {
  process.on("SIGTERM", () => {
    console.log(JSON.stringify({ viewers: states.length, messages: states.map((s) => s.messages),
                                 closed: states.filter((s) => s.closed).length }));
    process.exit(0);
  });
} else {
  setTimeout(() => {
    console.log(JSON.stringify({ timeout: true, ...report(states[0]) }));
    process.exit(1);
  }, timeoutS * 1000);
  setInterval(check, 200);
}
