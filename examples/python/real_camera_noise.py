#!/usr/bin/env python3
"""Reads a real camera's recording (default: the ifm O3D303 frames in tests/data/real) and prints
its temporal noise against amplitude and tofcam's predicted inaccuracy ΔL (eq. 2).

    PYTHONPATH=build/python /usr/bin/python3 examples/python/real_camera_noise.py \\
        --spec ifm-o3d3xx:tests/data/real/ifm_o3d303/o3d3xx.h5
"""

import argparse
import pathlib

import numpy as np

import tofcam

DEFAULT = pathlib.Path(__file__).resolve().parents[2] / "tests/data/real/ifm_o3d303/o3d3xx.h5"


def ranks(x):
    r = np.empty(len(x))
    r[np.argsort(x, kind="stable")] = np.arange(len(x))
    return r


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spec", default=f"ifm-o3d3xx:{DEFAULT}",
                        help="import spec <format>:<path> of a static multi-frame recording")
    args = parser.parse_args()

    seq = tofcam.import_sequence(args.spec)
    if len(seq) < 2:
        raise SystemExit(f"{args.spec}: {len(seq)} frame(s); temporal noise needs at least 2")
    frames = [tofcam.to_metric(f) for f in seq.frames]
    d = np.stack([f.radial_distance_m for f in frames])
    valid = np.all(np.stack([f.valid() for f in frames]), axis=0)
    amplitude = np.mean(np.stack([f.amplitude for f in frames]), axis=0)
    sigma = d.std(axis=0, ddof=1)
    delta_l = tofcam.delta_l(frames[0])
    use = valid & np.isfinite(delta_l)
    print(f"{seq.camera.model}: {len(seq)} frames of {seq.camera.width} x {seq.camera.height}, "
          f"{use.sum()} pixels valid in every frame")
    print(f"{'amplitude':>14} {'pixels':>7} {'median sigma':>13}")
    edges = [0, 100, 300, 1000, 3000, np.inf]
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = use & (amplitude >= lo) & (amplitude < hi)
        if sel.sum():
            print(f"{lo:>6.0f}-{hi:<7.0f} {sel.sum():>7d} {1000 * np.median(sigma[sel]):>10.1f} mm")
    rho = np.corrcoef(ranks(delta_l[use]), ranks(sigma[use]))[0, 1]
    print(f"Spearman rank correlation of ΔL with the temporal sigma: {rho:.2f} "
          f"(a {len(seq)}-frame sigma estimate is itself noisy)")


if __name__ == "__main__":
    main()
