"""A stand-in for `blender` in the farm's subprocess mode on machines without a Blender
executable: `python farm_fake_blender.py -b FILE.blend --python SCRIPT -- ARGS...` runs what
Blender would (open FILE, run SCRIPT as __main__ with Blender's argv) with the bpy module.
tests/test_farm.py writes a `blender` shell script that execs it."""

import runpy
import sys

import bpy

argv = sys.argv[1:]
blend = argv[argv.index("-b") + 1]
script = argv[argv.index("--python") + 1]
bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)
sys.argv = ["blender", *argv]
runpy.run_path(script, run_name="__main__")
