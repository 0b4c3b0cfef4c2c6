"""Bounce light through the scene's ordered mode (`Scene.gather`).

Each mesh's vertices are receivers too: their outgoing radiance, emission + albedo x
(direct + the previous pass's gathered light), is what `set_radiance` shows to the next pass.
`bounces` passes leave the radiance that texels gather for their indirect light; with
bounces = 0 only emission is gathered. Gathered light is SH bands 0-2 (world) over the
receiver's geometric hemisphere; irradiance for a lobe direction v is sum A_l G_lm Y_lm(v)
(A = pi, 2pi/3, pi/4), clamped at 0.
"""

from typing import NamedTuple

import numpy as np

from .. import sh_basis

_A = np.repeat([np.pi, 2 * np.pi / 3, np.pi / 4], [1, 3, 5]).astype(np.float32)
BANDS = 3
FLAT_PER_BAND0 = float(_A[0] * sh_basis(np.array([[0.0, 0.0, 1.0]]), 1)[0, 0] / np.pi)  # a band-0 coefficient's flat light


class BounceSurface(NamedTuple):
    """A mesh whose vertices receive bounce light and pass it on (`bake.bounce_receivers`):
    world `points` and unit `normals` (V, 3), `usable` (V,) the vertices with a normal,
    `albedo` and `emission` (V, 3); `triangles` (M, 3) link vertices that cannot be lit
    (inside solid geometry, no normal) to their neighbours (`fill`)."""
    mesh_id: int
    points: np.ndarray
    normals: np.ndarray
    usable: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    triangles: np.ndarray = None


def lobe_irradiance(gathered, lobes):
    """Irradiance / pi (P, L, 3) for lobes (P, L, 3) from gathered SH (P, 9, 3)."""
    p, l = lobes.shape[:2]
    y = sh_basis(lobes.reshape(-1, 3), BANDS).reshape(p, l, -1) * _A
    return np.maximum(np.einsum("plk,pkc->plc", y, gathered) / np.float32(np.pi), 0.0).astype(np.float32)


def vertex_radiance(scene, receivers, direct, bounces, offset=None, progress=None, steps=None, record=None):
    """Sets each surface's vertex radiance after `bounces` passes and returns it.
    steps: a `bake.Steps` given a step per vertex and pass, in chunks short enough for a
    cancel to get through (else `progress` goes to the engine).

    receivers: `BounceSurface`s; direct: per surface, the direct irradiance / pi (V, 3) at
    its vertices. record: their `VertexRecord`, made on the first pass with light to gather
    when not given. Vertices the record finds inside solid geometry, and those without a
    normal, take their neighbours' radiance (`fill`): lit where they stand, they would pass
    on the light of the other side of a wall (or the darkness inside it).
    """
    radiance = [surface.emission.astype(np.float32) for surface in receivers]
    vertices = sum(int(surface.usable.sum()) for surface in receivers)
    for _ in range(int(bounces)):
        _show(scene, receivers, radiance)
        gathered = None
        if vertices and any(r.any() for r in radiance):
            if record is None:
                record = VertexRecord(scene, receivers, offset, progress, steps)
            gathered = record.gathered()
        elif steps is not None:
            steps.step(vertices)
        new, first = [], 0
        for i, (surface, d) in enumerate(zip(receivers, direct)):
            ok = surface.usable
            light = d.copy()
            if gathered is not None:
                light[ok] += gathered[first:first + ok.sum()]
            first += ok.sum()
            rgb = (surface.emission + surface.albedo * light).astype(np.float32)
            new.append(rgb if record is None else fill(rgb, record.lit_of(i), surface.triangles))
        radiance = new
    _show(scene, receivers, radiance)
    return radiance


# Recorded (vertex, weight) pairs, 8 bytes each, past which passes gather anew (1 GiB).
MAX_WEIGHT_ENTRIES = 1 << 27


