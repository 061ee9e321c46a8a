// kinema's portable sampling loop in JavaScript (onnxruntime-web): docs/onnx_runtime.md, step by step.
//
//   const model = await loadModel("model/", ort);
//   const motion = await model.generate({prompt, seconds, seed, waypoints, steps, noise, onStep});
//   // motion: {fps, names, parents, positions (Float32Array, frames x joints x 3, metres, Y up), rotations, ...}
//
// The reference is kinema.portable.runtime (Python + onnxruntime); tests/test_web_runtime.py checks that
// this module, given the same initial noise, makes the motion Python makes.
// The human model's weights are licensed CC BY-NC 4.0 (non-commercial).

export class KinemaError extends Error {}

// ---------------------------------------------------------------------------------------------- noise
export function mulberry32(seed) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = Math.imul(a ^ (a >>> 15), a | 1);
    t = ((t + Math.imul(t ^ (t >>> 7), t | 61)) ^ t) >>> 0;
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

export function standardNormal(seed, count) {
  const next = mulberry32(seed);
  const out = new Float32Array(count);
  for (let i = 0; i < count; i += 2) {
    const u1 = next(), u2 = next();
    const r = Math.sqrt(-2 * Math.log(1 - u1));
    out[i] = r * Math.cos(2 * Math.PI * u2);
    if (i + 1 < count) out[i + 1] = r * Math.sin(2 * Math.PI * u2);
  }
  return out;
}

// ---------------------------------------------------------------------------------------------- tokenizer
const isPunct = (ch) => {
  const c = ch.codePointAt(0);
  if ((c >= 33 && c <= 47) || (c >= 58 && c <= 64) || (c >= 91 && c <= 96) || (c >= 123 && c <= 126)) return true;
  return /\p{P}/u.test(ch);
};
const isCjk = (c) => (c >= 0x4e00 && c <= 0x9fff) || (c >= 0x3400 && c <= 0x4dbf) || (c >= 0x20000 && c <= 0x2a6df) ||
  (c >= 0x2a700 && c <= 0x2b73f) || (c >= 0x2b740 && c <= 0x2b81f) || (c >= 0x2b820 && c <= 0x2ceaf) ||
  (c >= 0xf900 && c <= 0xfaff) || (c >= 0x2f800 && c <= 0x2fa1f);

export class WordPiece {
  constructor(vocabText, {lowerCase = true, maxTokens = 256, cls = "[CLS]", sep = "[SEP]", unk = "[UNK]"} = {}) {
    this.vocab = new Map();
    vocabText.split("\n").forEach((w, i) => { if (w.length) this.vocab.set(w.replace(/\r$/, ""), i); });
    Object.assign(this, {lowerCase, maxTokens, cls, sep, unk});
  }

  words(text) {  // BERT's normaliser and pre-tokeniser
    let s = "";
    for (const ch of text) {
      const c = ch.codePointAt(0);
      if (c === 0 || c === 0xfffd || (/\p{C}/u.test(ch) && !/[\t\n\r]/.test(ch))) continue;
      s += /\s/u.test(ch) ? " " : isCjk(c) ? ` ${ch} ` : ch;
    }
    if (this.lowerCase) s = s.toLowerCase().normalize("NFD").replace(/\p{Mn}/gu, "");
    const out = [];
    for (const piece of s.split(" ")) {
      let cur = "";
      for (const ch of piece) {
        if (isPunct(ch)) { if (cur) out.push(cur); out.push(ch); cur = ""; } else cur += ch;
      }
      if (cur) out.push(cur);
    }
    return out;
  }

  encode(text) {
    const ids = [this.vocab.get(this.cls)];
    for (const word of this.words(text)) {
      const chars = [...word];
      if (chars.length > 100) { ids.push(this.vocab.get(this.unk)); continue; }
      const pieces = [];
      let start = 0, bad = false;
      while (start < chars.length) {
        let end = chars.length, found = null;
        while (start < end) {
          const sub = (start > 0 ? "##" : "") + chars.slice(start, end).join("");
          if (this.vocab.has(sub)) { found = this.vocab.get(sub); break; }
          end -= 1;
        }
        if (found === null) { bad = true; break; }
        pieces.push(found);
        start = end;
      }
      ids.push(...(bad ? [this.vocab.get(this.unk)] : pieces));
    }
    const kept = ids.slice(0, this.maxTokens - 1);
    kept.push(this.vocab.get(this.sep));
    return kept;
  }
}

