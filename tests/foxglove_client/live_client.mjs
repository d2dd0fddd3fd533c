// Foxglove's own WebSocket client (@foxglove/ws-protocol over the `ws` package) against
// pandarcapd's live view, for tests/test_live_view.cpp. Test-only; versions pinned by
// package-lock.json (npm ci, .ci/install-deps).
//
//   node live_client.mjs watch URL FRAMES_DIR CLOUDS
//     subscribes to every channel, decodes CLOUDS PointCloud2 messages with Foxglove's ROS 2 CDR
//     reader (@foxglove/rosmsg2-serialization, the schema the server advertised) and compares
//     each cloud's points with the PCD file of the same revolution in FRAMES_DIR (same
//     frame_reference_time as the message's header.stamp, same DATA bytes); prints one JSON
//     object and exits 0 (1 on a protocol failure, 2 on a timeout).
//   node live_client.mjs view URL SECONDS
//     subscribes to every channel and reads everything for SECONDS from the connection, as
//     Foxglove's app would;
//     prints the messages and bytes received (for docs/live.md's cost measurement).
//   node live_client.mjs stall URL
//     subscribes to every channel, then never reads again (the socket paused); prints "stalled"
//     once subscribed, and stays until killed.
import wsProtocol from "@foxglove/ws-protocol";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;
import { readdir, readFile } from "node:fs/promises";

const [mode, url, framesDir, cloudsArg] = process.argv.slice(2);
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // channel id -> channel
const bySubscription = new Map(); // subscription id -> channel
const statuses = [];
client.on("status", (s) => statuses.push(s));
client.on("error", (e) => {
  console.error(`client error: ${e?.message ?? e}`);
  process.exit(1);
});

function subscribeAll(list) {
  for (const c of list) {
    channels.set(c.id, c);
    bySubscription.set(client.subscribe(c.id), c);
  }
}

// The PCD files of FRAMES_DIR by their frame_reference_time ("S.NNNNNNNNN"): their DATA bytes.
async function pcdFrames() {
  const frames = new Map();
  for (const name of await readdir(framesDir)) {
    if (!name.endsWith(".pcd")) continue;
    const bytes = await readFile(`${framesDir}/${name}`);
    const headerEnd = bytes.indexOf("DATA binary\n");
    if (headerEnd < 0) continue;
    const header = bytes.subarray(0, headerEnd).toString("latin1");
    const time = /frame_reference_time (\d+\.\d{9})/.exec(header);
    if (time) frames.set(time[1], bytes.subarray(headerEnd + "DATA binary\n".length));
  }
  return frames;
}

const stampText = (s) => `${s.sec}.${String(s.nanosec).padStart(9, "0")}`;

if (mode === "stall") {
  client.on("advertise", (list) => {
    subscribeAll(list);
    // Subscribed; from here the socket is never read: the server's messages fill the kernel's
    // buffers and then its own queue for this client.
    setTimeout(() => {
      ws._socket.pause();
      setInterval(() => {}, 1000); // a paused socket alone does not keep node running
      console.log("stalled");
    }, 100);
  });
} else if (mode === "view") {
  let messages = 0;
  let bytes = 0;
  client.on("advertise", subscribeAll);
  client.on("message", ({ data }) => {
    messages += 1;
    bytes += data.byteLength;
  });
  // SECONDS from the connection, not from node's start (which a busy machine can make last
  // longer than a short view).
  ws.on("open", () =>
    setTimeout(() => {
      console.log(JSON.stringify({ messages, bytes }));
      process.exit(0);
    }, Number(framesDir) * 1000),
  );
} else if (mode === "watch") {
  const wanted = Number(cloudsArg);
  let reader;
  const clouds = [];
  let health = 0;
  let healthState = null;
  let healthReason = null;
  let status = 0;
  let serverInfo = null;
  client.on("serverInfo", (info) => (serverInfo = info));
  client.on("advertise", (list) => {
    subscribeAll(list);
    const points = list.find((c) => c.schemaName.endsWith("PointCloud2"));
    if (points) reader = new MessageReader(parse(points.schema, { ros2: true }));
  });
  client.on("message", ({ subscriptionId, data }) => {
    const channel = bySubscription.get(subscriptionId);
    const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
    if (channel.encoding === "cdr" && clouds.length < wanted) {
      const msg = reader.readMessage(bytes);
      clouds.push({ stamp: stampText(msg.header.stamp), msg });
    } else if (channel.encoding === "json" && channel.schemaName === "pandarcap.Health") {
      const record = JSON.parse(new TextDecoder().decode(bytes));
      health += 1;
      healthState = record.state;
      healthReason = record.reason;
    } else if (channel.encoding === "json") {
      JSON.parse(new TextDecoder().decode(bytes));
      status += 1;
    }
    if (clouds.length >= wanted && health > 0) finish();
  });
  let done = false;
  async function finish() {
    if (done) return;
    done = true;
    client.close();
    // The writer puts a frame's PCD in place before it hands the frame to the live view.
    const frames = await pcdFrames();
    let matched = 0;
    const mismatches = [];
    for (const { stamp, msg } of clouds) {
      const pcd = frames.get(stamp);
      const data = Buffer.from(msg.data.buffer, msg.data.byteOffset, msg.data.byteLength);
      if (pcd && pcd.length === data.length && Buffer.compare(pcd, data) === 0) {
        matched += 1;
      } else {
        mismatches.push({ stamp, found: !!pcd, pcd_bytes: pcd?.length, live_bytes: data.length });
      }
    }
    const first = clouds[0].msg;
    console.log(
      JSON.stringify({
        server: serverInfo,
        channels: [...channels.values()].map((c) => ({
          topic: c.topic,
          encoding: c.encoding,
          schemaName: c.schemaName,
          schemaEncoding: c.schemaEncoding,
        })),
        clouds: clouds.length,
        fields: first.fields.map((f) => f.name),
        frame_id: first.header.frame_id,
        width_times_step_is_data: clouds.every(
          ({ msg }) => msg.width * msg.point_step === msg.data.length && msg.row_step === msg.data.length,
        ),
        matched,
        mismatches,
        health,
        health_state: healthState,
        health_reason: healthReason,
        status,
        statuses,
      }),
    );
    process.exit(0);
  }
  setTimeout(() => {
    console.error(`timeout: ${clouds.length} clouds, ${health} health messages`);
    process.exit(2);
  }, 20000);
} else {
  console.error("usage: live_client.mjs watch URL FRAMES_DIR CLOUDS | view URL SECONDS | stall URL");
  process.exit(64);
}
