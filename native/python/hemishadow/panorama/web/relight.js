// The relight on the GPU (WebGL2): per pixel the same sums as hemishadow.panorama.relight.
//   radiance = sum_i value_i * (w_i + sum_points I / d^2 * Y_i(to the point))     (a surface pixel)
//   radiance = sum_i E_i * Y_i(R d)                                               (a background pixel)
//   + the baked bounce term when asked (every pixel, as the native relight adds it)
// or, when the environment comes with its image, background pixels show the image itself (nearest pixel, looked
// up as Blender's Environment Texture through the World's Mapping rotation), as `hemishadow relight --env` does.
// value_i = offset_i + scale_i * byte / 255 (map i), w_i the per-coefficient weights of the suns and the
// environment (the same for every pixel), I the point's intensity P / (4 pi) in W/sr (d^2 = 1 with the
// "constant" falloff, Wong et al.'s option: every pixel lit as if the lamp were 1 m away), E the environment's
// SH, R the viewpoint's rotation. Then exposure and Blender's Standard view transform (clip, sRGB curve).
// Every texture is read with texelFetch, one texel per canvas pixel: no filtering, no colour conversion.

import { MAX_COEFFICIENTS } from "./sh.js";

export const MAX_POINTS = 4;

const VERTEX = `#version 300 es
void main() {  // one triangle covering the canvas
  vec2 p = vec2(gl_VertexID == 1 ? 3.0 : -1.0, gl_VertexID == 2 ? 3.0 : -1.0);
  gl_Position = vec4(p, 0.0, 1.0);
}`;

