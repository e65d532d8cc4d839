// An independent check of stereod's MCAP files with Foxglove's own reader (@mcap/core from npm).
//
//   node check_mcap.mjs indexed FILE   read through the summary and indexes (McapIndexedReader), every CRC
//                                      checked; every jsonschema schema parsed; every JSON message parsed
//   node check_mcap.mjs stream FILE    read front to back (McapStreamReader), as a reader of a file cut by a
//                                      crash must: every complete record up to the cut
//   ... --dump OUT                     also write every /stereod/frames message to OUT, one per line
//
// Prints one JSON object: per-topic message counts, the `seq` of every /stereod/frames message in order,
// schema names, and for `stream` the chunks read and the error that stopped it (if any). Exits 1 on any
// problem an intact file must not have.
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { open, readFile, writeFile } from "node:fs/promises";

const [mode, path, ...rest] = process.argv.slice(2);
const dumpPath = rest[0] === "--dump" ? rest[1] : undefined;
const dumped = [];
const out = { mode, topics: {}, schemas: {}, frames_seq: [], problems: [] };
const decoder = new TextDecoder();

function checkMessage(topic, encoding, data) {
  out.topics[topic] = (out.topics[topic] ?? 0) + 1;
  if (encoding !== "json") return;
  let message;
  const text = decoder.decode(data);
  try {
    message = JSON.parse(text);
  } catch (e) {
    out.problems.push(`${topic}: a message is not JSON: ${e.message}`);
    return;
  }
  if (topic === "/stereod/frames") {
    out.frames_seq.push(message.seq);
    if (dumpPath) dumped.push(text); // as stored, not re-serialised (JSON.stringify writes -0 as 0)
  }
}

function checkSchema(schema) {
  out.schemas[schema.name] = schema.encoding;
  if (schema.encoding !== "jsonschema") return;
  try {
    const parsed = JSON.parse(decoder.decode(schema.data));
    if (parsed.type !== "object") out.problems.push(`schema ${schema.name}: not an object schema`);
  } catch (e) {
    out.problems.push(`schema ${schema.name} does not parse: ${e.message}`);
  }
}

if (mode === "indexed") {
  const handle = await open(path, "r");
  const size = (await handle.stat()).size;
  const readable = {
    size: async () => BigInt(size),
    read: async (offset, length) => {
      const buffer = Buffer.alloc(Number(length));
      await handle.read(buffer, 0, Number(length), Number(offset));
      return new Uint8Array(buffer.buffer, buffer.byteOffset, buffer.length);
    },
  };
  const reader = await McapIndexedReader.Initialize({ readable });
  for (const schema of reader.schemasById.values()) checkSchema(schema);
  out.chunks = reader.chunkIndexes.length;
  out.statistics_messages = Number(reader.statistics?.messageCount ?? -1);
  out.profile = reader.header.profile;
  let total = 0;
  for await (const message of reader.readMessages({ validateCrcs: true })) {
    const channel = reader.channelsById.get(message.channelId);
    checkMessage(channel.topic, channel.messageEncoding, message.data);
    ++total;
  }
  out.messages = total;
  if (total !== out.statistics_messages)
    out.problems.push(`read ${total} messages through the indexes, the statistics say ${out.statistics_messages}`);
  const perChannel = reader.statistics?.channelMessageCounts ?? new Map();
  for (const [id, count] of perChannel) {
    const topic = reader.channelsById.get(id).topic;
    if ((out.topics[topic] ?? 0) !== Number(count))
      out.problems.push(`${topic}: ${out.topics[topic] ?? 0} messages read, statistics say ${count}`);
  }
  await handle.close();
} else if (mode === "stream") {
  const bytes = await readFile(path);
  const reader = new McapStreamReader({ validateCrcs: true, includeChunks: true });
  const channels = new Map();
  out.chunks = 0;
  out.messages = 0;
  try {
    // In pieces, as a stream arrives; a record cut by the end of the file is simply never returned.
    for (let at = 0; at < bytes.length; at += 1 << 20) {
      reader.append(bytes.subarray(at, Math.min(at + (1 << 20), bytes.length)));
      for (let record; (record = reader.nextRecord()); ) {
        if (record.type === "Schema") checkSchema(record);
        else if (record.type === "Channel") channels.set(record.id, record);
        else if (record.type === "Chunk") ++out.chunks;
        else if (record.type === "Message") {
          const channel = channels.get(record.channelId);
          checkMessage(channel.topic, channel.messageEncoding, record.data);
          ++out.messages;
        }
      }
    }
  } catch (e) {
    out.error = e.message;
  }
  out.done = reader.done();
  out.bytes_left = reader.bytesRemaining();
} else {
  console.error("usage: node check_mcap.mjs indexed|stream FILE");
  process.exit(2);
}
if (dumpPath) await writeFile(dumpPath, dumped.map((line) => line + "\n").join(""));
console.log(JSON.stringify(out));
process.exit(out.problems.length > 0 ? 1 : 0);
