"""The web viewer's local server: `python -m hemishadow serve PANORAMA.json`.

Serves, on 127.0.0.1 only:
    /                        the viewer (the files of web/ beside this module)
    /panorama/FILE           the files of the compact panorama's folder (panorama.json, shNN.png, alpha.png,
                             position.f32, bounce.png)
    /environments.json       {"environments": [{"name", "sh": k rows of [r, g, b], "image": {"file", "width",
                             "height"} or absent}]}: a white environment and Blender's bundled HDRIs, their
                             lighting SH truncated to the panorama's k (projected once, in the background from
                             the start)
    /environments/N.f32      environment N's equirectangular image, raw little-endian float32 RGB, row 0 at the
                             top: background pixels show it, as `hemishadow relight --env` does
Nothing else is reachable: no directory listings, no path outside those folders.
"""

from __future__ import annotations

import http.server
import json
import math
import pathlib
import threading
import urllib.parse

import numpy as np

WEB = pathlib.Path(__file__).resolve().parent / "web"
TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8", ".css": "text/css",
         ".json": "application/json", ".png": "image/png", ".f32": "application/octet-stream"}


def read_panorama(path) -> dict:
    """The compact panorama's JSON, checked enough that the viewer will find its files."""
    path = pathlib.Path(path)
    if path.suffix.lower() != ".json":
        raise ValueError(f"{path}: the viewer reads the compact form's JSON (Panorama.save('.../panorama.json') "
                         "or `hemishadow panorama ... --out .../panorama.json`), not a {path.suffix or 'bare'} file")
    try:
        meta = json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise ValueError(f"{path}: cannot read the panorama ({error})") from None
    if not isinstance(meta, dict) or meta.get("format") != "hemishadow-panorama" or meta.get("version") != 1:
        raise ValueError(f"{path}: not a compact hemishadow panorama (format hemishadow-panorama, version 1)")
    files = [m.get("file") for m in meta.get("maps", [])]
    files += [meta.get("position", {}).get("file"), meta.get("alpha", {}).get("file")]
    files += [meta["bounce"].get("file")] if isinstance(meta.get("bounce"), dict) else []
    for name in files:
        if not isinstance(name, str) or not (path.parent / name).is_file():
            raise ValueError(f"{path}: names {name!r}, which is not a file beside it")
    return meta


def uniform_white(count: int) -> list:
    """The SH of a uniform white environment of radiance 1 (an open surface reads albedo)."""
    sh = [[0.0, 0.0, 0.0] for _ in range(count)]
    sh[0] = [2 * math.sqrt(math.pi)] * 3  # 1 / Y00
    return sh


def environments(count: int) -> list[dict]:
    """[{"name", "sh" (count rows of RGB), "image" ((H, W, 3) float32) or None}]: white, then Blender's
    bundled HDRIs (when the bpy module and OpenEXR are installed)."""
    out = [{"name": "white", "sh": uniform_white(count), "image": None}]
    try:
        from .. import project_environment
        from ..environment import builtin_hdris, read_exr

        hdris = builtin_hdris()
    except ImportError:
        return out
    bands = math.isqrt(count)
    for name, path in hdris.items():
        try:
            image = np.ascontiguousarray(read_exr(path)[:, :, :3], dtype=np.float32)
            sh = project_environment(image, bands=bands)
        except (ImportError, OSError, ValueError):
            continue  # no OpenEXR, an unreadable file: that environment is left out
        out.append({"name": name, "sh": [[float(v) for v in row] for row in sh], "image": image})
    return out


def _published(found: list[dict]) -> tuple[bytes, dict[str, bytes]]:
    """(environments.json, {"environments/N.f32": image bytes})."""
    listed, images = [], {}
    for i, env in enumerate(found):
        entry = {"name": env["name"], "sh": [[float(v) for v in row] for row in env["sh"]]}
        image = env.get("image")
        if image is not None:
            image = np.asarray(image, dtype="<f4")
            if image.ndim != 3 or image.shape[2] != 3:
                raise ValueError(f"environment {env['name']}: the image must be (H, W, 3), got {image.shape}")
            entry["image"] = {"file": f"environments/{i}.f32", "width": image.shape[1], "height": image.shape[0]}
            images[entry["image"]["file"]] = np.ascontiguousarray(image).tobytes()
        listed.append(entry)
    return json.dumps({"environments": listed}).encode(), images


def make_server(panorama_json, port: int = 0, environments_list: list[dict] | None = None):
    """A ThreadingHTTPServer on 127.0.0.1:port (0: any free port); call serve_forever().
    environments_list: as `environments` returns (default: those, projected in the background)."""
    path = pathlib.Path(panorama_json).resolve()
    meta = read_panorama(path)
    count = len(meta["maps"])
    ready, published = threading.Event(), [b"", {}]

    def publish(found):
        published[:] = _published(found)
        ready.set()

    def project():  # a few seconds: started now, in the background, so the server answers at once
        try:
            publish(environments(count))
        finally:  # whatever happened, the page gets an answer (white alone if the projection failed)
            if not ready.is_set():
                publish([{"name": "white", "sh": uniform_white(count)}])

    if environments_list is None:
        threading.Thread(target=project, daemon=True).start()
    else:
        publish(environments_list)
    roots = {"": WEB, "panorama/": path.parent}

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 (http.server's name)
            name = urllib.parse.unquote(urllib.parse.urlsplit(self.path).path).lstrip("/") or "index.html"
            if name == "environments.json" or name.startswith("environments/"):
                ready.wait()
                body = published[0] if name == "environments.json" else published[1].get(name)
                return self.send_error(404) if body is None else self.reply(body, TYPES[pathlib.Path(name).suffix])
            prefix = "panorama/" if name.startswith("panorama/") else ""
            root = roots[prefix]
            file = (root / name[len(prefix):]).resolve()
            if file.parent != root or not file.is_file():  # one folder deep: no listings, no escapes
                return self.send_error(404)
            return self.reply(file.read_bytes(), TYPES.get(file.suffix, "application/octet-stream"))

        def reply(self, body: bytes, kind: str):
            self.send_response(200)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            try:
                self.wfile.write(body)
            except ConnectionError:  # the browser left (a reload, a closed tab): nothing to tell anyone
                pass

        def log_message(self, *args):  # quiet: errors still reach the browser
            pass

    return http.server.ThreadingHTTPServer(("127.0.0.1", port), Handler)


def serve_in_thread(panorama_json, port: int = 0, environments_list: list[dict] | None = None):
    """Start a server in a daemon thread (tests); returns it (server.server_address, server.shutdown())."""
    server = make_server(panorama_json, port, environments_list)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server
