// Renders a KHR_gaussian_splatting glTF written by trisplat with Babylon.js in headless
// Chromium (WebGL on SwiftShader: a viewer's renderer, not ours) from the cameras of a
// cameras.json, and compares each view with trisplat's own render of the source PLY from the
// same camera (`trisplat render SOURCE.ply --cameras CAMS.json -o OURS --outputs rgb,alpha`).
// Usage (Node 20; `npm ci` in this folder first; Debian's chromium at /usr/bin/chromium):
//     node render.mjs CONVERTED.glb CAMS.json OURS_DIR OUT_DIR
// Writes OUT_DIR/<img_name>_babylon.png per view and prints one JSON object: per view the
// silhouette IoU (alpha > 0.5; Babylon's alpha recovered from a black and a white background)
// and the PSNR of rgb over our silhouette. Exits 1 when a view's IoU is below 0.9.
import fs from "node:fs";
import http from "node:http";
import path from "node:path";
import { fileURLToPath } from "node:url";
import { chromium } from "playwright-core";

const here = path.dirname(fileURLToPath(import.meta.url));
const [glb, camsFile, oursDir, outDir] = process.argv.slice(2);
if (!outDir) {
  console.error("usage: node render.mjs CONVERTED.glb CAMS.json OURS_DIR OUT_DIR");
  process.exit(2);
}
const cameras = JSON.parse(fs.readFileSync(camsFile, "utf8"));
fs.mkdirSync(outDir, { recursive: true });

const types = { ".html": "text/html", ".js": "text/javascript", ".mjs": "text/javascript",
  ".png": "image/png", ".glb": "model/gltf-binary", ".gltf": "model/gltf+json",
  ".bin": "application/octet-stream", ".json": "application/json" };
// Serves this folder, the glTF as /input/<name> (its folder, for .gltf buffers) and our renders
// as /ours/.
const server = http.createServer((req, res) => {
  const url = decodeURIComponent(new URL(req.url, "http://x").pathname);
  let file;
  if (url.startsWith("/input/")) file = path.join(path.dirname(path.resolve(glb)), url.slice(7));
  else if (url.startsWith("/ours/")) file = path.join(path.resolve(oursDir), url.slice(6));
  else file = path.join(here, url);
  fs.readFile(file, (err, data) => {
    if (err) { res.writeHead(404); res.end(); return; }
    res.writeHead(200, { "content-type": types[path.extname(file)] ?? "application/octet-stream" });
    res.end(data);
  });
});
await new Promise((r) => server.listen(0, "127.0.0.1", r));
const base = `http://127.0.0.1:${server.address().port}`;

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
  args: ["--no-sandbox", "--disable-gpu-sandbox", "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic"],
});
let failed = false;
const views = [];
try {
  const page = await browser.newPage();
  const logs = [];
  page.on("console", (m) => logs.push(m.text()));
  page.on("pageerror", (e) => logs.push(`pageerror: ${e.message}`));
  await page.goto(`${base}/page.html`);
  await page.waitForFunction(() => window.pageReady === true, null, { timeout: 60000 });
  const { width, height } = cameras[0];
  const loaded = await page.evaluate(
    ([u, w, h]) => window.loadSplats(u, w, h),
    [`/input/${path.basename(glb)}`, width, height],
  );
  for (const cam of cameras) {
    if (cam.width !== width || cam.height !== height) throw new Error("cameras differ in size");
    const black = await page.evaluate(([c]) => window.renderView(c, 0), [cam]);
    const white = await page.evaluate(([c]) => window.renderView(c, 1), [cam]);
    fs.writeFileSync(path.join(outDir, `${cam.img_name}_babylon.png`),
      Buffer.from(black.split(",")[1], "base64"));
    const score = await page.evaluate(async ([b, wh, rgbUrl, alphaUrl, w, h]) => {
      const pixels = async (src) => {
        const img = new Image();
        img.src = src;
        await img.decode();
        const c = new OffscreenCanvas(w, h);
        const g = c.getContext("2d");
        g.drawImage(img, 0, 0, w, h);
        return g.getImageData(0, 0, w, h).data;
      };
      const [pb, pw, ours, oursA] = await Promise.all([pixels(b), pixels(wh), pixels(rgbUrl),
        pixels(alphaUrl)]);
      let inter = 0, union = 0, se = 0, n = 0, theirs = 0, mine = 0;
      for (let p = 0; p < w * h; p++) {
        // Composited on black: C = a c; on white: C + (1 - a). So 1 - a = white - black.
        let t = 0;
        for (let k = 0; k < 3; k++) t += (pw[4 * p + k] - pb[4 * p + k]) / 255;
        const aB = 1 - t / 3 > 0.5;
        const aO = oursA[4 * p] / 255 > 0.5;
        theirs += aB; mine += aO;
        if (aB && aO) inter++;
        if (aB || aO) union++;
        if (aO) {
          for (let k = 0; k < 3; k++) { const d = (pb[4 * p + k] - ours[4 * p + k]) / 255; se += d * d; }
          n += 3;
        }
      }
      return { iou: union ? inter / union : 1, psnr: n ? -10 * Math.log10(se / n) : null,
        babylon_pixels: theirs, trisplat_pixels: mine };
    }, [black, white, `/ours/${cam.img_name}_rgb.png`, `/ours/${cam.img_name}_alpha.png`,
      width, height]);
    views.push({ view: cam.img_name, ...score });
    if (!(score.iou >= 0.9)) failed = true;
  }
  console.log(JSON.stringify({ babylon: "9.28.0", loaded, views, logs: logs.slice(0, 20) }, null, 1));
} finally {
  await browser.close();
  server.close();
}
process.exit(failed ? 1 : 0);
