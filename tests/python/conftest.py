"""Shared fixtures of the Python tests: the command-line tool to compare against, test data."""

import os
import pathlib
import subprocess

import numpy as np
import pytest

import tofcam

DATA = pathlib.Path(os.environ.get("TOFCAM_TEST_DATA_DIR",
                                   pathlib.Path(__file__).parents[1] / "data"))


@pytest.fixture
def data_dir():
    return DATA


@pytest.fixture
def cli():
    """Runs the tofcam command-line tool (the C++ reference) and returns its stdout."""
    exe = os.environ.get("TOFCAM_CLI")
    if not exe:
        pytest.skip("TOFCAM_CLI is not set (the tests run from ctest)")

    def run(*args):
        done = subprocess.run([exe, *map(str, args)], capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        return done.stdout

    return run


# The binary PLY vertex layout tofcam writes (tofcam/io/cloud_io.h).
PLY_VERTEX = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("amplitude", "<f4"),
                       ("intensity", "<f4"), ("delta_l", "<f4"), ("flags", "<u2")])


def read_ply(path):
    data = pathlib.Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    count = int(next(l.split()[2] for l in header.splitlines() if l.startswith("element vertex")))
    assert "binary_little_endian" in header
    return np.frombuffer(data[end:], dtype=PLY_VERTEX, count=count)


def small_metric_frame(distance, amplitude, intensity=None, delta_l=None, flags=None):
    f32 = lambda a: None if a is None else np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    return tofcam.MetricFrame(radial_distance_m=f32(distance), amplitude=f32(amplitude),
                              intensity=f32(intensity), delta_l_m=f32(delta_l),
                              flags=None if flags is None else np.asarray(flags, np.uint16))
