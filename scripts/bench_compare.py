#!/usr/bin/python3
"""Before/after Markdown tables from two `tofcam bench --json` runs (single-thread rows).

Usage: scripts/bench_compare.py BEFORE_JSON AFTER_JSON
Per resolution and stage: µs/frame before and after, the speed-up, and after it ns/px, frames/s,
the memcpy floor of the stage's minimal traffic and the ratio to it. Stages only in one run show
"–" on the other side.
"""
import json
import sys


def load(path):
    with open(path) as f:
        r = json.load(f)
    rows = {}
    for s in r["stages"]:
        if s["threads"] == 1:
            rows[(s["resolution"], s["stage"])] = s
    return r, rows


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: bench_compare.py BEFORE_JSON AFTER_JSON")
    rb, before = load(sys.argv[1])
    ra, after = load(sys.argv[2])
    for name, r in (("before", rb), ("after", ra)):
        bw = r.get("memory_bandwidth_gb_s", {}).get("1_threads")
        print(f"- {name}: {r['machine']}, {r['frames']} frames, {r['min_time_s']} s per figure"
              + (f", memory bandwidth {bw:.1f} GB/s" if bw else ""))
    resolutions = []
    for s in ra["stages"]:
        if s["resolution"] not in resolutions:
            resolutions.append(s["resolution"])
    for res in resolutions:
        pixels = next(s["pixels"] for s in ra["stages"] if s["resolution"] == res)
        print(f"\n### {res} ({pixels} px)\n")
        print("| stage | before µs | after µs | speed-up | after ns/px | after frames/s "
              "| memcpy µs | ratio |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|")
        names = []
        for s in rb["stages"] + ra["stages"]:
            if s["resolution"] == res and s["threads"] == 1 and s["stage"] not in names:
                names.append(s["stage"])
        for n in names:
            b, a = before.get((res, n)), after.get((res, n))
            cells = [n, f"{b['us_per_frame']:.1f}" if b else "–"]
            if a:
                cells += [f"{a['us_per_frame']:.1f}",
                          f"{b['us_per_frame'] / a['us_per_frame']:.1f}x" if b else "–",
                          f"{a['ns_per_pixel']:.2f}", f"{a['frames_per_s']:.0f}",
                          f"{a['memcpy_us']:.1f}" if "memcpy_us" in a else "–",
                          f"{a['ratio_to_memcpy']:.2f}" if "ratio_to_memcpy" in a else "–"]
            else:
                cells += ["–"] * 6
            print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
