"""``implc view``: levels-of-detail chunks against the octree, the server's safety rules over raw HTTP, and
the page in a real browser (Debian's Chromium, headless with SwiftShader's WebGL2, driven by Playwright
for Python with the system browser; never a downloaded one): it loads without errors, shows the surface
where the PNG renderer does, turns under a drag, fetches deeper chunks when zoomed, and works as a static
export and inlined in a notebook's iframe; a mesh (from implc or a file) shows where the PNG renderer shows
the voxels it was made from, is cut away, and works served, exported and inlined."""

import http.client
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pytest

import implc
from implc.engines.morton import morton_codes
from implc.files.scene import load as load_scene
from implc.view.lod_chunks import CHUNK_LEVELS, HEADER_BYTES, LodChunks, decode_normals, encode_normals
from implc.view.mesh_payload import MAGIC as MESH_MAGIC
from implc.view.mesh_payload import MeshPayload
from implc.view.page import NotebookView, export, lod_chunks
from implc.view.render import View, render_voxels
from implc.view.server import ViewServer

from ..support.browser import until

BACKGROUND = np.array([20, 23, 28])  # Style().background, as the page clears to it


def _scene_voxels(name, depth):
    sc = load_scene(name)
    return implc.voxelize(implc.compile(sc.surface, bounds=sc.bounds), depth), sc


@pytest.fixture(scope="module")
def flower():
    voxels, sc = _scene_voxels("paper_sin4_sin8", 8)
    return voxels, lod_chunks(voxels, name="paper_sin4_sin8", view=sc.view)


# -- chunks ----------------------------------------------------------------------------------------
def _parse(data: bytes):
    header = np.frombuffer(data[:HEADER_BYTES], dtype=np.uint32)
    n = int(header[7])
    cells = np.frombuffer(data[HEADER_BYTES:HEADER_BYTES + 3 * n], dtype=np.uint8).reshape(n, 3)
    normals = np.frombuffer(data[HEADER_BYTES + 3 * n:HEADER_BYTES + 5 * n], dtype=np.uint8).reshape(n, 2)
    return header, cells, normals


def test_chunks_hold_the_octree_levels_with_their_mean_normals(flower):
    """Every chunk's points are the octree's nodes at its point level inside it, with the level's mean
    normals (octahedral, within 1.5 degrees); each level's chunks hold each node exactly once; the child
    counts a chunk announces are its children's."""
    voxels, chunks = flower
    tree = voxels.octree
    for level in range(chunks.max_chunk_level + 1):
        m = min(level + CHUNK_LEVELS, voxels.depth)
        coords, normals = tree.level(m)
        got_cells, got_normals = [], []
        for chunk_level, i, j, k in (c for c in chunks.chunk_ids() if c[0] == level):
            header, cells, encoded = _parse(chunks.chunk(chunk_level, i, j, k))
            assert tuple(header[2:7]) == (level, i, j, k, m)
            got_cells.append(cells.astype(np.uint32) + (np.array([i, j, k], np.uint32) << np.uint32(m - level)))
            got_normals.append(decode_normals(encoded))
            for c in range(8):
                child = (level + 1, 2 * i + (c & 1), 2 * j + (c >> 1 & 1), 2 * k + (c >> 2))
                data = chunks.chunk(*child) if level < chunks.max_chunk_level else None
                assert header[8 + c] == (_parse(data)[0][7] if data is not None else 0)
        cells = np.concatenate(got_cells)
        order = np.argsort(morton_codes(cells))
        assert np.array_equal(cells[order], coords)
        angle = np.degrees(np.arccos(np.clip(np.sum(np.concatenate(got_normals)[order] * normals, axis=1), -1, 1)))
        assert angle.max() < 1.5
    assert chunks.chunk(0, 1, 0, 0) is None and chunks.chunk(chunks.max_chunk_level + 1, 0, 0, 0) is None


