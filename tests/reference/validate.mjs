// Runs the Khronos glTF-Validator (npm package gltf-validator) on each file given and prints one
// JSON line per file: {file, errors, warnings, messages}. Exit status 1 if any file has errors.
// The package is resolved from GLTF_VALIDATOR_DIR (a folder with node_modules/gltf-validator).
import fs from "node:fs";
import path from "node:path";
import { createRequire } from "node:module";

const require = createRequire(path.join(process.env.GLTF_VALIDATOR_DIR, "package.json"));
const validator = require("gltf-validator");

let failed = false;
for (const file of process.argv.slice(2)) {
  const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
    uri: path.basename(file),
    maxIssues: 50,
    writeTimestamp: false,
    externalResourceFunction: (uri) =>
      fs.promises.readFile(path.resolve(path.dirname(file), decodeURIComponent(uri))).then((b) => new Uint8Array(b)),
  });
  const issues = report.issues;
  if (issues.numErrors > 0) failed = true;
  console.log(JSON.stringify({
    file,
    errors: issues.numErrors,
    warnings: issues.numWarnings,
    messages: issues.messages.filter((m) => m.severity <= 1).map((m) => `${m.code} ${m.pointer ?? ""}`),
  }));
}
process.exit(failed ? 1 : 0);
