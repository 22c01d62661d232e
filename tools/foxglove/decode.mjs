#!/usr/bin/env node
// Decode every topic of an MCAP log with Foxglove's own libraries and print a summary as JSON.
//
//   node tools/foxglove/decode.mjs LOG.mcap [--full]
//
// Reading: @mcap/core McapIndexedReader over @mcap/nodejs FileHandleReadable, chunks decompressed
// by @foxglove/wasm-zstd / @foxglove/wasm-lz4 (the handlers @mcap/support loads for Foxglove).
// CDR channels with a ros2msg schema: @foxglove/rosmsg parse(text, {ros2: true}) and
// @foxglove/rosmsg2-serialization MessageReader. JSON channels: JSON.parse, validated with ajv
// against the channel's JSON Schema.
//
// Output (stdout, one JSON object): {"topics": {topic: summary}, "message_count": n}. A summary:
//   CDR:  schema_name, message_encoding, schema_encoding, count, fields (name, type, isArray),
//         log_time_sha256 (sha256 of the uint64 LE log times in read order), first, last (decoded
//         messages), and per float64 field: sha256 of the values as float64 LE, sum (sequential,
//         in log-time order) and min/max. --full adds values[field] (every value).
//   JSON: the same counts plus every message as {log_time_ns, payload} and schema_errors
//         (ajv errors per message index, empty when all messages validate).
// Non-finite numbers are written as the strings "NaN", "Infinity", "-Infinity" (JSON has none).
// Exit 1 with a message on stderr when a message does not decode.
import { createHash } from "node:crypto";
import { open } from "node:fs/promises";

import { parse as parseMessageDefinition } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import lz4Decompress from "@foxglove/wasm-lz4";
import * as zstd from "@foxglove/wasm-zstd";
import { McapIndexedReader } from "@mcap/core";
import { FileHandleReadable } from "@mcap/nodejs";
import Ajv2020 from "ajv/dist/2020.js";
import Ajv from "ajv";

function usage(msg) {
  process.stderr.write(`decode.mjs: ${msg}\nusage: node decode.mjs LOG.mcap [--full]\n`);
  process.exit(2);
}

const args = process.argv.slice(2);
const full = args.includes("--full");
const paths = args.filter((a) => a !== "--full");
if (paths.length !== 1) usage("give exactly one MCAP path");

function jsonSafe(value) {
  if (typeof value === "number" && !Number.isFinite(value)) return String(value);
  if (typeof value === "bigint") return value.toString();
  if (ArrayBuffer.isView(value)) return Array.from(value, jsonSafe);
  if (Array.isArray(value)) return value.map(jsonSafe);
  if (value !== null && typeof value === "object") {
    return Object.fromEntries(Object.entries(value).map(([k, v]) => [k, jsonSafe(v)]));
  }
  return value;
}

function sha256(typedArray) {
  // little-endian on every platform node runs on (x86-64, arm64)
  return createHash("sha256").update(new Uint8Array(typedArray.buffer, typedArray.byteOffset,
    typedArray.byteLength)).digest("hex");
}

function makeValidator(schemaText, topic) {
  if (!schemaText) return null;
  const schema = JSON.parse(schemaText);
  const is2020 = typeof schema.$schema === "string" && schema.$schema.includes("2020-12");
  const ajv = is2020 ? new Ajv2020({ allErrors: true, strict: false })
    : new Ajv({ allErrors: true, strict: false });
  try {
    return ajv.compile(schema);
  } catch (err) {
    throw new Error(`${topic}: ajv cannot compile the channel's JSON Schema: ${err.message}`);
  }
}

