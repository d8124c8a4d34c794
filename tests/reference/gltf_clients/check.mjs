// Real glTF clients as checks of trisplat's animated glTF (issue #31).
//
// For each FILE.glb=FRAMES_DIR pair: the Khronos glTF-Validator must report 0 errors, and
// three.js's GLTFLoader (with its meshopt decoder) must load the file, and its AnimationMixer,
// set to frame k's time, must place every vertex of the visible mesh within
// TOL x (frame k's bounding-box diagonal) of frame k's PLY (FRAMES_DIR/frame_*.ply in name
// order). Frame times: --report report.json (its frame_times), --fps F (k / F) or --times
// T,T,... (one per frame file, in name order: a few frames of a rig evaluated by trisplat).
//
// usage: node check.mjs [--report report.json | --fps F | --times T,...] [--tolerance 1e-4]
//        [--only K,K,...]
//        A.glb=A_frames ...   (--only: check those frames alone, for long tracks)
// Prints one line per file and "N passed, M failed"; exits 1 on any failure.
import fs from 'node:fs';
import path from 'node:path';
import validator from 'gltf-validator';
import { AnimationMixer, LoopOnce, Vector3 } from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { PLYLoader } from 'three/examples/jsm/loaders/PLYLoader.js';
import { MeshoptDecoder } from 'three/examples/jsm/libs/meshopt_decoder.module.js';

function parseArgs(argv) {
  const opts = { report: null, fps: null, times: null, tolerance: 1e-4, only: null, pairs: [] };
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    if (a === '--report') opts.report = argv[++i];
    else if (a === '--fps') opts.fps = Number(argv[++i]);
    else if (a === '--times') opts.times = argv[++i].split(',').map(Number);
    else if (a === '--tolerance') opts.tolerance = Number(argv[++i]);
    else if (a === '--only') opts.only = new Set(argv[++i].split(',').map(Number));
    else if (a.includes('=')) {
      const [glb, frames] = a.split('=');
      opts.pairs.push({ glb, frames });
    } else throw new Error(`unknown argument ${a}`);
  }
  const timings = [opts.report, opts.fps, opts.times].filter((t) => t !== null).length;
  if (!opts.pairs.length || timings !== 1) {
    throw new Error('usage: check.mjs (--report R | --fps F | --times T,...) [--tolerance T] A.glb=FRAMES ...');
  }
  return opts;
}

function arrayBufferOf(file) {
  const b = fs.readFileSync(file);
  return b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength);
}

async function validate(file) {
  const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
    maxIssues: 100,
  });
  const { numErrors, numWarnings, numInfos, messages } = report.issues;
  const shown = messages
    .filter((m) => m.severity <= 1)
    .slice(0, 5)
    .map((m) => `${m.code} ${m.pointer ?? ''}: ${m.message}`);
  return { numErrors, numWarnings, numInfos, shown };
}

function loadGltf(file) {
  const loader = new GLTFLoader();
  loader.setMeshoptDecoder(MeshoptDecoder);
  return new Promise((resolve, reject) => loader.parse(arrayBufferOf(file), '', resolve, reject));
}

function framePositions(file) {
  const geometry = new PLYLoader().parse(arrayBufferOf(file));
  return geometry.getAttribute('position');
}

/** The world-space vertices of the one visible mesh of `scene`. */
function visibleVertices(scene) {
  scene.updateMatrixWorld(true);
  const visible = [];
  scene.traverse((o) => {
    if (o.isMesh && Math.abs(o.matrixWorld.determinant()) > 0) visible.push(o);
  });
  if (visible.length !== 1) throw new Error(`${visible.length} visible meshes, expected 1`);
  const mesh = visible[0];
  const count = mesh.geometry.getAttribute('position').count;
  const out = new Float64Array(3 * count);
  const v = new Vector3();
  for (let i = 0; i < count; i++) {
    mesh.getVertexPosition(i, v);
    v.applyMatrix4(mesh.matrixWorld);
    out[3 * i] = v.x;
    out[3 * i + 1] = v.y;
    out[3 * i + 2] = v.z;
  }
  return out;
}

async function checkPair({ glb, frames }, times, tolerance, only) {
  const problems = [];
  const v = await validate(glb);
  if (v.numErrors > 0) problems.push(`validator: ${v.numErrors} errors: ${v.shown.join('; ')}`);
  const files = fs
    .readdirSync(frames)
    .filter((f) => f.endsWith('.ply'))
    .sort()
    .map((f) => path.join(frames, f));
  if (files.length !== times.length) {
    problems.push(`${files.length} frame files for ${times.length} frame times`);
    return { problems, v, worst: NaN };
  }
  const gltf = await loadGltf(glb);
  const mixer = new AnimationMixer(gltf.scene);
  const action = mixer.clipAction(gltf.animations[0]);
  action.setLoop(LoopOnce, 1);
  action.clampWhenFinished = true;
  action.play();
  let worst = 0;
  for (let k = 0; k < files.length; k++) {
    if (only && !only.has(k)) continue;
    mixer.setTime(times[k]);
    const got = visibleVertices(gltf.scene);
    const want = framePositions(files[k]);
    if (got.length !== 3 * want.count) {
      problems.push(`frame ${k}: ${got.length / 3} vertices in the glTF, ${want.count} in ${files[k]}`);
      continue;
    }
    const lo = [Infinity, Infinity, Infinity];
    const hi = [-Infinity, -Infinity, -Infinity];
    let err = 0;
    for (let i = 0; i < want.count; i++) {
      const p = [want.getX(i), want.getY(i), want.getZ(i)];
      let d2 = 0;
      for (let c = 0; c < 3; c++) {
        lo[c] = Math.min(lo[c], p[c]);
        hi[c] = Math.max(hi[c], p[c]);
        d2 += (got[3 * i + c] - p[c]) ** 2;
      }
      err = Math.max(err, Math.sqrt(d2));
    }
    const diagonal = Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
    const relative = err / diagonal;
    worst = Math.max(worst, relative);
    if (!(relative <= tolerance)) {
      problems.push(`frame ${k}: a vertex is ${err} m off (${relative.toExponential(2)} of the diagonal)`);
    }
  }
  return { problems, v, worst };
}

async function main() {
  const opts = parseArgs(process.argv.slice(2));
  await MeshoptDecoder.ready;
  let passed = 0;
  let failed = 0;
  for (const pair of opts.pairs) {
    let times = opts.times ?? undefined;
    if (opts.report) times = JSON.parse(fs.readFileSync(opts.report, 'utf8')).frame_times;
    let result;
    try {
      const count = fs.readdirSync(pair.frames).filter((f) => f.endsWith('.ply')).length;
      times ??= Array.from({ length: count }, (_, k) => k / opts.fps);
      result = await checkPair(pair, times, opts.tolerance, opts.only);
    } catch (e) {
      result = { problems: [`${e.stack ?? e}`], v: null, worst: NaN };
    }
    const v = result.v;
    const summary = v ? `validator ${v.numErrors} errors ${v.numWarnings} warnings ${v.numInfos} infos` : '';
    const size = fs.existsSync(pair.glb) ? fs.statSync(pair.glb).size : 0;
    if (result.problems.length === 0) {
      passed++;
      console.log(`ok   ${pair.glb} (${size} bytes): ${summary}; worst vertex ${result.worst.toExponential(2)} of the diagonal`);
    } else {
      failed++;
      console.log(`FAIL ${pair.glb}: ${summary}\n  ${result.problems.join('\n  ')}`);
    }
  }
  console.log(`${passed} passed, ${failed} failed`);
  process.exit(failed ? 1 : 0);
}

main();
