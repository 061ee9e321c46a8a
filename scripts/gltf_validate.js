#!/usr/bin/env node
// Validate glTF/GLB files with the Khronos glTF-Validator (npm package `gltf-validator`).
// Usage: node scripts/gltf_validate.js FILE...  -> one JSON line per file: {file, errors, warnings, infos, messages}
// (messages: the first errors and warnings as "CODE at POINTER: message"). Exit status 1 when any file has errors.
// The package is found through NODE_PATH or the global npm folder (`npm install -g gltf-validator`).
"use strict";
const fs = require("fs");
const path = require("path");
const { execSync } = require("child_process");

function loadValidator() {
  try {
    return require("gltf-validator");
  } catch (err) {
    const root = execSync("npm root -g").toString().trim();
    return require(path.join(root, "gltf-validator"));
  }
}

async function main() {
  const validator = loadValidator();
  let failed = false;
  for (const file of process.argv.slice(2)) {
    const bytes = new Uint8Array(fs.readFileSync(file));
    const report = await validator.validateBytes(bytes, {
      uri: path.basename(file),
      maxIssues: 50,
      externalResourceFunction: (uri) =>
        Promise.resolve(new Uint8Array(fs.readFileSync(path.join(path.dirname(file), decodeURIComponent(uri))))),
    });
    const issues = report.issues;
    const messages = issues.messages
      .filter((m) => m.severity <= 1)
      .slice(0, 10)
      .map((m) => `${m.code} at ${m.pointer}: ${m.message}`);
    failed = failed || issues.numErrors > 0;
    console.log(JSON.stringify({ file, errors: issues.numErrors, warnings: issues.numWarnings,
                                 infos: issues.numInfos, messages }));
  }
  process.exit(failed ? 1 : 0);
}

main().catch((err) => {
  console.error(`gltf_validate: ${err.message || err}`);
  process.exit(2);
});
