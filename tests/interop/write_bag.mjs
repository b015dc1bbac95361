// Writes a bag from a JSON description with writers nobody in this project wrote: @mcap/core (MCAP),
// @foxglove/rosmsg + @foxglove/rosmsg2-serialization (ROS 2 CDR), @foxglove/wasm-zstd and Debian's lz4 tool
// (chunk compression), Python's sqlite3 (tests/interop/make_db3.py) for rosbag2 .db3 files. Used by the bag
// tests (tests/io/test_bags.cpp): the C++ readers must take what these produce.
//
//   node write_bag.mjs SPEC.json OUT      (OUT: an .mcap file, or a rosbag2 directory when storage is db3)
//
// SPEC: {"storage": "mcap" | "db3", "compression": "zstd" | "lz4" | "", "chunk_size": bytes,
//        "messages": [{"topic", "type": "pointcloud2" | "odometry" | "tf", "log_time_ns", ...the message}]}
// Or SPEC {"from_sequence": DIR, "points_topic", "odom_topic", "t0_ns", "storage", "compression"}: a
// simulated sequence directory (velodyne/NNNNNN.bin, poses.txt in the LiDAR frame, times.txt) as a drive: a
// PointCloud2 (x y z intensity, float32; with point_times/, also Ouster's t, uint32 ns) per scan and a
// nav_msgs/Odometry at each scan's stamp.
// A pointcloud2 message: stamp_ns, frame_id, height, width, is_bigendian, point_step, fields [{name, offset,
// datatype, count}], points [[one value per field, in field order]] (null for NaN); the data is packed here.
import { McapWriter } from "@mcap/core";
import { parse } from "@foxglove/rosmsg";
import { MessageWriter } from "@foxglove/rosmsg2-serialization";
import * as zstd from "@foxglove/wasm-zstd";
import { execFileSync } from "node:child_process";
import { readFileSync, mkdirSync, readdirSync, openSync, writeSync, closeSync, existsSync, unlinkSync } from "node:fs";
import { basename, dirname, join } from "node:path";
import { fileURLToPath } from "node:url";

const HEADER = `
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec`;
const VECTOR3 = `================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z`;
const QUATERNION = `================================================================================
MSG: geometry_msgs/Quaternion
float64 x
float64 y
float64 z
float64 w`;
const DEFINITIONS = {
  pointcloud2: ["sensor_msgs/msg/PointCloud2", `std_msgs/Header header
uint32 height
uint32 width
PointField[] fields
bool is_bigendian
uint32 point_step
uint32 row_step
uint8[] data
bool is_dense
================================================================================
MSG: sensor_msgs/PointField
string name
uint32 offset
uint8 datatype
uint32 count
================================================================================${HEADER}`],
  odometry: ["nav_msgs/msg/Odometry", `std_msgs/Header header
string child_frame_id
geometry_msgs/PoseWithCovariance pose
geometry_msgs/TwistWithCovariance twist
================================================================================
MSG: geometry_msgs/PoseWithCovariance
Pose pose
float64[36] covariance
================================================================================
MSG: geometry_msgs/Pose
Point position
Quaternion orientation
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
${QUATERNION}
================================================================================
MSG: geometry_msgs/TwistWithCovariance
Twist twist
float64[36] covariance
================================================================================
MSG: geometry_msgs/Twist
Vector3 linear
Vector3 angular
${VECTOR3}
================================================================================${HEADER}`],
  tf: ["tf2_msgs/msg/TFMessage", `geometry_msgs/TransformStamped[] transforms
================================================================================
MSG: geometry_msgs/TransformStamped
std_msgs/Header header
string child_frame_id
Transform transform
================================================================================
MSG: geometry_msgs/Transform
Vector3 translation
Quaternion rotation
${VECTOR3}
${QUATERNION}
================================================================================${HEADER}`],
};

const SIZES = [0, 1, 1, 2, 2, 4, 4, 4, 8];
const stamp = (ns) => ({ sec: Number(BigInt(ns) / 1000000000n), nanosec: Number(BigInt(ns) % 1000000000n) });

