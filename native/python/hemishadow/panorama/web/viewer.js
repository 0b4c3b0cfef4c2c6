// The panorama viewer: loads a compact panorama (panorama.json, its 8-bit shNN.png maps, alpha.png and the
// float32 position map) and the environments' SH, keeps the lights in the URL, and relights on every change.
//
// URL parameters (all optional; with none of sun, point, env given, a default sun lights the picture):
//   panorama=URL          the panorama's JSON (default panorama/panorama.json, where `hemishadow serve` puts it)
//   environments=URL      the environments' SH (default environments.json, written by `hemishadow serve`)
//   sun=X,Y,Z,STRENGTH    a sun: vector towards the light (world), irradiance in W/m^2; repeat for more
//   point=X,Y,Z,POWER[,constant]  a point lamp at X,Y,Z (world, m) of POWER W (Blender's: P / (4 pi) W/sr), 1/d^2
//                         falloff, or none with ",constant" (lit as if 1 m away); repeatable
//   env=NAME[,STRENGTH]   an environment by name (the list in the environments' JSON); background pixels show
//                         its image when it has one (as `hemishadow relight --env` does), else its SH
//   envrot=DEGREES        the environment turned about Z as the World's Mapping node turns it
//   bounce=1              add the panorama's baked bounce term (when it has one)
//   exposure=EV           2^EV times the radiance before the Standard view transform
//   ui=0                  the picture alone at one canvas pixel per screen pixel (screenshots)

import { basis, normalize, pixelDirection, rotateAboutZ } from "./sh.js";
import { MAX_POINTS, Relighter } from "./relight.js";

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const DEFAULT_SUN = { direction: normalize([0.5, -0.5, 0.7]), strength: 3 };

function numbers(text, count, name) {
  const values = text.split(",").map(Number);
  if (values.length !== count || !values.every(Number.isFinite)) {
    throw new Error(`${name}=${text}: expected ${count} comma-separated numbers`);
  }
  return values;
}

function stateFromUrl() {
  const suns = params.getAll("sun").map((s) => {
    const [x, y, z, strength] = numbers(s, 4, "sun");
    return { direction: normalize([x, y, z]), strength };
  });
  const points = params.getAll("point").map((s) => {
    const parts = s.split(",");
    const falloff = parts.length === 5 ? parts.pop() : "inverse_square";
    if (falloff !== "inverse_square" && falloff !== "constant") {
      throw new Error(`point=${s}: the falloff is inverse_square or constant, not ${falloff}`);
    }
    const [x, y, z, power] = numbers(parts.join(","), 4, "point");
    return { position: [x, y, z], power, falloff };
  });
  if (points.length > MAX_POINTS) throw new Error(`at most ${MAX_POINTS} point lights`);
  let env = { name: "", strength: 1 };
  if (params.has("env")) {
    const [name, strength] = params.get("env").split(",");
    env = { name, strength: strength === undefined ? 1 : numbers(strength, 1, "env strength")[0] };
  }
  const lit = suns.length || points.length || env.name;
  return {
    suns: suns.length ? suns : [{ ...DEFAULT_SUN }],
    sunOn: suns.length > 0 || !lit,
    points: points.length ? points : [{ position: null, power: 100, falloff: "inverse_square" }],  // null: the viewpoint
    pointOn: points.length > 0,
    env,
    envRotation: params.has("envrot") ? numbers(params.get("envrot"), 1, "envrot")[0] : 0,
    exposure: params.has("exposure") ? numbers(params.get("exposure"), 1, "exposure")[0] : 0,
    bounce: params.get("bounce") === "1",
  };
}

async function fetchOk(url) {
  const response = await fetch(url, { cache: "no-store" });
  if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
  return response;
}

// 8-bit maps as data: no colour-space conversion (an sRGB or gamma chunk is ignored), no premultiplication.
async function bitmap(url) {
  const blob = await (await fetchOk(url)).blob();
  return createImageBitmap(blob, { colorSpaceConversion: "none", premultiplyAlpha: "none" });
}

function littleEndianFloats(buffer) {
  const native = new Uint8Array(new Uint16Array([1]).buffer)[0] === 1;
  if (native) return new Float32Array(buffer);
  const view = new DataView(buffer), out = new Float32Array(buffer.byteLength / 4);
  for (let i = 0; i < out.length; i++) out[i] = view.getFloat32(4 * i, true);
  return out;
}

