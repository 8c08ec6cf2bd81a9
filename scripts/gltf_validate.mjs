// Validates `.glb` files with the Khronos glTF validator (npm `gltf-validator`, installed by
// scripts/gltf.sh) and prints one JSON line per file: errors, warnings, infos, hints and the
// first few messages. Exit status 1 when any file has an error or a warning or cannot be read.
//
//   node scripts/gltf_validate.mjs FILE.glb [FILE.glb ...]
import { readFile } from "node:fs/promises";
import { createRequire } from "node:module";
import path from "node:path";

const require = createRequire(path.resolve(process.env.GLTF_TOOLS ?? "target/gltf-tools", "package.json"));
const validator = require("gltf-validator");

let failed = false;
for (const file of process.argv.slice(2)) {
  try {
    const bytes = new Uint8Array(await readFile(file));
    const report = await validator.validateBytes(bytes, { uri: path.basename(file), maxIssues: 100 });
    const i = report.issues;
    const messages = i.messages.slice(0, 5).map((m) => `${m.code} ${m.pointer ?? ""}: ${m.message}`);
    console.log(JSON.stringify({
      file, validator: report.validatorVersion, errors: i.numErrors, warnings: i.numWarnings,
      infos: i.numInfos, hints: i.numHints, animations: report.info?.animationCount,
      morph_targets: report.info?.maxAttributes, messages,
    }));
    if (i.numErrors > 0 || i.numWarnings > 0) failed = true;
  } catch (e) {
    console.log(JSON.stringify({ file, error: String(e) }));
    failed = true;
  }
}
process.exit(failed ? 1 : 0);
