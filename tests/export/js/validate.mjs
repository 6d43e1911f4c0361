// Validate a glTF file with the Khronos glTF validator; print its report (JSON) on stdout.
// Usage: node validate.mjs FILE.glb
import { readFile } from "node:fs/promises";
import validator from "gltf-validator";

const path = process.argv[2];
const data = new Uint8Array(await readFile(path));
const report = await validator.validateBytes(data, { uri: path, maxIssues: 100 });
process.stdout.write(JSON.stringify(report));