const FRAGMENT = `#version 300 es
precision highp float;
precision highp int;
precision highp sampler2D;
precision highp sampler2DArray;
#define K ${MAX_COEFFICIENTS}
#define POINTS ${MAX_POINTS}
uniform sampler2DArray maps;
uniform sampler2D alpha;
uniform sampler2D position;
uniform sampler2D bounce;
uniform bool bounceOn;
uniform vec3 bounceScale;
uniform vec3 bounceOffset;
uniform int count;
uniform ivec2 size;
uniform vec3 scale[K];
uniform vec3 offset[K];
uniform vec3 weights[K];
uniform vec3 environment[K];
uniform int points;
uniform vec3 pointPosition[POINTS];
uniform vec3 pointIntensity[POINTS];
uniform bool pointInverseSquare[POINTS];
uniform mat3 rotation;
uniform float exposure;
uniform sampler2D envImage;
uniform bool envImageOn;
uniform mat3 envMapping;
uniform vec3 envImageScale;
out vec4 color;

void basis(vec3 d, out float y[K]) {
  float x = d.x, yy = d.y, z = d.z, x2 = x * x, y2 = yy * yy, z2 = z * z;
  y[0] = 0.282095;
  y[1] = -0.488603 * yy; y[2] = 0.488603 * z; y[3] = -0.488603 * x;
  y[4] = 1.092548 * x * yy; y[5] = -1.092548 * yy * z; y[6] = 0.315392 * (3.0 * z2 - 1.0);
  y[7] = -1.092548 * x * z; y[8] = 0.546274 * (x2 - y2);
  y[9] = -0.590044 * yy * (3.0 * x2 - y2); y[10] = 2.890611 * x * yy * z; y[11] = -0.457046 * yy * (5.0 * z2 - 1.0);
  y[12] = 0.373176 * z * (5.0 * z2 - 3.0); y[13] = -0.457046 * x * (5.0 * z2 - 1.0); y[14] = 1.445306 * z * (x2 - y2);
  y[15] = -0.590044 * x * (x2 - 3.0 * y2);
  y[16] = 2.503343 * x * yy * (x2 - y2); y[17] = -1.770131 * yy * z * (3.0 * x2 - y2);
  y[18] = 0.946175 * x * yy * (7.0 * z2 - 1.0); y[19] = -0.669047 * yy * z * (7.0 * z2 - 3.0);
  y[20] = 0.105786 * (35.0 * z2 * z2 - 30.0 * z2 + 3.0); y[21] = -0.669047 * x * z * (7.0 * z2 - 3.0);
  y[22] = 0.473087 * (x2 - y2) * (7.0 * z2 - 1.0); y[23] = -1.770131 * x * z * (x2 - 3.0 * y2);
  y[24] = 0.625836 * (x2 * (x2 - 3.0 * y2) - y2 * (3.0 * x2 - y2));
}

vec3 surface(ivec2 texel) {
  vec3 w[K];
  for (int i = 0; i < count; i++) w[i] = weights[i];
  vec3 p = texelFetch(position, texel, 0).rgb;
  float y[K];
  for (int j = 0; j < points; j++) {
    vec3 toLight = pointPosition[j] - p;
    float d2 = dot(toLight, toLight);
    if (!(d2 > 0.0)) continue;
    basis(toLight * inversesqrt(d2), y);
    vec3 irradiance = pointInverseSquare[j] ? pointIntensity[j] / d2 : pointIntensity[j];
    for (int i = 0; i < count; i++) w[i] += irradiance * y[i];
  }
  vec3 sum = vec3(0.0);
  for (int i = 0; i < count; i++) {
    vec3 value = offset[i] + scale[i] * texelFetch(maps, ivec3(texel, i), 0).rgb;
    sum += w[i] * value;
  }
  return sum;
}

vec3 background(ivec2 texel) {
  float u = (float(texel.x) + 0.5) / float(size.x), v = 1.0 - (float(texel.y) + 0.5) / float(size.y);
  float phi = (0.5 - u) * 6.283185307179586, theta = (v - 0.5) * 3.141592653589793;
  vec3 d = rotation * vec3(cos(theta) * cos(phi), cos(theta) * sin(phi), sin(theta));
  if (envImageOn) {  // hemishadow.panorama.picture.sample_equirectangular
    vec3 m = envMapping * d;
    float iu = -atan(m.y, m.x) / 6.283185307179586 + 0.5, iv = atan(m.z, length(m.xy)) / 3.141592653589793 + 0.5;
    ivec2 n = textureSize(envImage, 0);
    ivec2 at = clamp(ivec2(int(iu * float(n.x)), int((1.0 - iv) * float(n.y))), ivec2(0), n - 1);
    return envImageScale * texelFetch(envImage, at, 0).rgb;
  }
  float y[K];
  basis(d, y);
  vec3 sum = vec3(0.0);
  for (int i = 0; i < count; i++) sum += environment[i] * y[i];
  return sum;
}

vec3 standardView(vec3 c) {  // Blender's Standard view transform: clip to [0, 1], the sRGB curve
  c = clamp(c, 0.0, 1.0);
  return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
}

void main() {
  ivec2 texel = ivec2(gl_FragCoord.xy);
  texel.y = size.y - 1 - texel.y;  // row 0 is the top row, as in the files
  bool hit = texelFetch(alpha, texel, 0).r > 0.5;
  vec3 radiance = hit ? surface(texel) : background(texel);
  // The bounce term goes on every pixel but those that show the environment's image (relight's order).
  if (bounceOn && (hit || !envImageOn)) radiance += bounceOffset + bounceScale * texelFetch(bounce, texel, 0).rgb;
  color = vec4(standardView(radiance * exposure), 1.0);
}`;

function compile(gl, type, source) {
  const shader = gl.createShader(type);
  gl.shaderSource(shader, source);
  gl.compileShader(shader);
  if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) throw new Error(`shader: ${gl.getShaderInfoLog(shader)}`);
  return shader;
}

function program(gl) {
  const p = gl.createProgram();
  gl.attachShader(p, compile(gl, gl.VERTEX_SHADER, VERTEX));
  gl.attachShader(p, compile(gl, gl.FRAGMENT_SHADER, FRAGMENT));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(`shader: ${gl.getProgramInfoLog(p)}`);
  return p;
}