function packCloud(m) {
  const n = m.width * m.height;
  if (m.data) // already packed (a KITTI .bin is x y z intensity float32, little-endian: PointCloud2's layout)
    return { header: { stamp: stamp(m.stamp_ns), frame_id: m.frame_id }, height: m.height, width: m.width, fields: m.fields,
             is_bigendian: false, point_step: m.point_step, row_step: m.width * m.point_step, data: m.data, is_dense: true };
  const data = new Uint8Array(n * m.point_step);
  const view = new DataView(data.buffer);
  const le = !m.is_bigendian;
  m.points.forEach((p, i) => {
    m.fields.forEach((f, k) => {
      const at = i * m.point_step + f.offset;
      const v = p[k] === null ? NaN : p[k];
      switch (f.datatype) {
        case 1: view.setInt8(at, v); break;
        case 2: view.setUint8(at, v); break;
        case 3: view.setInt16(at, v, le); break;
        case 4: view.setUint16(at, v, le); break;
        case 5: view.setInt32(at, v, le); break;
        case 6: view.setUint32(at, v, le); break;
        case 7: view.setFloat32(at, v, le); break;
        case 8: view.setFloat64(at, v, le); break;
        default: throw new Error(`datatype ${f.datatype}`);
      }
    });
  });
  return {
    header: { stamp: stamp(m.stamp_ns), frame_id: m.frame_id },
    height: m.height, width: m.width, fields: m.fields, is_bigendian: m.is_bigendian,
    point_step: m.point_step, row_step: m.width * m.point_step, data, is_dense: false,
  };
}

const pose = (p, q) => ({ position: { x: p[0], y: p[1], z: p[2] }, orientation: { x: q[0], y: q[1], z: q[2], w: q[3] } });

function message(m) {
  if (m.type === "pointcloud2") return packCloud(m);
  if (m.type === "odometry")
    return {
      header: { stamp: stamp(m.stamp_ns), frame_id: m.frame_id }, child_frame_id: m.child_frame_id,
      pose: { pose: pose(m.position, m.orientation), covariance: new Array(36).fill(0) },
      twist: { twist: { linear: { x: 0, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } }, covariance: new Array(36).fill(0) },
    };
  return {
    transforms: m.transforms.map((t) => ({
      header: { stamp: stamp(t.stamp_ns), frame_id: t.frame_id }, child_frame_id: t.child_frame_id,
      transform: { translation: { x: t.position[0], y: t.position[1], z: t.position[2] },
                   rotation: { x: t.orientation[0], y: t.orientation[1], z: t.orientation[2], w: t.orientation[3] } },
    })),
  };
}

function compressor(name) {
  if (name === "zstd") return (data) => ({ compression: "zstd", compressedData: zstd.compress(data, 3) });
  if (name === "lz4")
    return (data) => ({ compression: "lz4", compressedData: new Uint8Array(execFileSync("lz4", ["-c", "-q"], { input: data, maxBuffer: 1 << 30 })) });
  return undefined;
}

// Rotation matrix (row-major 3x3 in a KITTI 3x4 line) to a quaternion [x, y, z, w].
function quaternion(m) {
  const [r00, r01, r02, , r10, r11, r12, , r20, r21, r22] = m;
  const tr = r00 + r11 + r22;
  let x, y, z, w;
  if (tr > 0) {
    const s = Math.sqrt(tr + 1) * 2;
    w = s / 4; x = (r21 - r12) / s; y = (r02 - r20) / s; z = (r10 - r01) / s;
  } else if (r00 > r11 && r00 > r22) {
    const s = Math.sqrt(1 + r00 - r11 - r22) * 2;
    w = (r21 - r12) / s; x = s / 4; y = (r01 + r10) / s; z = (r02 + r20) / s;
  } else if (r11 > r22) {
    const s = Math.sqrt(1 + r11 - r00 - r22) * 2;
    w = (r02 - r20) / s; x = (r01 + r10) / s; y = s / 4; z = (r12 + r21) / s;
  } else {
    const s = Math.sqrt(1 + r22 - r00 - r11) * 2;
    w = (r10 - r01) / s; x = (r02 + r20) / s; y = (r12 + r21) / s; z = s / 4;
  }
  const n = Math.hypot(x, y, z, w);
  return [x / n, y / n, z / n, w / n];
}

