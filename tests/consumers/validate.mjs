// Validate glTF/GLB files with the Khronos glTF-Validator (npm "gltf-validator").
// Usage: node validate.mjs FILE...   Prints one JSON object {file: summary} on stdout.
import { readFileSync } from "node:fs";
import { extname } from "node:path";
import validator from "gltf-validator";

const out = {};
for (const file of process.argv.slice(2)) {
  const bytes = new Uint8Array(readFileSync(file));
  const report = await validator.validateBytes(bytes, {
    format: extname(file).toLowerCase() === ".glb" ? "glb" : "gltf",
    maxIssues: 100,
  });
  const issues = report.issues;
  out[file] = {
    numErrors: issues.numErrors,
    numWarnings: issues.numWarnings,
    numInfos: issues.numInfos,
    numHints: issues.numHints,
    messages: issues.messages.map((m) => ({ code: m.code, severity: m.severity, message: m.message, pointer: m.pointer })),
    validatorVersion: report.validatorVersion,
  };
}
process.stdout.write(JSON.stringify(out));
