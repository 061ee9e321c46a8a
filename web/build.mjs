// Copies the browser files the page needs from node_modules into vendor/ (run `npm ci && npm run build`
// here; .ci/run and `kinema web` do). Nothing is fetched at run time: the page loads vendor/ only.
import {copyFileSync, existsSync, mkdirSync, readFileSync, writeFileSync} from "node:fs";
import {dirname, join} from "node:path";
import {fileURLToPath} from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const vendor = join(here, "vendor");
mkdirSync(vendor, {recursive: true});
const files = {
  "onnxruntime-web/dist/ort.wasm.min.mjs": "ort.wasm.min.mjs",
  "onnxruntime-web/dist/ort-wasm-simd-threaded.mjs": "ort-wasm-simd-threaded.mjs",
  "onnxruntime-web/dist/ort-wasm-simd-threaded.wasm": "ort-wasm-simd-threaded.wasm",
  "three/build/three.module.min.js": "three.module.min.js",
  "three/build/three.core.min.js": "three.core.min.js",
  "three/examples/jsm/controls/OrbitControls.js": "OrbitControls.js",
  "three/LICENSE": "LICENSE.three.txt",
};
for (const [src, dst] of Object.entries(files)) {
  const from = join(here, "node_modules", src);
  if (!existsSync(from)) throw new Error(`${from} is missing: run \`npm ci\` in ${here} first`);
  copyFileSync(from, join(vendor, dst));
}
// onnxruntime-web's package carries no licence file; its package.json says MIT (Microsoft Corporation)
const ortPkg = JSON.parse(readFileSync(join(here, "node_modules/onnxruntime-web/package.json"), "utf8"));
writeFileSync(join(vendor, "LICENSE.onnxruntime-web.txt"), `onnxruntime-web ${ortPkg.version}: ${ortPkg.license} License
Copyright (c) Microsoft Corporation.

Permission is hereby granted, free of charge, to any person obtaining a copy of this software and associated
documentation files (the "Software"), to deal in the Software without restriction, including without limitation
the rights to use, copy, modify, merge, publish, distribute, sublicense, and/or sell copies of the Software, and to
permit persons to whom the Software is furnished to do so, subject to the following conditions:

The above copyright notice and this permission notice shall be included in all copies or substantial portions of
the Software.

THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR IMPLIED, INCLUDING BUT NOT LIMITED TO THE
WARRANTIES OF MERCHANTABILITY, FITNESS FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE AUTHORS OR
COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER LIABILITY, WHETHER IN AN ACTION OF CONTRACT, TORT OR
OTHERWISE, ARISING FROM, OUT OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN THE SOFTWARE.
`);
console.log(`vendor/: ${Object.keys(files).length} files`);