function sequenceMessages(spec) {
  const dir = spec.from_sequence;
  const lines = (name) => readFileSync(join(dir, name), "utf8").split("\n").filter((l) => l.trim() && !l.startsWith("#"));
  const poses = lines("poses.txt").map((l) => l.trim().split(/\s+/).map(Number));
  const times = lines("times.txt").map(Number);
  const scans = readdirSync(join(dir, "velodyne")).filter((f) => f.endsWith(".bin")).sort();
  const t0 = BigInt(spec.t0_ns ?? "1700000000000000000");
  const out = [];
  scans.forEach((file, k) => {
    const stamp = t0 + BigInt(Math.round(times[k] * 1e9));
    let data = new Uint8Array(readFileSync(join(dir, "velodyne", file)));
    const fields = ["x", "y", "z", "intensity"].map((name, j) => ({ name, offset: 4 * j, datatype: 7, count: 1 }));
    let step = 16;
    const timesFile = join(dir, "point_times", file);
    if (existsSync(timesFile)) {
      // Ouster's convention: t, uint32 ns after the stamp, after x y z intensity.
      const times = new Float32Array(new Uint8Array(readFileSync(timesFile)).buffer);
      const n = data.length / 16;
      const packed = new Uint8Array(n * 20);
      const view = new DataView(packed.buffer);
      for (let i = 0; i < n; ++i) {
        packed.set(data.subarray(i * 16, i * 16 + 16), i * 20);
        view.setUint32(i * 20 + 16, Math.round(times[i] * 1e9), true);
      }
      fields.push({ name: "t", offset: 16, datatype: 6, count: 1 });
      data = packed;
      step = 20;
    }
    out.push({ topic: spec.points_topic, type: "pointcloud2", log_time_ns: (stamp + 5000000n).toString(), stamp_ns: stamp.toString(),
               frame_id: "velodyne", height: 1, width: data.length / step, is_bigendian: false, point_step: step, fields, data });
    const m = poses[k];
    out.push({ topic: spec.odom_topic, type: "odometry", log_time_ns: stamp.toString(), stamp_ns: stamp.toString(), frame_id: "odom",
               child_frame_id: "velodyne", position: [m[3], m[7], m[11]], orientation: quaternion([m[0], m[1], m[2], 0, m[4], m[5], m[6], 0, m[8], m[9], m[10]]) });
  });
  return out;
}

const [specPath, out] = process.argv.slice(2);
const spec = JSON.parse(readFileSync(specPath, "utf8"));
if (spec.from_sequence) spec.messages = sequenceMessages(spec);
await zstd.isLoaded;
const writers = {};
const encoded = spec.messages.map((m) => {
  const [type, text] = DEFINITIONS[m.type];
  writers[m.type] ??= new MessageWriter(parse(text, { ros2: true }));
  return { topic: m.topic, type, text, log_time_ns: BigInt(m.log_time_ns), data: writers[m.type].writeMessage(message(m)) };
});

if (spec.storage === "db3") {
  // make_db3.py reads the messages as JSON lines (data in base64) and writes OUT/OUT-name_0.db3 + metadata.yaml;
  // the lines go through a file, one message at a time (a long drive is more than a string can hold).
  mkdirSync(out, { recursive: true });
  const linesPath = join(out, "..", `.${basename(out)}.lines`);
  const fd = openSync(linesPath, "w");
  for (const e of encoded)
    writeSync(fd, JSON.stringify({ topic: e.topic, type: e.type, log_time_ns: e.log_time_ns.toString(),
                                   data: Buffer.from(e.data).toString("base64") }) + "\n");
  closeSync(fd);
  const input = openSync(linesPath, "r");
  execFileSync("/usr/bin/python3", [join(dirname(fileURLToPath(import.meta.url)), "make_db3.py"), out], { stdio: [input, "inherit", "inherit"] });
  closeSync(input);
  unlinkSync(linesPath);
} else {
  // Written straight to the file (an in-memory buffer of a long drive grows by copying).
  const fd = openSync(out, "w");
  let position = 0n;
  const writable = { position: () => position, write: async (data) => { writeSync(fd, data); position += BigInt(data.byteLength); } };
  const writer = new McapWriter({ writable, useChunks: spec.compression !== "nochunks",
                                  chunkSize: spec.chunk_size ?? 1024 * 1024, compressChunk: compressor(spec.compression) });
  await writer.start({ profile: "ros2", library: "sglc tests via @mcap/core" });
  const channels = {};
  for (const e of encoded) {
    if (!(e.topic in channels)) {
      const schemaId = await writer.registerSchema({ name: e.type, encoding: "ros2msg", data: new TextEncoder().encode(e.text) });
      channels[e.topic] = await writer.registerChannel({ topic: e.topic, schemaId, messageEncoding: "cdr", metadata: new Map() });
    }
    await writer.addMessage({ channelId: channels[e.topic], sequence: 0, logTime: e.log_time_ns, publishTime: e.log_time_ns, data: e.data });
  }
  await writer.end();
  closeSync(fd);
}
