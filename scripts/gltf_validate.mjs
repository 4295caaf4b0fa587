#!/usr/bin/env node
// Run the Khronos glTF Validator (npm gltf-validator, validateBytes) on each .glb / .gltf given.
//
//   node scripts/gltf_validate.mjs [--summary-tsv FILE] FILE...
//
// A .gltf's external resources (.bin buffers, .png images) are read from beside it. Prints the issue
// counts per file; exits 1 unless every file has 0 errors and 0 warnings (their messages are printed).
// Infos and hints are allowed: EXT_mesh_gpu_instancing and MSFT_lod are reported as unsupported at info
// level, because the validator cannot check them (scripts/check_outputs.py does).
//
// Unused objects (UNUSED_OBJECT, info level) fail too: a file holds only what it shows, and every
// UV set is sampled by a texture (`uv without texture` counts TEXCOORD_n attributes whose material
// has none). Accessors that EXT_mesh_gpu_instancing references are told apart and not failed: the
// validator cannot read that extension, so it calls them unused (our own checks read them).
//
// One warning is accepted, and counted apart: DATA_URI_GLB on a buffer verdant names `MSFT_lod
// level …` (src/export/streaming.rs). A chain file keeps each finer level's data behind a data:
// URI on purpose: Babylon.js streams MSFT_lod levels in order only for data behind a URI, and with
// the data in the binary chunk its default loader fails on the file. Any other data: URI in a GLB,
// or this one on another buffer, still fails.
//
// And MESH_PRIMITIVE_GENERATED_TANGENT_SPACE on a primitive with integer positions
// (KHR_mesh_quantization) whose every node has a non-uniform scale (`verdant terrain --quantize`):
// such a mesh is written without TANGENT on purpose. Babylon.js builds its normal-map frame from the
// node's matrix itself rather than its inverse transpose, so with the grid's scale any stored tangent
// frame lights the terrain wrongly there; without one, engines derive the frame from the surface and
// three.js and Babylon.js light it as the f32 file (check.sh 5a2 compares the frames).
import { readFile, appendFile } from 'node:fs/promises';
import path from 'node:path';
import validator from 'gltf-validator';

const SEVERITY = ['error', 'warning', 'info', 'hint'];
const MAX_PRINTED = 30;

function usage(message) {
  console.error(`gltf_validate: ${message}\nusage: node scripts/gltf_validate.mjs [--summary-tsv FILE] FILE...`);
  process.exit(2);
}

const args = process.argv.slice(2);
let summaryTsv = null;
const files = [];
for (let i = 0; i < args.length; i++) {
  if (args[i] === '--summary-tsv') {
    summaryTsv = args[++i] ?? usage('--summary-tsv needs a file name');
  } else if (args[i].startsWith('-')) {
    usage(`unknown option ${args[i]}`);
  } else {
    files.push(args[i]);
  }
}
if (files.length === 0) usage('no files given');

// The glTF JSON of a .glb or .gltf file.
function gltfJson(data) {
  const magic = String.fromCharCode(...data.subarray(0, 4));
  if (magic !== 'glTF') return JSON.parse(new TextDecoder().decode(data));
  const view = new DataView(data.buffer, data.byteOffset, data.byteLength);
  const jsonLength = view.getUint32(12, true);
  return JSON.parse(new TextDecoder().decode(data.subarray(20, 20 + jsonLength)));
}

// Accessor indices that EXT_mesh_gpu_instancing attributes name.
function instancingAccessors(doc) {
  const used = new Set();
  for (const node of doc.nodes ?? []) {
    const attributes = node.extensions?.EXT_mesh_gpu_instancing?.attributes ?? {};
    for (const a of Object.values(attributes)) used.add(a);
  }
  return used;
}

// Buffers only EXT_meshopt_compression's bufferView extensions name (the compressed data of a file
// without raw views, e.g. no images): used, through an extension the validator cannot read.
function meshoptBuffers(doc) {
  const used = new Set();
  for (const v of doc.bufferViews ?? []) {
    const ext = v.extensions?.EXT_meshopt_compression;
    if (ext && Number.isInteger(ext.buffer)) used.add(ext.buffer);
  }
  return used;
}

// Splits UNUSED_OBJECT messages into really unused, instancing (a validator blind spot), uv without texture.
function unusedObjects(messages, doc) {
  const instancing = instancingAccessors(doc);
  const meshopt = meshoptBuffers(doc);
  const out = { unused: [], instancing: 0, uvWithoutTexture: 0, meshopt: 0 };
  for (const m of messages) {
    if (m.code !== 'UNUSED_OBJECT') continue;
    const accessor = /^\/accessors\/(\d+)$/.exec(m.pointer ?? '');
    const buffer = /^\/buffers\/(\d+)$/.exec(m.pointer ?? '');
    if (buffer && meshopt.has(Number(buffer[1]))) out.meshopt++;
    else if (accessor && instancing.has(Number(accessor[1]))) out.instancing++;
    else if (/\/attributes\/TEXCOORD_\d+$/.test(m.pointer ?? '')) out.uvWithoutTexture++;
    else out.unused.push(m.pointer ?? '?');
  }
  return out;
}

