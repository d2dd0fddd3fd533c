// An independent reader of pandarcapd's MCAP files, for the tests (tests/test_mcap_reader.cpp):
// the MCAP project's own TypeScript reader (@mcap/core) and Foxglove's ROS 2 CDR deserialiser
// (@foxglove/rosmsg2-serialization), the code Foxglove itself opens files with. Nothing here
// shares code with pandarcap's writer.
//
//   node read_mcap.mjs FILE.mcap    prints one JSON object describing the file, exit 0
//                                   any error (the reader refuses the file, a CRC does not match,
//                                   a message does not decode or has bytes left over): a message
//                                   on stderr, exit 1
//
// The file is read twice: through its summary and indexes (McapIndexedReader, as Foxglove opens
// a local file), and front to back (McapStreamReader, as a streaming player reads it), with every
// CRC checked both times; both must see the same messages.
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import { decompress as zstdDecompress } from "fzstd";
import lz4 from "lz4js";
import { open, readFile } from "node:fs/promises";

const decompressHandlers = {
  zstd: (buffer, decompressedSize) => {
    const out = zstdDecompress(buffer);
    if (BigInt(out.byteLength) !== decompressedSize) {
      throw new Error(`zstd chunk: ${out.byteLength} bytes, the chunk says ${decompressedSize}`);
    }
    return out;
  },
  // MCAP's "lz4" is the LZ4 frame format; lz4js reads frames (block size, content size and
  // checksum flags included) into a buffer of the size the chunk states.
  lz4: (buffer, decompressedSize) => {
    const out = new Uint8Array(Number(decompressedSize));
    const n = lz4.decompressFrame(buffer, out);
    if (BigInt(n) !== decompressedSize) {
      throw new Error(`lz4 chunk: ${n} bytes, the chunk says ${decompressedSize}`);
    }
    return out;
  },
};

// PointField datatypes (sensor_msgs/msg/PointField).
const FIELD_READERS = {
  1: [1, (v, o) => v.getInt8(o)],
  2: [1, (v, o) => v.getUint8(o)],
  3: [2, (v, o) => v.getInt16(o, true)],
  4: [2, (v, o) => v.getUint16(o, true)],
  5: [4, (v, o) => v.getInt32(o, true)],
  6: [4, (v, o) => v.getUint32(o, true)],
  7: [4, (v, o) => v.getFloat32(o, true)],
  8: [8, (v, o) => v.getFloat64(o, true)],
};

function fail(message) {
  process.stderr.write(`read_mcap: ${message}\n`);
  process.exit(1);
}

function pointsOf(cloud) {
  if (cloud.is_bigendian) throw new Error("big-endian point cloud");
  const count = cloud.width * cloud.height;
  if (cloud.data.byteLength !== count * cloud.point_step) {
    throw new Error(`data holds ${cloud.data.byteLength} bytes, ${count} points of ${cloud.point_step}`);
  }
  if (cloud.row_step !== cloud.width * cloud.point_step) throw new Error("row_step != width * point_step");
  const view = new DataView(cloud.data.buffer, cloud.data.byteOffset, cloud.data.byteLength);
  const fields = cloud.fields.map((f) => {
    const reader = FIELD_READERS[f.datatype];
    if (!reader) throw new Error(`field ${f.name}: datatype ${f.datatype}`);
    if (f.offset + reader[0] * f.count > cloud.point_step) throw new Error(`field ${f.name} outside the point`);
    return { name: f.name, offset: f.offset, read: reader[1] };
  });
  const point = (i) => Object.fromEntries(fields.map((f) => [f.name, f.read(view, i * cloud.point_step + f.offset)]));
  const sums = Object.fromEntries(fields.map((f) => [f.name, 0]));
  for (let i = 0; i < count; ++i) {
    for (const f of fields) sums[f.name] += f.read(view, i * cloud.point_step + f.offset);
  }
  return {
    points: count,
    fields: cloud.fields.map((f) => ({ name: f.name, offset: f.offset, datatype: f.datatype, count: f.count })),
    point_step: cloud.point_step,
    first: count > 0 ? point(0) : null,
    last: count > 0 ? point(count - 1) : null,
    sums,
  };
}

function decoders(schemasById, channelsById) {
  const out = new Map();
  for (const [id, channel] of channelsById) {
    const schema = schemasById.get(channel.schemaId);
    if (!schema) throw new Error(`channel ${channel.topic}: schema ${channel.schemaId} missing`);
    if (channel.messageEncoding === "cdr") {
      if (schema.encoding !== "ros2msg") throw new Error(`${channel.topic}: schema encoding ${schema.encoding}`);
      const reader = new MessageReader(parse(new TextDecoder().decode(schema.data), { ros2: true }));
      out.set(id, (data) => {
        const message = reader.readMessage(data);
        if (reader.lastReadHadTrailingBytes()) throw new Error(`${channel.topic}: bytes left after the message`);
        return message;
      });
    } else if (channel.messageEncoding === "json") {
      if (schema.encoding !== "jsonschema") throw new Error(`${channel.topic}: schema encoding ${schema.encoding}`);
      JSON.parse(new TextDecoder().decode(schema.data));
      out.set(id, (data) => JSON.parse(new TextDecoder().decode(data)));
    } else {
      throw new Error(`${channel.topic}: message encoding ${channel.messageEncoding}`);
    }
  }
  return out;
}

