// Opens KTX2 files with the libktx (WebAssembly) that the official glTF Sample Viewer ships and
// prints, as JSON, what it reports per file: vkFormat, base size, components, orientation, and
// the messages libktx printed while opening it ("error": true where it refused the file).
const fs = require('fs');
const path = require('path');
const dist = path.join(__dirname, 'node_modules/@khronosgroup/gltf-viewer/dist/libs');
// the package is an ES module: scripts/ensure_readers.sh (make readers) copies its libktx.js here
const cjs = path.join(__dirname, 'node_modules/.libktx.cjs');
if (!fs.existsSync(cjs)) { console.error(`${cjs} is missing: run make readers`); process.exit(1); }
let log = [];
const say = (s) => log.push(String(s));
require(cjs)({ locateFile: (f) => path.join(dist, f), print: say, printErr: say }).then((ktx) => {
  const out = {};
  for (const f of process.argv.slice(2)) {
    log = [];
    const t = new ktx.ktxTexture(new Uint8Array(fs.readFileSync(f)));
    out[f] = t.baseWidth === 0 ? { error: true } : {
      vkFormat: t.vkFormat, baseWidth: t.baseWidth, baseHeight: t.baseHeight, numComponents: t.numComponents,
      orientation: [t.orientation.x.value, t.orientation.y.value, t.orientation.z.value],
    };
    out[f].messages = log;
  }
  process.stdout.write(JSON.stringify(out));
});
