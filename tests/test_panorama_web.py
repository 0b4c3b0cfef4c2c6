"""The web viewer (hemishadow/panorama/web) in headless Chromium against the native relight.

Small compact panoramas with known content (a box room seen from inside, a window of background, transfer projected
per pixel with an occluder) are written by the engine's exporter, served by the viewer's server, opened with the
lights in the URL and screenshot; the picture must match hemishadow.panorama.relight of the same files through
Blender's Standard view (the relight CLI's PNG) within 2/255 on 99 % of pixels.

Chromium: Debian's `chromium` (scripts/setup.sh installs it), driven over the DevTools protocol on a pipe by
scripts/panorama_web_screenshot.py (its flags: WebGL2 on SwiftShader through ANGLE, --use-angle=swiftshader
--enable-unsafe-swiftshader). Without chromium the tests skip, except on CI (CI=true), where they fail.
"""

from __future__ import annotations

import importlib.util
import json
import os
import pathlib
import re
import struct
import subprocess
import sys
import time
import urllib.parse
import zlib

import numpy as np
import pytest

import hemishadow
import hemishadow.panorama as hp
from hemishadow.panorama.picture import srgb  # the relight CLI's PNG: Blender's Standard view
from hemishadow.sh import fibonacci_directions, rotate_sh, rotation_matrix

PIL = pytest.importorskip("PIL.Image")

ROOT = pathlib.Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("panorama_web_screenshot", ROOT / "scripts" / "panorama_web_screenshot.py")
shots = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(shots)  # Chromium's flags and the screenshot, shared with the docs' figure
WINDOW = (400, 300)


def require_chromium() -> None:
    if shots.find_chromium():
        return
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail("chromium is not installed (CI=true): scripts/setup.sh installs Debian's chromium package")
    pytest.skip("chromium is not installed (Debian: apt-get install chromium, or scripts/setup.sh)")


# --- the test panorama -------------------------------------------------------------------------------------

def directions(width, height):
    """The contract's equirectangular mapping, (H, W, 3), row 0 at the top."""
    u = (np.arange(width) + 0.5) / width
    v = 1 - (np.arange(height) + 0.5) / height
    phi = (0.5 - u)[None, :] * 2 * np.pi
    theta = (v - 0.5)[:, None] * np.pi
    return np.stack(np.broadcast_arrays(np.cos(theta) * np.cos(phi), np.cos(theta) * np.sin(phi),
                                        np.sin(theta)), axis=-1)


def room(width, height, bands, rotation, origin):
    """A box room (half sizes 3, 2.5, 2) seen from `origin`: coefficients (H, W, k, 3) of
    albedo * V * max(0, n.w) / pi with an occluder per pixel, positions, normals, the hit mask (a window in the
    +X wall is background)."""
    half = np.array([3.0, 2.5, 2.0])
    d = directions(width, height) @ np.asarray(rotation).T
    with np.errstate(divide="ignore"):
        t_axis = (np.sign(d) * half - origin) / d
    axis = np.argmin(t_axis, axis=-1)
    t = np.take_along_axis(t_axis, axis[..., None], -1)[..., 0]
    position = origin + t[..., None] * d
    normal = -np.sign(np.take_along_axis(d, axis[..., None], -1)) * np.eye(3)[axis]
    hit = ~((axis == 0) & (d[..., 0] > 0) & (np.abs(position[..., 1]) < 1.8) & (np.abs(position[..., 2] - 0.3) < 1.2))
    wall_colour = np.array([[0.8, 0.3, 0.2], [0.2, 0.7, 0.3], [0.6, 0.6, 0.8]])[axis]
    checker = ((np.floor(position[..., 0] * 2) + np.floor(position[..., 1] * 2) + np.floor(position[..., 2] * 2)) % 2)
    albedo = wall_colour * (0.6 + 0.4 * checker[..., None])
    blocker = normal + 0.8 * np.stack([np.sin(3 * position[..., 1]), np.cos(2 * position[..., 2]),
                                       np.sin(position[..., 0])], -1)
    blocker /= np.linalg.norm(blocker, axis=-1, keepdims=True)
    w = fibonacci_directions(1500)
    y = hemishadow.sh_basis(w.astype(np.float32), bands).astype(np.float64)  # (N, k)
    cosine = np.maximum(0, normal.reshape(-1, 3) @ w.T) * ((blocker.reshape(-1, 3) @ w.T) < 0.8)
    transfer = (cosine / np.pi) @ y * (4 * np.pi / len(w))  # (H*W, k), white
    coefficients = transfer[:, :, None] * albedo.reshape(-1, 1, 3)
    coefficients = coefficients.reshape(height, width, bands * bands, 3) * hit[..., None, None]
    return coefficients, position * hit[..., None], normal * hit[..., None], hit


