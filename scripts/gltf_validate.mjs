#!/usr/bin/env node
// Run the Khronos glTF Validator (npm gltf-validator, validateBytes) on each .glb / .gltf given.
//
//   node scripts/gltf_validate.mjs [--summary-tsv FILE] FILE...
//
// A .gltf's external resources (.bin buffers, .png images) are read from beside it. Prints the issue
// counts per file; exits 1 unless every file has 0 errors and 0 warnings (their messages are printed).
// Infos and hints are allowed: EXT_mesh_gpu_instancing and MSFT_lod are reported as unsupported at info
// level, because the validator cannot check them (scripts/check_outputs.py does).
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
    const { numErrors, numWarnings, numInfos, numHints, messages } = report.issues;
    counts = `${numErrors}/${numWarnings}/${numInfos}/${numHints}`;
    const bad = numErrors > 0 || numWarnings > 0;
    // summarise infos/hints by code, so the allowed ones stay visible without flooding the log
    const minor = {};
    for (const m of messages) if (m.severity >= 2) minor[m.code] = (minor[m.code] ?? 0) + 1;
    const minorText = Object.entries(minor).map(([code, n]) => `${code}×${n}`).join(', ');
    console.log(`${bad ? 'FAIL' : 'OK  '}  ${name}: ${numErrors} errors, ${numWarnings} warnings, ` +
      `${numInfos} infos, ${numHints} hints${minorText ? ` (${minorText})` : ''}`);
    if (bad) {
      status = 'FAIL';
      failed++;
      const serious = messages.filter((m) => m.severity <= 1);
      for (const m of serious.slice(0, MAX_PRINTED)) {
        console.log(`      ${SEVERITY[m.severity]} ${m.code} at ${m.pointer ?? m.offset ?? '?'}: ${m.message}`);
      }
      if (serious.length > MAX_PRINTED) console.log(`      ... and ${serious.length - MAX_PRINTED} more`);
    }
  } catch (e) {
    status = 'FAIL';
    failed++;
    const message = typeof e === 'string' ? e : (e?.message ?? String(e));
    console.log(`FAIL  ${name}: validator could not run: ${message}`);
  }
  if (summaryTsv) await appendFile(summaryTsv, `${name}\t${status}\t${counts}\n`);
}

console.log(`gltf-validator: ${files.length - failed} of ${files.length} files without errors or warnings`);
process.exit(failed ? 1 : 0);
