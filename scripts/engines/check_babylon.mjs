// Loads glb files in Babylon.js or three.js (headless Chromium, WebGL through SwiftShader) and checks
// what a person would see: no loader error or warning, no page error, and for MSFT_lod chains, in
// Babylon every level arriving in order with exactly the default scene's LoD0 meshes enabled at the
// end; in three.js, with the project's MSFT_lod plugin (three_msft_lod.js), one level of each chain
// shown in the framing view, and from one distance inside each level's MSFT_screencoverage range
// that level shown, drawing exactly its triangles (renderer.info).
//
//   --engine babylon (default) | three
//
//   node scripts/engines/check_babylon.mjs [--thumbs DIR] [--no-range-requests] [--green] FILE.glb...
//   node scripts/engines/check_babylon.mjs [--engine three] --view [--thumbs DIR] out/<scene>/scene.glb...
//   node scripts/engines/check_babylon.mjs --engine three --lit-against terrain_LOD0.glb terrain_LOD1.glb...
//
// --view: each file is a built scene's scene.glb, rendered from its first [[view]] (manifest.json
// beside it) without frustum culling; the engine must count exactly the triangles and draw calls
// the view stage reported (three.js: renderer.info; Babylon: active indices / 3, draw calls), and
// a scene with [snow] must show it: at least a tenth of the covered frame snow-white.
//
// Every file's frame is measured where it is not the sky (covered share, mean colour, dark and
// green-leading shares). --green: the files are grass, which a person must see as green: at least
// 0.2 % of the frame covered, green leading on most of it and at most a fifth of it dark (wind data
// in COLOR_0 rendered grass black and cut it out under the alpha test).
//
// --lit-against REF.glb (three.js): each file is a coarse level of REF's terrain; drawn top-down
// under a low sun, with its normal maps it must differ from REF by under 4 of 255 in mean
// luminance, and by under half of what it differs with its vertex normals alone.
//
// --draw-limit N (Babylon, default 20 M): a file whose enabled meshes add up to more triangles is
// loaded and counted but its frame not drawn (Babylon ends an MSFT_lod scene at LoD0 everywhere).
//
// MSFT_lod files are loaded with the loader's `useRangeRequests` on (Babylon's progressive LoD
// loading needs it for a .glb); --no-range-requests loads them with Babylon's defaults instead.
// Exits 1 if any file fails.
import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import puppeteer from 'puppeteer-core';

const here = path.dirname(fileURLToPath(import.meta.url));
const args = process.argv.slice(2);
let thumbs = null;
let rangeRequests = true;
let expectGreen = false;
let engine = 'babylon';
let viewMode = false;
let drawLimit = 20e6;
let litAgainst = null;
const files = [];
for (let i = 0; i < args.length; i++) {
  if (args[i] === '--thumbs') thumbs = args[++i];
  else if (args[i] === '--no-range-requests') rangeRequests = false;
  else if (args[i] === '--green') expectGreen = true;
  else if (args[i] === '--engine') engine = args[++i];
  else if (args[i] === '--view') viewMode = true;
  else if (args[i] === '--draw-limit') drawLimit = Number(args[++i]);
  else if (args[i] === '--lit-against') litAgainst = path.resolve(args[++i]);
  else files.push(path.resolve(args[i]));
}
if (!files.length) {
  console.error('usage: node scripts/engines/check_babylon.mjs [--engine babylon|three] [--thumbs DIR] [--no-range-requests] [--green] [--draw-limit TRIANGLES] FILE.glb...');
  process.exit(2);
}