def add_gamma_chunk(path: pathlib.Path, gamma: float = 1.0) -> None:
    """Give a PNG a gAMA chunk (after IHDR): a browser that honours it would change the data."""
    data = path.read_bytes()
    body = b"gAMA" + struct.pack(">I", round(gamma * 100000))
    chunk = struct.pack(">I", 4) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)
    end_of_ihdr = 8 + 8 + 13 + 4
    path.write_bytes(data[:end_of_ihdr] + chunk + data[end_of_ihdr:])


def save_compact(folder: pathlib.Path, width, height, bands, rotation, origin, gamma_chunk=False, bounce=False):
    """The room's panorama in the compact form, written by the engine's exporter (Panorama.save). gamma_chunk:
    the maps get a gAMA chunk of 1.0 (not what the exporter writes), which the viewer must ignore as well.
    bounce: a bounce term (a smooth colour over the surfaces)."""
    coefficients, position, normal, hit = room(width, height, bands, rotation, origin)
    depth = np.where(hit, np.linalg.norm(position - origin, axis=-1), np.inf)
    extra = None
    if bounce:
        extra = (0.08 + 0.06 * np.sin(position[..., [1, 2, 0]] * [1.5, 2.0, 1.0])) * hit[..., None]
    panorama = hp.Panorama(coefficients=coefficients.astype(np.float32), position=position.astype(np.float32),
                           normal=normal.astype(np.float32), depth=depth.astype(np.float32),
                           alpha=hit.astype(np.float32), origin=origin, rotation=rotation, bands=bands,
                           bounce=None if extra is None else extra.astype(np.float32))
    path = folder / "panorama.json"
    panorama.save(path)
    if gamma_chunk:
        for png in folder.glob("sh*.png"):
            add_gamma_chunk(png)
    return path


def dequantized(path: pathlib.Path):
    meta = json.loads(path.read_text())
    maps = [m["offset"] + np.asarray(m["scale"]) * np.asarray(PIL.open(path.parent / m["file"]), np.float64) / 255
            for m in meta["maps"]]
    shape = (meta["height"], meta["width"], 3)
    position = np.fromfile(path.parent / meta["position"]["file"], "<f4").reshape(shape).astype(np.float64)
    hit = np.asarray(PIL.open(path.parent / meta["alpha"]["file"])) > 127
    return np.stack(maps, axis=2), position, hit, np.asarray(meta["rotation"])


# --- the references: the engine's relight, and its sums written out in numpy ---------------------------------

def native_radiance(path, suns=(), points=(), env=None, env_rotation_deg=0.0, bounce=False, exposure=0.0,
                    image=None):
    """hemishadow.panorama.relight of the compact panorama (its 8-bit maps) under the lights. points:
    (position, power[, falloff]). image: the environment's picture for background pixels, looked up as
    `hemishadow relight --env` does (else they show the environment's SH)."""
    lights = [hp.Sun(d, s) for d, s in suns] + [hp.Point(*p) if len(p) < 3 else hp.Point(p[0], p[1], falloff=p[2])
                                                 for p in points]
    if env is not None:
        lights.append(hp.Environment(env, rotation=np.radians(env_rotation_deg)))
    panorama = hp.Panorama.load(path)
    background = None
    if image is not None:
        from hemishadow.panorama import picture

        mapping = rotation_matrix((0, 0, 1), np.radians(env_rotation_deg))  # the CLI's --env-rotation
        dirs = hp.directions(panorama.width, panorama.height, panorama.rotation)
        background = picture.sample_equirectangular(image, dirs, mapping)
    return hp.relight(panorama, lights, exposure=exposure, bounce=bounce, background=background)


