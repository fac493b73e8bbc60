// Reads MCAP files with @mcap/core (the TypeScript reader Foxglove is built on, CRCs checked)
// and decodes every message of every channel under the rules Foxglove's JSON-schema parser
// applies: message encoding "json", schema encoding "jsonschema", an object at the root, and
// each field of exactly one type among boolean, string, number, integer, object and array
// (arrays with one item type). A field typed any other way (a type list such as
// ["number", "null"], no type, "null") makes Foxglove skip the whole channel.
//
//   node analysis/foxglove/check.mjs FILE.mcap...
// Prints one JSON line per file ({file, channels: {topic: messages}}) and exits non-zero on
// the first problem, naming the file, channel and field.
import { readFileSync } from "node:fs";
import { McapStreamReader } from "@mcap/core";
import { decompress } from "fzstd";

const SCALARS = new Set(["boolean", "string", "number", "integer"]);

function fail(msg) {
  console.error(`foxglove-check: ${msg}`);
  process.exit(1);
}

// The field's single type, checked recursively; returns a decoder that checks a value.
function fieldDecoder(schema, where) {
  const t = schema?.type;
  if (typeof t !== "string") fail(`${where}: type ${JSON.stringify(t)} is not a single type; Foxglove skips the channel`);
  if (SCALARS.has(t)) {
    return (v, at) => {
      const ok = t === "boolean" ? typeof v === "boolean"
        : t === "string" ? typeof v === "string"
        : t === "integer" ? Number.isInteger(v)
        : typeof v === "number" && Number.isFinite(v);
      if (!ok) fail(`${at}: ${JSON.stringify(v)} is not a ${t}`);
    };
  }
  if (t === "array") {
    const item = fieldDecoder(schema.items, `${where}[]`);
    return (v, at) => {
      if (!Array.isArray(v)) fail(`${at}: not an array`);
      v.forEach((x, i) => item(x, `${at}[${i}]`));
    };
  }
  if (t === "object") return objectDecoder(schema, where);
  fail(`${where}: unsupported type "${t}"`);
}

function objectDecoder(schema, where) {
  if (schema?.type !== "object" || typeof schema.properties !== "object") fail(`${where}: not an object schema with properties`);
  const fields = Object.entries(schema.properties).map(([name, s]) => [name, fieldDecoder(s, `${where}.${name}`)]);
  const required = schema.required ?? [];
  return (v, at) => {
    if (typeof v !== "object" || v === null || Array.isArray(v)) fail(`${at}: not an object`);
    for (const name of required) if (!(name in v)) fail(`${at}: required field ${name} is missing`);
    for (const [name, decode] of fields) if (name in v) decode(v[name], `${at}.${name}`);
  };
}

const files = process.argv.slice(2);
if (files.length === 0) fail("usage: node check.mjs FILE.mcap...");
for (const file of files) {
  const reader = new McapStreamReader({
    validateCrcs: true,
    decompressHandlers: { zstd: (data, size) => decompress(data, new Uint8Array(Number(size))) },
  });
  reader.append(readFileSync(file));
  const schemas = new Map();
  const channels = new Map();
  const counts = {};
  let footer = false;
  for (let rec; (rec = reader.nextRecord()); ) {
    if (rec.type === "Schema") {
      if (rec.encoding !== "jsonschema") fail(`${file}: schema ${rec.name} has encoding ${rec.encoding}`);
      schemas.set(rec.id, JSON.parse(new TextDecoder().decode(rec.data)));
    } else if (rec.type === "Channel") {
      if (rec.messageEncoding !== "json") fail(`${file}: channel ${rec.topic} has message encoding ${rec.messageEncoding}`);
      const schema = schemas.get(rec.schemaId);
      if (!schema) fail(`${file}: channel ${rec.topic} names unknown schema ${rec.schemaId}`);
      channels.set(rec.id, { topic: rec.topic, decode: objectDecoder(schema, `${file} ${rec.topic}`) });
      counts[rec.topic] ??= 0; // the summary section repeats the channel records
    } else if (rec.type === "Message") {
      const ch = channels.get(rec.channelId);
      if (!ch) fail(`${file}: message on unknown channel ${rec.channelId}`);
      ch.decode(JSON.parse(new TextDecoder().decode(rec.data)), `${file} ${ch.topic} #${rec.sequence}`);
      counts[ch.topic] += 1;
    } else if (rec.type === "Footer") {
      footer = true;
    }
  }
  if (!footer || !reader.done()) fail(`${file}: truncated (no footer)`);
  console.log(JSON.stringify({ file, channels: counts }));
}
