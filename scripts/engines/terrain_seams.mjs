// Usage: node terrain_seams.mjs SCENE_DIR...
// Each scene's terrain levels (SCENE_DIR/terrain/terrain_LOD<k>.glb) in three.js (headless Chromium,
// WebGL through SwiftShader) with neighbouring chunks at different levels (chunk (i, j) at level
// (i + j + s) mod the level count, for every s): seen from above no sky may show through the
// ground, and seen at 35° at most MAX_HOLES pixels where every level alone draws ground (a notch
// in the skyline; jagged chunk edges left thousands, skirts shallower than the step between
// levels 3-11 on meadow). Prints "ok NAME: ..." or "FAIL NAME: ..." per scene.
import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import puppeteer from 'puppeteer-core';

const here = path.dirname(fileURLToPath(import.meta.url));
const SIZE = 1024;
const MAX_HOLES = 4;
const dirs = process.argv.slice(2).map((d) => path.resolve(d));
const allowed = new Set();
const scenes = dirs.map((dir) => {
  const files = [];
  for (let k = 0; fs.existsSync(path.join(dir, 'terrain', `terrain_LOD${k}.glb`)); k++) files.push(path.join(dir, 'terrain', `terrain_LOD${k}.glb`));
  files.forEach((f) => allowed.add(f));
  return { dir, files };
});
const server = http.createServer((req, res) => {
  const url = decodeURIComponent(req.url.split('?')[0]);
  let file;
  if (url === '/') file = path.join(here, 'terrain_seams.html');
  else if (url.startsWith('/node_modules/')) file = path.join(here, url);
  else if (url.startsWith('/files/') && allowed.has(url.slice('/files'.length))) file = url.slice('/files'.length);
  if (!file) { res.writeHead(url === '/favicon.ico' ? 204 : 404); res.end(); return; }
  fs.readFile(file, (err, data) => {
    if (err) { res.writeHead(404); res.end(); return; }
    const type = file.endsWith('.html') ? 'text/html' : file.endsWith('.js') ? 'text/javascript' : 'application/octet-stream';
    res.writeHead(200, { 'Content-Type': type });
    res.end(data);
  });
}).listen(0, '127.0.0.1');
await new Promise((r) => server.on('listening', r));
const port = server.address().port;
const browser = await puppeteer.launch({
  executablePath: process.env.CHROMIUM ?? '/usr/bin/chromium',
  headless: true,
  protocolTimeout: 600000,
  args: ['--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--no-first-run',
    '--disable-background-networking', '--disable-component-update', '--disable-sync'],
});
let failed = 0;
for (const { dir, files } of scenes) {
  const name = path.basename(dir);
  if (files.length < 2) { console.log(`FAIL ${name}: ${files.length} terrain level file(s), need 2 or more`); failed++; continue; }
  const page = await browser.newPage();
  const errors = [];
  page.on('pageerror', (e) => errors.push(e.message));
  try {
    await page.goto(`http://127.0.0.1:${port}/`);
    await page.waitForFunction('window.ready === true', { timeout: 60000 });
    const chunks = await page.evaluate((urls, size) => window.setup(urls, size), files.map((f) => '/files' + f), SIZE);
    const m = await page.evaluate(() => window.measure());
    const problems = [];
    if (chunks.some((c) => c !== chunks[0] || c < 2)) problems.push(`chunks per level ${chunks.join('/')}`);
    if (m.uniformTop.some((n) => n > 0)) problems.push(`sky through a single level from above: ${m.uniformTop.join('/')} px`);
    if (m.top.some((n) => n > 0)) problems.push(`sky through mixed levels from above: ${m.top.join('/')} px`);
    if (m.oblique.some((n) => n > MAX_HOLES)) problems.push(`holes at 35°: ${m.oblique.join('/')} px (at most ${MAX_HOLES})`);
    if (errors.length) problems.push(`page errors: ${errors.join('; ')}`);
    const figures = `${files.length} levels × ${chunks[0]} chunks, mixed: sky from above ${m.top.join('/')} px, holes at 35° ${m.oblique.join('/')} px of ${SIZE}²`;
    if (problems.length) { console.log(`FAIL ${name}: ${problems.join('; ')} (${figures})`); failed++; } else console.log(`ok ${name}: ${figures}`);
  } catch (e) {
    console.log(`FAIL ${name}: ${e.message}`);
    failed++;
  }
  await page.close();
}
await browser.close();
server.close();
process.exit(failed ? 1 : 0);
