# Entry points for a fresh machine: `make demo` and `make test` install everything first.
.PHONY: setup setup-all demo demo-lightmaps demo-probes demo-panorama demo-cli test test-platforms clean extension extensions

PY := .venv/bin/python

# .venv: Python 3.13, bpy 5.3 (the primary version) and the engine.
setup:
	bash scripts/setup.sh

# .venv and the second-tier environments .venv-4.2, .venv-4.5, .venv-5.0 (requirements-X.Y.txt).
setup-all:
	bash scripts/setup.sh --all

# The main job: build the extension zip (when stale), install it into the project's bpy
# (user folder out/blender_user), and run the cloth demo through it: live self-shadowing
# with per-frame times, Cycles renders in out/demo/ (scripts/demo_blender.py).
demo: setup
	$(PY) scripts/build_extension.py --if-stale
	$(PY) scripts/demo_blender.py

# Lightmaps (issue 11): a room corner with a box under a Blender HDRI and a sun, baked headless
# through the installed extension and rendered by Cycles, path traced and from the lightmaps
# alone: out/demo_lightmaps/*.png (scripts/demo_lightmaps.py).
demo-lightmaps: setup
	$(PY) scripts/build_extension.py --if-stale
	$(PY) scripts/demo_lightmaps.py

# A probe grid baked over the same room corner lights a walking character live (issue 12):
# out/demo_probes/side_by_side.png, in the sun and in the back wall's shade.
demo-probes: setup
	$(PY) scripts/build_extension.py --if-stale
	$(PY) scripts/demo_probes.py

# A relightable panorama (issue 13): baked once from a point of a small scene, relit under a
# sky, two suns and a point lamp without the scene, beside Cycles' renders of the same lights:
# out/demo_panorama/relit_*.png and vs_cycles_*.png (scripts/demo_panorama.py).
demo-panorama: setup
	$(PY) scripts/build_extension.py --if-stale
	$(PY) scripts/demo_panorama.py

# The engine alone from the command line: spot.obj (ships in tests/assets) lit by Blender's
# "forest" HDRI (ships with the bpy module), written to out/spot.glb and out/spot.npz.
demo-cli: setup
	$(PY) -m hemishadow transfer tests/assets/spot.obj --out out/spot

# Every test, group by group (scripts/run_tests.py): cargo test; the full suite on Blender 5.3;
# the second tier (the zip installed, live, World, bake and CLI tests) on 4.2, 4.5 and 5.0;
# the Windows and macOS zips (built, validated, Wine smoke test, static checks). Times per
# group go to out/test-times.txt; the last line sums the counts.
test: setup-all
	$(PY) scripts/run_tests.py

# Only the Windows and macOS zips and their tests (docs/packaging.md).
test-platforms: setup
	$(PY) scripts/run_tests.py --only platforms

# The Blender extension zip for this machine: dist/hemishadow-0.1.0-linux_x64.zip.
extension: setup
	$(PY) scripts/build_extension.py

# Every platform's zip (linux_x64, windows_x64, macos_arm64, macos_x64); needs the cross
# toolchains, which scripts/setup_platforms.sh installs.
extensions: setup
	bash scripts/setup_platforms.sh
	$(PY) scripts/build_extension.py --platforms all

clean:
	rm -rf .venv .venv-[0-9]* out native/target .pytest_cache build dist
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
	find native/python -name '_native*.so' -delete
