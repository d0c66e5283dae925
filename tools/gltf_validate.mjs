// Validates .glb / .gltf files with the Khronos glTF validator (npm gltf-validator) and
// fails on any error, except the validator's complaint about the KHR_gaussian_splatting
// attribute names: its released version predates the ratified extension and flags every
// `KHR_gaussian_splatting:` semantic (and the extension itself as unsupported, a warning
// or info, which never fails). Usage: node tools/gltf_validate.mjs NODE_MODULES FILE...
// Prints one line per file: the counts and each error not excused.
import { createRequire } from 'node:module';
import { readFile } from 'node:fs/promises';
import path from 'node:path';

const [modules, ...files] = process.argv.slice(2);
const require = createRequire(path.resolve(modules, 'x.js'));
const validator = require('gltf-validator');

let failed = false;
for (const file of files) {
  const data = new Uint8Array(await readFile(file));
  const report = await validator.validateBytes(data, {
    uri: path.basename(file),
    maxIssues: 0,
    externalResourceFunction: (uri) =>
      readFile(path.resolve(path.dirname(file), decodeURIComponent(uri))).then((b) => new Uint8Array(b)),
  });
  const excused = (m) =>
    m.code === 'MESH_PRIMITIVE_INVALID_ATTRIBUTE' && /KHR_gaussian_splatting:/.test(m.pointer ?? m.message);
  const errors = report.issues.messages.filter((m) => m.severity === 0);
  const left = errors.filter((m) => !excused(m));
  console.log(
    `${file}: ${report.issues.numErrors} errors (${errors.length - left.length} the extension's attribute names), ` +
      `${report.issues.numWarnings} warnings, ${report.issues.numInfos} infos`,
  );
  for (const m of left) {
    console.log(`  error ${m.code} at ${m.pointer}: ${m.message}`);
  }
  for (const m of report.issues.messages.filter((m) => m.severity === 1)) {
    console.log(`  warning ${m.code} at ${m.pointer}: ${m.message}`);
  }
  if (left.length > 0 || errors.length !== report.issues.numErrors) failed = true;
}
process.exit(failed ? 1 : 0);