function summarise(schemaName, message) {
  if (schemaName === "sensor_msgs/msg/PointCloud2") {
    return { stamp: message.header.stamp, frame_id: message.header.frame_id, height: message.height,
             width: message.width, is_dense: message.is_dense, ...pointsOf(message) };
  }
  if (schemaName === "pandar_msgs/msg/PandarPacket") {
    if (message.size !== message.data.byteLength) throw new Error("PandarPacket: size != data length");
    return { stamp: message.stamp, size: message.size, first_bytes: Array.from(message.data.slice(0, 2)) };
  }
  return { state: message.state, reason: message.reason ?? "",
           datagrams_received: message.counters?.datagrams_received ?? null };
}

async function main() {
  const path = process.argv[2];
  if (!path) fail("usage: node read_mcap.mjs FILE.mcap");
  const handle = await open(path, "r");
  const size = (await handle.stat()).size;
  const readable = {
    size: async () => BigInt(size),
    read: async (offset, length) => {
      const buffer = new Uint8Array(Number(length));
      const { bytesRead } = await handle.read(buffer, 0, buffer.length, Number(offset));
      if (bytesRead !== buffer.length) throw new Error(`short read at ${offset}`);
      return buffer;
    },
  };
  const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  const decode = decoders(reader.schemasById, reader.channelsById);
  const topics = {};
  for (const channel of reader.channelsById.values()) {
    topics[channel.topic] = { schema: reader.schemasById.get(channel.schemaId).name, count: 0, messages: [] };
  }
  let previous = -1n;
  for await (const message of reader.readMessages({ validateCrcs: true })) {
    if (message.logTime < previous) throw new Error("messages out of log-time order");
    previous = message.logTime;
    const channel = reader.channelsById.get(message.channelId);
    const topic = topics[channel.topic];
    ++topic.count;
    const decoded = decode.get(message.channelId)(message.data);
    topic.messages.push({ log_time: message.logTime.toString(), sequence: message.sequence,
                          ...summarise(topic.schema, decoded) });
  }
  const attachments = [];
  for await (const a of reader.readAttachments({ validateCrcs: true })) {
    attachments.push({ name: a.name, media_type: a.mediaType, text: new TextDecoder().decode(a.data) });
  }
  const metadata = [];
  for await (const m of reader.readMetadata()) metadata.push({ name: m.name, entries: Object.fromEntries(m.metadata) });

  // Front to back, every record and CRC, as a streaming reader sees the file.
  const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true });
  stream.append(await readFile(path));
  let streamed = 0;
  let footer = false;
  for (let record; (record = stream.nextRecord()) !== undefined;) {
    if (record.type === "Message") ++streamed;
    if (record.type === "Footer") footer = true;
  }
  if (!stream.done() || !footer) throw new Error("the stream reader did not reach the footer");
  const indexed = Object.values(topics).reduce((n, t) => n + t.count, 0);
  if (streamed !== indexed) throw new Error(`stream reader saw ${streamed} messages, the indexes ${indexed}`);
  const stats = reader.statistics;
  if (!stats || Number(stats.messageCount) !== indexed) throw new Error("statistics disagree with the messages");
  for (const [id, count] of stats.channelMessageCounts) {
    if (Number(count) !== topics[reader.channelsById.get(id).topic].count) {
      throw new Error(`statistics: channel ${id} count ${count}`);
    }
  }

  process.stdout.write(JSON.stringify({
    header: { profile: reader.header.profile, library: reader.header.library },
    statistics: { message_count: Number(stats.messageCount), chunk_count: stats.chunkCount,
                  message_start_time: stats.messageStartTime.toString(),
                  message_end_time: stats.messageEndTime.toString() },
    chunk_compression: [...new Set(reader.chunkIndexes.map((c) => c.compression))],
    // Each chunk's, in the chunk index's order ("" for a chunk stored as it is).
    chunk_compressions: reader.chunkIndexes.map((c) => c.compression),
    schemas: [...reader.schemasById.values()].map((s) => ({ id: s.id, name: s.name, encoding: s.encoding })),
    channels: [...reader.channelsById.values()].map((c) => ({
      id: c.id,
      topic: c.topic,
      message_encoding: c.messageEncoding,
      metadata: Object.fromEntries(c.metadata),
    })),
    attachments,
    metadata,
    topics,
  }) + "\n");
  await handle.close();
}

main().catch((error) => fail(error?.stack ?? String(error)));
