"""Screenshot the panorama web viewer in headless Chromium (docs/images/panorama_web.png; the test's helper).

    .venv/bin/python scripts/panorama_web_screenshot.py PANORAMA.json OUT.png [--query "sun=...&env=forest"]
        [--window 1280x900] [--bare]

Serves PANORAMA.json as `python -m hemishadow serve` does (127.0.0.1, a free port), opens the viewer with the
query's lights, and writes Chromium's screenshot. WebGL2 runs on SwiftShader (software Vulkan) through ANGLE:
--use-angle=swiftshader --enable-unsafe-swiftshader (newer Chromium uses SwiftShader for WebGL only with the
latter); one device pixel per CSS pixel and the sRGB profile keep a canvas pixel's value in the screenshot.
Chromium is driven over the DevTools protocol on a pipe, so the screenshot is taken once the page says it has
drawn (<html data-state="ready">), not after a guessed time (--screenshot with --virtual-time-budget missed the
first frame now and then: the maps are decoded off the main thread, which virtual time does not wait for).
"""

from __future__ import annotations

import argparse
import base64
import fcntl
import json
import os
import pathlib
import select
import shutil
import subprocess
import sys
import time

FLAGS = ["--headless", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
         "--force-device-scale-factor=1", "--force-color-profile=srgb", "--hide-scrollbars",
         "--disable-extensions", "--no-first-run", "--disable-dev-shm-usage"]


def find_chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


class DevTools:
    """Chromium driven over the DevTools protocol on a pipe (--remote-debugging-pipe: it reads commands on its
    fd 3 and writes replies on fd 4, JSON messages ended by a NUL byte): no WebSocket library needed."""

    def __init__(self, window=(400, 300)):
        chromium = find_chromium()
        if chromium is None:
            raise FileNotFoundError("chromium is not installed (Debian: apt-get install chromium, or scripts/setup.sh)")
        to_chromium, self._write = os.pipe()
        self._read, from_chromium = os.pipe()
        # Moved above 9 so that bash's 3<& and 4>& cannot overwrite one with the other (dash takes one digit).
        high = [fcntl.fcntl(fd, fcntl.F_DUPFD, 10) for fd in (to_chromium, from_chromium)]
        for fd in (to_chromium, from_chromium):
            os.close(fd)
        command = [chromium, *FLAGS, f"--window-size={window[0]},{window[1]}", "--remote-debugging-pipe",
                   "about:blank"]
        self.process = subprocess.Popen(
            ["bash", "-c", f'exec "$@" 3<&{high[0]} 4>&{high[1]} {high[0]}<&- {high[1]}>&-', "bash", *command],
            pass_fds=high, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        for fd in high:
            os.close(fd)
        self._buffer, self._id, self.session = b"", 0, None

    def call(self, method, timeout=60, **params):
        self._id += 1
        message = {"id": self._id, "method": method, "params": params}
        if self.session and not method.startswith(("Target.", "Browser.")):
            message["sessionId"] = self.session
        os.write(self._write, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            while b"\0" not in self._buffer:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise RuntimeError(f"chromium did not answer {method} within {timeout} s")
                if select.select([self._read], [], [], min(remaining, 1.0))[0]:
                    chunk = os.read(self._read, 1 << 20)
                    if not chunk:
                        raise RuntimeError(f"chromium closed the pipe during {method}: {self._stderr()}")
                    self._buffer += chunk
                elif self.process.poll() is not None:
                    raise RuntimeError(f"chromium exited during {method}: {self._stderr()}")
            raw, self._buffer = self._buffer.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def _stderr(self) -> str:
        if self.process.poll() is None:
            return "(still running)"
        return self.process.stderr.read().decode(errors="replace")[-2000:]

    def open(self, url, window=(400, 300)):
        """The tab (the one Chromium opened) at `url`, one CSS pixel per device pixel, the viewport `window`."""
        if self.session is None:
            pages = [t for t in self.call("Target.getTargets")["targetInfos"] if t["type"] == "page"]
            target = pages[0]["targetId"] if pages else self.call("Target.createTarget", url="about:blank")["targetId"]
            self.session = self.call("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        self.url = url
        self.call("Emulation.setDeviceMetricsOverride", width=window[0], height=window[1], deviceScaleFactor=1,
                  mobile=False)
        self.call("Page.enable")
        self.call("Page.navigate", url=url)

    def evaluate(self, expression):
        return self.call("Runtime.evaluate", expression=expression, returnByValue=True)["result"].get("value")

    def wait_for_viewer(self, timeout=60) -> dict:
        """{"state": "ready" | "error" | None, "status": the page's status line} once the viewer has drawn its
        first frame or failed (the page sets <html data-state>)."""
        deadline = time.monotonic() + timeout
        while True:
            state = self.evaluate(f"document.URL === new URL({json.dumps(self.url)}).href && "
                                  "document.documentElement.dataset.state || null")
            if state in ("ready", "error") or time.monotonic() > deadline:
                status = self.evaluate("(document.getElementById('status') || {}).textContent || ''")
                return {"state": state, "status": status}
            time.sleep(0.05)

    def screenshot(self, out):
        data = self.call("Page.captureScreenshot", format="png")["data"]
        pathlib.Path(out).write_bytes(base64.b64decode(data))

    def close(self):
        try:
            self.call("Browser.close", timeout=10)
        except (RuntimeError, OSError):
            pass
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        for fd in (self._read, self._write):
            os.close(fd)
        self.process.stderr.close()


def screenshot(url: str, out, window=(400, 300), tools: DevTools | None = None) -> dict:
    """The viewer at `url` as a PNG of the viewport `window` at `out`, taken once it has drawn (or failed);
    returns the viewer's state and status line. tools: a running DevTools to reuse (else one for this shot)."""
    own = tools is None
    tools = DevTools(window) if own else tools
    try:
        tools.open(url, window)
        state = tools.wait_for_viewer()
        tools.screenshot(out)
    finally:
        if own:
            tools.close()
    return state


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
        state = screenshot(url, args.out, (width, height))
        if state["state"] != "ready":
            raise SystemExit(f"the viewer did not draw: {state}")
    finally:
        server.shutdown()
        server.server_close()
    print(f"wrote {args.out} ({url})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
