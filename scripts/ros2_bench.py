#!/usr/bin/env python3
"""ROS 2 publishing bench (issue 15; docs/benchmarks.md "ROS 2 topics").

For SR-2 (160 x 124) and VGA (640 x 480) simulated frames (pavilion, recorded once to
out/ros2_bench/*.h5 and played back in real time at the camera's 30 frames/s, looping) it runs
`tofcam run --ros2` for --seconds with build/bench/ros2_listener subscribed to <ns>/points and
<ns>/depth in another process, with best-effort and with reliable QoS, and once without --ros2
for the CPU baseline. Prints a Markdown table: frames published, received per topic, dropped per
second, transport latency (write -> take), time in the publisher per frame, CPU per frame.

Usage: scripts/ros2_bench.py [--build build] [--seconds 10] [--domain 90]
Cyclone settings: scripts/cyclonedds-local.xml unless CYCLONEDDS_URI is set.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def cpu_children():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--domain", type=int, default=90)
    a = ap.parse_args()
    tofcam = os.path.join(a.build, "apps/tofcam/tofcam")
    listener = os.path.join(a.build, "bench/ros2_listener")
    out = os.path.join(ROOT, "out/ros2_bench")
    os.makedirs(out, exist_ok=True)
    env = dict(os.environ)
    env.setdefault("CYCLONEDDS_URI", "file://" + os.path.join(ROOT, "scripts/cyclonedds-local.xml"))
    frames = int(round(30 * a.seconds))
    sizes = [("SR-2 160x124", "sr2", []), ("VGA 640x480", "vga", ["--camera-model", "generic640x480"])]
    rows = []
    for label, name, model in sizes:
        rec = os.path.join(out, name + ".h5")
        if not os.path.exists(rec):
            subprocess.run([tofcam, "record", "--camera", "sim:pavilion", "--frames", "30",
                            "--compression", "0", "--out", rec] + model, check=True,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        base = [tofcam, "run", "--camera", "file:" + rec, "--loop", "--real-time", "--frames",
                str(frames)]
        for qos in ["none", "best effort", "reliable"]:
            run_out = os.path.join(out, "run_%s_%s" % (name, qos.replace(" ", "_")))
            cmd = base + ["--out", run_out]
            lst = None
            if qos != "none":
                cmd += ["--ros2", "--ros2-domain", str(a.domain), "--ros2-wait-subscribers", "1"]
                if qos == "reliable":
                    cmd += ["--ros2-reliable"]
                lst = subprocess.Popen([listener, "--domain", str(a.domain), "--seconds",
                                        str(a.seconds + 3), "--reliable",
                                        "1" if qos == "reliable" else "0"],
                                       stdout=subprocess.PIPE, env=env, text=True)
                time.sleep(0.5)
            c0 = cpu_children()
            subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL)
            cpu = cpu_children() - c0
            summary = json.load(open(os.path.join(run_out, "summary.json")))
            row = {"size": label, "qos": qos, "frames": summary["frames"],
                   "elapsed_s": summary["elapsed_s"], "cpu_ms_per_frame": 1e3 * cpu / summary["frames"]}
            if lst is not None:
                stats = json.loads(lst.communicate()[0])
                row["listener"] = stats
                row["publish_ms"] = summary["ros2_publish_ms_per_frame"]
            rows.append(row)
    print("| frames | QoS | published | received points / depth | dropped/s points / depth "
          "| latency points mean / p99 ms | depth mean / p99 ms | in publisher ms/frame "
          "| publisher CPU ms/frame (+ vs no ROS 2) | listener CPU ms/frame |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    baseline = {}
    for r in rows:
        if r["qos"] == "none":
            baseline[r["size"]] = r["cpu_ms_per_frame"]
            continue
        s = r["listener"]
        n = r["frames"]
        el = r["elapsed_s"]
        print("| %s | %s | %d in %.1f s | %d / %d | %.2f / %.2f | %.2f / %.2f | %.2f / %.2f | %.2f "
              "| %.2f (+%.2f) | %.2f |" % (
                  r["size"], r["qos"], n, el, s["points"]["samples"], s["depth"]["samples"],
                  (n - s["points"]["samples"]) / el, (n - s["depth"]["samples"]) / el,
                  s["points"]["latency_ms_mean"], s["points"]["latency_ms_p99"],
                  s["depth"]["latency_ms_mean"], s["depth"]["latency_ms_p99"], r["publish_ms"],
                  r["cpu_ms_per_frame"], r["cpu_ms_per_frame"] - baseline[r["size"]],
                  1e3 * s["cpu_s"] / n))
    print("\nno-ROS-2 baseline CPU ms/frame: " +
          ", ".join("%s %.2f" % (k, v) for k, v in baseline.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
