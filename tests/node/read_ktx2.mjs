// Reads KTX2 files with ktx-parse (the parser of three.js's KTX2Loader) and prints, per file, its
// header, data format descriptor, key/value data and every level's bytes (base64) as JSON.
import { readFileSync } from 'node:fs';
import { read } from 'ktx-parse';

const out = {};
for (const path of process.argv.slice(2)) {
  try {
    const c = read(new Uint8Array(readFileSync(path)));
    const kv = {};
    for (const [k, v] of Object.entries(c.keyValue)) {
      kv[k] = typeof v === 'string' ? v : new TextDecoder().decode(v).replace(/\0+$/, '');
    }
    out[path] = {
      vkFormat: c.vkFormat, typeSize: c.typeSize, pixelWidth: c.pixelWidth, pixelHeight: c.pixelHeight,
      pixelDepth: c.pixelDepth, layerCount: c.layerCount, faceCount: c.faceCount,
      supercompressionScheme: c.supercompressionScheme, keyValue: kv,
      dfd: c.dataFormatDescriptor.map((d) => ({
        colorModel: d.colorModel, colorPrimaries: d.colorPrimaries, transferFunction: d.transferFunction,
        flags: d.flags, bytesPlane: Array.from(d.bytesPlane), versionNumber: d.versionNumber,
        samples: d.samples.map((s) => ({ bitOffset: s.bitOffset, bitLength: s.bitLength,
                                         channelType: s.channelType, lower: s.sampleLower, upper: s.sampleUpper })),
      })),
      levels: c.levels.map((l) => ({ uncompressedByteLength: l.uncompressedByteLength,
                                     data: Buffer.from(l.levelData).toString('base64') })),
    };
  } catch (e) {
    out[path] = { error: String(e) };
  }
}
process.stdout.write(JSON.stringify(out));
