// Read an MCAP file with @mcap/core and decode every ros2msg message with
// @foxglove/rosmsg2-serialization, as Foxglove does; print one JSON line per topic with what a
// test compares: message count, schema, and for each message a digest of what was decoded.
import { createHash } from "node:crypto";
import { open } from "node:fs/promises";
import { McapIndexedReader } from "@mcap/core";
import { loadDecompressHandlers } from "@mcap/support";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";

const path = process.argv[2];
const handle = await open(path, "r");
const readable = {
  size: async () => BigInt((await handle.stat()).size),
  read: async (offset, length) => {
    const buf = new Uint8Array(Number(length));
    await handle.read(buf, 0, Number(length), Number(offset));
    return buf;
  },
};
const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers: await loadDecompressHandlers() });
const readers = new Map();
const out = {};
for await (const msg of reader.readMessages()) {
  const channel = reader.channelsById.get(msg.channelId);
  const schema = reader.schemasById.get(channel.schemaId);
  if (schema.encoding !== "ros2msg") throw new Error(`${channel.topic}: schema encoding ${schema.encoding}`);
  let r = readers.get(channel.id);
  if (!r) {
    r = new MessageReader(parse(new TextDecoder().decode(schema.data), { ros2: true }));
    readers.set(channel.id, r);
  }
  const m = r.readMessage(msg.data);
  const t = (out[channel.topic] ??= { schema: schema.name, count: 0, items: [] });
  t.count += 1;
  if (channel.topic.endsWith("/image")) {
    t.items.push({ w: m.width, h: m.height, encoding: m.encoding,
                   sha256: createHash("sha256").update(m.data).digest("hex") });
  } else if (channel.topic.endsWith("/metadata")) {
    t.items.push({ json: m.json, grade: m.thermal_contrast_grade, targets: m.target_count });
  } else if (channel.topic.endsWith("/annotations")) {
    t.items.push({ boxes: m.points.length, labels: m.texts.map((x) => x.text) });
  } else {
    t.items.push({ json: m.json });
  }
}
await handle.close();
process.stdout.write(JSON.stringify(out));
