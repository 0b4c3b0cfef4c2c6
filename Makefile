# Entry points for a fresh machine: `make demo` and `make test` install everything first.
.PHONY: setup demo demo-cli test clean extension

PY := .venv/bin/python

setup:
	bash scripts/setup.sh

# The main job: build the extension zip (when stale), install it into the project's bpy
# (user folder out/blender_user), and run the cloth demo through it: live self-shadowing
# with per-frame times, Cycles renders in out/demo/ (scripts/demo_blender.py).
demo: setup
	$(PY) scripts/build_extension.py --if-stale
	$(PY) scripts/demo_blender.py

# The engine alone from the command line: spot.obj (ships in tests/assets) lit by Blender's
# "forest" HDRI (ships with the bpy module), written to out/spot.glb and out/spot.npz.
demo-cli: setup
	$(PY) -m hemishadow transfer tests/assets/spot.obj --out out/spot

# cargo first, so that pytest's summary is the run's closing line (cargo's last line
# is its doc-tests, usually "0 passed"). pytest exits 5 when it collects no test.
test: setup
	cargo test --release --manifest-path native/Cargo.toml
	$(PY) -m pytest -q tests || [ $$? -eq 5 ]

# The Blender extension zip: dist/hemishadow-0.1.0-linux_x64.zip (docs/packaging.md).
extension: setup
	$(PY) scripts/build_extension.py

clean:
	rm -rf .venv out native/target .pytest_cache build dist
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
	find native/python -name '_native*.so' -delete