// what the page may load: the page, Babylon from node_modules, and the files named on the command line
const allowed = new Set(litAgainst ? [...files, litAgainst] : files);
const server = http.createServer((req, res) => {
  const url = decodeURIComponent(req.url.split('?')[0]);
  let file;
  if (url === '/') file = path.join(here, 'babylon.html');
  else if (url === '/three.html') file = path.join(here, 'three.html');
  else if (url === '/frame_stats.js') file = path.join(here, 'frame_stats.js');
  else if (url === '/meshopt_shim.js') file = path.join(here, 'meshopt_shim.js');
  else if (url === '/three_msft_lod.js') file = path.join(here, 'three_msft_lod.js');
  else if (url.startsWith('/node_modules/')) file = path.join(here, url);
  else if (url.startsWith('/files/') && allowed.has(url.slice('/files'.length))) file = url.slice('/files'.length);
  if (!file) { res.writeHead(url === '/favicon.ico' ? 204 : 404); res.end(); return; }
  fs.readFile(file, (err, data) => {
    if (err) { res.writeHead(404); res.end(); return; }
    const range = /bytes=(\d+)-(\d*)/.exec(req.headers.range || '');
    const type = file.endsWith('.html') ? 'text/html' : file.endsWith('.js') ? 'text/javascript' : 'application/octet-stream';
    if (range) {
      const a = Number(range[1]);
      const b = range[2] ? Math.min(Number(range[2]), data.length - 1) : data.length - 1;
      res.writeHead(206, { 'Content-Type': type, 'Content-Range': `bytes ${a}-${b}/${data.length}`, 'Content-Length': b - a + 1, 'Accept-Ranges': 'bytes' });
      res.end(data.subarray(a, b + 1));
      return;
    }
    res.writeHead(200, { 'Content-Type': type, 'Accept-Ranges': 'bytes' });
    res.end(data);
  });
}).listen(0, '127.0.0.1');
await new Promise((resolve) => server.once('listening', resolve));
const port = server.address().port;

// the default-scene mesh nodes a viewer must show, and whether the file is an MSFT_lod chain
function expected(file) {
  const data = fs.readFileSync(file);
  if (data.length < 20 || data.readUInt32LE(0) !== 0x46546c67 || 20 + data.readUInt32LE(12) > data.length) {
    throw new Error(`not a whole GLB (${data.length} bytes; a GLB starts with "glTF" and its JSON chunk)`);
  }
  const json = JSON.parse(data.subarray(20, 20 + data.readUInt32LE(12)).toString('utf8'));
  const scene = json.scenes[json.scene ?? 0];
  const stack = [...scene.nodes];
  let meshNodes = 0;
  let levels = 0;
  // triangles a node and its children draw (triangle lists: indices, else vertices, over 3; times
  // the instances of an EXT_mesh_gpu_instancing node, as renderer.info counts them)
  const triangles = (n) => {
    const node = json.nodes[n];
    const copies = node.extensions?.EXT_mesh_gpu_instancing
      ? json.accessors[node.extensions.EXT_mesh_gpu_instancing.attributes.TRANSLATION].count : 1;
    const own = node.mesh === undefined ? 0 : copies * json.meshes[node.mesh].primitives.reduce((sum, p) =>
      sum + json.accessors[p.indices ?? p.attributes.POSITION].count / 3, 0);
    return own + (node.children ?? []).reduce((sum, c) => sum + triangles(c), 0);
  };
  const chains = {};
  while (stack.length) {
    const n = stack.pop();
    const node = json.nodes[n];
    if (node.mesh !== undefined) meshNodes++;
    const ids = node.extensions?.MSFT_lod?.ids ?? [];
    levels = Math.max(levels, ids.length);
    if (ids.length) chains[node.name ?? `node ${n}`] = [n, ...ids].map(triangles);
    stack.push(...(node.children ?? []));
  }
  const shown = scene.nodes.reduce((sum, n) => sum + triangles(n), 0);
  return { chain: (json.extensionsUsed ?? []).includes('MSFT_lod'), levels: levels + 1, chains, shown };
}

const browser = await puppeteer.launch({
  executablePath: process.env.CHROMIUM ?? '/usr/bin/chromium',
  headless: true,
  protocolTimeout: 240000,
  args: ['--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--no-first-run',
    '--disable-background-networking', '--disable-component-update', '--disable-sync', '--disable-quic'],
});
let failed = 0;
// --lit-against: the largest mean luminance difference (0..255) a level may show with its normal
// map, which must also halve the difference it shows without
const LIT_MAX_DIFFERENCE = 4;
if (!['babylon', 'three'].includes(engine)) {
  console.error(`--engine ${engine}: use babylon or three`);
  process.exit(2);
}
const engineName = engine === 'three' ? 'three.js' : 'Babylon.js';
const version = (pkg) => JSON.parse(fs.readFileSync(path.join(here, `node_modules/${pkg}/package.json`))).version;
console.log(engine === 'three' ? `three.js ${version('three')} (GLTFLoader with the project's MSFT_lod plugin, three_msft_lod.js)`
  : `Babylon.js ${version('babylonjs')}, MSFT_lod files with range requests ${rangeRequests ? 'on' : 'off (Babylon defaults)'}`);