async function loadPanorama(url) {
  const meta = await (await fetchOk(url)).json();
  if (meta.format !== "hemishadow-panorama" || meta.version !== 1) {
    throw new Error(`${url}: not a hemishadow panorama (format ${meta.format}, version ${meta.version})`);
  }
  const base = new URL(url, location.href);
  const at = (file) => new URL(file, base).href;
  const { width, height } = meta;
  const count = meta.maps.length;
  const [maps, alpha, position] = await Promise.all([
    Promise.all(meta.maps.map((m) => bitmap(at(m.file)))),
    bitmap(at(meta.alpha.file)),
    fetchOk(at(meta.position.file)).then((r) => r.arrayBuffer()).then(littleEndianFloats),
  ]);
  const bounce = meta.bounce && { bitmap: await bitmap(at(meta.bounce.file)), scale: meta.bounce.scale, offset: meta.bounce.offset };
  const images = [...meta.maps.map((m, i) => [m.file, maps[i]]), [meta.alpha.file, alpha]];
  if (bounce) images.push([meta.bounce.file, bounce.bitmap]);
  for (const [name, image] of images) {
    if (image.width !== width || image.height !== height) {
      throw new Error(`${name} is ${image.width} x ${image.height}, the panorama ${width} x ${height}`);
    }
  }
  if (position.length !== width * height * 3) {
    throw new Error(`${meta.position.file} holds ${position.length} floats, expected ${width * height * 3}`);
  }
  return {
    width, height, count, maps, alpha, position, bounce,
    scale: meta.maps.map((m) => m.scale), offset: meta.maps.map((m) => m.offset),
    origin: meta.origin || [0, 0, 0],
    rotation: meta.rotation || [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
  };
}

async function loadEnvironments(url) {
  try {
    const list = (await (await fetchOk(url)).json()).environments;
    for (const e of list) if (e.image) e.image.url = new URL(e.image.file, new URL(url, location.href)).href;
    return list;
  } catch (error) {
    if (params.has("env")) throw error;
    return [];  // the viewer works with lamps alone (e.g. the files served by another server)
  }
}

// An environment's image (raw float32 RGB), fetched once.
async function environmentPixels(env) {
  const { url, width, height } = env.image;
  env.pixels ??= littleEndianFloats(await (await fetchOk(url)).arrayBuffer());
  if (env.pixels.length !== width * height * 3) throw new Error(`${url}: not ${width} x ${height} RGB floats`);
  return { width, height, data: env.pixels };
}

// The lights as the shader takes them: per-coefficient weights (suns + environment), the environment's SH
// for the background, the point lamps' intensities.
function lightsOf(state, environments, count, imageShown) {
  const weights = Array.from({ length: count }, () => [0, 0, 0]);
  for (const sun of state.sunOn ? state.suns : []) {
    basis(sun.direction).slice(0, count).forEach((y, i) => { for (let c = 0; c < 3; c++) weights[i][c] += sun.strength * y; });
  }
  let environment = [], environmentImage = null;
  if (state.env.name) {
    const found = environments.find((e) => e.name === state.env.name);
    if (!found) throw new Error(`no environment named ${state.env.name} (have: ${environments.map((e) => e.name).join(", ")})`);
    const sh = found.sh.slice(0, count).map((c) => c.map((v) => v * state.env.strength));
    // The Mapping node looks the image up at Rz(angle) d, so the light turns by -angle.
    environment = rotateAboutZ(sh, (-state.envRotation * Math.PI) / 180);
    environment.forEach((e, i) => { for (let c = 0; c < 3; c++) weights[i][c] += e[c]; });
    if (imageShown === found.name) {
      const a = (state.envRotation * Math.PI) / 180, cos = Math.cos(a), sin = Math.sin(a);
      environmentImage = { mapping: [[cos, -sin, 0], [sin, cos, 0], [0, 0, 1]], scale: Array(3).fill(state.env.strength) };
    }
  }
  const points = (state.pointOn ? state.points : []).map((p) => {
    const intensity = p.power / (4 * Math.PI);
    return { position: p.position, intensity: [intensity, intensity, intensity], inverseSquare: p.falloff !== "constant" };
  });
  return { weights, environment, environmentImage, points, bounce: state.bounce, exposure: state.exposure };
}

function writeUrl(state) {
  const out = new URLSearchParams();
  for (const key of ["panorama", "environments", "ui"]) if (params.has(key)) out.set(key, params.get(key));
  const fmt = (v) => +v.toFixed(4);
  if (state.sunOn) for (const s of state.suns) out.append("sun", [...s.direction, s.strength].map(fmt).join(","));
  if (state.pointOn) {
    for (const p of state.points) {
      out.append("point", [...p.position, p.power].map(fmt).join(",") + (p.falloff === "constant" ? ",constant" : ""));
    }
  }
  if (state.env.name) out.set("env", `${state.env.name},${fmt(state.env.strength)}`);
  if (state.envRotation) out.set("envrot", fmt(state.envRotation));
  if (state.bounce) out.set("bounce", "1");
  if (state.exposure) out.set("exposure", fmt(state.exposure));
  history.replaceState(null, "", `?${out}`);
}

function showState(state) {
  $("sun-on").checked = state.sunOn;
  $("sun-strength").value = state.suns[0].strength;
  $("sun-direction").textContent = `towards (${state.suns[0].direction.map((v) => v.toFixed(2)).join(", ")})`;
  $("point-on").checked = state.pointOn;
  ["x", "y", "z"].forEach((axis, i) => { $(`point-${axis}`).value = +state.points[0].position[i].toFixed(3); });
  $("point-power").value = state.points[0].power;
  $("env-name").value = state.env.name;
  $("env-strength").value = state.env.strength;
  $("env-rotation").value = state.envRotation;
  $("bounce").checked = state.bounce;
  $("exposure").value = state.exposure;
  $("exposure-value").textContent = `${state.exposure.toFixed(1)} EV`;
}

function readControls(state) {
  const num = (id, fallback) => (Number.isFinite(parseFloat($(id).value)) ? parseFloat($(id).value) : fallback);
  state.sunOn = $("sun-on").checked;
  state.suns[0].strength = num("sun-strength", state.suns[0].strength);
  state.pointOn = $("point-on").checked;
  state.points[0].position = ["x", "y", "z"].map((a, i) => num(`point-${a}`, state.points[0].position[i]));
  state.points[0].power = num("point-power", state.points[0].power);
  state.env = { name: $("env-name").value, strength: num("env-strength", state.env.strength) };
  state.envRotation = num("env-rotation", state.envRotation);
  state.bounce = $("bounce").checked;
  state.exposure = num("exposure", state.exposure);
}

// Drag: the sun moves to the direction under the cursor; with shift, the point lamp moves in front of the
// surface under the cursor (half a metre towards the viewpoint, at most half the way).
function onDrag(event, state, panorama, relighter, redraw) {
  const rect = event.target.getBoundingClientRect();
  const column = Math.floor(((event.clientX - rect.left) / rect.width) * panorama.width);
  const row = Math.floor(((event.clientY - rect.top) / rect.height) * panorama.height);
  if (column < 0 || row < 0 || column >= panorama.width || row >= panorama.height) return;
  const d = pixelDirection(column, row, panorama.width, panorama.height);
  const R = panorama.rotation;
  const world = [0, 1, 2].map((i) => R[i][0] * d[0] + R[i][1] * d[1] + R[i][2] * d[2]);
  if (event.shiftKey) {
    const index = row * panorama.width + column;
    if (!relighter.hits[index]) return;
    const p = Array.from(panorama.position.subarray(3 * index, 3 * index + 3));
    const distance = Math.hypot(...p.map((v, i) => v - panorama.origin[i]));
    const back = Math.min(0.5, 0.5 * distance);
    state.points[0].position = p.map((v, i) => v - back * world[i]);
    state.pointOn = true;
  } else {
    state.suns[0].direction = normalize(world);
    state.sunOn = true;
  }
  redraw();
}

async function main() {
  const bare = params.get("ui") === "0";
  document.body.classList.toggle("bare", bare);
  const state = stateFromUrl();
  const relighter = new Relighter($("view"));
  // The environments are projected by the server when it starts: wait for them only when the URL asks for one.
  const environmentsLoading = loadEnvironments(params.get("environments") || "environments.json");
  const panorama = await loadPanorama(params.get("panorama") || "panorama/panorama.json");
  const environments = state.env.name ? await environmentsLoading : [];
  if (state.bounce && !panorama.bounce) throw new Error("bounce=1: this panorama has no bounce term");
  $("bounce").disabled = !panorama.bounce;
  relighter.upload(panorama);
  state.points[0].position ??= panorama.origin.slice();
  const addEnvironments = (list) => {
    if (list !== environments) environments.push(...list);
    for (const e of list) $("env-name").append(new Option(e.name, e.name));
    $("env-name").value = state.env.name;
  };
  if (state.env.name) addEnvironments(environments);
  else environmentsLoading.then(addEnvironments, (error) => { $("status").textContent = error.message; });
  let imageShown = null;  // the environment whose image the relighter holds
  const showImage = async () => {
    const found = environments.find((e) => e.name === state.env.name);
    if (!found?.image || imageShown === found.name) return false;
    relighter.setEnvironmentImage(await environmentPixels(found));
    imageShown = found.name;
    return true;
  };
  let pending = false;
  const redraw = () => {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => {
      pending = false;
      try {
        relighter.draw(lightsOf(state, environments, panorama.count, imageShown));
        $("status").textContent = "";
      } catch (error) {
        $("status").textContent = error.message;
      }
      showState(state);
      writeUrl(state);
    });
  };
  await showImage();
  relighter.draw(lightsOf(state, environments, panorama.count, imageShown));  // the first frame at once: errors surface
  showState(state);
  $("controls").addEventListener("input", () => {
    readControls(state);
    redraw();  // the SH at once, the image when it is there
    showImage().then((shown) => shown && redraw(), (error) => { $("status").textContent = error.message; });
  });
  const canvas = $("view");
  canvas.addEventListener("pointerdown", (e) => { canvas.setPointerCapture(e.pointerId); onDrag(e, state, panorama, relighter, redraw); });
  canvas.addEventListener("pointermove", (e) => { if (e.buttons & 1) onDrag(e, state, panorama, relighter, redraw); });
  $("save").addEventListener("click", () => { $("save").href = canvas.toDataURL("image/png"); });
  $("status").textContent = "";
  document.documentElement.dataset.state = "ready";
}

main().catch((error) => {
  $("status").textContent = `error: ${error.message}`;
  document.documentElement.dataset.state = "error";
  document.body.classList.remove("bare");
  console.error(error);
});
