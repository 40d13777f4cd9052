// The official VDA 5050 JSON schemas (fleet/schemas/, draft 2020-12), compiled by Ajv with
// its formats: one validator per topic. Used by master.mjs (what the master receives) and
// validate.mjs (the Rust fleet tests' schema check).

import fs from "node:fs";
import path from "node:path";
import Ajv2020Module from "ajv/dist/2020.js";
import addFormatsModule from "ajv-formats";

const Ajv2020 = Ajv2020Module.default ?? Ajv2020Module;
const addFormats = addFormatsModule.default ?? addFormatsModule;

export const TOPICS = ["connection", "factsheet", "instantActions", "order", "state", "visualization"];

// { ajv, validators: { topic: validate } } for the schemas in schemaDir.
export function compileSchemas(schemaDir) {
  const ajv = new Ajv2020({ strict: false, allErrors: true });
  addFormats(ajv);
  const validators = {};
  for (const topic of TOPICS) {
    const schema = JSON.parse(fs.readFileSync(path.join(schemaDir, `${topic}.schema`), "utf8"));
    delete schema.$id;
    validators[topic] = ajv.compile(schema);
  }
  return { ajv, validators };
}
