#!/usr/bin/python3
"""Peer comparison for issue 7: Open3D's statistical and radius outlier removal on the same
simulated frames as tofcam's filters, with the bad/good counts from the simulator's ground truth,
beside PCL's (bench/peers/pcl_outlier_removal.cc, results read from DIR/pcl.json if present).

Input: the folder written by `tofcam bench --export-peers DIR`: one <WxH>_frame<k>.f32 per frame
(float32 rows x, y, z, bad; every pixel with a distance, i.e. the cloud a user would export) and
tofcam_filters.json (tofcam's filters on the same points: time and counts, the exposure). A point
is bad when |measured - true| > 5 cm or the ray hits nothing (tofcam/pipeline/frame_stats.h).

Output: one table (tofcam, Open3D, PCL per resolution) and, per peer method, the fastest tofcam
filter (or set) that removes at least as large a share of the bad points, with the speed ratio
and both good-point losses. --markdown prints the tables as Markdown (docs/benchmarks.md).

Usage: bench/peers/peer_outlier_removal.py DIR [--json OUT] [--only WxH] [--markdown]
Run through `make bench-peers` (installs python3-open3d and libpcl-dev, builds, exports, runs).
"""
import argparse
import json
import os
import sys
import time

import numpy as np

try:
    import open3d as o3d
except ImportError:
    sys.exit("peer_outlier_removal.py: open3d missing (apt-get install python3-open3d)")

# Parameter sets. SOR (20, 2.0) is Open3D's tutorial setting; (50, 1.0) is PCL's tutorial one.
# Radius settings: an SR-2 pixel at 4 m spans ~3 cm (0.45 deg/px), so 10 cm holds a few pixels'
# neighbours on a surface; 5 cm is the tighter choice a user would try next.
METHODS = [
    ("Open3D statistical (k=20, std=2.0)", "sor", 20, 2.0),
    ("Open3D statistical (k=50, std=1.0)", "sor", 50, 1.0),
    ("Open3D radius (r=0.10 m, min 6)", "ror", 6, 0.10),
    ("Open3D radius (r=0.05 m, min 4)", "ror", 4, 0.05),
]
REPEATS = 1  # per frame; Open3D takes seconds per VGA frame, one run each keeps this short


def run(pcd, kind, a, b):
    if kind == "sor":
        _, ind = pcd.remove_statistical_outlier(nb_neighbors=a, std_ratio=b)
    else:
        _, ind = pcd.remove_radius_outlier(nb_points=a, radius=b)
    return ind


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("--json", default="")
    ap.add_argument("--only", default="", help="one resolution, e.g. 160x124 (default: all)")
    ap.add_argument("--markdown", action="store_true", help="Markdown tables")
    ap.add_argument("--from-json", default="",
                    help="print the tables of an earlier --json output instead of running Open3D")
    args = ap.parse_args()
    with open(os.path.join(args.dir, "tofcam_filters.json")) as f:
        tof = json.load(f)
    keep = (lambda res: not args.only or res == args.only)
    if args.from_json:
        with open(args.from_json) as f:
            rows = [r for r in json.load(f) if keep(r["resolution"])]
        report(args, tof, rows, o3d_version=None)
        return
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    rows = [r for r in tof["tofcam"] if keep(r["resolution"])]
    for res, files in tof["clouds"].items():
        if not keep(res):
            continue
        clouds = []
        for name in files:
            a = np.fromfile(os.path.join(args.dir, name), dtype=np.float32).reshape(-1, 4)
            pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(a[:, :3].astype(np.float64)))
            clouds.append((pcd, a[:, 3] > 0.5))
        for label, kind, a, b in METHODS:
            total_s = 0.0
            bad = good = bad_removed = good_lost = done = 0
            for pcd, is_bad in clouds:
                best = float("inf")
                for _ in range(REPEATS):
                    t0 = time.perf_counter()
                    ind = run(pcd, kind, a, b)
                    best = min(best, time.perf_counter() - t0)
                total_s += best
                done += 1
                print(f"peers: {res} {label}: frame {done}/{len(clouds)} {best:.1f} s",
                      file=sys.stderr, flush=True)
                kept = np.zeros(len(is_bad), dtype=bool)
                kept[np.asarray(ind, dtype=np.int64)] = True
                bad += int(is_bad.sum())
                good += int((~is_bad).sum())
                bad_removed += int((is_bad & ~kept).sum())
                good_lost += int((~is_bad & ~kept).sum())
            rows.append({"method": label, "resolution": res, "frames": len(clouds),
                         "ms_per_frame": 1e3 * total_s / len(clouds), "bad_points": bad,
                         "good_points": good, "bad_removed": bad_removed, "good_lost": good_lost})
    pcl_path = os.path.join(args.dir, "pcl.json")
    if os.path.exists(pcl_path):
        with open(pcl_path) as f:
            rows += [r for r in json.load(f) if keep(r["resolution"])]
    else:
        print(f"(no {pcl_path}: run bench/peers/pcl_outlier_removal first for the PCL rows)")
    report(args, tof, rows, o3d_version=o3d.__version__)
    if args.json:
        with open(args.json + ".tmp", "w") as f:
            json.dump(rows, f, indent=2)
        os.replace(args.json + ".tmp", args.json)


