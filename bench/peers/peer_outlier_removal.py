#!/usr/bin/python3
"""Peer comparison for issue 7: Open3D's statistical and radius outlier removal on the same
simulated frames as tofcam's filters, with the bad/good counts from the simulator's ground truth.

Input: the folder written by `tofcam bench --export-peers DIR`: one <WxH>_frame<k>.f32 per frame
(float32 rows x, y, z, bad; every pixel with a distance, i.e. the cloud a user would export) and
tofcam_filters.json (tofcam's filters on the same points: time and counts). A point is bad when
|measured - true| > 5 cm or the ray hits nothing (tofcam/pipeline/frame_stats.h).

Usage: bench/peers/peer_outlier_removal.py DIR [--json OUT]
Run through `make bench-peers` (installs python3-open3d, builds tofcam, exports, runs this).
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
    args = ap.parse_args()
    with open(os.path.join(args.dir, "tofcam_filters.json")) as f:
        tof = json.load(f)
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    keep = (lambda res: not args.only or res == args.only)
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
            bad = good = bad_removed = good_lost = 0
            for pcd, is_bad in clouds:
                best = float("inf")
                for _ in range(REPEATS):
                    t0 = time.perf_counter()
                    ind = run(pcd, kind, a, b)
                    best = min(best, time.perf_counter() - t0)
                total_s += best
                kept = np.zeros(len(is_bad), dtype=bool)
                kept[np.asarray(ind, dtype=np.int64)] = True
                bad += int(is_bad.sum())
                good += int((~is_bad).sum())
                bad_removed += int((is_bad & ~kept).sum())
                good_lost += int((~is_bad & ~kept).sum())
            rows.append({"method": label, "resolution": res, "frames": len(clouds),
                         "ms_per_frame": 1e3 * total_s / len(clouds), "bad_points": bad,
                         "good_points": good, "bad_removed": bad_removed, "good_lost": good_lost})
    threads = os.environ.get("OMP_NUM_THREADS", "default")
    print(f"Open3D {o3d.__version__} (OMP_NUM_THREADS={threads}); tofcam single-threaded")
    print(f"{'resolution':10} {'method':45} {'ms/frame':>9} {'bad removed':>16} "
          f"{'good lost':>16}")
    for r in sorted(rows, key=lambda r: (r["resolution"], r["method"].startswith("Open3D"))):
        br = r["bad_removed"] / max(r["bad_points"], 1)
        gl = r["good_lost"] / max(r["good_points"], 1)
        print(f"{r['resolution']:10} {r['method']:45} {r['ms_per_frame']:9.3f} "
              f"{r['bad_removed']:8d} {100 * br:5.1f}% {r['good_lost']:8d} {100 * gl:5.1f}%")
    if args.json:
        with open(args.json + ".tmp", "w") as f:
            json.dump(rows, f, indent=2)
        os.replace(args.json + ".tmp", args.json)


if __name__ == "__main__":
    main()