// ---------------------------------------------------------------------------------------------- grounding
function decodeArray(entry) {
  const bin = atob(entry.base64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  if (entry.dtype !== "float16") throw new KinemaError(`unsupported array dtype ${entry.dtype}`);
  const view = new DataView(bytes.buffer);
  const out = new Float32Array(bytes.length / 2);
  for (let i = 0; i < out.length; i++) out[i] = halfToFloat(view.getUint16(2 * i, true));
  return out;
}

function halfToFloat(h) {
  const s = h & 0x8000 ? -1 : 1, e = (h >> 10) & 0x1f, f = h & 0x3ff;
  if (e === 0) return s * 2 ** -14 * (f / 1024);
  if (e === 31) return f ? NaN : s * Infinity;
  return s * 2 ** (e - 15) * (1 + f / 1024);
}

const setEq = (a, b) => a.size === b.size && [...a].every((x) => b.has(x));
const norm = (v) => Math.sqrt(v.reduce((s, x) => s + x * x, 0));

export class Grounding {
  constructor(g) {
    Object.assign(this, {weight: g.settings.weight, temperature: g.settings.temperature, topK: g.settings.top_k,
      unknownBelow: g.unknown_below, exactAbove: g.exact_above, captions: g.captions});
    this.captionSet = new Set(g.captions.map((c) => c.trim()));
    const [n, dim] = g.embeddings.shape;
    const e = decodeArray(g.embeddings);
    for (let i = 0; i < n; i++) {  // unit rows
      const row = e.subarray(i * dim, (i + 1) * dim);
      const l = Math.max(norm(row), 1e-12);
      for (let k = 0; k < dim; k++) row[k] /= l;
    }
    Object.assign(this, {n, dim, emb: e});
    this.words_ = g.captions.map((_, i) => ({sides: new Set(g.caption_sides[i]), away: new Set(g.caption_away[i]),
      pace: g.caption_pace[i], manner: g.caption_manner[i], actions: new Set(g.caption_actions[i])}));
    this.made = g.caption_made;  // false: the caption's action is measured not to be made
    this.learned = new Set(g.learned_actions);
    this.hasManner = g.manner_phrases.length > 0;
    const p = g.patterns;
    this.side = new RegExp(p.side, "gi");
    this.away = new RegExp(p.away, "gi");
    this.actionRes = Object.entries(p.actions).map(([a, r]) => [a, new RegExp(r, "i"), new RegExp(r, "gi")]);
    this.verbs = p.action_verbs;
    this.pace_ = Object.fromEntries(Object.entries(p.pace).map(([k, r]) => [k, new RegExp(r, "i")]));
    const esc = (s) => s.replace(/[.*+?^${}()|[\]\\]/g, "\\$&");
    this.mannerRe = this.hasManner ? new RegExp(`\\b(?:${g.manner_phrases.map(esc).join("|")})\\b`, "i") : null;
  }

  actions(text) { return new Set(this.actionRes.filter(([, re]) => re.test(text)).map(([a]) => a)); }

  pace(text) {
    for (const k of ["sprint", "jog", "stroll"]) if (this.pace_[k].test(text)) return k;
    if (this.pace_.slow.test(text)) {
      const a = this.actions(text);
      return a.has("run") ? "jog" : a.has("walk") ? "stroll" : null;
    }
    return null;
  }

  words(text) {
    const actions = this.actions(text);
    const away = new Set([...text.matchAll(this.away)].map((m) => (m[1].toLowerCase().startsWith("side") ? "sideways" : "backward")));
    if (actions.has("walk back")) away.add("backward");
    const sides = new Set([...text.matchAll(this.side)].map((m) => m[1].toLowerCase()));
    return {sides, away, pace: this.pace(text), manner: !!(this.mannerRe && this.mannerRe.test(text)), actions};
  }

  reworded(text) {
    let out = text;
    for (const [a, , re] of this.actionRes) out = out.replace(re, (m) => (m.includes(" ") ? m : this.verbs[a]));
    return out;
  }

  sims(v) {
    const u = v.map((x) => x / norm(v));
    const out = new Float64Array(this.n);
    for (let i = 0; i < this.n; i++) {
      let s = 0;
      for (let k = 0; k < this.dim; k++) s += this.emb[i * this.dim + k] * u[k];
      out[i] = s;
    }
    return out;
  }

  candidates(w, manner = true, paced = true) {
    return this.words_.map((c) => {
      let ok = setEq(c.sides, w.sides) && setEq(c.away, w.away);
      if (paced) ok = ok && c.pace === w.pace;
      if (manner && this.hasManner && !(paced && w.pace)) ok = ok && c.manner === w.manner;
      return ok && (!w.actions.size || [...w.actions].every((a) => c.actions.has(a)));
    });
  }

  // among the captions whose action is made when one is near enough, else among all
  nearest(same, sims, floor) {
    return this.top(same.map((ok, i) => ok && this.made[i]), sims, floor) || this.top(same, sims, floor);
  }

  top(same, sims, floor) {
    const idx = [...same.keys()].filter((i) => same[i]).sort((a, b) => sims[b] - sims[a] || a - b).slice(0, this.topK);
    return !idx.length || sims[idx[0]] < floor ? null : idx;
  }

  // {embedding, status, captions} for a prompt of embedding e; reworded: the reworded prompt's, or null
  ground(prompt, e, reworded) {
    if (this.weight === 0) return {embedding: e, status: "off", captions: []};
    let sims = this.sims(e), best = Math.max(...sims), ref = e;
    if (reworded && best < this.unknownBelow) {
      const r = this.sims(reworded), rb = Math.max(...r);
      if (rb > best) { best = rb; ref = reworded; sims = r; }
    }
    const w = this.words(prompt);
    if ([...w.actions].some((a) => !this.learned.has(a))) return {embedding: e, status: "unknown", captions: []};
    if (this.captionSet.has(prompt.trim()) || (ref === e && best >= this.exactAbove)) return {embedding: e, status: "exact", captions: []};
    if (best < this.unknownBelow) return {embedding: e, status: "unknown", captions: []};
    let top = this.nearest(this.candidates(w), sims, w.pace ? -1 : this.unknownBelow);
    if (!top && w.pace) top = this.nearest(this.candidates(w, true, false), sims, this.unknownBelow);
    if (!top && w.actions.size && this.hasManner && w.manner) top = this.nearest(this.candidates(w, false), sims, this.unknownBelow);
    if (!top) return {embedding: e, status: "unmatched", captions: []};
    const vmax = sims[top[0]];
    const ex = top.map((i) => Math.exp((sims[i] - vmax) / this.temperature));
    const z = ex.reduce((s, x) => s + x, 0);
    const ue = e.map((x) => x / norm(e));
    const blend = ue.map((x, k) => (1 - this.weight) * x + this.weight * top.reduce((s, i, j) => s + (ex[j] / z) * this.emb[i * this.dim + k], 0));
    const scale = norm(e) / norm(blend);
    return {embedding: Float32Array.from(blend, (x) => x * scale), status: "grounded", captions: top.map((i) => this.captions[i])};
  }
}

// ---------------------------------------------------------------------------------------------- loop helpers
export function spacedTimesteps(N, n) {
  return Array.from({length: n}, (_, i) => Math.floor((2 * (n - i) * N + n) / (2 * n)) - 1);
}

function gaussianKernel(sigma) {
  const r = Math.max(Math.ceil(3 * sigma), 0);
  if (sigma <= 0 || r === 0) return [1];
  const k = Array.from({length: 2 * r + 1}, (_, i) => Math.exp(-0.5 * ((i - r) / sigma) ** 2));
  const s = k.reduce((a, b) => a + b, 0);
  return k.map((v) => Math.fround(v / s));
}

// Gaussian along time of a (T,) series, ends padded by point reflection
function smooth(x, sigma) {
  const k = gaussianKernel(sigma), r = (k.length - 1) / 2, T = x.length;
  if (r === 0) return Float32Array.from(x);
  const at = (i) => {
    if (i < 0) return 2 * x[0] - x[Math.min(-i, T - 1)];
    if (i >= T) return 2 * x[T - 1] - x[Math.max(2 * (T - 1) - i, 0)];
    return x[i];
  };
  const out = new Float32Array(T);
  for (let t = 0; t < T; t++) {
    let s = 0;
    for (let j = 0; j < k.length; j++) s += k[j] * at(t + j - r);
    out[t] = s;
  }
  return out;
}

const column = (x, T, D, c) => Float32Array.from({length: T}, (_, t) => x[t * D + c]);

// docs/onnx_runtime.md step 7.4, one root channel c: move x0[:, c] onto aim[:, c] where mask[:, c]
function displaceChannel(x0, aim, mask, T, D, c, origin) {
  const m = new Array(T).fill(false), r = new Float64Array(T);
  for (let t = 0; t < T; t++) if (mask && mask[t * D + c] > 0) { m[t] = true; r[t] = aim[t * D + c] - x0[t * D + c]; }
  if (!m[0]) {
    const first = m.indexOf(true);
    r[0] = first >= 0 ? r[first] : origin - x0[c];
    m[0] = true;
  }
  const prev = new Int32Array(T), next = new Int32Array(T);
  for (let t = 0, p = -1; t < T; t++) { if (m[t]) p = t; prev[t] = p; }
  for (let t = T - 1, n = T; t >= 0; t--) { if (m[t]) n = t; next[t] = n; }
  for (let t = 0; t < T; t++) {
    const w = next[t] < T ? (t - prev[t]) / Math.max(next[t] - prev[t], 1) : 0;
    x0[t * D + c] = x0[t * D + c] + (1 - w) * r[prev[t]] + w * r[Math.min(next[t], T - 1)];
  }
}

function axisAngleToMatrix(aa) {  // Rodrigues, row-major 3x3
  const angle = Math.hypot(aa[0], aa[1], aa[2]), l = Math.max(angle, 1e-12);
  const [x, y, z] = aa.map((v) => v / l), c = Math.cos(angle), s = Math.sin(angle), C = 1 - c;
  return [c + x * x * C, x * y * C - z * s, x * z * C + y * s,
    y * x * C + z * s, c + y * y * C, y * z * C - x * s,
    z * x * C - y * s, z * y * C + x * s, c + z * z * C];
}

const matMul = (A, B) => Array.from({length: 9}, (_, k) => {
  const r = Math.floor(k / 3), c = k % 3;
  return A[3 * r] * B[c] + A[3 * r + 1] * B[3 + c] + A[3 * r + 2] * B[6 + c];
});

function sixdToMatrix(d) {  // columns b1, b2, b3 (row-major 3x3)
  const n = (v) => { const l = Math.sqrt(Math.max(v[0] * v[0] + v[1] * v[1] + v[2] * v[2], 1e-38)); return v.map((x) => x / l); };
  const b1 = n([d[0], d[1], d[2]]);
  const dot = b1[0] * d[3] + b1[1] * d[4] + b1[2] * d[5];
  const b2 = n([d[3] - dot * b1[0], d[4] - dot * b1[1], d[5] - dot * b1[2]]);
  const b3 = [b1[1] * b2[2] - b1[2] * b2[1], b1[2] * b2[0] - b1[0] * b2[2], b1[0] * b2[1] - b1[1] * b2[0]];
  return [b1[0], b2[0], b3[0], b1[1], b2[1], b3[1], b1[2], b2[2], b3[2]];
}

// ---------------------------------------------------------------------------------------------- the model
export class KinemaModel {
  static async load(base, ort, {precision = "fp32"} = {}) {
    const url = (f) => new URL(f, new URL(base, globalThis.location?.href ?? "file:///")).href;
    const fetchOk = async (f) => {
      const r = await fetch(url(f));
      if (!r.ok) throw new KinemaError(`cannot load ${f}: HTTP ${r.status} (is ${base} an exported folder?)`);
      return r;
    };
    const m = await (await fetchOk("kinema_runtime.json")).json();
    if (m.format !== "kinema-onnx-1") throw new KinemaError(`${base}: not a kinema-onnx-1 folder`);
    const opts = {executionProviders: ["wasm"], graphOptimizationLevel: "all"};
    const session = async (entry) => ort.InferenceSession.create(url(entry[precision]), opts);
    const sessions = {};
    for (const [name, entry] of Object.entries(m.graphs)) sessions[name] = await session(entry);
    const text = await session(m.text_encoder);
    const t = m.text_encoder;
    const tok = new WordPiece(await (await fetchOk(t.vocab)).text(), {lowerCase: t.lower_case, maxTokens: t.max_tokens,
      cls: t.cls, sep: t.sep, unk: t.unk});
    return new KinemaModel(m, ort, sessions, text, tok);
  }

  constructor(manifest, ort, sessions, textSession, tokenizer) {
    Object.assign(this, {m: manifest, ort, sessions, textSession, tokenizer});
    this.grounding = manifest.grounding ? new Grounding(manifest.grounding) : null;
    this.mean = Float32Array.from(manifest.normalization.mean);
    this.std = Float32Array.from(manifest.normalization.std);
  }

  get fps() { return this.m.fps; }
  get maxSeconds() { return this.m.max_frames / this.m.fps; }

  async embed(text) {
    const ids = this.tokenizer.encode(this.m.text_encoder.lower_case ? text.toLowerCase() : text);
    const big = BigInt64Array.from(ids, (i) => BigInt(i));
    const feeds = {input_ids: new this.ort.Tensor("int64", big, [1, ids.length]),
      attention_mask: new this.ort.Tensor("int64", BigInt64Array.from(ids, () => 1n), [1, ids.length])};
    const out = await this.textSession.run(feeds);
    return Float32Array.from(out.sentence_embedding.data);
  }

  async condition(prompt) {
    const e = await this.embed(prompt);
    if (!this.grounding) return {embedding: e, status: "off", captions: []};
    const words = this.grounding.reworded(prompt);
    const rw = words === prompt ? null : await this.embed(words);
    return this.grounding.ground(prompt, e, rw);
  }

  graphFor(prompt, grounded) {
    const ex = this.m.action_expert;
    if (!ex || !this.grounding) return "denoiser";
    const words = grounded.captions.length ? grounded.captions[0] : prompt;
    const acts = this.grounding.actions(words);
    return ex.actions.some((a) => acts.has(a)) ? "action_expert" : "denoiser";
  }

  frames(seconds) {
    if (typeof seconds !== "number" || !Number.isFinite(seconds)) throw new KinemaError(`seconds must be a number, got ${seconds}`);
    const v = seconds * this.fps, f = Math.floor(v);
    const T = v - f === 0.5 ? (f % 2 === 0 ? f : f + 1) : Math.round(v);  // half to even, as Python
    if (T < 2 || T > this.m.max_frames) throw new KinemaError(`seconds must be in [${2 / this.fps}, ${this.maxSeconds}], got ${seconds}`);
    return T;
  }

  // {prompt, seconds, seed, waypoints: [{x, z, time}], path: [{x, z, time}] (dense),
  //  keyframes: [{time, root: [x, y, z], rotations: J x [ax, ay, az] local axis-angle}], steps, noise (Float32Array T*D),
  //  guidance: [w_text, w_constr], onStep}
  async generate({prompt, seconds = 5, seed = 0, waypoints = [], path = [], keyframes = [], steps, noise, guidance, onStep} = {}) {
    const m = this.m, t0 = performance.now();
    if (typeof prompt !== "string" || !prompt.trim()) throw new KinemaError("prompt must be a non-empty text");
    const T = this.frames(seconds), D = m.feature_dim, fps = this.fps;
    const nSteps = steps ?? m.schedule.steps;
    if (!Number.isInteger(nSteps) || nSteps < 1 || nSteps > m.schedule.num_train_steps) throw new KinemaError(`steps must be an integer in [1, ${m.schedule.num_train_steps}], got ${steps}`);
    if (!Number.isInteger(seed) || seed < 0) throw new KinemaError(`seed must be a non-negative integer, got ${seed}`);
    let x;
    if (noise) {
      if (noise.length !== T * D) throw new KinemaError(`noise must hold ${T} x ${D} numbers, got ${noise.length}`);
      x = Float32Array.from(noise);
    } else x = standardNormal(seed, T * D);
    const grounded = await this.condition(prompt);
    const graph = this.graphFor(prompt, grounded);
    const [rx, rz] = m.layout.root_xz, [px, pz] = m.layout.pelvis_xz;
    // constraints (docs/onnx_runtime.md step 5): full-body keyframes, then waypoints at their frames, then a
    // dense path (a later entry wins); a keyframe's joint x/z are relative to its frame's final root x/z
    let tgtN = null, mask = null;
    for (const [name, v] of [["waypoints", waypoints], ["path", path], ["keyframes", keyframes]]) {
      if (!Array.isArray(v)) throw new KinemaError(`${name} must be a list`);
    }
    const frameOf = (w, what) => {
      if (![w?.x ?? 0, w?.z ?? 0, w?.time].every((v) => typeof v === "number" && Number.isFinite(v))) throw new KinemaError(`${what} ${JSON.stringify(w).slice(0, 80)}: x, z and time must be finite numbers`);
      const f = Math.round(w.time * fps);
      if (f < 0 || f >= T) throw new KinemaError(`${what} time ${w.time} s is outside the motion (0 to ${(T - 1) / fps} s)`);
      return f;
    };
    const tgt = new Float64Array(T * D);
    if (waypoints.length || path.length || keyframes.length) mask = new Float32Array(T * D);
    const put = (f, x, z) => { tgt[f * D + rx] = x; tgt[f * D + rz] = z; mask[f * D + rx] = 1; mask[f * D + rz] = 1; };
    const world = keyframes.map((k) => this.keyframe(k, tgt, mask, frameOf(k, "keyframe")));
    for (const w of waypoints) put(frameOf(w, "waypoint"), w.x, w.z);
    if (path.length) {
      const fs = path.map((w) => frameOf(w, "path point"));
      if (fs.length < 2 || fs.some((f, i) => i > 0 && f <= fs[i - 1])) throw new KinemaError("a path needs at least two points at increasing frames");
      for (let k = 0; k + 1 < fs.length; k++) {
        for (let f = fs[k]; f <= fs[k + 1]; f++) {
          const a = (f - fs[k]) / (fs[k + 1] - fs[k]);
          put(f, path[k].x + a * (path[k + 1].x - path[k].x), path[k].z + a * (path[k + 1].z - path[k].z));
        }
      }
    }
    const jp0 = m.layout.slices.joint_pos[0];
    for (const {f, xz} of world) {
      for (let j = 0; j < xz.length; j++) {
        tgt[f * D + jp0 + 3 * j] = xz[j][0] - tgt[f * D + rx];
        tgt[f * D + jp0 + 3 * j + 2] = xz[j][1] - tgt[f * D + rz];
      }
    }
    if (mask) tgtN = Float32Array.from(tgt, (v, i) => (Math.fround(v) - this.mean[i % D]) / this.std[i % D] * mask[i]);
    let {mode, w_text: wt, w_constr: wc} = m.guidance;
    if (guidance) { mode = "separated"; [wt, wc] = guidance; }
    if (!mask && mode === "separated") mode = "regular";
    const branches = {none: [[1, 1, 1]], regular: [[0, 0, 1 - wt], [1, 1, wt]],
      separated: [[0, 0, 1 - wt - wc], [1, 0, wt], [0, 1, wc]]}[mode];  // [text?, constraints?, weight]
    const K = branches.length, E = m.text_dim;
    const text = new Float32Array(K * E), cdir = new Float32Array(K * 2), xt = new Float32Array(K * T * D);
    const maskB = new Float32Array(K * T * D), tgtB = new Float32Array(K * T * D);
    branches.forEach(([hasText, hasCons], k) => {
      if (hasText) text.set(grounded.embedding, k * E);
      cdir[2 * k] = 1;
      if (tgtN) tgtB.set(tgtN, k * T * D);
      if (hasCons && mask) maskB.set(mask, k * T * D);
    });
    const ort = this.ort, dims = [K, T, D];
    const fixed = {text_emb: new ort.Tensor("float32", text, [K, E]), c_dir: new ort.Tensor("float32", cdir, [K, 2]),
      x_tgt: new ort.Tensor("float32", tgtB, dims), mask: new ort.Tensor("float32", maskB, dims),
      weights: new ort.Tensor("float32", Float32Array.from(branches, (b) => b[2]), [K])};
    const abar = m.schedule.alphas_cumprod, ts = spacedTimesteps(m.schedule.num_train_steps, nSteps);
    const corr = m.corrections, session = this.sessions[graph];
    for (let i = 0; i < ts.length; i++) {
      const t = ts[i];
      for (let k = 0; k < K; k++) xt.set(x, k * T * D);
      const out = await session.run({...fixed, x_t: new ort.Tensor("float32", xt, dims),
        t: new ort.Tensor("int64", BigInt64Array.from({length: K}, () => BigInt(t)), [K])});
      const x0 = Float32Array.from(out.x0.data);
      for (const c of [rx, rz]) {  // root smoothing
        const s = smooth(column(x0, T, D, c), corr.root_smoothing_seconds * fps);
        for (let f = 0; f < T; f++) x0[f * D + c] = s[f];
      }
      let aim = tgtN;
      if (mask) {  // pelvis aim
        aim = Float32Array.from(tgtN);
        [[rx, px], [rz, pz]].forEach(([c, p]) => {
          const pel = Float32Array.from(column(x0, T, D, p), (v) => v * this.std[p] + this.mean[p]);
          const bias = smooth(pel, corr.root_sigma_seconds * fps);
          for (let f = 0; f < T; f++) {
            if (mask[f * D + c] > 0 && mask[f * D + p] === 0) aim[f * D + c] = tgtN[f * D + c] - bias[f] / this.std[c];
          }
        });
      }
      for (const c of [rx, rz]) displaceChannel(x0, aim, mask, T, D, c, -this.mean[c] / this.std[c]);
      if (i + 1 < ts.length) {  // DDIM, eta 0
        const at = abar[t], ap = abar[ts[i + 1]];
        const sa = Math.fround(Math.sqrt(at)), s1a = Math.fround(Math.sqrt(1 - at));
        const sp = Math.fround(Math.sqrt(ap)), s1p = Math.fround(Math.sqrt(1 - ap));
        for (let j = 0; j < x.length; j++) {
          const eps = Math.fround((x[j] - sa * x0[j]) / s1a);
          x[j] = sp * x0[j] + s1p * eps;
        }
      } else x = x0;
      if (onStep) onStep(i + 1, ts.length);
    }
    const features = Float32Array.from(x, (v, j) => v * this.std[j % D] + this.mean[j % D]);
    const {positions, rotations} = this.pose(features, T);
    const sk = m.skeleton;
    return {fps, names: sk.names, parents: sk.parents, offsets: sk.offsets, frames: T, positions, rotations,
      grounding: {status: grounded.status, captions: grounded.captions}, graph, guidance: mode,
      seconds: (performance.now() - t0) / 1000};
  }

  // one full-body keyframe's channels into tgt / mask at frame f; returns {f, xz: world joint x/z}
  keyframe(k, tgt, mask, f) {
    const m = this.m, sk = m.skeleton, sl = m.layout.slices, D = m.feature_dim, J = sk.parents.length;
    const rot = k.rotations, root = k.root;
    const finite = (a, n) => Array.isArray(a) && a.length === n && a.every((v) => typeof v === "number" && Number.isFinite(v));
    if (!finite(root, 3) || !Array.isArray(rot) || rot.length !== J || !rot.every((r) => finite(r, 3))) {
      throw new KinemaError(`keyframe at ${k.time} s: root must be 3 finite numbers and rotations ${J} x 3`);
    }
    if (sk.left_hip == null) throw new KinemaError("this model's skeleton names no hips, so its keyframes have no heading");
    const G = [], P = [];
    sk.parents.forEach((p, j) => {
      const L = axisAngleToMatrix(rot[j]);
      if (p < 0) { G.push(L); P.push([...root]); return; }
      G.push(matMul(G[p], L));
      const o = sk.offsets[j], A = G[p];
      P.push([0, 1, 2].map((a) => P[p][a] + A[3 * a] * o[0] + A[3 * a + 1] * o[1] + A[3 * a + 2] * o[2]));
    });
    const set = (c, v) => { tgt[f * D + c] = v; mask[f * D + c] = 1; };
    const r = P[sk.root];
    [0, 1, 2].forEach((a) => set(sl.root_pos[0] + a, r[a]));
    const v = [0, 1, 2].map((a) => P[sk.right_hip][a] - P[sk.left_hip][a]);
    const fx = v[2], fz = -v[0], n = Math.max(Math.hypot(fx, fz), 1e-9);
    set(sl.heading[0], fz / n); set(sl.heading[0] + 1, fx / n);
    for (let j = 0; j < J; j++) {
      [0, 1, 2].forEach((a) => set(sl.joint_pos[0] + 3 * j + a, a === 1 ? P[j][1] : 0));
      const A = G[j];
      [A[0], A[3], A[6], A[1], A[4], A[7]].forEach((x, i) => set(sl.joint_rot[0] + 6 * j + i, x));
    }
    return {f, xz: P.map((p) => [p[0], p[2]])};
  }

  // joint positions (T*J*3) and global rotation matrices (T*J*9, row-major) of unnormalised features
  pose(F, T) {
    const m = this.m, sk = m.skeleton, D = m.feature_dim, J = sk.parents.length;
    const jp = m.layout.slices.joint_pos[0], jr = m.layout.slices.joint_rot[0], [rx, rz] = m.layout.root_xz;
    const positions = new Float32Array(T * J * 3), rotations = new Float32Array(T * J * 9);
    for (let t = 0; t < T; t++) {
      const row = F.subarray(t * D, (t + 1) * D), R = [];
      for (let j = 0; j < J; j++) {
        R.push(sixdToMatrix(Array.from(row.subarray(jr + 6 * j, jr + 6 * j + 6))));
        rotations.set(R[j], (t * J + j) * 9);
      }
      const p = new Float64Array(J * 3);
      for (let j = 0; j < J; j++) {
        const par = sk.parents[j];
        if (par < 0) {
          p[3 * j] = row[jp + 3 * j] + row[rx]; p[3 * j + 1] = row[jp + 3 * j + 1]; p[3 * j + 2] = row[jp + 3 * j + 2] + row[rz];
          continue;
        }
        const o = sk.offsets[j], A = R[par];
        for (let a = 0; a < 3; a++) p[3 * j + a] = p[3 * par + a] + A[3 * a] * o[0] + A[3 * a + 1] * o[1] + A[3 * a + 2] * o[2];
      }
      positions.set(p, t * J * 3);
    }
    return {positions, rotations};
  }
}

// ---------------------------------------------------------------------------------------------- BVH
// BVH text of a generated motion: OFFSETs from the skeleton (metres; the root's 0, its position channels
// absolute), root position + ZXY Euler channels
// of each joint's local rotation R[parent]^T R[joint].
export function toBvh(motion) {
  const {names, parents, offsets, positions, rotations, fps, frames: T} = motion, J = names.length;
  const children = names.map((_, j) => parents.map((p, c) => (p === j ? c : -1)).filter((c) => c >= 0));
  const lines = ["HIERARCHY"];
  const f = (v) => v.toFixed(6);
  const write = (j, depth) => {
    const ind = "  ".repeat(depth);
    lines.push(`${ind}${parents[j] < 0 ? "ROOT" : "JOINT"} ${names[j]}`, `${ind}{`);
    lines.push(`${ind}  OFFSET ${(parents[j] < 0 ? [0, 0, 0] : offsets[j]).map(f).join(" ")}`);  // root: absolute channels
    lines.push(`${ind}  CHANNELS ${parents[j] < 0 ? "6 Xposition Yposition Zposition" : "3"} Zrotation Xrotation Yrotation`);
    if (!children[j].length) lines.push(`${ind}  End Site`, `${ind}  {`, `${ind}    OFFSET 0 0 0`, `${ind}  }`);
    for (const c of children[j]) write(c, depth + 1);
    lines.push(`${ind}}`);
  };
  const order = [];
  const visit = (j) => { order.push(j); children[j].forEach(visit); };
  parents.forEach((p, j) => { if (p < 0) { write(j, 0); visit(j); } });
  lines.push("MOTION", `Frames: ${T}`, `Frame Time: ${f(1 / fps)}`);
  const deg = 180 / Math.PI;
  for (let t = 0; t < T; t++) {
    const vals = [];
    for (const j of order) {
      const R = rotations.subarray((t * J + j) * 9, (t * J + j) * 9 + 9);
      let L = R;
      if (parents[j] >= 0) {
        const P = rotations.subarray((t * J + parents[j]) * 9, (t * J + parents[j]) * 9 + 9);
        L = Array.from({length: 9}, (_, k) => { const a = Math.floor(k / 3), b = k % 3; return P[a] * R[b] + P[3 + a] * R[3 + b] + P[6 + a] * R[6 + b]; });
      } else vals.push(...[0, 1, 2].map((a) => positions[(t * J + j) * 3 + a]));
      // R = Rz(z) Rx(x) Ry(y): x = asin(L[2][1]), z = atan2(-L[0][1], L[1][1]), y = atan2(-L[2][0], L[2][2])
      const xr = Math.asin(Math.max(-1, Math.min(1, L[7])));
      vals.push(Math.atan2(-L[1], L[4]) * deg, xr * deg, Math.atan2(-L[6], L[8]) * deg);
    }
    lines.push(vals.map(f).join(" "));
  }
  return lines.join("\n") + "\n";
}
