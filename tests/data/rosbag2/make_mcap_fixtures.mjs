// Writes the MCAP fixtures of tests/test_io_mcap.cpp with the reference MCAP
// writer (@mcap/core), so that rcm's reader is checked against an independent
// implementation rather than against itself. Dev tool: the build never runs it.
//
//   mkdir /tmp/mcapgen && cd /tmp/mcapgen && npm init -y
//   npm install @mcap/core@2.2.2 @foxglove/wasm-zstd@1.0.1 lz4js@0.2.0
//   node /path/to/rcm/tests/data/rosbag2/make_mcap_fixtures.mjs [output_dir]
//
// The output is deterministic: same package versions give byte-identical files.
import { writeFileSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import { createRequire } from "node:module";

// Resolve packages from the working directory (the scratch install), not from
// this script's folder inside the repository.
const require = createRequire(join(process.cwd(), "package.json"));
const { McapWriter } = await import(require.resolve("@mcap/core"));
const zstd = require("@foxglove/wasm-zstd");
const lz4js = require("lz4js");
await zstd.isLoaded;

const out_dir = process.argv[2] ?? dirname(fileURLToPath(import.meta.url));

const JOINT_STATE_MSG = `# This is a message that holds data to describe the state of a set of torque controlled joints.
std_msgs/Header header

string[] name
float64[] position
float64[] velocity
float64[] effort

================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id

================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
`;

const WRENCH_STAMPED_MSG = `# A wrench with reference coordinate frame and timestamp
std_msgs/Header header
Wrench wrench

================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id

================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec

================================================================================
MSG: geometry_msgs/Wrench
Vector3  force
Vector3  torque

================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
`;

const JOINTS = ["outer_yaw", "outer_pitch", "outer_insertion", "outer_roll",
  "outer_wrist_pitch", "outer_wrist_yaw", "jaw"];
const T0_NS = 1_700_000_000_000_000_000n;
const JOINT_STATE_COUNT = 50;
const WRENCH_COUNT = 20;

// ROS 2 CDR (XCDR1, little-endian): alignment counts from the byte after the
// 4-byte encapsulation header.
class CdrWriter {
  constructor() { this.bytes = [0x00, 0x01, 0x00, 0x00]; }
  align(n) { while ((this.bytes.length - 4) % n !== 0) this.bytes.push(0); }
  push(view) { for (let i = 0; i < view.byteLength; ++i) this.bytes.push(view.getUint8(i)); }
  int32(v) { this.align(4); const d = new DataView(new ArrayBuffer(4)); d.setInt32(0, v, true); this.push(d); }
  uint32(v) { this.align(4); const d = new DataView(new ArrayBuffer(4)); d.setUint32(0, v, true); this.push(d); }
  float64(v) { this.align(8); const d = new DataView(new ArrayBuffer(8)); d.setFloat64(0, v, true); this.push(d); }
  string(s) { const b = Buffer.from(s, "utf8"); this.uint32(b.length + 1); for (const c of b) this.bytes.push(c); this.bytes.push(0); }
  header(t_ns, frame_id) {
    this.int32(Number(t_ns / 1_000_000_000n));
    this.uint32(Number(t_ns % 1_000_000_000n));
    this.string(frame_id);
  }
  float64_seq(values) { this.uint32(values.length); for (const v of values) this.float64(v); }
  data() { return Uint8Array.from(this.bytes); }
}

function joint_state(k, t_ns) {
  const w = new CdrWriter();
  w.header(t_ns, "");
  w.uint32(JOINTS.length);
  for (const n of JOINTS) w.string(n);
  w.float64_seq(JOINTS.map((_, j) => 0.1 * (j + 1) + 0.001 * k));
  w.float64_seq(JOINTS.map((_, j) => 0.01 * (j + 1)));
  w.float64_seq(JOINTS.map((_, j) => -0.05 * (j + 1) + 0.0001 * k));
  return w.data();
}

function wrench_stamped(k, t_ns) {
  const w = new CdrWriter();
  w.header(t_ns, "PSM1");
  for (const v of [1 + 0.01 * k, -2, 0.5, 0, 0, 0]) w.float64(v);
  return w.data();
}

class MemoryWritable {
  constructor() { this.parts = []; this.size = 0n; }
  async write(buffer) { this.parts.push(Uint8Array.from(buffer)); this.size += BigInt(buffer.byteLength); }
  position() { return this.size; }
  bytes() { return Buffer.concat(this.parts); }
}

const COMPRESSORS = {
  none: undefined,
  zstd: (data) => ({ compression: "zstd", compressedData: zstd.compress(data, 19) }),
  lz4: (data) => ({ compression: "lz4", compressedData: Uint8Array.from(lz4js.compress(data)) }),
};

async function write_fixture(file_name, options) {
  const writable = new MemoryWritable();
  const writer = new McapWriter({ writable, ...options });
  await writer.start({ profile: "ros2", library: "rcm fixture writer (@mcap/core)" });
  const js_schema = await writer.registerSchema({
    name: "sensor_msgs/msg/JointState", encoding: "ros2msg",
    data: new TextEncoder().encode(JOINT_STATE_MSG) });
  const wrench_schema = await writer.registerSchema({
    name: "geometry_msgs/msg/WrenchStamped", encoding: "ros2msg",
    data: new TextEncoder().encode(WRENCH_STAMPED_MSG) });
  const qos = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n";
  const js_channel = await writer.registerChannel({
    topic: "/PSM1/measured_js", messageEncoding: "cdr", schemaId: js_schema,
    metadata: new Map([["offered_qos_profiles", qos]]) });
  const wrench_channel = await writer.registerChannel({
    topic: "/PSM1/body/measured_cf", messageEncoding: "cdr", schemaId: wrench_schema,
    metadata: new Map([["offered_qos_profiles", qos]]) });
  // Wrenches at 40 Hz interleaved with joint states at 100 Hz, in log-time order.
  let wrench_k = 0;
  for (let k = 0; k < JOINT_STATE_COUNT; ++k) {
    const t = T0_NS + BigInt(k) * 10_000_000n;
    while (wrench_k < WRENCH_COUNT && BigInt(wrench_k) * 25_000_000n <= BigInt(k) * 10_000_000n) {
      const tw = T0_NS + BigInt(wrench_k) * 25_000_000n;
      await writer.addMessage({ channelId: wrench_channel, sequence: wrench_k, logTime: tw,
        publishTime: tw, data: wrench_stamped(wrench_k, tw) });
      ++wrench_k;
    }
    await writer.addMessage({ channelId: js_channel, sequence: k, logTime: t, publishTime: t,
      data: joint_state(k, t) });
  }
  // rosbag2 stores its bag description in a Metadata record: readers must skip it.
  await writer.addMetadata({ name: "rosbag2", metadata: new Map([["serialized_metadata", "rcm test fixture"]]) });
  await writer.end();
  const bytes = writable.bytes();
  writeFileSync(join(out_dir, file_name), bytes);
  console.log(`${file_name}: ${bytes.length} bytes`);
}

const CHUNK_BYTES = 4096;
await write_fixture("joint_states_unchunked.mcap", { useChunks: false });
await write_fixture("joint_states_zstd.mcap", { chunkSize: CHUNK_BYTES, compressChunk: COMPRESSORS.zstd });
await write_fixture("joint_states_lz4.mcap", { chunkSize: CHUNK_BYTES, compressChunk: COMPRESSORS.lz4 });
await write_fixture("joint_states_none.mcap", { chunkSize: CHUNK_BYTES, compressChunk: COMPRESSORS.none });
// No summary: nothing repeated after DataEnd, no indexes, no statistics, no
// summary offsets, so the Footer's summary_start is 0.
await write_fixture("joint_states_no_summary.mcap", {
  chunkSize: CHUNK_BYTES, compressChunk: COMPRESSORS.zstd, useStatistics: false,
  useSummaryOffsets: false, repeatSchemas: false, repeatChannels: false,
  useAttachmentIndex: false, useMetadataIndex: false, useChunkIndex: false });
// Indexed or not: chunks without MessageIndex records and a summary without
// ChunkIndex records (schemas, channels and statistics only).
await write_fixture("joint_states_unindexed.mcap", {
  chunkSize: CHUNK_BYTES, compressChunk: COMPRESSORS.lz4, useMessageIndex: false, useChunkIndex: false });
