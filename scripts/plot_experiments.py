#!/usr/bin/python3
"""Plots the CSVs written by `tofcam experiment` (issue 5). The numbers are computed in C++; this
script only draws them. Usage: plot_experiments.py <csv dir> <png dir>. Missing CSVs are skipped
(one experiment run alone), so the script works on partial runs."""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

SRC, DST = sys.argv[1], sys.argv[2]
os.makedirs(DST, exist_ok=True)


def load(name):
    path = os.path.join(SRC, name + ".csv")
    if not os.path.exists(path):
        return None
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def num(v):
    """A CSV cell as a number: plain numbers, "12.5 %" (as a fraction), "-" or "nan" (NaN)."""
    v = v.strip()
    try:
        if v.endswith("%"):
            return float(v[:-1]) / 100.0
        return float(v)
    except ValueError:
        return float("nan")


def mark(marks, prefix):
    """The row of fig3_marks whose name starts with `prefix` (rows are found by name: their order
    is the C++ side's choice)."""
    for m in marks or []:
        if m["mark"].startswith(prefix):
            return m
    return None


def col(rows, key):
    return [num(r[key]) for r in rows]


def save(fig, name):
    # Small PNGs for the repository: modest size and dpi, palette-friendly plots.
    fig.tight_layout()
    fig.savefig(os.path.join(DST, name + ".png"), dpi=72)
    plt.close(fig)


def fig3():
    rows = load("fig3_sweep")
    marks = load("fig3_marks")
    if not rows:
        return
    reg = col(rows, "register")
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    axes[0].plot(reg, col(rows, "mean_distance_m"))
    axes[0].set_ylabel("mean distance [m]")
    axes[1].plot(reg, col(rows, "mean_amplitude"), label="mean amplitude")
    axes[1].plot(reg, col(rows, "amplitude_linear"), "--", label="linearisation")
    axes[1].set_ylim(0, max(col(rows, "mean_amplitude")) * 1.3)
    axes[2].plot(reg, col(rows, "mean_intensity"), label="mean intensity")
    axes[2].plot(reg, col(rows, "intensity_linear"), "--", label="linearisation")
    axes[2].set_ylim(0, 70000)
    amax = mark(marks, "amplitude maximum")
    onset = mark(marks, "saturation onset")
    target = mark(marks, "I_A")
    for ax in axes:
        if amax:
            ax.axvline(num(amax["register"]), color="r", lw=1.2,
                       label="amplitude max (plateau start)")
        if onset:
            ax.axvline(num(onset["register"]), color="k", ls=":", lw=0.8, label="saturation onset")
    if target:
        axes[2].axhline(num(target["mean_intensity"]), color="g", lw=0.8, label="I_A")
        axes[2].axvline(num(target["register"]), color="g", ls="--", lw=0.8, label="c_0")
    axes[2].axhspan(15000, 18000, color="g", alpha=0.15, label="paper's I_A band")
    for ax in axes:
        ax.set_xlabel("integration-time register (x 255 us)")
    axes[1].legend(fontsize=7)
    axes[2].legend(fontsize=7)
    save(fig, "fig3")


def fig5():
    rows = load("fig5_amplitude")
    if not rows:
        return
    fig, ax = plt.subplots(figsize=(6, 3.6))
    t = col(rows, "time_ms")
    ax.plot(t, col(rows, "amplitude_near_objects"), label="near objects (oversaturating)")
    ax.plot(t, col(rows, "amplitude_no_near_objects"), label="no near objects")
    ax.set_xlabel("integration time [ms]")
    ax.set_ylabel("mean amplitude")
    ax.legend(fontsize=8)
    save(fig, "fig5")


