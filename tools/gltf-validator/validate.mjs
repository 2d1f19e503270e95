// Validates glTF files with the Khronos glTF validator and prints its report as JSON.
// Usage: node validate.mjs FILE.glb   (exit status 0; the report's issues.numErrors tells the result)
import { readFile } from "node:fs/promises";
import path from "node:path";
import validator from "gltf-validator";

const file = process.argv[2];
if (!file) {
  console.error("usage: node validate.mjs FILE.glb");
  process.exit(2);
}
const data = await readFile(file);
const report = await validator.validateBytes(new Uint8Array(data), {
  uri: path.basename(file),
  maxIssues: 0, // every issue
  // a file that names another one (a .gltf's .bin) is given it from beside the file
  externalResourceFunction: (uri) =>
    readFile(path.join(path.dirname(file), decodeURIComponent(uri))).then((b) => new Uint8Array(b)),
});
process.stdout.write(JSON.stringify(report, null, 2) + "\n");
