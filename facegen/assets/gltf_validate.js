#!/usr/bin/env node
// Runs the Khronos glTF-Validator (npm `gltf-validator`) on one .glb/.gltf file for `facegen validate`.
// Usage: node gltf_validate.js FILE [MAX_ISSUES]
// Prints the validator's JSON report on stdout and exits 0 (whatever the file's issues are);
// exits 3 with {"error": ...} when the validator package is missing, 2 on any other failure.
// The package is looked up beside this script (facegen/assets/node_modules, made by `make node-deps`),
// then in FACEGEN_NODE_MODULES / NODE_PATH.
"use strict";
const fs = require("fs");
const path = require("path");

function loadValidator() {
  const places = [path.join(__dirname, "node_modules")];
  if (process.env.FACEGEN_NODE_MODULES) places.push(process.env.FACEGEN_NODE_MODULES);
  for (const dir of places) {
    try {
      return require(require.resolve("gltf-validator", { paths: [dir, path.dirname(dir)] }));
    } catch (err) {
      if (err.code !== "MODULE_NOT_FOUND") throw err;
    }
  }
  return require("gltf-validator"); // NODE_PATH, global folders
}

function fail(code, message) {
  process.stdout.write(JSON.stringify({ error: message }) + "\n");
  process.exit(code);
}

const file = process.argv[2];
const maxIssues = parseInt(process.argv[3] || "100", 10);
if (!file) fail(2, "usage: node gltf_validate.js FILE [MAX_ISSUES]");

let validator;
try {
  validator = loadValidator();
} catch (err) {
  fail(3, "the npm package gltf-validator is not installed (" + err.code + ")");
}

let bytes;
try {
  bytes = new Uint8Array(fs.readFileSync(file));
} catch (err) {
  fail(2, "cannot read " + file + ": " + err.message);
}

const folder = path.dirname(path.resolve(file));
validator
  .validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: maxIssues,
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.resolve(folder, decodeURIComponent(uri)), (err, data) =>
          err ? reject(err.toString()) : resolve(new Uint8Array(data)));
      }),
  })
  .then(
    (report) => {
      report.validatorVersion = validator.version();
      process.stdout.write(JSON.stringify(report) + "\n");
    },
    (err) => fail(2, "the validator could not read " + file + ": " + err),
  );