def numpy_radiance(path, suns=(), points=(), env=None, env_rotation_deg=0.0, bounce=False):
    """The same sums read from the files with Pillow and written out in numpy (float64), from the contract:
    sum_i c_i (sum of the lights' SH weights) per surface pixel, the environment seen in the pixel's direction
    for background pixels. env: (k, 3) lighting SH; env_rotation_deg turns it about Z as the World's Mapping
    node does (the image is looked up at Rz d)."""
    c, position, hit, rotation = dequantized(path)
    height, width, k, _ = c.shape
    bands = int(round(np.sqrt(k)))
    basis = lambda d: hemishadow.sh_basis(np.asarray(d, np.float32).reshape(-1, 3), bands).astype(np.float64)  # noqa: E731
    weights = np.zeros((k, 3))
    for direction, strength in suns:
        weights += strength * basis(np.asarray(direction) / np.linalg.norm(direction))[0][:, None]
    env_sh = np.zeros((k, 3))
    if env is not None:
        turn = rotation_matrix((0, 0, 1), -np.radians(env_rotation_deg))
        env_sh = rotate_sh(np.asarray(env, np.float64)[:k], turn).astype(np.float64)
        weights += env_sh
    per_pixel = np.broadcast_to(weights, (height, width, k, 3)).copy()
    for light, power, *falloff in points:
        to_light = np.asarray(light) - position
        d2 = np.sum(to_light ** 2, axis=-1)
        y = basis(to_light / np.sqrt(d2)[..., None]).reshape(height, width, k)
        falloff = np.ones_like(d2) if falloff == ["constant"] else d2  # constant: as if 1 m away
        per_pixel += (power / (4 * np.pi) / falloff)[..., None, None] * y[..., None]
    surface = np.sum(c * per_pixel, axis=2)
    world = directions(width, height) @ rotation.T
    background = (basis(world) @ env_sh).reshape(height, width, 3)
    radiance = np.where(hit[..., None], surface, background)
    if bounce:  # added to every pixel, as relight(bounce=True) adds it
        meta = json.loads(path.read_text())["bounce"]
        radiance += meta["offset"] + np.asarray(meta["scale"]) * np.asarray(PIL.open(path.parent / meta["file"])) / 255
    return radiance


# --- the viewer ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def browser():
    """One headless Chromium for the module's pages (each launch costs seconds)."""
    require_chromium()
    tools = shots.DevTools(WINDOW)
    yield tools
    tools.close()


def screenshot(browser, url: str, width: int, height: int, out: pathlib.Path) -> tuple[np.ndarray, dict]:
    """The viewer at `url` in headless Chromium once it has drawn: its canvas (top-left, one pixel per pixel)
    as (H, W, 3), and the page's state and status line."""
    state = shots.screenshot(url, out, WINDOW, browser)
    return np.asarray(PIL.open(out).convert("RGB"))[:height, :width], state


