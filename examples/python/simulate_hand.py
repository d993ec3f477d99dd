#!/usr/bin/env python3
"""Simulates the paper's hand scene (figs. 2, 8, 9), runs tofcam's pipeline with the integration-
time controller, and plots the raw and the filtered false-colour image side by side.

    PYTHONPATH=build/python /usr/bin/python3 examples/python/simulate_hand.py --out hand.png
"""

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import tofcam  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=30, help="frames to run (controller)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", default="hand.png", help="output PNG")
    args = parser.parse_args()

    camera = tofcam.SimulatedCamera("hand", seed=args.seed)
    # The noise scale of eq. 2 for the simulated SR-2 (docs/calibration.md: a calibrated
    # pipeline measures it; 0.165 is what `tofcam calibrate --noise` fits on this camera).
    pipeline = tofcam.Pipeline(camera, {"accuracy": {"scale": 0.165}})
    camera.integration_time_register = pipeline.initial_integration_register
    for _ in range(args.frames):
        result = pipeline.process(camera.grab())
        camera.integration_time_register = result.next_integration_register
    s = result.stats
    print(f"register {s.integration_time_register} ({s.integration_time_us / 1000:.1f} ms), "
          f"mean intensity {s.mean_intensity:.0f}, valid {100 * s.valid_fraction:.1f} %, "
          f"RMSE of kept pixels {1000 * s.rmse_m:.0f} mm, bad pixels removed "
          f"{100 * s.bad_removed_fraction:.1f} %")

    frame = result.frame
    error = np.abs(frame.radial_distance_m - frame.truth.radial_distance_m)
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    axes[0].imshow(pipeline.render_raw(result))
    axes[0].set_title("raw (false colour, paper section III-A)")
    axes[1].imshow(pipeline.render_filtered(result))
    axes[1].set_title("after the accuracy filter (ΔL > 7 cm black)")
    im = axes[2].imshow(np.minimum(error, 0.3) * 1000, cmap="magma")
    axes[2].set_title("|error| against ground truth, mm")
    fig.colorbar(im, ax=axes[2], fraction=0.04)
    for ax in axes:
        ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
