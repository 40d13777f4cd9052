// The fleet tests' schema check (fleet/tests/common/mod.rs): the official VDA 5050 JSON
// schemas (fleet/schemas/, draft 2020-12) with Ajv and its formats, as master.mjs checks
// what the master receives. One process per test binary:
//
//   node validate.mjs SCHEMA_DIR
//
// reads one JSON line per message, {"topic": "state", "msg": {...}}, and answers each with
// one JSON line: the list of schema errors, [] when the message is valid.

import readline from "node:readline";
import { compileSchemas } from "./schemas.mjs";

const schemaDir = process.argv[2];
if (!schemaDir) {
  console.error("usage: node validate.mjs SCHEMA_DIR");
  process.exit(2);
}
const { validators } = compileSchemas(schemaDir);

const lines = readline.createInterface({ input: process.stdin, crlfDelay: Infinity });
for await (const line of lines) {
  let errors;
  try {
    const { topic, msg } = JSON.parse(line);
    const validate = validators[topic];
    if (!validate) {
      errors = [`no schema for ${topic}`];
    } else if (validate(msg)) {
      errors = [];
    } else {
      errors = validate.errors.map((e) => `${e.message} at ${e.instancePath || "/"} (${e.schemaPath})`);
    }
  } catch (e) {
    errors = [`not a request: ${e}`];
  }
  process.stdout.write(JSON.stringify(errors) + "\n");
}
