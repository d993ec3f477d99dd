"""`tofcam noise-check` end to end on a folder of MESA SR-4000 exports (issue 14).

The frames follow the real sample-viewer layout (one frame per file, five sections of H rows of W
tab-separated numbers, the time stamp row padded with nan). The scene is a tilted plane whose
pixels have a known temporal σ that is *not* eq. 2's: it falls with amplitude up to A = 800 and
rises above it (as measured on a real SR-4000), and a per-pixel factor that only the camera's
confidence map sees. The expectations come from that law, not from tofcam: eq. 2 (σ ∝ 1/A) must
mis-predict the deciles, the confidence map must rank σ, and the fitted model must rank at least
as well as both and predict every decile within 25 %.
"""

import os
import pathlib
import re
import subprocess

import numpy as np
import pytest

W, H = 96, 72
FX, CX, CY = 130.0, 47.5, 35.5


def sigma_law(amplitude, factor):
    # Shot-noise fall below A = 800, a rise above it (noisier bright pixels), times the factor.
    return 0.004 * (800.0 / amplitude) ** 0.8 * np.exp(amplitude / 1500.0) / np.exp(800 / 1500.0) \
        * factor


def write_frame(path, z, x, y, amplitude, confidence, stamp_ms):
    with open(path, "w") as f:
        for header, channel in (("% Calibrated Distance", z), ("% Calibrated xVector", x),
                                ("% Calibrated yVector", y), ("% Amplitude", amplitude),
                                ("% Confidence map", confidence)):
            f.write(header + "\n")
            for row in channel:
                f.write("\t".join(f"{v:.6f}" for v in row) + "\n")
        f.write("% additional data / time stamp [ms]\n")
        f.write("\t".join([f"{stamp_ms:.1f}"] + ["nan"] * (W - 1)) + "\n")


@pytest.fixture
def mesa_folder(tmp_path):
    rng = np.random.default_rng(5)
    cols, rows = np.meshgrid(np.arange(W), np.arange(H))
    a, b = (cols - CX) / FX, (rows - CY) / FX
    z0 = 1.5 / (1.0 - 0.3 * a)  # the plane z = 1.5 + 0.3 x
    radial0 = z0 * np.sqrt(1 + a * a + b * b)
    amplitude = 100.0 * 30.0 ** rng.uniform(0, 1, (H, W))  # 100..3000, log-uniform
    factor = 1.0 + 2.0 * rng.uniform(0, 1, (H, W))         # what only the confidence sees
    sigma = sigma_law(amplitude, factor)
    confidence = 20000.0 / factor * rng.uniform(0.9, 1.1, (H, W))
    for k in range(12):
        radial = radial0 + sigma * rng.standard_normal((H, W))
        z = radial / np.sqrt(1 + a * a + b * b)
        write_frame(tmp_path / f"frm_{k + 1:04d}.dat", z, a * z, b * z,
                    np.round(amplitude), np.round(confidence), 1000.0 + 50.0 * k)
    return tmp_path


def run(*args):
    exe = os.environ.get("TOFCAM_CLI")
    if not exe:
        pytest.skip("TOFCAM_CLI is not set (the tests run from ctest)")
    return subprocess.run([exe, *map(str, args)], capture_output=True, text=True, timeout=120)


def predictor(out, label):
    m = re.search(rf"^\s+{re.escape(label)}\S*(?: \(scale [^)]*\))?\s+([-0-9.]+)\s+(\d+) %", out,
                  re.M)
    assert m, f"no line for {label!r} in:\n{out}"
    return float(m.group(1)), float(m.group(2)) / 100.0


def test_noise_check_on_a_mesa_folder(mesa_folder, tmp_path):
    png = tmp_path / "chart.png"
    done = run("noise-check", "--camera", f"import:mesa-dat:{mesa_folder}", "--png", png)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "12 static frames" in out
    rho_eq2, decile_eq2 = predictor(out, "eq. 2")
    rho_model, decile_model = predictor(out, "fitted model")
    vendor = re.search(r"^\s+vendor confidence\s+([-0-9.]+)\s+ranks only", out, re.M)
    assert vendor, out
    rho_vendor = float(vendor.group(1))
    # The law's non-monotone amplitude dependence: eq. 2's single slope misses some decile.
    assert decile_eq2 > 0.25
    # The confidence sees the factor: it ranks σ (the factor spans 3x, amplitude ~2x over most).
    assert rho_vendor > 0.3
    # The targets: at least as good a rank as either (within the 2-standard-error tie
    # band the tool itself uses; ~3000 held-out pixels: se < 0.01) and every decile within 25 %.
    assert rho_model >= max(rho_eq2, rho_vendor) - 0.02
    assert decile_model <= 0.25
    # The fitted law is the true one: ln σ = c - 0.8 ln A + A / 1500 - ln(confidence) (the
    # confidence is 20000 / factor; the model's channel is ln(1 + C), the same here to 1e-4).
    m = re.search(r"ln sigma = (\S+) ([-+]\S+) ln A ([-+]\S+) ln I ([-+]\S+) ln r ([-+]\S+) "
                  r"A/(\S+) ([-+]\S+) ln\(1\+C\)", out)
    assert m, out
    c_a, c_sat, a_ref, c_c = (float(m.group(k)) for k in (2, 5, 6, 7))
    assert c_a == pytest.approx(-0.8, abs=0.1)
    assert c_sat / a_ref == pytest.approx(1 / 1500.0, rel=0.15)
    assert c_c == pytest.approx(-1.0, abs=0.15)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_noise_check_rejects_what_it_cannot_judge(mesa_folder, tmp_path):
    one = tmp_path / "one"
    one.mkdir()
    (one / "frm_0001.dat").write_bytes((mesa_folder / "frm_0001.dat").read_bytes())
    done = run("noise-check", "--camera", f"import:mesa-dat:{one}")
    assert done.returncode != 0
    assert "at least 3 static frames" in done.stderr
    done = run("noise-check", "--camera", f"import:mesa-dat:{mesa_folder}", "--frames", "2")
    assert done.returncode != 0 and "--frames 2" in done.stderr
    done = run("noise-check", "--camera", f"import:mesa-dat:{tmp_path / 'missing'}")
    assert done.returncode != 0 and "missing" in done.stderr
    # A damaged export names its file and line.
    bad = tmp_path / "bad"
    bad.mkdir()
    for k in (1, 2, 3):
        text = (mesa_folder / f"frm_{k:04d}.dat").read_text()
        if k == 2:
            text = text.replace("% Amplitude\n", "% Amplitude\n1 2 x\n", 1)
        (bad / f"frm_{k:04d}.dat").write_text(text)
    done = run("noise-check", "--camera", f"import:mesa-dat:{bad}")
    assert done.returncode != 0
    assert re.search(r"frm_0002\.dat line \d+", done.stderr), done.stderr
    assert pathlib.Path(bad).exists()
