// Loads a .glb/.gltf with Babylon.js's KHR_gaussian_splatting loader (a viewer's loader, not
// ours), captures the splat rows it builds for rendering, and compares them with the INRIA PLY
// the file was converted from. Usage (Node 20; `npm ci` in this folder first):
//     node check.mjs SOURCE.ply CONVERTED.glb
// Prints one JSON object (counts, worst deviations) and exits 1 when a deviation exceeds what
// Babylon's own 8-bit packing allows (one step: the glTF holds f32 values, Babylon quantises).
import fs from "node:fs";
import path from "node:path";
import { NullEngine } from "@babylonjs/core/Engines/nullEngine.js";
import { Scene } from "@babylonjs/core/scene.js";
import { LoadAssetContainerAsync } from "@babylonjs/core/Loading/sceneLoader.js";
import { GaussianSplattingMesh } from "@babylonjs/core/Meshes/GaussianSplatting/gaussianSplattingMesh.pure.js";
import "@babylonjs/loaders/glTF/2.0/index.js";

const SH_C0 = 0.28209479177387814;

/** Reads a binary little-endian INRIA PLY of float properties into {count, columns}. */
function readInriaPly(file) {
  const bytes = fs.readFileSync(file);
  const end = bytes.indexOf("end_header\n");
  if (end < 0) throw new Error(`${file}: no end_header`);
  const header = bytes.subarray(0, end).toString("latin1").split("\n");
  if (!header.includes("format binary_little_endian 1.0")) {
    throw new Error(`${file}: only binary little-endian PLY is read here`);
  }
  let count = 0;
  const names = [];
  let inVertex = false;
  for (const line of header) {
    const w = line.trim().split(/\s+/);
    if (w[0] === "element") {
      inVertex = w[1] === "vertex";
      if (inVertex) count = Number(w[2]);
    } else if (w[0] === "property" && inVertex) {
      if (w[1] !== "float") throw new Error(`${file}: property ${w[2]} is ${w[1]}, not float`);
      names.push(w[2]);
    }
  }
  const body = new DataView(bytes.buffer, bytes.byteOffset + end + "end_header\n".length);
  const columns = Object.fromEntries(names.map((n) => [n, new Float32Array(count)]));
  for (let i = 0; i < count; i++) {
    names.forEach((n, k) => {
      columns[n][i] = body.getFloat32(4 * (i * names.length + k), true);
    });
  }
  return { count, columns };
}

const clamp255 = (v) => (v <= 0 ? 0 : v >= 255 ? 255 : (v + 0.5) | 0);

const [source, converted] = process.argv.slice(2);
if (!source || !converted) {
  console.error("usage: node check.mjs SOURCE.ply CONVERTED.glb");
  process.exit(2);
}
const ply = readInriaPly(source);

let captured = null;
GaussianSplattingMesh.prototype.updateDataAsync = async function (buffer, sh, _partial, degree) {
  captured = { buffer, sh, degree: degree ?? 0 };
};
const engine = new NullEngine();
const scene = new Scene(engine);
// A .glb goes in as bytes; a .gltf (trisplat embeds its buffers as data URIs) as a data string.
const extension = path.extname(converted).toLowerCase();
const input =
  extension === ".gltf"
    ? "data:" + fs.readFileSync(converted, "utf8")
    : new Uint8Array(fs.readFileSync(converted));
const container = await LoadAssetContainerAsync(input, scene, { pluginExtension: extension });
const splatMeshes = container.meshes.filter((m) => m.getClassName() === "GaussianSplattingMesh");
if (!captured || splatMeshes.length !== 1) {
  console.log(JSON.stringify({ ok: false, error: "Babylon built no Gaussian splatting mesh" }));
  process.exit(1);
}

const rows = captured.buffer.byteLength / 32;
const f = new Float32Array(captured.buffer);
const b = new Uint8Array(captured.buffer);
const c = ply.columns;
const restCount = Object.keys(c).filter((n) => n.startsWith("f_rest_")).length / 3;
const worst = { position: 0, scale_rel: 0, color: 0, alpha: 0, rotation: 0, sh: 0 };
const bump = (key, v) => {
  if (!(v <= worst[key])) worst[key] = v;
};
for (let i = 0; i < Math.min(rows, ply.count); i++) {
  ["x", "y", "z"].forEach((n, k) => bump("position", Math.abs(f[8 * i + k] - c[n][i])));
  [0, 1, 2].forEach((k) => {
    const want = Math.exp(c[`scale_${k}`][i]);
    bump("scale_rel", Math.abs(f[8 * i + 3 + k] - want) / want);
    bump("color", Math.abs(b[32 * i + 24 + k] - clamp255((0.5 + SH_C0 * c[`f_dc_${k}`][i]) * 255)));
  });
  bump("alpha", Math.abs(b[32 * i + 27] - clamp255((1 / (1 + Math.exp(-c.opacity[i]))) * 255)));
  const q = [0, 1, 2, 3].map((k) => c[`rot_${k}`][i]); // w x y z
  const norm = Math.hypot(...q);
  q.forEach((v, k) => bump("rotation", Math.abs(b[32 * i + 28 + k] - clamp255((v / norm) * 127.5 + 127.5))));
  if (captured.sh) {
    for (let k = 0; k < restCount; k++) {
      for (let ch = 0; ch < 3; ch++) {
        const flat = 3 * k + ch;
        const got = captured.sh[flat >> 4][16 * i + (flat & 15)];
        bump("sh", Math.abs(got - clamp255(c[`f_rest_${ch * restCount + k}`][i] * 128 + 128)));
      }
    }
  }
}
const ok =
  rows === ply.count &&
  captured.degree === Math.round(Math.sqrt(restCount + 1)) - 1 &&
  worst.position === 0 &&
  worst.scale_rel <= 1e-6 &&
  Math.max(worst.color, worst.alpha, worst.rotation, worst.sh) <= 1;
console.log(
  JSON.stringify({ ok, babylon: "9.28.0", splats: rows, ply_rows: ply.count, sh_degree: captured.degree, worst }),
);
process.exit(ok ? 0 : 1);