def report(args, tof, rows, o3d_version):
    threads = os.environ.get("OMP_NUM_THREADS", "default")
    o3d = f"Open3D {o3d_version} (OMP_NUM_THREADS={threads})" if o3d_version else \
        "Open3D rows from json (as run)"
    print(f"{o3d}; PCL and tofcam single-threaded; exposure: {tof.get('controller', '?')} "
          f"settled register {tof.get('integration_register', '?')}, ΔL scale "
          f"{tof.get('delta_l_scale', 1.0):.4g}")

    def frac(r, k, n):
        return r[k] / max(r[n], 1)

    def peer(r):
        return not r["method"].startswith("tofcam")

    order = {"tofcam": 0, "Open3D": 1, "PCL": 2}
    rows.sort(key=lambda r: (r["resolution"], order.get(r["method"].split()[0], 3)))
    md = args.markdown
    if md:
        print("\n| resolution | method | ms/frame | bad removed | good lost |")
        print("|---|---|---:|---:|---:|")
    else:
        print(f"{'resolution':10} {'method':45} {'ms/frame':>9} {'bad removed':>16} "
              f"{'good lost':>16}")
    for r in rows:
        br, gl = frac(r, "bad_removed", "bad_points"), frac(r, "good_lost", "good_points")
        if md:
            print(f"| {r['resolution']} | {r['method']} | {r['ms_per_frame']:.3f} | "
                  f"{r['bad_removed']} ({100 * br:.1f}%) | {r['good_lost']} ({100 * gl:.1f}%) |")
        else:
            print(f"{r['resolution']:10} {r['method']:45} {r['ms_per_frame']:9.3f} "
                  f"{r['bad_removed']:8d} {100 * br:5.1f}% {r['good_lost']:8d} {100 * gl:5.1f}%")

    # Per peer method: the fastest tofcam row removing at least the same share of bad points,
    # and whether some tofcam row is at least as good on both counts (>= bad removed, <= good
    # lost).
    if md:
        print("\n| resolution | peer | peer ms | fastest tofcam with >= bad removed | tofcam ms | "
              "speed-up | bad removed (peer / tofcam) | good lost (peer / tofcam) | "
              "tofcam at least as good on both |")
        print("|---|---|---:|---|---:|---:|---:|---:|---|")
    else:
        print("\nper peer method: the fastest tofcam filter removing at least as many bad points")
    for p in [r for r in rows if peer(r)]:
        pb = frac(p, "bad_removed", "bad_points")
        cands = [t for t in rows if not peer(t) and t["resolution"] == p["resolution"]
                 and frac(t, "bad_removed", "bad_points") >= pb]
        if not cands:
            print(f"{p['resolution']:10} {p['method']:38} no tofcam filter removes as many")
            continue
        t = min(cands, key=lambda r: r["ms_per_frame"])
        tb, tg = frac(t, "bad_removed", "bad_points"), frac(t, "good_lost", "good_points")
        pg = frac(p, "good_lost", "good_points")
        ratio = p["ms_per_frame"] / max(t["ms_per_frame"], 1e-9)
        dom = [c for c in cands if frac(c, "good_lost", "good_points") <= pg]
        both = (min(dom, key=lambda r: r["ms_per_frame"])["method"] + " ({:.0f}x)".format(
            p["ms_per_frame"] / max(min(dom, key=lambda r: r["ms_per_frame"])["ms_per_frame"],
                                    1e-9))) if dom else "none"
        if md:
            print(f"| {p['resolution']} | {p['method']} | {p['ms_per_frame']:.1f} | {t['method']} | "
                  f"{t['ms_per_frame']:.3f} | {ratio:.0f}x | {100 * pb:.1f}% / {100 * tb:.1f}% | "
                  f"{100 * pg:.1f}% / {100 * tg:.1f}% | {both} |")
        else:
            print(f"{p['resolution']:10} {p['method']:38} {p['ms_per_frame']:8.1f} ms  vs  "
                  f"{t['method']:40} {t['ms_per_frame']:7.3f} ms  {ratio:7.0f}x  bad removed "
                  f"{100 * pb:5.1f}% / {100 * tb:5.1f}%  good lost {100 * pg:5.1f}% / "
                  f"{100 * tg:5.1f}%  at least as good on both: {both}")


if __name__ == "__main__":
    main()
