#!/usr/bin/python3
"""Viewer throughput to one headless Chromium on loopback (issue 17's bench target): starts
`tofcam view` on a camera source, loads the page through the DevTools protocol, and reports the
frames per second the page received and drew, the frames it skipped, and the server's CPU time
per frame (camera loop + pipeline + packing + HTTP, from its /status).

  scripts/viewer_bench.py --tofcam build/apps/tofcam/tofcam --camera sim:demo [--seconds 10]
  scripts/viewer_bench.py --camera file:vga.h5 --loop   # a recording, e.g. 640x480
"""
import argparse
import json
import os
import sys
import time
import urllib.request

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests", "viewer"))
import test_viewer_browser as tvb  # noqa: E402  (the DevTools client and launchers)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tofcam", default="build/apps/tofcam/tofcam")
    ap.add_argument("--camera", default="sim:demo")
    ap.add_argument("--loop", action="store_true")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--cloud-off", action="store_true", help="load the page with ?cloud=off")
    a = ap.parse_args()
    tvb.CLI = a.tofcam
    extra = ["--loop"] if a.loop else []
    view = tvb.start_view(a.camera, extra)
    browser = tvb.start_browser()
    try:
        url, dev = next(view), next(browser)
        dev.call("Page.navigate", url=url + ("?cloud=off" if a.cloud_off else ""))
        tvb.wait_for(dev, "window.viewerState && window.viewerState.frames >= 5", 60, "frames")
        f0, d0, t0 = dev.eval("viewerState.frames"), dev.eval("viewerState.dropped"), time.time()
        s0 = json.load(urllib.request.urlopen(url + "status"))
        time.sleep(a.seconds)
        f1, d1, t1 = dev.eval("viewerState.frames"), dev.eval("viewerState.dropped"), time.time()
        s1 = json.load(urllib.request.urlopen(url + "status"))
        size = dev.eval("viewerState.meta.width + 'x' + viewerState.meta.height")
        render_ms = dev.eval("viewerState.renderMs")
        loop_frames = s1["frames"] - s0["frames"]
        print(f"{a.camera} ({size}): page {(f1 - f0) / (t1 - t0):.1f} frames/s drawn, "
              f"{d1 - d0} skipped, {render_ms:.1f} ms to draw one; camera loop {loop_frames / (t1 - t0):.1f} frames/s; "
              f"server CPU {s1['cpu_ms_per_frame']:.2f} ms/frame (whole run)")
    finally:
        for g in (browser, view):
            try:
                next(g)
            except StopIteration:
                pass


if __name__ == "__main__":
    main()
