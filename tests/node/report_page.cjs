// Drives an iblbake report page (iblbake/study/html.py) in headless Chromium and prints JSON:
// {open_ms, errors, results: [one per step]}. Usage: node report_page.cjs DIR/index.html STEPS.json
// STEPS: [{"eval": "JS expression (awaited)"}, {"click": "CSS selector", "shift": false}, {"key": " "},
//         {"move": true, "selector": "#paneA", "fx": 0.5, "fy": 0.5}, {"wheel": 5, "deltaY": -100, ...as move},
//         {"screenshot": "FILE.png", "clip": {...}}]
const fs = require('node:fs');
const path = require('node:path');
const puppeteer = require('puppeteer-core');

(async () => {
  const [file, stepsFile] = process.argv.slice(2);
  const steps = JSON.parse(fs.readFileSync(stepsFile, 'utf8'));
  const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium', headless: true,
    args: ['--no-sandbox', '--disable-background-networking', '--disable-component-update', '--disable-sync',
           '--no-first-run', '--disable-gpu-sandbox', '--force-color-profile=srgb'],
  });
  try {
    const page = await browser.newPage();
    await page.setViewport({width: 1500, height: 1000});
    const errors = [];
    page.on('pageerror', (e) => errors.push(e.message));
    page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
    page.on('requestfailed', (r) => errors.push(`${r.url()}: ${r.failure().errorText}`));
    const t0 = Date.now();
    await page.goto('file://' + path.resolve(file));
    await page.evaluate('window.IBL.ready');
    const openMs = Date.now() - t0;
    const results = [];
    for (const s of steps) {
      if (s.eval) results.push(await page.evaluate(`(async () => (${s.eval}))()`));
      else if (s.click) {
        if (s.shift) await page.keyboard.down('Shift');
        await page.click(s.click);
        if (s.shift) await page.keyboard.up('Shift');
        results.push(await page.evaluate('window.IBL.render().then(() => true)'));
      } else if (s.move || s.wheel) {       // at a fraction (fx, fy) of an element's box; then wheel turns
        const box = await (await page.$(s.selector)).boundingBox();
        await page.mouse.move(box.x + s.fx * box.width, box.y + s.fy * box.height);
        for (let k = 0; k < (s.wheel || 0); k++) await page.mouse.wheel({deltaY: s.deltaY});
        results.push(await page.evaluate('window.IBL.render().then(() => true)'));
      } else if (s.key) {
        await page.keyboard.press(s.key);
        results.push(await page.evaluate('window.IBL.render().then(() => true)'));
      } else if (s.screenshot) {
        await page.screenshot({path: s.screenshot, clip: s.clip});
        results.push(true);
      }
    }
    process.stdout.write(JSON.stringify({open_ms: openMs, errors, results}));
  } finally {
    await browser.close();
  }
})().catch((e) => { console.error(String(e)); process.exit(1); });
