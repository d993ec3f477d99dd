"""The viewer page in a real browser (issue 17): headless Chromium loads `tofcam view --camera
sim:demo` on loopback and is driven through the DevTools protocol (python3-websocket). Bounded in
time; skipped with a clear message only when Chromium cannot start. TOFCAM_VIEWER_SCREENSHOT=path
also saves the screenshot there (docs/viewer.png is made that way)."""
import base64
import itertools
import json
import os
import re
import shutil
import subprocess
import tempfile
import time
import urllib.request

import pytest
import websocket

CLI = os.environ.get("TOFCAM_CLI", "tofcam")


def read_line_matching(stream, pattern, timeout_s):
    """The first match of `pattern` in the lines of `stream` within `timeout_s`."""
    deadline = time.time() + timeout_s
    seen = []
    while time.time() < deadline:
        line = stream.readline()
        if not line:
            time.sleep(0.05)
            continue
        seen.append(line)
        m = re.search(pattern, line)
        if m:
            return m
    raise AssertionError(f"no line matching {pattern!r} within {timeout_s} s: {seen[-5:]}")


def stop(proc):
    """Terminates a child, killing it when it does not exit within 10 s."""
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def remove_tree(path):
    """Removes a directory that exiting Chromium helpers may still write into for a moment."""
    for _ in range(20):
        shutil.rmtree(path, ignore_errors=True)
        if not os.path.exists(path):
            return
        time.sleep(0.25)


class DevTools:
    """A minimal Chrome DevTools Protocol client over one page's websocket."""

    def __init__(self, url):
        self.ws = websocket.create_connection(url, timeout=30)
        self.ids = itertools.count(1)

    def call(self, method, **params):
        i = next(self.ids)
        self.ws.send(json.dumps({"id": i, "method": method, "params": params}))
        while True:
            reply = json.loads(self.ws.recv())
            if reply.get("id") == i:
                if "error" in reply:
                    raise AssertionError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def eval(self, expression):
        r = self.call("Runtime.evaluate", expression=expression, returnByValue=True,
                      awaitPromise=True)
        if "exceptionDetails" in r:
            raise AssertionError(f"{expression}: {r['exceptionDetails']}")
        return r["result"].get("value")


def start_view(camera="sim:demo", extra=()):
    """Generator: yields the viewer's URL, stops the process when resumed."""
    proc = subprocess.Popen([CLI, "view", "--camera", camera, "--port", "0", "--seed", "3",
                             *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        m = read_line_matching(proc.stderr, r"serving (http://127\.0\.0\.1:\d+/)", 30)
        yield m.group(1)
    finally:
        stop(proc)


@pytest.fixture
def viewer():
    yield from start_view()


def start_browser():
    """Generator: yields a DevTools client of a blank page; pytest.skip when Chromium cannot
    start."""
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if not exe:
        pytest.skip("Chromium is not installed (apt-get install chromium)")
    profile = tempfile.mkdtemp(prefix="tofcam_chromium_")
    proc = subprocess.Popen(
        [exe, "--headless=new", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
         "--enable-unsafe-swiftshader", "--no-first-run", "--disable-extensions",
         f"--user-data-dir={profile}", "--remote-debugging-port=0", "--window-size=1500,1500",
         "about:blank"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        try:
            m = read_line_matching(proc.stderr, r"DevTools listening on (ws://[^\s]+)", 30)
        except AssertionError as e:
            pytest.skip(f"Chromium could not start: {e}")
        port = re.search(r":(\d+)/", m.group(1)).group(1)
        targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list",
                                                   timeout=10))
        page = next(t for t in targets if t["type"] == "page")
        yield DevTools(page["webSocketDebuggerUrl"])
    finally:
        stop(proc)
        remove_tree(profile)


@pytest.fixture
def browser():
    yield from start_browser()


def wait_for(devtools, expression, timeout_s, what):
    deadline = time.time() + timeout_s
    value = None
    while time.time() < deadline:
        value = devtools.eval(expression)
        if value:
            return value
        time.sleep(0.2)
    raise AssertionError(f"{what} within {timeout_s} s (last {value!r})")


# Non-black pixels of a canvas (2D or WebGL with preserveDrawingBuffer), through a 2D copy.
NON_BLANK = """(id) => {
  const src = typeof id === 'string' ? document.getElementById(id) : id;
  const c = document.createElement('canvas'); c.width = src.width; c.height = src.height;
  const ctx = c.getContext('2d'); ctx.drawImage(src, 0, 0);
  const d = ctx.getImageData(0, 0, c.width, c.height).data;
  let n = 0; for (let i = 0; i < d.length; i += 4) if (d[i] + d[i + 1] + d[i + 2] > 30) ++n;
  return n; }"""


def status(base):
    return json.load(urllib.request.urlopen(base + "status", timeout=10))


def test_page_shows_live_frames_and_a_control_changes_the_filtered_image(viewer, browser):
    browser.call("Page.enable")
    browser.call("Page.navigate", url=viewer)
    wait_for(browser, "window.viewerState && window.viewerState.frames >= 10", 60,
             "10 frames on the page")
    # Every image and the chart drawn (non-blank), the 3D view too when WebGL is available.
    for canvas in ["raw", "filtered", "amplitude", "intensity", "delta_l", "chart"]:
        assert browser.eval(f"({NON_BLANK})('{canvas}')") > 100, canvas
    webgl = browser.eval("!!document.querySelector('#view3d canvas')")
    if webgl:
        assert browser.eval(f"({NON_BLANK})(document.querySelector('#view3d canvas'))") > 100
    # The chart follows the frames.
    before_updates = browser.eval("viewerState.chartUpdates")
    wait_for(browser, f"viewerState.chartUpdates >= {before_updates + 5}", 20, "chart updates")
    # Turning the accuracy filter off keeps a superset of the pixels: the filtered image's valid
    # share rises, on the page and in the server's summary.
    page_before = browser.eval("viewerState.validPct")
    server_before = status(viewer)["valid_fraction"]
    assert browser.eval("viewerPost({filters: {accuracy: false}})") is True
    seq = browser.eval("viewerState.seq")
    wait_for(browser, f"viewerState.seq >= {seq + 10}", 30, "10 more frames")
    page_after = browser.eval("viewerState.validPct")
    server_after = status(viewer)["valid_fraction"]
    print(f"valid: page {page_before:.1f} -> {page_after:.1f} %, server "
          f"{100 * server_before:.1f} -> {100 * server_after:.1f} %, webgl {webgl}")
    assert page_after > page_before + 1.0
    assert browser.eval("document.getElementById('filter_accuracy').checked") is False
    assert server_after > server_before + 0.01
    # A refused control is shown on the page, and the loop keeps running.
    assert browser.eval("viewerPost({max_delta_l_m: -1})") is False
    assert "max_delta_l_m" in browser.eval("viewerState.lastError")
    shot = base64.b64decode(browser.call("Page.captureScreenshot", format="png")["data"])
    assert shot.startswith(b"\x89PNG")
    out = os.environ.get("TOFCAM_VIEWER_SCREENSHOT")
    if out:
        with open(out, "wb") as f:
            f.write(shot)
    s = status(viewer)
    assert s["frames"] > 20 and s["served"] > 10
