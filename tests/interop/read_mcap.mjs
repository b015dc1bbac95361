// Reads an MCAP file with @mcap/core (an implementation nobody here wrote) and prints what it found as JSON:
// every record through the streaming reader (CRCs and framing checked), and the summary through the indexed
// reader (which seeks to the footer, as Foxglove does).
//   node read_mcap.mjs FILE
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { readFileSync } from "node:fs";
import { open } from "node:fs/promises";

const path = process.argv[2];
const bytes = readFileSync(path);
const stream = new McapStreamReader({ validateCrcs: true });
stream.append(bytes);
const out = { header: null, schemas: {}, channels: {}, messages: {}, footer: false, indexed: null };
for (let record; (record = stream.nextRecord()) !== undefined; ) {
  if (record.type === "Header") out.header = { profile: record.profile, library: record.library };
  else if (record.type === "Schema") out.schemas[record.id] = { name: record.name, encoding: record.encoding };
  else if (record.type === "Channel")
    out.channels[record.id] = { topic: record.topic, schemaId: record.schemaId, encoding: record.messageEncoding,
                                metadata: Object.fromEntries(record.metadata) };
  else if (record.type === "Message") {
    const topic = out.channels[record.channelId].topic;
    (out.messages[topic] ??= []).push({ logTime: record.logTime.toString(),
                                        data: JSON.parse(new TextDecoder().decode(record.data)) });
  } else if (record.type === "Footer") out.footer = true;
}
if (!stream.done()) throw new Error(`${path}: the stream reader did not reach the end`);
const handle = await open(path, "r");
const readable = {
  size: async () => BigInt((await handle.stat()).size),
  read: async (offset, size) => {
    const buf = new Uint8Array(Number(size));
    await handle.read(buf, 0, Number(size), Number(offset));
    return buf;
  },
};
const indexed = await McapIndexedReader.Initialize({ readable });
out.indexed = {
  channels: [...indexed.channelsById.values()].map((c) => c.topic).sort(),
  schemas: [...indexed.schemasById.values()].map((s) => s.name).sort(),
  messageCount: indexed.statistics ? indexed.statistics.messageCount.toString() : null,
};
await handle.close();
console.log(JSON.stringify(out));
