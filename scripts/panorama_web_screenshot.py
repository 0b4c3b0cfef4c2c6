"""Screenshot the panorama web viewer in headless Chromium (docs/images/panorama_web.png; the test's helper).

    .venv/bin/python scripts/panorama_web_screenshot.py PANORAMA.json OUT.png [--query "sun=...&env=forest"]
        [--window 1280x900] [--bare]

Serves PANORAMA.json as `python -m hemishadow serve` does (127.0.0.1, a free port), opens the viewer with the
query's lights, and writes Chromium's screenshot. WebGL2 runs on SwiftShader (software Vulkan) through ANGLE:
--use-angle=swiftshader --enable-unsafe-swiftshader (newer Chromium uses SwiftShader for WebGL only with the
latter); one device pixel per CSS pixel and the sRGB profile keep a canvas pixel's value in the screenshot;
--virtual-time-budget lets the page's fetches and first frame finish before the screenshot.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import shutil
import subprocess
import sys

FLAGS = ["--headless", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
         "--force-device-scale-factor=1", "--force-color-profile=srgb", "--hide-scrollbars",
         "--disable-extensions", "--no-first-run", "--disable-dev-shm-usage", "--virtual-time-budget=20000"]


def find_chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def run_chromium(url: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    chromium = find_chromium()
    if chromium is None:
        raise FileNotFoundError("chromium is not installed (Debian: apt-get install chromium, or scripts/setup.sh)")
    return subprocess.run([chromium, *FLAGS, *args, url], capture_output=True, text=True, timeout=timeout)


def screenshot(url: str, out: pathlib.Path, window=(400, 300)) -> None:
    """The page at `url` as a PNG (the window's size) at `out`."""
    out = pathlib.Path(out)
    out.unlink(missing_ok=True)
    result = run_chromium(url, f"--window-size={window[0]},{window[1]}", f"--screenshot={out}")
    if not out.is_file():
        raise RuntimeError(f"chromium wrote no screenshot of {url}:\n{result.stderr[-2000:]}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("panorama", type=pathlib.Path)
    parser.add_argument("out", type=pathlib.Path)
    parser.add_argument("--query", default="", help="URL parameters, e.g. 'sun=0.4,-0.6,0.7,3&env=forest,0.5'")
    parser.add_argument("--window", default="1280x900", help="window size WxH (default 1280x900)")
    parser.add_argument("--bare", action="store_true", help="the picture alone (ui=0)")
    args = parser.parse_args(argv)
    from hemishadow.panorama.server import serve_in_thread

    server = serve_in_thread(args.panorama)
    try:
        query = "&".join(q for q in (args.query, "ui=0" if args.bare else "") if q)
        url = "http://%s:%d/?%s" % (*server.server_address[:2], query)
        width, height = (int(v) for v in args.window.lower().split("x"))
        args.out.parent.mkdir(parents=True, exist_ok=True)
        screenshot(url, args.out, (width, height))
    finally:
        server.shutdown()
        server.server_close()
    print(f"wrote {args.out} ({url})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
