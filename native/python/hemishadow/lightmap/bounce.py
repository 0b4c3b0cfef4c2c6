"""Bounce light through the scene's ordered mode (`Scene.gather`).

Each mesh's vertices are receivers too: their outgoing radiance, emission + albedo x
(direct + the previous pass's gathered light), is what `set_radiance` shows to the next pass.
`bounces` passes leave the radiance that texels gather for their indirect light; with
bounces = 0 only emission is gathered. Gathered light is SH bands 0-2 (world) over the
receiver's geometric hemisphere; irradiance for a lobe direction v is sum A_l G_lm Y_lm(v)
(A = pi, 2pi/3, pi/4), clamped at 0.
"""

import numpy as np

from .. import sh_basis

_A = np.repeat([np.pi, 2 * np.pi / 3, np.pi / 4], [1, 3, 5]).astype(np.float32)
BANDS = 3


def lobe_irradiance(gathered, lobes):
    """Irradiance / pi (P, L, 3) for lobes (P, L, 3) from gathered SH (P, 9, 3)."""
    p, l = lobes.shape[:2]
    y = sh_basis(lobes.reshape(-1, 3), BANDS).reshape(p, l, -1) * _A
    return np.maximum(np.einsum("plk,pkc->plc", y, gathered) / np.float32(np.pi), 0.0).astype(np.float32)


def vertex_radiance(scene, receivers, direct, bounces, offset=None, progress=None, steps=None):
    """Sets each surface's vertex radiance after `bounces` passes and returns it.
    steps: a `bake.Steps` given a step per vertex and pass, in chunks short enough for a
    cancel to get through (else `progress` goes to the engine).

    receivers: per surface (mesh_id, points (V, 3), normals (V, 3), usable (V,) bool, albedo
    (V, 3), emission (V, 3)); direct: per surface, the direct irradiance / pi (V, 3) at its
    vertices.

    Which surface a vertex sees in each direction is the same in every pass: the first pass
    that has light to gather records it (`Scene.bounce_weights`) and every later pass reuses
    it, unless the record would outgrow MAX_WEIGHT_ENTRIES; then each pass gathers anew.
    """
    radiance = [emission.astype(np.float32) for (_, _, _, _, _, emission) in receivers]
    usable = [r[3] for r in receivers]
    points = np.concatenate([r[1][u] for r, u in zip(receivers, usable)]) if receivers else np.zeros((0, 3))
    normals = np.concatenate([r[2][u] for r, u in zip(receivers, usable)]) if receivers else np.zeros((0, 3))
    gather = _Gatherer(scene, points, normals, offset, progress, steps)
    for _ in range(int(bounces)):
        _show(scene, receivers, radiance)
        gathered = gather() if any(r.any() for r in radiance) and len(points) else None
        if gathered is None and steps is not None:
            steps.step(len(points))
        new, first = [], 0
        for (mesh_id, _, _, ok, albedo, emission), d in zip(receivers, direct):
            light = d.copy()
            if gathered is not None:
                light[ok] += gathered[first:first + ok.sum()]
            first += ok.sum()
            new.append((emission + albedo * light).astype(np.float32))
        radiance = new
    _show(scene, receivers, radiance)
    return radiance


# Recorded (vertex, weight) pairs, 8 bytes each, past which passes gather anew (1 GiB).
MAX_WEIGHT_ENTRIES = 1 << 27


class _Gatherer:
    """Irradiance / pi (V, 3) gathered at vertices along their normals under the radiance the
    scene shows, from weights recorded on the first call (in chunks, each a progress step)."""

    def __init__(self, scene, points, normals, offset, progress, steps):
        self.scene, self.points, self.normals, self.offset = scene, points, normals, offset
        self.progress, self.steps = progress, steps
        self.weights = None  # per chunk; False once the record outgrew MAX_WEIGHT_ENTRIES

    def __call__(self):
        """One pass: a progress step per vertex."""
        if self.weights is None:
            self.weights = self._record()  # its chunks step the pass
        elif self.weights is not False and self.steps is not None:
            self.steps.step(len(self.points))
        if self.weights is False:
            return self._gathered()
        return np.concatenate([w.irradiance() for _, w in self.weights])

    def _slices(self):
        if self.steps is None:
            return [slice(0, len(self.points))]
        return self.steps.chunks(len(self.points), least=1024)

    def _record(self):
        weights, entries = [], 0
        for s in self._slices():
            w = self.scene.bounce_weights(self.points[s], self.normals[s], offset=self.offset,
                                          progress=self.progress if self.steps is None else None)
            weights.append((s, w))
            entries += w.entries
            if entries > MAX_WEIGHT_ENTRIES:
                return False
        return weights

    def _gathered(self):
        out = np.empty((len(self.points), 3), np.float32)
        for s in self._slices():
            g = self.scene.gather(self.points[s], self.normals[s], bands=BANDS, offset=self.offset,
                                  progress=self.progress if self.steps is None else None)
            out[s] = lobe_irradiance(g, self.normals[s][:, None])[:, 0]
        return out


def _show(scene, receivers, radiance):
    for (mesh_id, *_), rgb in zip(receivers, radiance):
        scene.set_radiance(mesh_id, rgb)
