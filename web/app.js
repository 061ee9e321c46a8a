// The page: a form, a three.js skeleton view, waypoints clicked on the ground, BVH download, and
// window.kinema.generate({prompt, seconds, seed, waypoints}) for scripts and tests.
import * as THREE from "three";
import {OrbitControls} from "./vendor/OrbitControls.js";
import * as ort from "./vendor/ort.wasm.min.mjs";
import {KinemaError, KinemaModel, toBvh} from "./kinema-runtime.js";

ort.env.wasm.wasmPaths = new URL("./vendor/", import.meta.url).href;
ort.env.wasm.numThreads = 1;

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const modelUrl = params.get("model") || "./model/";
const precision = params.get("precision") === "fp16" ? "fp16" : "fp32";  // fp16: the float16-weight graphs, half the download

// ------------------------------------------------------------------------------------------- scene
const view = $("view");
const renderer = new THREE.WebGLRenderer({antialias: true, preserveDrawingBuffer: true});
renderer.setPixelRatio(window.devicePixelRatio);
view.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x1d2026);
const camera = new THREE.PerspectiveCamera(45, 1, 0.05, 200);
camera.position.set(4.5, 3.2, -2.5);
const controls = new OrbitControls(camera, renderer.domElement);
controls.target.set(0, 0.9, 1.5);
controls.update();
scene.add(new THREE.GridHelper(20, 20, 0x556070, 0x353b45));
scene.add(new THREE.HemisphereLight(0xffffff, 0x334455, 2.2));
const ground = new THREE.Mesh(new THREE.PlaneGeometry(40, 40).rotateX(-Math.PI / 2), new THREE.MeshBasicMaterial({visible: false}));
scene.add(ground);
const bones = new THREE.LineSegments(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({color: 0xffd166}));
const joints = new THREE.Points(new THREE.BufferGeometry(), new THREE.PointsMaterial({color: 0x7ad7ff, size: 0.05}));
const trail = new THREE.Line(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({color: 0x5c677a}));
scene.add(bones, joints, trail);
const markers = new THREE.Group();
scene.add(markers);

function resize() {
  const w = view.clientWidth, h = view.clientHeight;
  renderer.setSize(w, h);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
}
window.addEventListener("resize", resize);
resize();

// ------------------------------------------------------------------------------------------- state
let model = null, motion = null, playStart = performance.now();
const waypoints = [];  // [{x, z}], times spread over the motion when generated

function showMotion(m) {
  motion = m;
  window.kinema.lastPositions = m.positions;
  const J = m.names.length;
  const pairs = [];
  m.parents.forEach((p, j) => { if (p >= 0) pairs.push(p, j); });
  bones.userData.pairs = pairs;
  bones.geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(pairs.length * 3), 3));
  joints.geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(J * 3), 3));
  const root = m.parents.indexOf(-1);
  const path = new Float32Array(m.frames * 3);
  for (let t = 0; t < m.frames; t++) { path[3 * t] = m.positions[(t * J + root) * 3]; path[3 * t + 2] = m.positions[(t * J + root) * 3 + 2]; }
  trail.geometry.setAttribute("position", new THREE.BufferAttribute(path, 3));
  playStart = performance.now();
}

function drawFrame() {
  if (motion) {
    const J = motion.names.length, t = Math.floor(((performance.now() - playStart) / 1000) * motion.fps) % motion.frames;
    const P = motion.positions.subarray(t * J * 3, (t + 1) * J * 3);
    joints.geometry.attributes.position.array.set(P);
    joints.geometry.attributes.position.needsUpdate = true;
    const arr = bones.geometry.attributes.position.array;
    bones.userData.pairs.forEach((j, k) => arr.set(P.subarray(3 * j, 3 * j + 3), 3 * k));
    bones.geometry.attributes.position.needsUpdate = true;
    window.kinema.frame = t;
  }
  renderer.render(scene, camera);
  requestAnimationFrame(drawFrame);
}
requestAnimationFrame(drawFrame);

