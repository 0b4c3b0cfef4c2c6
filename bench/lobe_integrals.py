"""CPU time per receiver of `Scene.lobe_integrals`, the lightmap environment's per-sample sums
(native/engine/src/scene/lobes.rs), on random masks (about one cell in eight blocked).

Run: PYTHONPATH=native/python .venv/bin/python bench/lobe_integrals.py [--receivers 50000]
Cases: 4 lobes (HL2 and the normal) or 1 (flat), 26 values (25 SH and AO) or 10 (9 and AO).
Also prints the largest difference from the numpy quadrature (`cells.lobe_weights`).
"""

import argparse
import time

import numpy as np

from hemishadow import _native
from hemishadow.lightmap import cells


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--receivers", type=int, default=50000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(1)
    p = args.receivers
    masks = rng.integers(0, 2 ** 63, (p, 16), dtype=np.uint64)
    for _ in range(2):
        masks &= rng.integers(0, 2 ** 63, (p, 16), dtype=np.uint64)
    moments = np.ascontiguousarray(cells.moments()[:, :3], np.float32)
    for lobe_count, k in ((4, 26), (1, 26), (4, 10)):
        lobes = rng.normal(size=(p, lobe_count, 3)).astype(np.float32)
        lobes /= np.linalg.norm(lobes, axis=-1, keepdims=True)
        values = rng.normal(size=(1024, k)).astype(np.float32)
        best = np.inf
        for _ in range(args.repeats):
            t0 = time.process_time()
            out = _native.Scene.lobe_integrals(masks, lobes, moments, values)
            best = min(best, time.process_time() - t0)
        reference = (cells.lobe_weights(lobes[:200]) * (~cells.unpack(masks[:200]))[:, None, :]) @ values
        error = np.abs(out[:200] - reference).max() / np.abs(reference).max()
        print(f"{lobe_count} lobes, {k} values: {best / p * 1e6:.2f} us CPU per receiver "
              f"(best of {args.repeats}); largest difference from numpy {error:.1e} of the largest value")


if __name__ == "__main__":
    main()
