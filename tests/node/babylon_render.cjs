// Renders a glTF file with Babylon.js in headless Chromium (Debian's /usr/bin/chromium, WebGL2 on
// SwiftShader) and prints {version, webgl, width, height, pixels: base64 RGBA, rows bottom to top}.
// Usage: node babylon_render.cjs FILE.gltf WIDTH HEIGHT '{"linearEnvironment": true}'
const path = require('node:path');
const puppeteer = require('puppeteer-core');

(async () => {
  const [file, width, height, options] = process.argv.slice(2);
  const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium', headless: true,
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--allow-file-access-from-files',
           '--disable-background-networking', '--disable-component-update', '--disable-sync', '--no-first-run',
           '--disable-gpu-sandbox'],
  });
  try {
    const page = await browser.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(e.message));
    await page.goto('file://' + path.join(__dirname, 'babylon_page.html'));
    const url = 'file://' + path.resolve(file);
    const out = await page.evaluate((u, w, h, o) => window.renderGltf(u, w, h, o), url, +width, +height,
                                    JSON.parse(options || '{}'));
    if (errors.length) throw new Error(errors.join('; '));
    process.stdout.write(JSON.stringify({...out, width: +width, height: +height}));
  } finally {
    await browser.close();
  }
})().catch((e) => { console.error(String(e)); process.exit(1); });
