// Real orthonormal spherical harmonics as hemishadow defines them (DESIGN.md: Condon-Shortley phase,
// index l*(l+1)+m, up to l = 4), written out as polynomials in x, y, z. The fragment shader has the same
// polynomials (relight.js); this copy serves the lights whose direction is the same for every pixel.

export const MAX_COEFFICIENTS = 25;

export function basis(d) {
  const [x, y, z] = d;
  const x2 = x * x, y2 = y * y, z2 = z * z;
  return [
    0.282095,
    -0.488603 * y, 0.488603 * z, -0.488603 * x,
    1.092548 * x * y, -1.092548 * y * z, 0.315392 * (3 * z2 - 1), -1.092548 * x * z, 0.546274 * (x2 - y2),
    -0.590044 * y * (3 * x2 - y2), 2.890611 * x * y * z, -0.457046 * y * (5 * z2 - 1), 0.373176 * z * (5 * z2 - 3),
    -0.457046 * x * (5 * z2 - 1), 1.445306 * z * (x2 - y2), -0.590044 * x * (x2 - 3 * y2),
    2.503343 * x * y * (x2 - y2), -1.770131 * y * z * (3 * x2 - y2), 0.946175 * x * y * (7 * z2 - 1),
    -0.669047 * y * z * (7 * z2 - 3), 0.105786 * (35 * z2 * z2 - 30 * z2 + 3), -0.669047 * x * z * (7 * z2 - 3),
    0.473087 * (x2 - y2) * (7 * z2 - 1), -1.770131 * x * z * (x2 - 3 * y2),
    0.625836 * (x2 * (x2 - 3 * y2) - y2 * (3 * x2 - y2)),
  ];
}

// Coefficients (k rows of [r, g, b]) of g(d) = f(Rz(angle)^T d): f turned by `angle` radians about +Z.
// Y(l, m) goes as cos(m phi) and Y(l, -m) as sin(m phi) with the same factor, so each pair turns by m * angle.
export function rotateAboutZ(coefficients, angle) {
  const out = coefficients.map((c) => c.slice());
  const bands = Math.round(Math.sqrt(coefficients.length));
  for (let l = 1; l < bands; l++) {
    for (let m = 1; m <= l; m++) {
      const cos = Math.cos(m * angle), sin = Math.sin(m * angle);
      const a = coefficients[l * (l + 1) + m], b = coefficients[l * (l + 1) - m];
      for (let c = 0; c < 3; c++) {
        out[l * (l + 1) + m][c] = a[c] * cos - b[c] * sin;
        out[l * (l + 1) - m][c] = a[c] * sin + b[c] * cos;
      }
    }
  }
  return out;
}

export function normalize(v) {
  const n = Math.hypot(v[0], v[1], v[2]);
  if (!(n > 0) || !Number.isFinite(n)) throw new Error(`not a direction: ${v.join(",")}`);
  return [v[0] / n, v[1] / n, v[2] / n];
}

// Pixel (column, row; row 0 at the top) -> direction in the viewpoint's frame (Blender's equirectangular
// mapping: the centre column looks along +X, the left quarter along +Y, the top row along +Z).
export function pixelDirection(column, row, width, height) {
  const u = (column + 0.5) / width, v = 1 - (row + 0.5) / height;
  const phi = (0.5 - u) * 2 * Math.PI, theta = (v - 0.5) * Math.PI;
  return [Math.cos(theta) * Math.cos(phi), Math.cos(theta) * Math.sin(phi), Math.sin(theta)];
}
