// Validates glTF files with Khronos' glTF-Validator and prints, per file, its report's issue
// counts and messages as JSON (external resources read from beside the file).
import { readFileSync } from 'node:fs';
import { dirname, join } from 'node:path';
import validator from 'gltf-validator';

const out = {};
for (const path of process.argv.slice(2)) {
  try {
    const report = await validator.validateBytes(new Uint8Array(readFileSync(path)), {
      uri: path,
      externalResourceFunction: (uri) => new Promise((resolve, reject) => {
        try { resolve(new Uint8Array(readFileSync(join(dirname(path), decodeURIComponent(uri))))); }
        catch (e) { reject(e.toString()); }
      }),
    });
    out[path] = { numErrors: report.issues.numErrors, numWarnings: report.issues.numWarnings,
                  numInfos: report.issues.numInfos, messages: report.issues.messages, info: report.info };
  } catch (e) {
    out[path] = { error: String(e) };
  }
}
process.stdout.write(JSON.stringify(out));