def fig67():
    rows = load("fig67_threshold")
    if not rows:
        return
    for name, scene in (("fig6", "oversaturated"), ("fig7", "non-saturated")):
        sel = [r for r in rows if r["scene"] == scene]
        regs = sorted({int(r["register"]) for r in sel})
        shown = regs[:: max(1, len(regs) // 7)]
        fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
        for reg in shown:
            rr = [r for r in sel if int(r["register"]) == reg]
            t = col(rr, "threshold_m")
            lab = "%.1f ms" % (reg * 0.255)
            axes[0].plot(t, col(rr, "mean_delta_l_m"), label=lab)
            axes[1].plot(t, col(rr, "passing_pixels"), label=lab)
        axes[0].set_xlabel("threshold [m]")
        axes[0].set_ylabel("mean inaccuracy of passing px [m]")
        axes[1].set_xlabel("threshold [m]")
        axes[1].set_ylabel("passing pixels")
        axes[0].legend(fontsize=6)
        at = [r for r in sel if abs(num(r["threshold_m"]) - 0.07) < 1e-6]
        ax2 = axes[2]
        ax2.plot(col(at, "register"), col(at, "mean_delta_l_m"), "b", label="mean dL (t=0.07 m)")
        ax2.set_xlabel("integration-time register")
        ax2.set_ylabel("mean inaccuracy [m]", color="b")
        ax3 = ax2.twinx()
        ax3.plot(col(at, "register"), col(at, "passing_pixels"), "r", label="passing")
        ax3.set_ylabel("passing pixels", color="r")
        fig.suptitle(f"{name}: {scene}")
        save(fig, name)


def fig2():
    rows = load("fig2_scattering_bias")
    if not rows:
        return
    img = [[num(v) * 1e3 for v in r.values()] for r in rows]
    fig, ax = plt.subplots(figsize=(5.5, 4))
    im = ax.imshow(img, cmap="RdBu", vmin=-200, vmax=200, interpolation="nearest")
    ax.set_title("scattering bias of the background, 15 ms [mm]\n"
                 "(noise-free, PSF on - off; blank: hand, saturated, edges)", fontsize=8)
    fig.colorbar(im, ax=ax, fraction=0.04)
    save(fig, "fig2_bias")


def fig89():
    rows = load("fig89_distance")
    if not rows:
        return
    d = col(rows, "wall m")
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    px = col(rows, "wall px")
    axes[0].plot(d, [a / b for a, b in zip(col(rows, "wall > 5 cm"), px)], "o-",
                 label="wall biased > 5 cm")
    axes[0].plot(d, [a / b for a, b in zip(col(rows, "wall > 20 cm"), px)], "s-",
                 label="wall biased > 20 cm")
    axes[0].plot(d, col(rows, "wall amplitude with / without scattering"), "k^--",
                 label="wall amplitude with / without scattering (median)")
    axes[0].set_xlabel("wall distance [m]")
    axes[0].set_ylabel("fraction / ratio")
    axes[0].legend(fontsize=7)
    axes[1].plot(d, col(rows, "removed (wall > 5 cm)"), "o-", label="removed: wall > 5 cm")
    axes[1].plot(d, col(rows, "removed (wall > 20 cm)"), "s-", label="removed: wall > 20 cm")
    axes[1].plot(d, col(rows, "removed (background > 20 cm)"), "d-",
                 label="removed: background (wall + floor) > 20 cm")
    axes[1].plot(d, col(rows, "wall unbiased kept"), "k^--", label="kept: unbiased wall")
    axes[1].set_xlabel("wall distance [m]")
    axes[1].set_ylabel("fraction (accuracy filter, 0.07 m)")
    axes[1].set_ylim(-0.02, 1.02)
    axes[1].legend(fontsize=7)
    for ax in axes:
        # Where the hand's and the wall's phasors oppose (L/2 + 0.2 m).
        ax.axvline(7.4948 / 2 + 0.2, color="grey", lw=0.6, ls=":")
    save(fig, "fig89_distance")


def calibration():
    rows = load("calibration_sweep")
    if rows:
        fig, ax = plt.subplots(figsize=(7, 3.6))
        for held, marker in (("0", "o"), ("1", "x")):
            rr = [r for r in rows if r["held_out"] == held]
            d = col(rr, "wall_distance_m")
            suffix = " (held out)" if held == "1" else ""
            ax.plot(d, [v * 1e3 for v in col(rr, "rms_raw_m")], "k" + marker, ms=4,
                    label="raw" + suffix)
            ax.plot(d, [v * 1e3 for v in col(rr, "rms_offsets_m")], "b" + marker, ms=4,
                    label="per-pixel (eq. 1)" + suffix)
            ax.plot(d, [v * 1e3 for v in col(rr, "rms_full_m")], "g" + marker, ms=4,
                    label="+ distance LUT" + suffix)
        ax.plot(col(rows, "wall_distance_m"), [v * 1e3 for v in col(rows, "noise_floor_m")],
                "r:", label="noise floor")
        ax.set_xlabel("wall distance [m]")
        ax.set_ylabel("RMS error [mm]")
        ax.legend(fontsize=6, ncol=2)
        save(fig, "calibration_rms")
    before, after = load("calibration_offset_map"), load("calibration_error_after")
    if before and after:
        fig, axes = plt.subplots(1, 2, figsize=(8, 3))
        for ax, m, title in ((axes[0], before, "error before (offset map)"),
                             (axes[1], after, "error after full calibration")):
            img = [[num(v) * 1e3 for v in r.values()] for r in m]
            im = ax.imshow(img, cmap="RdBu", vmin=-100, vmax=100,
                           interpolation="nearest")
            ax.set_title(title + " [mm]", fontsize=9)
            fig.colorbar(im, ax=ax, fraction=0.04)
        save(fig, "calibration_maps")


def controllers():
    rows = load("controllers_frames")
    if not rows:
        return
    names = []
    for r in rows:
        if r["controller"] not in names:
            names.append(r["controller"])
    keys = [("register", "register"), ("mean_intensity", "mean intensity"),
            ("saturated_fraction", "saturated"), ("valid_fraction", "valid"),
            ("rmse_m", "RMSE valid [m]")]
    fig, axes = plt.subplots(len(keys), 1, figsize=(8, 10), sharex=True)
    for n in names:
        rr = [r for r in rows if r["controller"] == n]
        t = col(rr, "time_s")
        for ax, (k, label) in zip(axes, keys):
            ax.plot(t, col(rr, k), label=n, lw=0.9)
            ax.set_ylabel(label, fontsize=8)
    for ax in axes:
        for s in (3.0, 4.5, 5.0, 7.0, 8.0):
            ax.axvline(s, color="grey", lw=0.5, ls=":")
    axes[-1].set_yscale("log")
    axes[0].legend(fontsize=6, ncol=3)
    axes[-1].set_xlabel("time [s]")
    save(fig, "controllers")


def filters():
    rows = load("filters_pr")
    if not rows:
        return

    def group(r):
        # One curve per filter; the cloud filters sweep two parameters, one curve per k / r.
        if r["filter"] in ("sor", "radius"):
            return r["filter"] + " " + r["parameter"].split(",")[0]
        return r["filter"]

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    names = []
    for r in rows:
        if group(r) not in names:
            names.append(group(r))
    for ax, suffix, title in ((axes[0], "5cm", "bad = |error| > 5 cm"),
                              (axes[1], "3sigma", "bad = |error| > 3 true sigma")):
        ax.set_prop_cycle(color=plt.cm.tab20.colors)  # more curves than the default 10 colours
        for n in names:
            rr = [r for r in rows if group(r) == n]
            ax.plot(col(rr, "recall_" + suffix), col(rr, "precision_" + suffix), "o-", ms=3,
                    label=n)
        ax.set_xlabel("recall")
        ax.set_ylabel("precision")
        ax.set_title(title, fontsize=9)
        ax.set_xlim(0, 1.02)
        ax.set_ylim(0, 1.02)
    axes[0].legend(fontsize=6, ncol=2)
    save(fig, "filters_pr")


def real_data():
    rows = load("real_data_deciles")
    if not rows:
        return
    fig, ax = plt.subplots(figsize=(5, 3.6))
    ax.plot(col(rows, "mean_delta_l_m"), col(rows, "rms_sigma_m"), "o-", label="measured sigma")
    ax.plot(col(rows, "mean_delta_l_m"), col(rows, "predicted_sigma_m"), "--",
            label="fitted scale x dL")
    ax.set_xlabel("predicted dL (eq. 2, amplitude-only) [m]")
    ax.set_ylabel("temporal sigma [m]")
    ax.legend(fontsize=8)
    save(fig, "real_data")


for plot in (fig2, fig3, fig5, fig67, fig89, calibration, controllers, filters, real_data):
    plot()