def sky_image(width, height):
    """An equirectangular image with detail in every direction (the background's lookup must hit its pixels)."""
    d = directions(width, height)
    bands = 0.5 + 0.5 * np.sin(7 * np.arctan2(d[..., 1], d[..., 0]))[..., None] * [1.0, 0.6, 0.2]
    return (0.3 + 0.7 * np.clip(d[..., 2:3], 0, 1) * [0.6, 0.8, 1.2] + 0.4 * bands).astype(np.float32)


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """Two panoramas, each behind its own viewer's server: 128 x 64 x 25 coefficients turned 30 degrees about Z with
    a bounce term; 96 x 48 x 16 with gAMA chunks in its maps. Two environments: "sky" with an image (the
    background shows it), "glow" with SH only."""
    from hemishadow.panorama.server import serve_in_thread

    root = tmp_path_factory.mktemp("panoweb")
    origin = np.array([0.2, -0.1, 0.3])
    turn = rotation_matrix((0, 0, 1), np.radians(30))
    big = save_compact(root / "p25", 128, 64, 5, turn, origin, bounce=True)
    small = save_compact(root / "p16", 96, 48, 4, np.eye(3), origin, gamma_chunk=True)
    env = np.zeros((25, 3))
    env[0] = [1.6, 1.8, 2.4]  # a sky brighter above, a warm glow towards +X
    env[2] = [0.9, 1.0, 1.3]
    env[3] = [-0.6, -0.3, 0.0]
    env[6] = [0.2, 0.2, 0.3]
    env[8] = [0.15, 0.1, -0.1]
    env[10] = [0.1, 0.0, 0.05]
    env[20] = [0.05, 0.05, 0.05]
    image = sky_image(96, 48)
    environments = [{"name": "sky", "sh": env, "image": image}, {"name": "glow", "sh": 0.3 * env, "image": None}]
    servers = [serve_in_thread(path, 0, environments) for path in (big, small)]
    bases = ["http://%s:%d/" % s.server_address[:2] for s in servers]
    yield {"big": big, "small": small, "env": env, "image": image, "bases": dict(zip(("big", "small"), bases))}
    for server in servers:
        server.shutdown()
        server.server_close()


def compare(browser, base: str, name, query: dict, reference, hit, tmp_path):
    """The viewer's screenshot against the reference: 99 % of pixels within 2/255, over the picture and over the
    surface and background pixels each (a background is a few % of the picture)."""
    height, width = reference.shape[:2]
    url = base + "?" + urllib.parse.urlencode({"ui": "0", **query}, doseq=True)
    shot, state = screenshot(browser, url, width, height, tmp_path / f"{name}.png")
    assert state["state"] == "ready", f"{name}: the viewer did not draw: {state}"
    error = np.abs(shot.astype(int) - reference.astype(int)).max(axis=-1)
    within = {part: float(np.mean(error[mask] <= 2)) for part, mask in
              (("all", np.ones_like(hit)), ("surface", hit), ("background", ~hit)) if mask.any()}
    print(f"{name}: {within['all'] * 100:.2f} % of pixels within 2/255 (surface {within['surface'] * 100:.2f} %, "
          f"background {within.get('background', 1) * 100:.2f} %), max error {error.max()}/255")
    if min(within.values()) < 0.99:
        PIL.fromarray(reference).save(tmp_path / f"{name}_reference.png")
        pytest.fail(f"{name}: pixels within 2/255: {within} (max error {error.max()}); "
                    f"pictures in {tmp_path}")
    return within, int(error.max())


SUN, POINT, LONE_POINT = ((0.4, -0.6, 0.7), 2.5), ((1.2, 0.8, -0.5), 150.0), ((-1.5, 1.0, 0.8), 300.0)
CONSTANT_POINT = ((-2.0, -1.5, 1.2), 8.0, "constant")
ALL = dict(suns=[SUN], points=[POINT, CONSTANT_POINT], env=None, env_rotation_deg=40, bounce=True)


def test_the_native_relight_does_the_sums_of_the_contract(served):
    """The reference the viewer is held to (hemishadow.panorama.relight) against the sums written out here
    from the contract, on the same files: the two test pictures, in float."""
    for path, lights in ((served["big"], dict(ALL, env=served["env"])), (served["small"], dict(points=[LONE_POINT]))):
        native, ours = native_radiance(path, **lights), numpy_radiance(path, **lights)
        assert np.abs(native - ours).max() <= 1e-4 * max(1.0, np.abs(ours).max()), path