function nearest(gl, target) {
  for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, gl.NEAREST], [gl.TEXTURE_MAG_FILTER, gl.NEAREST],
    [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE]]) gl.texParameteri(target, k, v);
}

export class Relighter {
  constructor(canvas) {
    const gl = canvas.getContext("webgl2", {
      alpha: false, antialias: false, depth: false, stencil: false, premultipliedAlpha: false,
      preserveDrawingBuffer: true,  // screenshots and "save PNG" read the last frame
    });
    if (!gl) throw new Error("this browser has no WebGL2");
    // The maps are data: no colour-space conversion, no premultiplication, no flip.
    gl.pixelStorei(gl.UNPACK_COLORSPACE_CONVERSION_WEBGL, gl.NONE);
    gl.pixelStorei(gl.UNPACK_PREMULTIPLY_ALPHA_WEBGL, false);
    gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    this.gl = gl;
    this.canvas = canvas;
    this.program = program(gl);
    this.uniforms = {};
    const n = gl.getProgramParameter(this.program, gl.ACTIVE_UNIFORMS);
    for (let i = 0; i < n; i++) {
      const name = gl.getActiveUniform(this.program, i).name.replace(/\[0\]$/, "");
      this.uniforms[name] = gl.getUniformLocation(this.program, name);
    }
  }