async function validateFile(file) {
  const dir = path.dirname(file);
  const data = new Uint8Array(await readFile(file));
  return validator.validateBytes(data, {
    uri: path.basename(file),
    maxIssues: 0, // no limit
    writeTimestamp: false,
    externalResourceFunction: async (uri) => {
      const resolved = path.resolve(dir, decodeURIComponent(uri));
      try {
        return new Uint8Array(await readFile(resolved));
      } catch (e) {
        throw new Error(`cannot read external resource ${uri} (${resolved}): ${e.code ?? e.message}`);
      }
    },
  });
}

let failed = 0;
for (const file of files) {
  const name = path.basename(file);
  let status = 'ok';
  let counts = '-';
  try {
    const report = await validateFile(file);
    const { numErrors, numInfos, numHints } = report.issues;
    const doc = gltfJson(new Uint8Array(await readFile(file)));
    // the chain files' level buffers (see the header)
    const isLevelBuffer = (m) => {
      const k = /^\/buffers\/(\d+)\/uri$/.exec(m.pointer ?? '');
      return m.code === 'DATA_URI_GLB' && k && /^MSFT_lod level \d+/.test(doc?.buffers?.[Number(k[1])]?.name ?? '');
    };
    const levelBuffers = report.issues.messages.filter(isLevelBuffer).length;
    // quantized meshes on a non-uniform grid, written without TANGENT (see the header)
    const isOmittedTangents = (m) => {
      const k = /^\/meshes\/(\d+)\/primitives\/(\d+)\/material$/.exec(m.pointer ?? '');
      if (m.code !== 'MESH_PRIMITIVE_GENERATED_TANGENT_SPACE' || !k) return false;
      const mesh = Number(k[1]);
      const position = doc?.meshes?.[mesh]?.primitives?.[Number(k[2])]?.attributes?.POSITION;
      const integer = Number.isInteger(position) && doc.accessors?.[position]?.componentType !== 5126;
      const nodes = (doc?.nodes ?? []).filter((n) => n.mesh === mesh);
      const nonUniform = (n) => Array.isArray(n.scale) && !(n.scale[0] === n.scale[1] && n.scale[1] === n.scale[2]);
      return integer && nodes.length > 0 && nodes.every(nonUniform);
    };
    const omittedTangents = report.issues.messages.filter(isOmittedTangents).length;
    const messages = report.issues.messages.filter((m) => !isLevelBuffer(m) && !isOmittedTangents(m));
    const numWarnings = report.issues.numWarnings - levelBuffers - omittedTangents;
    const unused = unusedObjects(messages, doc);
    counts = `${numErrors}/${numWarnings}/${numInfos}/${numHints} unused ${unused.unused.length + unused.uvWithoutTexture}`;
    const bad = numErrors > 0 || numWarnings > 0 || unused.unused.length > 0 || unused.uvWithoutTexture > 0;
    // summarise infos/hints by code, so the allowed ones stay visible without flooding the log
    const minor = {};
    for (const m of messages) if (m.severity >= 2) minor[m.code] = (minor[m.code] ?? 0) + 1;
    const minorText = Object.entries(minor).map(([code, n]) => `${code}×${n}`).join(', ');
    console.log(`${bad ? 'FAIL' : 'OK  '}  ${name}: ${numErrors} errors, ${numWarnings} warnings, ` +
      `${numInfos} infos, ${numHints} hints${minorText ? ` (${minorText})` : ''}; ` +
      `unused objects ${unused.unused.length}, uv without texture ${unused.uvWithoutTexture} ` +
      `(not counted: ${unused.instancing} accessors EXT_mesh_gpu_instancing names` +
      `${levelBuffers ? `, ${levelBuffers} MSFT_lod level buffers as data: URIs` : ''}` +
      `${unused.meshopt ? `, ${unused.meshopt} buffer of EXT_meshopt_compression data` : ''}` +
      `${omittedTangents ? `, ${omittedTangents} quantized non-uniformly scaled primitives without TANGENT` : ''})`);
    if (bad) {
      status = 'FAIL';
      failed++;
      const serious = messages.filter((m) => m.severity <= 1);
      for (const m of serious.slice(0, MAX_PRINTED)) {
        console.log(`      ${SEVERITY[m.severity]} ${m.code} at ${m.pointer ?? m.offset ?? '?'}: ${m.message}`);
      }
      if (serious.length > MAX_PRINTED) console.log(`      ... and ${serious.length - MAX_PRINTED} more`);
      if (unused.unused.length) {
        console.log(`      unused objects: ${unused.unused.slice(0, MAX_PRINTED).join(', ')}` +
          (unused.unused.length > MAX_PRINTED ? ` ... and ${unused.unused.length - MAX_PRINTED} more` : ''));
      }
    }
  } catch (e) {
    status = 'FAIL';
    failed++;
    const message = typeof e === 'string' ? e : (e?.message ?? String(e));
    console.log(`FAIL  ${name}: validator could not run: ${message}`);
  }
  if (summaryTsv) await appendFile(summaryTsv, `${name}\t${status}\t${counts}\n`);
}

console.log(`gltf-validator: ${files.length - failed} of ${files.length} files without errors, warnings or unused objects`);
process.exit(failed ? 1 : 0);
