"""The examples in examples/python run and say what they should."""

import os
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]


def run(script, *args):
    env = dict(os.environ, MPLBACKEND="Agg")
    done = subprocess.run([sys.executable, str(ROOT / "examples/python" / script), *args],
                          capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_simulate_hand_writes_the_plot(tmp_path):
    out = tmp_path / "hand.png"
    text = run("simulate_hand.py", "--frames", "5", "--out", str(out))
    assert "valid" in text and out.read_bytes()[:4] == b"\x89PNG"


def test_real_camera_noise_reports_the_ifm_recording(data_dir):
    spec = f"ifm-o3d3xx:{data_dir / 'real/ifm_o3d303/o3d3xx.h5'}"
    text = run("real_camera_noise.py", "--spec", spec)
    assert "ifm O3D303: 3 frames of 176 x 132" in text
    # The recording's noise falls with amplitude (shared/data/real/README.md measured this too).
    sigmas = [float(line.split()[-2]) for line in text.splitlines() if line.endswith(" mm")]
    assert sigmas == sorted(sigmas, reverse=True) and len(sigmas) >= 3