def test_sun_point_environment_and_exposure_match_the_relight(served, browser, tmp_path):
    """All the sums at once: a sun, a point lamp, a point lamp without falloff, an environment turned about Z
    (its image in the background, as the relight CLI shows it), the bounce term, exposure; a turned viewpoint
    (background directions) and 25 coefficients (every SH polynomial of the shader)."""
    reference = srgb(native_radiance(served["big"], **dict(ALL, env=served["env"]), exposure=-0.5,
                                     image=served["image"]))
    assert 0.2 < np.mean(reference) / 255 < 0.8 and np.mean(reference == 255) < 0.05  # a picture, not clipped
    compare(browser, served["bases"]["big"], "all", {"sun": "0.4,-0.6,0.7,2.5", "point": ["1.2,0.8,-0.5,150", "-2,-1.5,1.2,8,constant"],
                                            "env": "sky,1", "envrot": "40", "bounce": "1", "exposure": "-0.5"},
            reference, hp.Panorama.load(served["big"]).mask, tmp_path)


def test_point_light_and_environment_sh_match_the_relight(served, browser, tmp_path):
    """A point lamp, 1/d^2 from the float32 position map, and an environment without an image (background pixels
    show its SH), 16 coefficients; the maps carry a gAMA chunk that must change nothing (they are data)."""
    reference = srgb(native_radiance(served["small"], points=[LONE_POINT], env=0.3 * served["env"]))
    compare(browser, served["bases"]["small"], "point", {"point": "-1.5,1,0.8,300", "env": "glow"}, reference,
            hp.Panorama.load(served["small"]).mask, tmp_path)


# --- `python -m hemishadow serve` ---------------------------------------------------------------------------

WEB = pathlib.Path(hemishadow.__file__).parent / "panorama" / "web"


def test_viewer_files_are_all_local():
    """No CDN: the page and its scripts name no other host, and every file they load is in web/."""
    names = {p.name for p in WEB.iterdir()}
    assert {"index.html", "viewer.js", "relight.js", "sh.js", "viewer.css"} <= names
    for path in WEB.iterdir():
        text = path.read_text()
        assert not re.search(r"(https?:)?//[a-z0-9.-]+\.[a-z]{2,}/", text, re.I), f"{path.name} names another host"
        for ref in re.findall(r'(?:src|href)="([^"#]+)"|from "\./([^"]+)"', text):
            ref = next(r for r in ref if r)
            assert (WEB / ref).is_file(), f"{path.name} loads {ref}, which is not in {WEB}"