async function main() {
  await zstd.isLoaded;
  await lz4Decompress.isLoaded;
  const handle = await open(paths[0], "r");
  try {
    const reader = await McapIndexedReader.Initialize({
      readable: new FileHandleReadable(handle),
      decompressHandlers: {
        zstd: (buffer, size) => zstd.decompress(buffer, Number(size)),
        lz4: (buffer, size) => lz4Decompress(buffer, Number(size)),
      },
    });
    const decoders = new Map(); // channel id -> {topic, kind, ...}
    for (const [id, channel] of reader.channelsById) {
      const schema = reader.schemasById.get(channel.schemaId);
      const schemaText = schema ? new TextDecoder().decode(schema.data) : "";
      const state = {
        topic: channel.topic,
        schema_name: schema?.name ?? "",
        message_encoding: channel.messageEncoding,
        schema_encoding: schema?.encoding ?? "",
        logTimes: [],
        messages: [],
      };
      if (channel.messageEncoding === "cdr" && schema?.encoding === "ros2msg") {
        const defs = parseMessageDefinition(schemaText, { ros2: true });
        state.kind = "cdr";
        state.reader = new MessageReader(defs);
        state.fields = defs[0].definitions.filter((f) => !f.isConstant)
          .map((f) => ({ name: f.name, type: f.type, isArray: Boolean(f.isArray) }));
      } else if (channel.messageEncoding === "json") {
        state.kind = "json";
        state.validate = makeValidator(schemaText, channel.topic);
      } else {
        state.kind = "raw";
      }
      decoders.set(id, state);
    }
    const text = new TextDecoder("utf-8", { fatal: true });
    let total = 0;
    for await (const msg of reader.readMessages()) { // log-time order
      const st = decoders.get(msg.channelId);
      let decoded;
      try {
        if (st.kind === "cdr") decoded = st.reader.readMessage(msg.data);
        else if (st.kind === "json") decoded = JSON.parse(text.decode(msg.data));
        else decoded = msg.data.byteLength;
      } catch (err) {
        throw new Error(`${st.topic}: message at log time ${msg.logTime} ns does not decode: ${err.message}`);
      }
      st.logTimes.push(msg.logTime);
      st.messages.push(decoded);
      total += 1;
    }
    const topics = {};
    for (const st of decoders.values()) {
      const n = st.messages.length;
      const out = {
        schema_name: st.schema_name,
        message_encoding: st.message_encoding,
        schema_encoding: st.schema_encoding,
        count: n,
        log_time_sha256: sha256(BigUint64Array.from(st.logTimes)),
        first_log_time_ns: n ? st.logTimes[0].toString() : null,
        last_log_time_ns: n ? st.logTimes[n - 1].toString() : null,
      };
      if (st.kind === "cdr") {
        out.fields = st.fields;
        out.first = n ? jsonSafe(st.messages[0]) : null;
        out.last = n ? jsonSafe(st.messages[n - 1]) : null;
        out.float64 = {};
        for (const f of st.fields) {
          if (f.type !== "float64" || f.isArray) continue;
          const col = new Float64Array(n);
          let sum = 0;
          let min = Infinity;
          let max = -Infinity;
          for (let i = 0; i < n; i++) {
            const v = st.messages[i][f.name];
            col[i] = v;
            sum += v;
            if (v < min) min = v;
            if (v > max) max = v;
          }
          out.float64[f.name] = jsonSafe({ sha256: sha256(col), sum, min, max });
          if (full) out.float64[f.name].values = jsonSafe(Array.from(col));
        }
      } else if (st.kind === "json") {
        out.messages = st.messages.map((p, i) => ({ log_time_ns: st.logTimes[i].toString(), payload: p }));
        out.schema_errors = [];
        if (st.validate) {
          st.messages.forEach((p, i) => {
            if (!st.validate(p)) out.schema_errors.push({ index: i, errors: st.validate.errors });
          });
        } else {
          out.schema_errors.push({ index: null, errors: "the channel has no JSON Schema" });
        }
      }
      topics[st.topic] = out;
    }
    process.stdout.write(JSON.stringify({ path: paths[0], message_count: total, topics }) + "\n");
  } finally {
    await handle.close();
  }
}

main().catch((err) => {
  process.stderr.write(`decode.mjs: ${err.message}\n`);
  process.exit(1);
});
