#!/usr/bin/env python3
"""Python overhead per SR-2 frame: grab + process + array access from Python against the same
loop in C++ (Pipeline._cpp_loop_seconds), on the same in-memory camera, interleaved repeats.

    PYTHONPATH=build/python /usr/bin/python3 bench/python_bench.py [--frames 2000 --repeats 7]

Prints the per-frame times and the overhead (median and spread over the repeats); the target of
issue 16 is <= 10 µs per frame.
"""

import argparse
import statistics
import time

import tofcam


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()

    sim = tofcam.SimulatedCamera("pavilion", seed=1)
    sim.integration_time_register = 71
    frames = [sim.grab() for _ in range(8)]
    camera = tofcam.ImportedCamera(tofcam.ImportedSequence(sim.info, frames), loop=True)
    pipeline = tofcam.Pipeline(camera.info, {"accuracy": {"scale": 0.165},
                                             "controller": {"enabled": False}})
    result = tofcam.PipelineResult()

    def python_loop(n):
        nonlocal result
        start = time.perf_counter()
        for _ in range(n):
            frame = camera.grab()
            result = pipeline.process(frame, out=result)
            distance = result.frame.radial_distance_m
            _ = distance[0, 0]
        return time.perf_counter() - start

    python_loop(200)  # warm caches
    pipeline._cpp_loop_seconds(camera, 200)
    py_us, cpp_us, over_us = [], [], []
    for _ in range(args.repeats):
        c = pipeline._cpp_loop_seconds(camera, args.frames) / args.frames * 1e6
        p = python_loop(args.frames) / args.frames * 1e6
        cpp_us.append(c)
        py_us.append(p)
        over_us.append(p - c)
    med = statistics.median
    print(f"SR-2 frame, {args.frames} frames x {args.repeats} interleaved repeats")
    print(f"  C++ loop:    median {med(cpp_us):7.2f} µs/frame (range {min(cpp_us):.2f}-{max(cpp_us):.2f})")
    print(f"  Python loop: median {med(py_us):7.2f} µs/frame (range {min(py_us):.2f}-{max(py_us):.2f})")
    print(f"  overhead:    median {med(over_us):7.2f} µs/frame (range {min(over_us):.2f}-{max(over_us):.2f}); "
          f"target <= 10 µs")


if __name__ == "__main__":
    main()
