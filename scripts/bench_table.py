#!/usr/bin/python3
"""Turns `tofcam bench --json` output into the Markdown tables of docs/benchmarks.md.

Usage: tofcam bench --json > bench.json; scripts/bench_table.py bench.json
"""
import json
import sys


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: bench_table.py BENCH_JSON")
    with open(sys.argv[1]) as f:
        r = json.load(f)
    print(f"Machine: {r['machine']}; compiler {r['compiler']}; {r['frames']} frames per "
          f"resolution; {r['min_time_s']} s per figure (median of 5 batches).\n")
    for k, v in r.get("memory_bandwidth_gb_s", {}).items():
        print(f"- memory bandwidth, 256 MiB memcpy (read + write), {k}: {v:.1f} GB/s")
    res_order = []
    for s in r["stages"]:
        if s["resolution"] not in res_order:
            res_order.append(s["resolution"])
    for res in res_order:
        rows = [s for s in r["stages"] if s["resolution"] == res]
        print(f"\n### {res} ({rows[0]['pixels']} px)\n")
        print("| stage | 1 thread µs/frame | ns/px | frames/s | memcpy µs | ratio "
              "| 2 threads µs/frame (wall) | ratio |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|")
        names = []
        for s in rows:
            if s["stage"] not in names:
                names.append(s["stage"])
        for n in names:
            one = next((s for s in rows if s["stage"] == n and s["threads"] == 1), None)
            two = next((s for s in rows if s["stage"] == n and s["threads"] == 2), None)
            cells = [n]
            if one:
                cells += [f"{one['us_per_frame']:.1f}", f"{one['ns_per_pixel']:.2f}",
                          f"{one['frames_per_s']:.0f}",
                          f"{one['memcpy_us']:.1f}" if "memcpy_us" in one else "–",
                          f"{one['ratio_to_memcpy']:.1f}" if "ratio_to_memcpy" in one else "–"]
            else:
                cells += ["–"] * 5
            if two:
                cells += [f"{two['us_per_frame']:.1f}",
                          f"{two['ratio_to_memcpy']:.1f}" if "ratio_to_memcpy" in two else "–"]
            else:
                cells += ["–", "–"]
            print("| " + " | ".join(cells) + " |")
    if r.get("simulator"):
        print("\n### Simulator (SimulatedCamera::Grab)\n")
        print("| scene | threads | frames/s |")
        print("|---|---:|---:|")
        for s in r["simulator"]:
            print(f"| {s['scene']} | {s['threads']} | {s['frames_per_s']:.1f} |")


if __name__ == "__main__":
    main()