def test_octahedral_normals_round_trip():
    rng = np.random.default_rng(1)
    n = rng.normal(size=(5000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n = np.concatenate([n, np.eye(3), -np.eye(3)])
    angle = np.degrees(np.arccos(np.clip(np.sum(decode_normals(encode_normals(n)) * n, axis=1), -1, 1)))
    assert angle.max() < 1.5


def test_sections_are_the_solid_layers_at_each_level():
    """A section at the grid's depth is render.cross_section's layer (the cut-away PNG's); at a coarser
    level, the layer of the octree's nodes and inside entries there."""
    from implc.view.render import cross_section
    voxels, _ = _solid_torus()
    chunks = LodChunks(voxels)
    for axis, index in ((2, 64), (0, 40), (1, 100)):
        header = np.frombuffer(chunks.section(axis, index, 7)[:32], np.uint32)
        uv = np.frombuffer(chunks.section(axis, index, 7)[32:], np.uint32).reshape(-1, 2)
        cells = np.insert(uv, axis, index, axis=1)
        expected = cross_section(voxels, axis, index)
        assert tuple(header[2:6]) == (axis, index, 7, len(expected))
        assert np.array_equal(np.sort(morton_codes(cells)), np.sort(morton_codes(expected)))
        coarse = np.frombuffer(chunks.section(axis, index // 2, 6)[32:], np.uint32).reshape(-1, 2)
        both = np.concatenate([cross_section(voxels, axis, index // 2 * 2 + d) for d in (0, 1)])  # its two layers
        assert {tuple(c) for c in np.delete(both >> 1, axis, axis=1).tolist()} == set(map(tuple, coarse.tolist()))
    assert chunks.section(3, 0, 7) is None and chunks.section(2, 128, 7) is None and chunks.section(2, 0, 3) is None


def _solid_torus():
    sc = load_scene("torus")
    return implc.voxelize(implc.compile(sc.surface, bounds=sc.bounds), 7, solid=True), sc


def test_a_grid_shallower_than_a_chunk_is_one_chunk():
    voxels, _ = _scene_voxels("torus", 4)
    chunks = LodChunks(voxels)
    assert chunks.max_chunk_level == 0 and list(chunks.chunk_ids()) == [(0, 0, 0, 0)]
    header, cells, _ = _parse(chunks.chunk(0, 0, 0, 0))
    assert header[6] == 4 and np.array_equal(np.sort(morton_codes(cells)), np.sort(morton_codes(voxels.coords)))


# -- the server over raw HTTP ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def server(flower):
    with ViewServer(flower[1], port=0).start() as s:
        yield s


def _get(server, path, host=None, method="GET"):
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
    conn.putrequest(method, path, skip_host=True, skip_accept_encoding=True)
    conn.putheader("Host", host or f"127.0.0.1:{server.port}")
    conn.endheaders()
    response = conn.getresponse()
    body = response.read()
    conn.close()
    return response.status, body, response


def test_the_server_serves_its_routes_under_its_token(server, flower):
    t = server.token
    status, body, response = _get(server, f"/{t}/meta.json")
    assert status == 200 and json.loads(body)["depth"] == 8
    assert _get(server, f"/{t}/")[0] == 200 and b"viewer.js" in _get(server, f"/{t}/")[1]
    assert _get(server, f"/{t}/viewer.js")[0] == 200
    status, body, _ = _get(server, f"/{t}/chunks/0-0-0-0.bin")
    assert status == 200 and body == flower[1].chunk(0, 0, 0, 0)
    assert _get(server, f"/{t}/chunks/1-5-0-0.bin")[0] == 404
    assert _get(server, f"/{t}")[0] == 301
    assert _get(server, f"/{t}/", host=f"localhost:{server.port}")[0] == 200
    assert response.getheader("X-Content-Type-Options") == "nosniff"


def test_the_server_binds_loopback_only(server):
    assert server.httpd.server_address[0] == "127.0.0.1" and server.url.startswith("http://127.0.0.1:")


@pytest.mark.parametrize("path", ["/../../etc/passwd", "/%2e%2e/%2e%2e/etc/passwd", "/%2e%2e/",
                                  "/TOKEN/../TOKEN/meta.json", "/TOKEN/%2e%2e/TOKEN/meta.json",
                                  "/TOKEN/chunks/../meta.json", "/TOKEN/./meta.json",
                                  "/TOKEN/..%2f..%2fetc%2fpasswd", "/TOKEN/nothing", "/TOKEN/chunks/0-0-0.bin",
                                  "/TOKEN/%5c..%5cmeta.json"])
def test_traversal_and_unknown_paths_are_not_found(server, path):
    status, body, _ = _get(server, path.replace("TOKEN", server.token))
    assert status == 404 and b"root:" not in body


@pytest.mark.parametrize("case", ["no token", "wrong token", "token prefix", "foreign host", "no port", "rebinding"])
def test_requests_without_the_token_or_from_a_foreign_host_are_refused(server, case):
    t, port = server.token, server.port
    path, host = {"no token": ("/meta.json", None), "wrong token": ("/" + "x" * len(t) + "/meta.json", None),
                  "token prefix": (f"/{t[:-1]}/meta.json", None),
                  "foreign host": (f"/{t}/meta.json", f"evil.example:{port}"),
                  "no port": (f"/{t}/meta.json", "127.0.0.1"),
                  "rebinding": (f"/{t}/meta.json", f"attacker.test:{port}")}[case]
    status, body, _ = _get(server, path, host=host)
    assert status == 403 and b'"depth"' not in body


def _raw(server, request: bytes, read=True) -> bytes:
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as sock:
        sock.sendall(request)
        return sock.recv(65536) if read else b""


def test_doubled_hosts_and_absolute_targets_are_refused(server):
    t, port = server.token, server.port
    doubled = _raw(server, f"GET /{t}/meta.json HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nHost: evil.example\r\n\r\n"
                   .encode())
    assert doubled.startswith(b"HTTP/1.1 403") and b'"depth"' not in doubled
    for target, status in ((f"http://evil.example/{t}/meta.json", b"400"), (f"http://127.0.0.1:{port}/{t}/meta.json",
                                                                            b"400"),
                           (f"//evil.example/{t}/meta.json", b"403")):  # http.server makes it /evil.example/...
        answer = _raw(server, f"GET {target} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode())
        assert answer.startswith(b"HTTP/1.1 " + status) and b'"depth"' not in answer, target


def test_clients_that_hang_up_or_stall_leave_no_traceback(server, capfd):
    """Clients that send half a request and leave, or leave before reading a chunk, cost nothing and print
    nothing; a stalled one holds no connection slot for ever (its socket times out)."""
    import implc.view.server as view_server
    t, port = server.token, server.port
    for _ in range(50):
        _raw(server, f"GET /{t}/chunks/0-0-0-0.bin HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode(),
             read=False)
        _raw(server, b"GET /", read=False)
    assert _get(server, f"/{t}/meta.json")[0] == 200
    err = capfd.readouterr().err
    assert "Traceback" not in err and "Exception" not in err
    assert view_server.READ_TIMEOUT <= 30 and view_server._Handler.timeout == view_server.READ_TIMEOUT
    # the burst above fits the listen queue (with socketserver's 5, connections waited for TCP's SYN retry)
    assert server.httpd.request_queue_size == view_server.LISTEN_QUEUE >= 100


def test_connections_are_capped(flower):
    """The server's connection slots are the cap (what bounds the handlers running at once; the stalled
    clients' release is the read timeout, checked above)."""
    import implc.view.server as view_server
    with ViewServer(flower[1], port=0).start() as s:
        assert s.httpd._slots._initial_value == view_server.MAX_CONNECTIONS


def test_other_methods_are_not_served(server):
    assert _get(server, f"/{server.token}/meta.json", method="POST")[0] == 501


def test_the_cli_prints_its_url_serves_and_stops_on_ctrl_c(tmp_path):
    with subprocess.Popen([sys.executable, "-m", "implc", "view", "torus", "--depth", "6", "--no-browser",
                           "--port", "0", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                          cwd=tmp_path) as proc:
        try:
            url = next(line.strip() for line in proc.stdout if line.startswith("http://"))
            host, _, rest = url[len("http://"):].partition("/")
            conn = http.client.HTTPConnection(*host.split(":"), timeout=10)
            try:
                conn.request("GET", "/" + rest + "meta.json")
                assert json.loads(conn.getresponse().read())["name"] == "torus"
            finally:
                conn.close()
            proc.send_signal(signal.SIGINT)
            assert proc.wait(timeout=10) == 130
        finally:
            proc.kill()
            proc.wait()
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("argv,words", [
    (["view", "torus", "--port", "70000"], "--port"),
    (["view", "torus", "--budget", "10"], "--budget"),
    (["view", "x.ply"], "'implc view' shows"),
    (["view"], "name a SCENE"),
])
def test_bad_view_arguments_are_named(argv, words, capsys):
    from implc.cli.commands import main
    assert main(argv) == 2
    assert words in capsys.readouterr().err


def test_a_taken_port_is_named(flower, capsys):
    from implc.cli.commands import main
    with ViewServer(flower[1], port=0) as taken:
        assert main(["view", "torus", "--depth", "5", "--quiet", "--no-browser", "--port", str(taken.port)]) == 2
    assert "cannot listen on 127.0.0.1" in capsys.readouterr().err


# -- the page in a real browser ------------------------------------------------------------------------
def _open(browser, url, size=512):
    page = browser.new_page(viewport={"width": size, "height": size})
    errors = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url)
    page.evaluate("window.implcViewer.ready")
    return page, errors


def _settle(page, timeout=60.0):
    """Wait until the page has drawn what it wants and fetches nothing more."""
    until(page, "window.implcViewer.stats().settled", timeout)


def _pixels(page):
    """The canvas as shown, with the overlay and controls hidden for the screenshot, (H, W, 3) int."""
    hide = "document.querySelectorAll('#overlay, #controls, #help').forEach(e => { e.style.display = '%s'; })"
    page.evaluate(hide % "none")
    page.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
    from io import BytesIO

    from PIL import Image
    image = np.asarray(Image.open(BytesIO(page.screenshot())).convert("RGB")).astype(int)
    page.evaluate(hide % "")
    return image


def _drawn(image):
    """The pixels of an (H, W, 3) image that are not background."""
    return np.abs(np.asarray(image, dtype=int) - BACKGROUND).sum(axis=2) > 12


def _mask(page):
    """The pixels of the page's canvas that are not background."""
    return _drawn(_pixels(page))


def _iou(shown, png):
    """Intersection over union of the ``shown`` pixels and those the PNG renderer drew in ``png``."""
    expected = _drawn(png)
    return (shown & expected).sum() / (shown | expected).sum()


def test_the_page_shows_the_surface_where_the_png_renderer_does(browser, server, flower):
    voxels, _ = flower
    page, errors = _open(browser, server.url)
    _settle(page)
    stats = page.evaluate("window.implcViewer.stats()")
    assert stats["points"] > 0 and stats["frameMs"] >= 0
    overlay = page.inner_text("#overlay")
    assert "depth 8" in overlay and f"{len(voxels):,}" in overlay and "points drawn" in overlay and "frame" in overlay
    shown = _mask(page)
    az, el = load_scene("paper_sin4_sin8").view or (35.0, 25.0)
    iou = _iou(shown, render_voxels(voxels, size=512, view=View(az, el, perspective=True)))
    assert iou >= 0.9, iou
    assert errors == []
    page.close()


def test_a_drag_turns_the_view_and_reset_brings_it_back(browser, server):
    page, errors = _open(browser, server.url)
    _settle(page)
    before = _mask(page)
    camera = page.evaluate("({...window.implcViewer.camera})")
    page.mouse.move(256, 256)
    page.mouse.down()
    page.mouse.move(356, 286, steps=5)
    page.mouse.up()
    _settle(page)
    after = page.evaluate("({...window.implcViewer.camera})")
    assert after["azimuth"] != camera["azimuth"] and after["elevation"] != camera["elevation"]
    turned = _mask(page)
    assert (before ^ turned).sum() > 0.05 * before.sum()
    page.keyboard.press("r")
    _settle(page)
    assert np.array_equal(_mask(page), before)
    assert errors == []
    page.close()


@pytest.mark.slow  # a 1024³ voxelization and its chunks, 8 s
def test_zooming_in_fetches_deeper_chunks(browser):
    """At 256 pixels the 1024³ flower needs only coarse chunks; the wheel brings the camera close, and
    the page fetches deeper ones for what is in view, within its point budget."""
    voxels, sc = _scene_voxels("paper_sin4_sin8", 10)
    with ViewServer(lod_chunks(voxels, view=sc.view), port=0, budget=300_000).start() as s:
        page, errors = _open(browser, s.url, size=256)
        _settle(page)
        coarse = page.evaluate("window.implcViewer.stats()")
        assert coarse["deepest"] < 4
        page.mouse.move(128, 128)
        for _ in range(12):
            page.mouse.wheel(0, -400)
        _settle(page)
        close = page.evaluate("window.implcViewer.stats()")
        assert close["deepest"] > coarse["deepest"] and close["requests"] > coarse["requests"]
        assert close["points"] <= 300_000
        assert errors == []
        page.close()


def test_a_cut_away_of_a_solid_matches_the_png_renderers(browser):
    """The cut control hides what lies beyond the plane and draws the solid's section there, as
    'implc render --cut z=0.1 --solid' does."""
    voxels, sc = _solid_torus()
    with ViewServer(lod_chunks(voxels, view=sc.view), port=0).start() as s:
        page, errors = _open(browser, s.url)
        _settle(page)
        whole = _pixels(page)
        page.select_option("#cut-axis", "2")  # the control, as a user picks it
        page.evaluate("window.implcViewer.setCut(2, 0.1)")
        _settle(page)
        cut = _pixels(page)
        assert errors == []
        page.close()
    shown = _drawn(cut)
    assert _iou(shown, render_voxels(voxels, size=512, view=View(*sc.view, perspective=True), cut=(2, 0.1))) >= 0.9
    changed = np.abs(cut - whole).sum(axis=2) > 24  # the top removed, the flat section in its place
    assert changed.sum() > 0.3 * shown.sum()


def _serve_folder(folder):
    handler = partial(SimpleHTTPRequestHandler, directory=str(folder))
    handler.log_message = lambda *a: None
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    return httpd


def test_a_static_export_shows_the_same_picture(browser, server, flower, tmp_path):
    page, _ = _open(browser, server.url)
    _settle(page)
    served = _mask(page)
    page.close()
    folder = export(flower[1], tmp_path / "site")
    assert {"index.html", "viewer.js", "viewer.css", "meta.json", "chunks"} <= set(os.listdir(folder))
    httpd = _serve_folder(folder)
    try:
        page, errors = _open(browser, f"http://127.0.0.1:{httpd.server_address[1]}/index.html")
        _settle(page)
        assert np.array_equal(_mask(page), served) and errors == []
        page.close()
    finally:
        httpd.shutdown()
        httpd.server_close()


def test_the_notebook_view_is_self_contained(browser, flower, tmp_path):
    voxels, _ = flower
    shown = voxels.show(height=400)
    assert isinstance(shown, NotebookView)
    html = shown._repr_html_()
    assert html.startswith('<div class="implc-view"><iframe srcdoc=') and "IMPLC_EMBED" in html
    assert "http" not in shown.document.split("<body>")[1]  # nothing fetched from anywhere
    assert voxels._repr_html_().startswith('<div class="implc-view"><iframe srcdoc=')
    path = shown.save(tmp_path / "view.html")
    page, errors = _open(browser, path.as_uri())
    _settle(page)
    assert page.evaluate("window.implcViewer.stats()")["points"] > 100_000
    assert _mask(page).sum() > 10_000 and errors == []
    page.close()


@pytest.mark.slow
def test_a_wheel_carries_the_page(tmp_path):
    """The page's files are package data: a built wheel holds them (and the viewer reads them there)."""
    import zipfile
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    done = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w",
                           str(tmp_path), root], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    (wheel,) = tmp_path.glob("implc-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    assert {f"implc/view/assets/{n}" for n in ("index.html", "viewer.js", "viewer.css")} <= names


# -- a mesh in the page ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def torus_mesh():
    voxels, sc = _scene_voxels("torus", 7)
    return voxels, voxels.mesh(), sc


def test_mesh_bin_holds_the_mesh_and_the_server_serves_only_it(torus_mesh):
    _, mesh, sc = torus_mesh
    payload = MeshPayload(mesh, name="torus", view=sc.view)
    body = payload.body()
    header = np.frombuffer(body[:32], "<u4")
    v, t = len(mesh.vertices), len(mesh.faces)
    assert header[0] == MESH_MAGIC and header[2] == v and header[3] == t and len(body) == payload.size
    positions = np.frombuffer(body, "<f4", 3 * v, 32).reshape(-1, 3)
    normals = np.frombuffer(body, "<f4", 3 * v, 32 + 12 * v).reshape(-1, 3)
    faces = np.frombuffer(body, "<u4", 3 * t, 32 + 24 * v).reshape(-1, 3)
    np.testing.assert_allclose(positions, mesh.vertices, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1, atol=1e-5)
    assert np.array_equal(faces, mesh.faces)
    with ViewServer(payload, port=0).start() as s:
        meta = json.loads(_get(s, f"/{s.token}/meta.json")[1])
        assert meta["kind"] == "mesh" and meta["triangles"] == t
        assert _get(s, f"/{s.token}/mesh.bin")[1] == body
        assert _get(s, f"/{s.token}/chunks/0-0-0-0.bin")[0] == 404


def test_a_mesh_shows_where_the_png_renderer_shows_its_voxels_and_is_cut_away(browser, torus_mesh):
    voxels, mesh, sc = torus_mesh
    with ViewServer(MeshPayload(mesh, name="torus", view=sc.view), port=0).start() as s:
        page, errors = _open(browser, s.url)
        _settle(page)
        stats = page.evaluate("window.implcViewer.stats()")
        assert stats["triangles"] == len(mesh.faces)
        assert f"{len(mesh.faces):,} triangles" in page.inner_text("#overlay")
        whole = _pixels(page)
        page.evaluate("window.implcViewer.setCut(2, 0.0)")
        _settle(page)
        cut = _pixels(page)
        assert errors == []
        page.close()
    shown = _drawn(whole)
    assert _iou(shown, render_voxels(voxels, size=512, view=View(*sc.view, perspective=True))) >= 0.9
    assert np.unique(whole[shown].sum(axis=1)).size > 50  # shaded by its normals, not one flat colour
    changed = np.abs(cut - whole).sum(axis=2) > 24  # the upper half gone
    assert changed.sum() > 0.2 * shown.sum()


def test_a_mesh_shows_the_same_exported_and_inlined_and_a_mesh_file_is_framed_by_its_extent(browser, torus_mesh,
                                                                                            tmp_path):
    """export() and Mesh.show() give the served picture; 'implc view part.stl --export DIR' frames the file's
    own extent (a file carries no bounds) and shows every triangle."""
    from implc.cli.commands import main
    _, mesh, sc = torus_mesh
    payload = MeshPayload(mesh, view=sc.view)
    with ViewServer(payload, port=0).start() as s:
        page, _ = _open(browser, s.url)
        _settle(page)
        served = _mask(page)
        page.close()
    export(payload, tmp_path / "site")
    mesh.save(tmp_path / "torus.stl")
    assert main(["view", str(tmp_path / "torus.stl"), "--export", str(tmp_path / "file"), "--quiet"]) == 0
    assert {"index.html", "viewer.js", "meta.json", "mesh.bin"} <= set(os.listdir(tmp_path / "file"))
    meta = json.loads((tmp_path / "file" / "meta.json").read_text())
    np.testing.assert_allclose(meta["bounds"], np.stack([mesh.vertices.min(0), mesh.vertices.max(0)], 1), rtol=1e-6)
    shown = {}
    for name in ("site", "file"):
        httpd = _serve_folder(tmp_path / name)
        try:
            page, errors = _open(browser, f"http://127.0.0.1:{httpd.server_address[1]}/index.html")
            _settle(page)
            shown[name] = _mask(page)
            assert errors == [] and page.evaluate("window.implcViewer.stats()")["triangles"] == len(mesh.faces)
            page.close()
        finally:
            httpd.shutdown()
            httpd.server_close()
    assert np.array_equal(shown["site"], served)
    assert shown["file"].sum() > served.sum()  # framed closer: the torus fills more of the page
    inline = mesh.show(view=sc.view)
    assert isinstance(inline, NotebookView) and "http" not in inline.document.split("<body>")[1]
    page, errors = _open(browser, inline.save(tmp_path / "mesh.html").as_uri())
    _settle(page)
    assert np.array_equal(_mask(page), served) and errors == []
    page.close()


def test_a_mesh_too_large_for_a_notebook_is_refused_in_one_line(torus_mesh):
    with pytest.raises(ValueError, match="more than the 0 MiB a notebook view carries"):
        torus_mesh[1].show(max_bytes=1000)


def test_a_voxel_file_with_mesh_is_refused_and_a_surface_with_mesh_exports_a_mesh(tmp_path, capsys):
    from implc.cli.commands import main
    voxels, _ = _scene_voxels("torus", 5)
    from implc.files import voxel_files
    voxel_files.save(voxels, tmp_path / "t.npz")
    assert main(["view", str(tmp_path / "t.npz"), "--mesh", "--export", str(tmp_path / "a")]) == 2
    assert "--mesh meshes a surface" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()
    assert main(["view", "torus", "--depth", "5", "--mesh", "--export", str(tmp_path / "b"), "--quiet"]) == 0
    meta = json.loads((tmp_path / "b" / "meta.json").read_text())
    assert meta["kind"] == "mesh" and meta["triangles"] == len(voxels.mesh().faces)


def test_a_client_trickling_its_request_is_cut_off(flower):
    """A client that sends a byte of its request every half second never lets a receive time out; the
    request's deadline (2 s here, the server's parameter) still closes its connection."""
    with ViewServer(flower[1], port=0, request_seconds=2.0).start() as slow:
        request = f"GET /{slow.token}/meta.json HTTP/1.1\r\nHost: 127.0.0.1:{slow.port}\r\n".encode()
        t0 = time.monotonic()
        closed = False
        with socket.create_connection(("127.0.0.1", slow.port), timeout=10) as sock:
            for byte in request * 4:
                try:
                    sock.sendall(bytes([byte]))
                except OSError:
                    closed = True
                    break
                sock.settimeout(0.5)
                try:
                    if sock.recv(1024) == b"":
                        closed = True
                        break
                except TimeoutError:
                    pass
                if time.monotonic() - t0 > 8:
                    break
        assert closed and time.monotonic() - t0 < 5
        assert _get(slow, f"/{slow.token}/meta.json")[0] == 200  # the server goes on


def test_meta_json_is_strict_json_with_non_finite_values(tmp_path):
    """JSON has no NaN: a value that is not finite goes out as null, and the page's JSON.parse (here,
    Python's json in strict mode) reads every exported meta.json."""
    from implc.view.json_text import json_bytes
    text = json_bytes({"a": float("nan"), "b": [1.0, float("inf"), {"c": -float("inf")}], "d": np.float64(np.nan)})
    assert json.loads(text, parse_constant=lambda name: pytest.fail(f"{name} in JSON")) == \
        {"a": None, "b": [1.0, None, {"c": None}], "d": None}