  // panorama: {width, height, count, scale, offset (count x [r,g,b]), maps (ImageBitmaps), alpha (ImageBitmap),
  // position (Float32Array, height x width x 3), rotation (3x3 rows), bounce ({bitmap, scale, offset} or null)}
  upload(panorama) {
    const { gl } = this;
    const { width, height, count } = panorama;
    const limit = gl.getParameter(gl.MAX_TEXTURE_SIZE);
    if (width > limit || height > limit) throw new Error(`${width} x ${height} exceeds this GPU's ${limit} px textures`);
    this.canvas.width = width;
    this.canvas.height = height;
    gl.viewport(0, 0, width, height);
    for (const t of [this.maps, this.alpha, this.position, this.bounce]) gl.deleteTexture(t ?? null);
    this.maps = gl.createTexture();
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D_ARRAY, this.maps);
    gl.texStorage3D(gl.TEXTURE_2D_ARRAY, 1, gl.RGBA8, width, height, count);
    panorama.maps.forEach((bitmap, i) =>
      gl.texSubImage3D(gl.TEXTURE_2D_ARRAY, 0, 0, 0, i, width, height, 1, gl.RGBA, gl.UNSIGNED_BYTE, bitmap));
    nearest(gl, gl.TEXTURE_2D_ARRAY);
    this.alpha = gl.createTexture();
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_2D, this.alpha);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA8, width, height);
    gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, panorama.alpha);
    nearest(gl, gl.TEXTURE_2D);
    this.position = gl.createTexture();
    gl.activeTexture(gl.TEXTURE2);
    gl.bindTexture(gl.TEXTURE_2D, this.position);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGB32F, width, height);
    gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, width, height, gl.RGB, gl.FLOAT, panorama.position);
    nearest(gl, gl.TEXTURE_2D);
    this.bounce = gl.createTexture();  // 1 x 1 black when the panorama has no bounce term
    gl.activeTexture(gl.TEXTURE3);
    gl.bindTexture(gl.TEXTURE_2D, this.bounce);
    const b = panorama.bounce;
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA8, b ? width : 1, b ? height : 1);
    if (b) gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, b.bitmap);
    nearest(gl, gl.TEXTURE_2D);
    gl.useProgram(this.program);
    const u = this.uniforms;
    gl.uniform1i(u.maps, 0);
    gl.uniform1i(u.alpha, 1);
    gl.uniform1i(u.position, 2);
    gl.uniform1i(u.bounce, 3);
    gl.uniform1i(u.envImage, 4);
    if (!this.envImage) this.setEnvironmentImage(null);
    gl.uniform3fv(u.bounceScale, b ? b.scale : [0, 0, 0]);
    gl.uniform3fv(u.bounceOffset, b ? b.offset : [0, 0, 0]);
    gl.uniform1i(u.count, count);
    gl.uniform2i(u.size, width, height);
    gl.uniform3fv(u.scale, panorama.scale.flat());
    gl.uniform3fv(u.offset, panorama.offset.flat());
    const r = panorama.rotation;  // rows; GL takes columns
    gl.uniformMatrix3fv(u.rotation, false, [0, 1, 2].flatMap((c) => [r[0][c], r[1][c], r[2][c]]));
    this.count = count;
    this.hits = this.readHits(width, height);
  }

  // image: {width, height, data (Float32Array, RGB, row 0 at the top)} or null (a 1 x 1 black texture).
  setEnvironmentImage(image) {
    const { gl } = this;
    gl.deleteTexture(this.envImage ?? null);
    this.envImage = gl.createTexture();
    gl.activeTexture(gl.TEXTURE4);
    gl.bindTexture(gl.TEXTURE_2D, this.envImage);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGB32F, image ? image.width : 1, image ? image.height : 1);
    if (image) gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, image.width, image.height, gl.RGB, gl.FLOAT, image.data);
    nearest(gl, gl.TEXTURE_2D);
  }

  // The hit mask on the CPU (for placing a point light on a surface), read back exactly from the texture.
  readHits(width, height) {
    const { gl } = this;
    const fb = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, this.alpha, 0);
    const rgba = new Uint8Array(width * height * 4);
    gl.readPixels(0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, rgba);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.deleteFramebuffer(fb);
    const hits = new Uint8Array(width * height);
    for (let i = 0; i < hits.length; i++) hits[i] = rgba[4 * i] > 127 ? 1 : 0;
    return hits;  // row 0 = texture row 0 = the top row
  }

  // lights: {weights, environment (count x [r,g,b]), points: [{position, intensity: [r,g,b] W/sr, inverseSquare}],
  // bounce (bool), environmentImage (null or {mapping: 3x3 rows, scale: [r,g,b]}: show the uploaded image),
  // exposure (EV)}
  draw(lights) {
    const { gl } = this;
    const u = this.uniforms;
    const pad = (rows) => rows.concat(Array(this.count - rows.length).fill([0, 0, 0])).slice(0, this.count).flat();
    if (lights.points.length > MAX_POINTS) throw new Error(`at most ${MAX_POINTS} point lights`);
    gl.useProgram(this.program);
    gl.uniform3fv(u.weights, pad(lights.weights));
    gl.uniform3fv(u.environment, pad(lights.environment));
    gl.uniform1i(u.points, lights.points.length);
    if (lights.points.length) {
      gl.uniform3fv(u.pointPosition, lights.points.flatMap((p) => p.position));
      gl.uniform3fv(u.pointIntensity, lights.points.flatMap((p) => p.intensity));
      gl.uniform1iv(u.pointInverseSquare, lights.points.map((p) => (p.inverseSquare ? 1 : 0)));
    }
    gl.uniform1i(u.bounceOn, lights.bounce ? 1 : 0);
    const image = lights.environmentImage;
    gl.uniform1i(u.envImageOn, image ? 1 : 0);
    if (image) {
      const m = image.mapping;
      gl.uniformMatrix3fv(u.envMapping, false, [0, 1, 2].flatMap((c) => [m[0][c], m[1][c], m[2][c]]));
      gl.uniform3fv(u.envImageScale, image.scale);
    }
    gl.uniform1f(u.exposure, Math.pow(2, lights.exposure));
    gl.drawArrays(gl.TRIANGLES, 0, 3);
  }
}