class VertexRecord:
    """The bounce surfaces' usable vertices and what one walk each sees from them
    (`Scene.bounce_weights`): their visibility masks, for their direct light, whether they
    are inside solid geometry, and their gather weights. Which surface a vertex sees in
    each direction is the same in every pass, so every pass reuses the weights instead of
    walking the scene again; past MAX_WEIGHT_ENTRIES they are dropped and each pass gathers
    anew. Recording steps `steps` once per vertex, the first pass's share."""

    def __init__(self, scene, receivers, offset=None, progress=None, steps=None):
        self.scene, self.offset, self.progress, self.steps = scene, offset, progress, steps
        self.usable = [surface.usable for surface in receivers]
        self.counts = [int(ok.sum()) for ok in self.usable]
        self.points = np.concatenate([r.points[r.usable] for r in receivers]) if receivers else np.zeros((0, 3))
        self.normals = np.concatenate([r.normals[r.usable] for r in receivers]) if receivers else np.zeros((0, 3))
        self.masks, self.valid, self.weights = _record(scene, self.points, self.normals, offset, progress, steps)
        self._stepped = True

    def _usable_span(self, surface):
        """Where one surface's usable vertices lie in `points`, `masks` and `valid`."""
        first = sum(self.counts[:surface])
        return slice(first, first + self.counts[surface])

    def masks_of(self, surface):
        """The masks (V_usable, 16) of one surface's usable vertices."""
        return self.masks[self._usable_span(surface)]

    def lit_of(self, surface):
        """(V,) bool: the surface's vertices whose own light counts: usable and not inside
        solid geometry (`Scene.valid`)."""
        lit = self.usable[surface].copy()
        lit[lit] = self.valid[self._usable_span(surface)]
        return lit

    def gathered(self):
        """Irradiance / pi (V_usable, 3) gathered along the normals under the radiance the
        scene shows now: one pass, a progress step per vertex."""
        if self.weights is None:
            return _gathered(self.scene, self.points, self.normals, self.offset, self.progress, self.steps)
        if self.steps is not None and not self._stepped:
            self.steps.step(len(self.points))
        self._stepped = False
        return np.concatenate([w.irradiance() for w in self.weights]) if self.weights else np.zeros((0, 3), np.float32)


def _record(scene, points, normals, offset, progress, steps):
    """Masks (V, 16), validity (V,) and `Scene.bounce_weights` per chunk (None past
    MAX_WEIGHT_ENTRIES)."""
    masks = np.zeros((len(points), 16), np.uint64)
    valid = np.zeros(len(points), bool)
    weights, entries = [], 0
    for s in _slices(len(points), steps):
        w = scene.bounce_weights(points[s], normals[s], offset=offset, progress=progress if steps is None else None)
        masks[s], valid[s] = w.masks, w.valid
        entries += w.entries
        if weights is not None:
            weights.append(w)
            if entries > MAX_WEIGHT_ENTRIES:
                weights = None  # freed: past the budget, passes gather anew
    return masks, valid, weights


def _slices(count, steps):
    """Chunks of the vertices, each a progress step (one slice without `steps`)."""
    return [slice(0, count)] if steps is None else steps.chunks(count, least=1024)


def _gathered(scene, points, normals, offset, progress, steps):
    """Irradiance / pi (V, 3) gathered anew (`Scene.gather`, 3 bands) along the normals."""
    out = np.empty((len(points), 3), np.float32)
    for s in _slices(len(points), steps):
        g = scene.gather(points[s], normals[s], bands=BANDS, offset=offset, progress=progress if steps is None else None)
        out[s] = lobe_irradiance(g, normals[s][:, None])[:, 0]
    return out


def _show(scene, receivers, radiance):
    for surface, rgb in zip(receivers, radiance):
        scene.set_radiance(surface.mesh_id, rgb)


def fill(values, known, triangles):
    """`values` (V, 3) with every vertex not `known` set to the mean of its neighbours (along
    triangle edges) that are, growing out from the known ones a ring at a time, as texels
    are filled (`dilate.fill`); vertices no known one reaches, and every vertex when
    `triangles` is None, keep their values."""
    if triangles is None or known.all():
        return values
    t = np.asarray(triangles, dtype=np.int64)
    edges = np.stack([t[:, [0, 1, 2, 1, 2, 0]].ravel(), t[:, [1, 2, 0, 0, 1, 2]].ravel()], axis=1)
    size = int(edges.max()) + 1  # each neighbour once, however many triangles share the edge (1-D keys: fast)
    to, src = np.divmod(np.unique(edges[:, 0] * size + edges[:, 1]), size)
    out, known = values.copy(), known.copy()
    while True:
        edge = known[src] & ~known[to]
        if not edge.any():
            return out
        count = np.bincount(to[edge], minlength=len(out))
        sums = np.stack([np.bincount(to[edge], out[src[edge], c], minlength=len(out)) for c in range(3)], axis=1)
        reached = count > 0
        out[reached] = (sums[reached] / count[reached, None]).astype(out.dtype)
        known |= reached
