"""Recordings, calibration files and the calibration procedure, writers."""

import numpy as np
import pytest

import tofcam
from conftest import read_ply


def record(path, frames=3, scene="wall"):
    cam = tofcam.SimulatedCamera(scene, seed=9, supersampling=1)
    grabbed = [cam.grab() for _ in range(frames)]
    with tofcam.RecordingWriter(path, cam.info, compression_level=1) as w:
        for f in grabbed:
            w.append(f)
        assert len(w) == frames
    return grabbed


def test_recording_round_trip_is_bit_exact(tmp_path):
    path = tmp_path / "rec.h5"
    grabbed = record(path)
    r = tofcam.RecordingReader(path)
    assert len(r) == 3 and r.metadata.has_ground_truth
    assert r.metadata.camera.model == "SR-2"
    for a, b in zip(grabbed, r):
        np.testing.assert_array_equal(a.distance, b.distance)
        np.testing.assert_array_equal(a.truth.sigma_m, b.truth.sigma_m)
        np.testing.assert_array_equal(a.truth.footprint_near_m, b.truth.footprint_near_m)
        np.testing.assert_array_equal(a.truth.footprint_far_m, b.truth.footprint_far_m)
    assert r.metadata.has_truth_footprint
    np.testing.assert_array_equal(r[-1].amplitude, grabbed[-1].amplitude)
    assert r.info(1).sequence == grabbed[1].info.sequence
    assert r.index_at_or_after(grabbed[1].info.timestamp_ns) == 1
    with pytest.raises(IndexError):
        r[3]


def test_playback_serves_the_frames_and_seeks(tmp_path):
    path = tmp_path / "rec.h5"
    grabbed = record(path, frames=4)
    cam = tofcam.PlaybackCamera(path)
    assert len(cam) == 4
    cam.seek(2)
    np.testing.assert_array_equal(cam.grab().distance, grabbed[2].distance)
    assert cam.position == 3
    assert cam.grab() is not None and cam.grab() is None
    # A recording cannot change what was recorded.
    with pytest.raises(tofcam.UnsupportedError):
        cam.seek(0)
        cam.integration_time_register = grabbed[0].info.integration_time_register + 1
    with pytest.raises(tofcam.InvalidArgumentError):
        tofcam.PlaybackCamera(path, speed=-1.0)


def test_bad_recordings_are_clear_errors(tmp_path):
    with pytest.raises(tofcam.NotFoundError) as missing:
        tofcam.RecordingReader(tmp_path / "missing.h5")
    assert isinstance(missing.value, FileNotFoundError)
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not an hdf5 file" * 100)
    with pytest.raises(tofcam.FormatError, match="junk.h5"):
        tofcam.RecordingReader(junk)
    path = tmp_path / "rec.h5"
    record(path)
    data = bytearray(path.read_bytes())
    cut = tmp_path / "cut.h5"
    cut.write_bytes(bytes(data[: len(data) // 3]))
    with pytest.raises(tofcam.FormatError):
        r = tofcam.RecordingReader(cut)
        for _ in r:
            pass


def test_calibration_on_a_simulated_wall_removes_the_fixed_pattern(tmp_path):
    cam = tofcam.SimulatedCamera("wall?distance_m=1.5", seed=4, supersampling=1)
    phases = []
    cal = tofcam.calibrate(cam, wall_distance_m=1.5, frames=20, warmup_window_frames=20,
                           progress=lambda phase, k, n, msg: phases.append(phase))
    assert phases, "progress was reported"
    assert cal.offset_m.shape == (124, 160) and cal.wall_distance_m == 1.5
    path = tmp_path / "cal.yaml"
    tofcam.save_calibration(path, cal)
    loaded = tofcam.load_calibration(path)
    np.testing.assert_array_equal(loaded.offset_m, cal.offset_m)  # 9 digits: bit-exact
    # Independent check: the simulator's own fixed-pattern map is what the offsets must remove.
    frame = tofcam.to_metric(cam.grab())
    truth = frame.truth.radial_distance_m
    before = np.nanmedian(np.abs(frame.radial_distance_m - truth))
    after_frame = tofcam.apply_calibration(frame, loaded)
    after = np.nanmedian(np.abs(after_frame.radial_distance_m - truth))
    assert after < 0.5 * before
    with pytest.raises(tofcam.FormatError):
        bad = tmp_path / "bad.yaml"
        bad.write_text("format: tofcam-calibration\nversion: 99\n")
        tofcam.load_calibration(bad)


def test_writers(tmp_path):
    cam = tofcam.SimulatedCamera("wall", seed=1, supersampling=1)
    pipe = tofcam.Pipeline(cam.info, {"accuracy": {"scale": 0.2}})
    res = pipe.process(cam.grab())
    tofcam.write_ply(tmp_path / "c.ply", res.cloud, only_valid=True)
    ply = read_ply(tmp_path / "c.ply")
    assert len(ply) == res.cloud.count_valid()
    tofcam.write_png(tmp_path / "f.png", pipe.render_filtered(res))
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(TypeError):
        tofcam.write_png(tmp_path / "g.png", np.zeros((4, 4, 3)))


def test_reader_info_counts_from_the_end_and_returns_copies(tmp_path):
    path = tmp_path / "rec.h5"
    grabbed = record(path)
    r = tofcam.RecordingReader(path)
    assert r.info(-1).sequence == grabbed[-1].info.sequence
    with pytest.raises(IndexError):
        r.info(-4)
    info = r.info(0)
    info.modulation_frequency_hz = 5.0
    assert r.info(0).modulation_frequency_hz != 5.0
    meta = r.metadata
    meta.camera.model = "changed"
    assert r.metadata.camera.model == "SR-2"


def test_calibrate_option_types_are_named():
    cam = tofcam.SimulatedCamera("wall", seed=1)
    with pytest.raises(TypeError, match="warmup_max_frames.*int"):
        tofcam.calibrate(cam, 2.0, warmup_max_frames="x")