def test_serve_command_serves_the_viewer_the_panorama_and_environments(served):
    """The CLI on 127.0.0.1 (a free port), the viewer's files, the panorama's folder, the environments' SH
    (white first, truncated to the panorama's coefficients), nothing outside those folders."""
    import http.client

    process = subprocess.Popen([sys.executable, "-m", "hemishadow", "serve", str(served["small"]), "--port", "0",
                                "--no-browser"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = process.stdout.readline()
        match = re.search(r"at (http://127\.0\.0\.1:(\d+)/)", line)
        assert match, f"no URL on the first line: {line!r} {process.stderr.read() if process.poll() else ''}"
        port = int(match.group(2))

        def get(path):
            connection = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
            connection.request("GET", path)
            response = connection.getresponse()
            return response.status, response.getheader("Content-Type"), response.read()

        for name in ("index.html", "viewer.js", "relight.js", "sh.js", "viewer.css"):
            status, kind, body = get("/" + name)
            assert status == 200 and body == (WEB / name).read_bytes(), name
        assert get("/")[2] == (WEB / "index.html").read_bytes()
        assert get("/viewer.js")[1].startswith("text/javascript")  # module scripts need a JavaScript type
        status, _, body = get("/panorama/panorama.json")
        assert status == 200 and json.loads(body)["coefficients"] == 16
        assert get("/panorama/sh15.png")[2] == (served["small"].parent / "sh15.png").read_bytes()
        environments = json.loads(get("/environments.json")[2])["environments"]
        assert environments[0]["name"] == "white"
        assert all(len(e["sh"]) == 16 and all(len(row) == 3 for row in e["sh"]) for e in environments)
        assert abs(environments[0]["sh"][0][0] * 0.282095 - 1) < 1e-5  # radiance 1 in every direction
        from hemishadow.environment import builtin_hdris, read_exr

        hdris = builtin_hdris()
        for env in environments[1:]:  # Blender's HDRIs, each with its image for the background
            image = read_exr(hdris[env["name"]])[:, :, :3]
            assert (env["image"]["height"], env["image"]["width"]) == image.shape[:2]
            status, _, body = get("/" + env["image"]["file"])
            assert status == 200 and np.array_equal(np.frombuffer(body, "<f4").reshape(image.shape), image)
        assert len(environments) == 1 + len(hdris)
        assert get(f"/environments/{len(environments)}.f32")[0] == 404
        for path in ("/panorama/../panorama.json", "/panorama/%2e%2e/p25/panorama.json", "/../cli.py",
                     "/%2e%2e/server.py", "/panorama/", "/web/index.html", "/nothing.js"):
            assert get(path)[0] == 404, path
    finally:
        process.terminate()
        process.wait(timeout=30)


def test_serve_command_names_a_bad_panorama(tmp_path):
    result = subprocess.run([sys.executable, "-m", "hemishadow", "serve", str(tmp_path / "pano.exr"), "--no-browser"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "pano.exr: the viewer reads the compact form's JSON" in result.stderr
    (tmp_path / "panorama.json").write_text(json.dumps({"format": "hemishadow-panorama", "version": 1,
                                                        "maps": [{"file": "sh00.png"}]}))
    result = subprocess.run([sys.executable, "-m", "hemishadow", "serve", str(tmp_path / "panorama.json"),
                             "--no-browser", "--port", "0"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert "panorama.json: names 'sh00.png', which is not a file beside it" in result.stderr


def test_dragging_moves_the_sun_and_shift_dragging_the_point_lamp(served, browser):
    """Mouse events through DevTools: a drag ends with the sun towards the pixel under the cursor (the contract's
    mapping); a shift-drag puts the point lamp half a metre in front of the surface there (the position map)."""
    path = served["small"]
    panorama = hp.Panorama.load(path)
    dirs = hp.directions(panorama.width, panorama.height, panorama.rotation)
    tools = browser
    try:
        tools.open(served["bases"]["small"] + "?sun=0,0,1,3", (800, 600))
        assert tools.wait_for_viewer()["state"] == "ready"
        box = json.loads(tools.evaluate("JSON.stringify(document.getElementById('view').getBoundingClientRect())"))

        def drag(path_pixels, modifiers=0):
            points = [(box["x"] + (c + 0.5) / panorama.width * box["width"],
                       box["y"] + (r + 0.5) / panorama.height * box["height"]) for c, r in path_pixels]
            before = tools.evaluate("location.search")
            for kind, (x, y) in [("mousePressed", points[0])] + [("mouseMoved", p) for p in points[1:]] + \
                    [("mouseReleased", points[-1])]:
                tools.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", buttons=1, clickCount=1,
                           modifiers=modifiers)
            for _ in range(100):  # the URL follows the lights after the next frame
                search = tools.evaluate("location.search")
                if search != before:
                    return urllib.parse.parse_qs(search[1:])
                time.sleep(0.05)
            raise AssertionError(f"the drag changed nothing: {before}")

        query = drag([(10, 40), (40, 20), (70, 12)])
        *sun, strength = (float(v) for v in query["sun"][0].split(","))
        assert np.abs(np.array(sun) - dirs[12, 70]).max() < 1e-3 and strength == 3
        query = drag([(30, 40), (25, 36)], modifiers=8)  # shift
        *point, power = (float(v) for v in query["point"][0].split(","))
        hit = panorama.position[36, 25].astype(np.float64)
        back = min(0.5, 0.5 * np.linalg.norm(hit - panorama.origin))
        assert panorama.mask[36, 25] and np.abs(np.array(point) - (hit - back * dirs[36, 25])).max() < 1e-3
    finally:
        tools.open("about:blank", WINDOW)  # the next page starts from the module's window


def test_serve_command_names_a_busy_port(served):
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = subprocess.run([sys.executable, "-m", "hemishadow", "serve", str(served["small"]), "--no-browser",
                                 "--port", str(port)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert f"cannot serve on 127.0.0.1:{port} (Address already in use); pick another with --port" in result.stderr