if (litAgainst && engine !== 'three') {
  console.error('--lit-against needs --engine three');
  process.exit(2);
}
for (const file of files) {
  if (litAgainst) {
    // a coarse terrain level must be lit like LoD0 through its normal map (and worse without it)
    const page = await browser.newPage();
    await page.goto(`http://127.0.0.1:${port}/three.html`);
    await page.waitForFunction('window.threeReady === true', { timeout: 60000 });
    const r = await page.evaluate((ref, url) => window.litDifference(ref, url), `/files${litAgainst}`, `/files${file}`);
    await page.close();
    const good = r.ok && r.maps > 0 && r.withMap < LIT_MAX_DIFFERENCE && r.withMap < 0.5 * r.without;
    failed += !good;
    const what = r.ok ? `${r.maps} meshes with a normal map and tangents; mean |Δ luminance| against ${path.basename(litAgainst)} ${r.withMap.toFixed(2)} with their normal maps, ${r.without.toFixed(2)} without` : r.error;
    console.log(`${good ? 'ok  ' : 'FAIL'}  ${file}: ${what}`);
    continue;
  }
  let want;
  try {
    want = expected(file);
  } catch (e) {
    // (named, not a stack trace: the file is what is wrong)
    failed += 1;
    console.log(`FAIL  ${file}: cannot be read: ${e.message}`);
    continue;
  }
  const page = await browser.newPage();
  const pageErrors = [];
  page.on('console', (m) => {
    const t = m.type();
    if ((t === 'error' || t === 'warn' || t === 'warning') && !/GL Driver Message/.test(m.text())) pageErrors.push(m.text());
  });
  page.on('pageerror', (e) => pageErrors.push(String(e)));
  await page.goto(`http://127.0.0.1:${port}/${engine === 'three' ? 'three.html' : ''}`);
  if (engine === 'three') await page.waitForFunction('window.threeReady === true', { timeout: 60000 });
  let r;
  let view = null;
  let snowScene = false;
  if (viewMode) {
    const manifest = JSON.parse(fs.readFileSync(path.join(path.dirname(file), 'manifest.json'), 'utf8'));
    view = manifest.view?.views?.[0] ?? null;
    snowScene = Boolean(manifest.snow);
  }
  try {
    r = await page.evaluate((url, options) => window.loadGlb(url, options), `/files${file}`,
      { rangeRequests: want.chain && rangeRequests, timeoutMs: 120000, view: view?.camera, drawLimit });
  } catch (e) {
    r = { ok: false, error: String(e) };
  }
  await new Promise((resolve) => setTimeout(resolve, 200));
  const problems = [];
  if (!r.ok) problems.push(r.error);
  problems.push(...(r.errors ?? []), ...pageErrors);
  if (r.ok && want.chain && engine === 'three') {
    // the framing view shows one level of each chain: the one its coverage selects (LoD0, unless the
    // file's MSFT_screencoverage lets LoD1 in as soon as the object no longer fills the screen)
    // (per chain: chains of one variant in different placement tiles share their meshes' names, and
    // a framing close enough, as a scene tile's, shows them at different levels)
    if ((r.chainLevels ?? []).length !== r.lodCount) problems.push(`${r.lodCount} LOD objects, ${(r.chainLevels ?? []).length} visible`);
    for (const c of r.chainLevels ?? []) {
      if (c.levels.length > 1) problems.push(`${c.name}: levels ${c.levels.join(', ')} shown at once`);
    }
    const walked = r.lodWalk ?? [];
    if (r.lodCount !== Object.keys(want.chains).length || walked.length !== Math.min(r.lodCount, 32)) {
      problems.push(`${r.lodCount} LOD objects made of ${Object.keys(want.chains).length} MSFT_lod nodes, ${walked.length} walked`);
    }
    for (const lod of walked) {
      const tris = want.chains[lod.name];
      // every level whose coverage range is not empty must be walked to
      const reachable = lod.coverage.filter((c, k) => c < (k === 0 ? 1 : lod.coverage[k - 1])).length;
      if (!tris) problems.push(`LOD ${lod.name} is no MSFT_lod node of the file`);
      else if (lod.walk.length !== reachable) problems.push(`LOD ${lod.name}: ${lod.walk.length} of ${reachable} levels walked`);
      for (const w of lod.walk) {
        if (tris && (w.shown !== w.level || w.triangles !== tris[w.level])) {
          problems.push(`LOD ${lod.name} at coverage ${w.coverage.toExponential(2)} (${w.distance.toFixed(1)} m): level ${w.shown} shown with ${w.triangles} triangles, expected level ${w.level} with ${tris[w.level]}`);
        }
      }
    }
  } else if (r.ok && engine !== 'three' && r.triangles !== want.shown) {
    problems.push(`Babylon shows ${r.triangles} triangles, the file's default scene has ${want.shown}`);
  }
  if (r.ok && want.chain && engine !== 'three') {
    const inOrder = r.lodLevels.length === want.levels && r.lodLevels.every((l, k) => l === k);
    if (!inOrder) problems.push(`MSFT_lod levels arrived as ${JSON.stringify(r.lodLevels)}, expected 0..${want.levels - 1} in order`);
    if (r.enabled.some((n) => !/_LOD0(_primitive\d+)?$/.test(n))) problems.push(`levels other than LoD0 left enabled: ${r.enabled.join(', ')}`);
  }
  if (viewMode && !view) problems.push('no view in manifest.json beside the file');
  if (r.ok && view && r.info && (r.info.triangles !== view.triangles || r.info.calls !== view.draw_calls)) {
    problems.push(`${engineName} draws ${r.info.triangles} triangles in ${r.info.calls} calls, the view stage reported ${view.triangles} in ${view.draw_calls}`);
  }
  const seen = r.pixels;
  if (r.ok && expectGreen && !seen) problems.push('not drawn, so not seen as green grass');
  if (r.ok && expectGreen && seen && !(seen.covered >= 0.002 && seen.green >= 0.5 && seen.dark <= 0.2)) {
    problems.push(`not seen as green grass: ${(100 * seen.covered).toFixed(1)} % of the frame covered, green leading on ${(100 * seen.green).toFixed(0)} %, dark ${(100 * seen.dark).toFixed(0)} %`);
  }
  // a [snow] scene's terrain shows its cover in the base colour (it showed none when the layers had
  // a fixed 2,500 m snowline): a tenth of what the view covers must be snow-white
  if (r.ok && snowScene && seen && !(seen.white >= 0.1)) {
    problems.push(`a [snow] scene seen without snow: ${(100 * seen.white).toFixed(1)} % of the covered frame white`);
  }
  if (thumbs && r.ok && seen) {
    fs.mkdirSync(thumbs, { recursive: true });
    const canvas = await page.$('#c');
    const owner = path.basename(path.dirname(viewMode ? file : path.dirname(file)));
    await canvas.screenshot({ path: path.join(thumbs, `${engine}_${owner}_${path.basename(file, '.glb')}.png`) });
  }
  failed += problems.length > 0;
  const colour = seen ? `, frame ${(100 * seen.covered).toFixed(1)} % covered, mean rgb ${seen.mean.map((v) => v.toFixed(2)).join(' ')}, green ${(100 * seen.green).toFixed(0)} %, dark ${(100 * seen.dark).toFixed(0)} %, white ${(100 * seen.white).toFixed(0)} %` : '';
  const drawn = r.ok && view && r.info ? `view ${view.camera.name}: ${r.info.triangles} triangles, ${r.info.calls} draw calls (report: ${view.triangles}, ${view.draw_calls}), ` : '';
  const walk = (r.lodWalk ?? []).map((l) => ` ${l.name} by coverage: ${l.walk.map((w) => `LoD${w.shown} ${w.triangles} tris at ${w.distance.toFixed(1)} m`).join(', ')}`).join(';');
  const undrawn = r.ok && !seen ? `, frame not drawn (${r.triangles} triangles over the ${drawLimit} --draw-limit)` : '';
  const what = r.ok ? `${drawn}${r.meshes} meshes, ${r.enabled.length} enabled${engine === 'three' ? '' : ` with ${r.triangles} triangles`}${undrawn}${want.chain && engine !== 'three' ? `, LoD levels ${JSON.stringify(r.lodLevels)}` : ''}${walk ? ';' + walk : ''}${colour}` : '';
  console.log(`${problems.length ? 'FAIL' : 'ok  '}  ${file}: ${what}${problems.length ? ' — ' + problems.join(' | ') : ''}`);
  await page.close();
}
await browser.close();
server.close();
console.log(`${engineName}: ${files.length - failed} of ${files.length} files load without errors`);
process.exit(failed ? 1 : 0);