function addMarker(x, z) {
  const m = new THREE.Mesh(new THREE.CylinderGeometry(0.08, 0.08, 0.02, 24), new THREE.MeshBasicMaterial({color: 0xef476f}));
  m.position.set(x, 0.01, z);
  markers.add(m);
}

renderer.domElement.addEventListener("click", (ev) => {
  if (ev.detail === 0) return;
  const rect = renderer.domElement.getBoundingClientRect();
  const ndc = new THREE.Vector2(((ev.clientX - rect.left) / rect.width) * 2 - 1, -((ev.clientY - rect.top) / rect.height) * 2 + 1);
  const ray = new THREE.Raycaster();
  ray.setFromCamera(ndc, camera);
  const hit = ray.intersectObject(ground)[0];
  if (!hit) return;
  waypoints.push({x: hit.point.x, z: hit.point.z});
  addMarker(hit.point.x, hit.point.z);
  $("status").textContent = `${waypoints.length} waypoint(s); they are reached in order, evenly spaced in time`;
});

$("clear").onclick = () => { waypoints.length = 0; markers.clear(); };

// ------------------------------------------------------------------------------------------- generate
// waypoints without a time are spread evenly: the k-th of n at (k + 1) / n of the motion
function timed(list, seconds, fps) {
  const last = (Math.round(seconds * fps) - 1) / fps;
  return list.map((w, k) => ({x: w.x, z: w.z, time: w.time ?? (last * (k + 1)) / list.length}));
}

async function generate(opts = {}) {
  if (!model) throw new KinemaError("the model is not loaded yet");
  const {prompt, seconds = 5, seed = 0, waypoints: wps = [], path = [], keyframes = [], steps, noise} = opts;
  $("generate").disabled = true;
  $("error").textContent = "";
  const progress = $("progress");
  progress.value = 0;
  try {
    const m = await model.generate({prompt, seconds, seed, steps, path, keyframes, noise: noise ? Float32Array.from(noise) : undefined,
      waypoints: timed(wps, seconds, model.fps), onStep: (d, n) => { progress.value = d / n; }});
    showMotion(m);
    markers.clear();  // the waypoints this motion was made with
    for (const w of wps) addMarker(w.x, w.z);
    $("bvh").disabled = false;
    const g = m.grounding.captions.length ? `\ngrounded on "${m.grounding.captions[0]}"` : `\ngrounding: ${m.grounding.status}`;
    $("status").textContent = `${m.frames} frames in ${m.seconds.toFixed(2)} s (${m.graph === "action_expert" ? "action expert" : "main weights"})${g}`;
    return {fps: m.fps, names: m.names, parents: m.parents, positions: Array.from(m.positions), seconds: m.seconds,
      grounding: m.grounding, graph: m.graph, frames: m.frames};
  } catch (err) {
    $("error").textContent = String(err.message || err).split("\n")[0];
    throw err;
  } finally {
    $("generate").disabled = false;
  }
}

$("generate").onclick = () => generate({prompt: $("prompt").value, seconds: Number($("seconds").value),
  seed: Number($("seed").value), waypoints}).catch(() => {});

$("bvh").onclick = () => {
  if (!motion) return;
  const blob = new Blob([toBvh(motion)], {type: "text/plain"});
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = `kinema-${(motion.grounding.captions[0] || "motion").replace(/\W+/g, "-").slice(0, 40)}.bvh`;
  a.click();
  URL.revokeObjectURL(a.href);
};

window.kinema = {generate, ready: false, frame: 0, bvh: () => (motion ? toBvh(motion) : null), view: {camera, controls, renderer}};

const t0 = performance.now();
KinemaModel.load(modelUrl, ort, {precision}).then((m) => {
  model = m;
  window.kinema.model = m;
  window.kinema.ready = true;
  $("generate").disabled = false;
  $("status").textContent = `model (${precision}) loaded in ${((performance.now() - t0) / 1000).toFixed(1)} s · up to ${m.maxSeconds} s`;
}).catch((err) => {
  window.kinema.loadError = String(err.message || err);
  $("error").textContent = `cannot load the model from ${modelUrl}: ${String(err.message || err).split("\n")[0]}`;
  $("status").textContent = "";
});
