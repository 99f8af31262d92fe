#!/usr/bin/env node
// Runs the Khronos glTF-Validator (npm package gltf-validator) on .glb/.gltf files and prints one
// JSON report per file on stdout: {"path", "errors", "warnings", "infos", "hints", "messages"}.
// Exit code 1 when any file has errors or warnings.
//   IMUBAKE_NODE_MODULES  the node_modules folder holding gltf-validator (scripts/test.sh sets it)
import { readFile } from "node:fs/promises";
import { createRequire } from "node:module";
import path from "node:path";

const modules = process.env.IMUBAKE_NODE_MODULES;
const require = createRequire(modules ? path.join(modules, "noop.js") : import.meta.url);
const validator = require("gltf-validator");

let failed = false;
for (const file of process.argv.slice(2)) {
  const data = new Uint8Array(await readFile(file));
  const dir = path.dirname(file);
  const report = await validator.validateBytes(data, {
    uri: path.basename(file),
    maxIssues: 1000,
    externalResourceFunction: (uri) =>
      readFile(path.join(dir, decodeURIComponent(uri))).then((b) => new Uint8Array(b)),
  });
  const issues = report.issues;
  if (issues.numErrors > 0 || issues.numWarnings > 0) failed = true;
  console.log(JSON.stringify({
    path: file,
    validator: report.validatorVersion,
    errors: issues.numErrors,
    warnings: issues.numWarnings,
    infos: issues.numInfos,
    hints: issues.numHints,
    messages: issues.messages,
  }));
}
process.exit(failed ? 1 : 0);
