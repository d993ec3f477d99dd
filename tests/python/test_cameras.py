"""Cameras from Python: the simulator equals the command-line simulator bit for bit, scenes and
models, importers of real cameras, playback."""

import numpy as np
import pytest

import tofcam


def test_simulator_frames_equal_the_cli_recording(cli, tmp_path):
    path = tmp_path / "hand.h5"
    cli("simulate", "--scene", "hand", "--frames", 3, "--seed", 7, "--integration-time-us",
        4080, "--out", path)
    recorded = tofcam.RecordingReader(path)
    cam = tofcam.SimulatedCamera("hand", seed=7)
    cam.integration_time_register = 16  # 16 x 255 µs = 4080 µs
    for expected in recorded:
        got = cam.grab()
        for channel in ("distance", "amplitude", "intensity"):
            np.testing.assert_array_equal(getattr(got, channel), getattr(expected, channel))
        np.testing.assert_array_equal(got.truth.causes, expected.truth.causes)
        np.testing.assert_array_equal(got.truth.radial_distance_m,
                                      expected.truth.radial_distance_m)
        np.testing.assert_array_equal(got.truth.sigma_m, expected.truth.sigma_m)
        for channel in ("footprint_near_m", "footprint_far_m"):
            np.testing.assert_array_equal(getattr(got.truth, channel),
                                          getattr(expected.truth, channel))
        # The footprint holds the central ray's surface where that is hit, up to the distance
        # change between the centre and the sub-rays, which sample other points of the pixel's
        # area (sub-mm on the walls, 6 mm on the floor at a grazing angle; 1 % allowed).
        d = got.truth.radial_distance_m
        hit = np.isfinite(d)
        assert (got.truth.footprint_near_m[hit] <= 1.01 * d[hit]).all()
        assert (got.truth.footprint_far_m[hit] >= 0.99 * d[hit]).all()
        # The hand's edge: pixels whose footprint holds the hand (0.2 m) and the wall (3 m).
        assert ((got.truth.footprint_near_m < 0.5) & (got.truth.footprint_far_m > 2.5)).any()
        assert got.info.timestamp_ns == expected.info.timestamp_ns
        assert got.info.integration_time_register == 16


def test_same_seed_same_frames_other_seed_other_noise():
    a = tofcam.SimulatedCamera("wall", seed=5, supersampling=1).grab()
    b = tofcam.SimulatedCamera("wall", seed=5, supersampling=1).grab()
    c = tofcam.SimulatedCamera("wall", seed=6, supersampling=1).grab()
    np.testing.assert_array_equal(a.distance, b.distance)
    assert (a.distance != c.distance).mean() > 0.5


def test_options_keywords_and_objects():
    opts = tofcam.SimulatorOptions(seed=3, supersampling=1, scattering=False)
    assert (opts.seed, opts.supersampling, opts.scattering) == (3, 1, False)
    cam = tofcam.SimulatedCamera("wall", options=opts, threads=2)
    assert cam.options.threads == 2 and cam.options.seed == 3
    with pytest.raises(TypeError, match="no option 'bogus'"):
        tofcam.SimulatedCamera("wall", bogus=1)
    with pytest.raises(tofcam.InvalidArgumentError, match="supersampling"):
        tofcam.SimulatedCamera("wall", supersampling=99)
    ideal = tofcam.SimulatorOptions.ideal()
    assert not ideal.shot_noise and not ideal.scattering


def test_planar_shortcut_gives_the_exact_frames_up_to_rounding():
    # With the noise off the shortcut's closed-form subsample distances differ from Embree's in
    # the last bits only, so no register moves by more than one count (docs/simulator.md).
    frames = []
    for shortcut in (False, True):
        cam = tofcam.SimulatedCamera("pavilion", shot_noise=False, read_noise=False,
                                     planar_shortcut=shortcut)
        assert cam.options.planar_shortcut == shortcut
        frames.append(cam.grab())
    exact, fast = frames
    for name in ("distance", "amplitude", "intensity"):
        a = getattr(exact, name).astype(np.int64)
        b = getattr(fast, name).astype(np.int64)
        assert np.abs(a - b).max() <= 1, name
    assert np.array_equal(exact.truth.radial_distance_m, fast.truth.radial_distance_m)


def test_scenes_from_names_parameters_yaml_and_errors(tmp_path):
    assert "hand" in tofcam.builtin_scenes()
    wall = tofcam.Scene.builtin("wall", distance_m=3)
    assert wall.parameters["distance_m"] == 3.0
    cam = tofcam.SimulatedCamera(wall, supersampling=1, options=tofcam.SimulatorOptions.ideal())
    truth = cam.grab().truth.radial_distance_m
    assert truth[61, 79] == pytest.approx(3.0, abs=0.01)
    text = """
name: box
materials:
  white: {albedo: 0.8}
objects:
  - {type: plane, material: white, position_m: [0, 0, 2.5], size_m: [10, 10]}
"""
    scene = tofcam.Scene.from_yaml(text, source="box.yaml")
    cam = tofcam.SimulatedCamera(scene, supersampling=1, options=tofcam.SimulatorOptions.ideal())
    assert cam.grab().truth.radial_distance_m[61, 79] == pytest.approx(2.5, abs=0.01)
    with pytest.raises(tofcam.NotFoundError, match="nope"):
        tofcam.Scene.builtin("nope")
    with pytest.raises(tofcam.InvalidArgumentError, match="frobnicate"):
        tofcam.Scene.builtin("wall", frobnicate=1)
    with pytest.raises(tofcam.FormatError, match="bad.yaml"):
        tofcam.Scene.from_yaml("objects: [", source="bad.yaml")
    path = tmp_path / "box.yaml"
    path.write_text(text)
    assert tofcam.Scene.load(path).name == "box"
    assert tofcam.SimulatedCamera(str(path), supersampling=1).scene.name == "box"


def test_camera_models():
    sr4000 = tofcam.CameraModel.builtin("sr4000")
    assert (sr4000.intrinsics.width, sr4000.intrinsics.height) == (176, 144)
    small = tofcam.CameraModel.builtin("sr2").with_resolution(80, 62)
    cam = tofcam.SimulatedCamera("wall", model=small, supersampling=1)
    assert cam.grab().distance.shape == (62, 80)
    with pytest.raises(tofcam.NotFoundError):
        tofcam.CameraModel.builtin("sr9000")


def test_camera_settings_are_properties_with_checked_ranges():
    cam = tofcam.SimulatedCamera("wall", supersampling=1)
    cam.integration_time_register = 100
    assert cam.integration_time_register == 100
    assert cam.grab().info.integration_time_us == pytest.approx(100 * 255.0)
    with pytest.raises(tofcam.InvalidArgumentError):
        cam.integration_time_register = 1000
    with pytest.raises(tofcam.InvalidArgumentError):
        cam.modulation_frequency_hz = 12.3e6
    cam.pan_angle_rad = 0.5
    assert cam.pan_angle_rad == pytest.approx(0.5)


def test_importers_keep_the_real_cameras_channels(data_dir):
    adi = data_dir / "real" / "adi_adtf3175" / "frame_mode3.bin"
    seq = tofcam.import_sequence(f"adi-interleaved:{adi}")
    assert len(seq) == 1 and seq.camera.width == 512
    frame = seq.frames[0]
    # Independent decode of the file (5 bytes per pixel, depth uint16 LE in mm).
    raw = np.fromfile(adi, np.uint8).reshape(512, 512, 5)
    depth_mm = raw[..., 0].astype(np.uint16) | (raw[..., 1].astype(np.uint16) << 8)
    metric = tofcam.to_metric(frame)
    valid = depth_mm > 0
    # Register = 8 x mm (lossless, L = 8.192 m): the metric distance is the depth in metres.
    np.testing.assert_allclose(metric.radial_distance_m[valid], depth_mm[valid] / 1000.0,
                               rtol=0, atol=1e-6)
    assert (frame.source_flags[~valid] & int(tofcam.Flag.INVALID)).all()
    # The camera's confidence byte (0 = best) is kept, turned so that higher is better, and
    # travels into the metric frame.
    np.testing.assert_array_equal(frame.confidence, 255.0 - raw[..., 2])
    assert frame.info.confidence_source.startswith("ADI")
    np.testing.assert_array_equal(metric.confidence, frame.confidence)
    cam = tofcam.ImportedCamera(seq)
    assert len(cam) == 1 and cam.grab() is not None and cam.grab() is None
    assert "adi-interleaved" in tofcam.import_formats()
    with pytest.raises(tofcam.NotFoundError):
        tofcam.import_sequence("adi-interleaved:/nonexistent.bin")
    with pytest.raises(tofcam.InvalidArgumentError, match="unknown"):
        tofcam.import_sequence("foo:bar")


def test_finite_cameras_iterate_to_the_end(data_dir):
    ifm = data_dir / "real" / "ifm_o3d303" / "o3d3xx.h5"
    cam = tofcam.ImportedCamera(f"ifm-o3d3xx:{ifm}")
    frames = list(cam)
    assert len(frames) == 3
    assert [f.info.sequence for f in frames] == sorted(f.info.sequence for f in frames)


def test_a_cameras_info_model_and_options_are_copies():
    cam = tofcam.SimulatedCamera("wall", seed=1)
    info = cam.info
    info.intrinsics.width = 4000
    assert cam.info.intrinsics.width == 160
    tofcam.Pipeline(cam)  # still built for the camera's real size
    opts = cam.options
    opts.supersampling = 100
    assert cam.options.supersampling != 100
    model = cam.model
    model.intrinsics.width = 7
    assert cam.model.intrinsics.width == 160
    with pytest.raises(TypeError, match="'seed'.*-1"):
        tofcam.SimulatedCamera("wall", seed=-1)


def test_an_imported_sequence_checks_frames_set_after_construction():
    cam = tofcam.SimulatedCamera("wall", seed=1)
    seq = tofcam.ImportedSequence(cam.info, [cam.grab()])
    with pytest.raises(TypeError, match="frame 0 is None"):
        seq.frames = [None]
    other = tofcam.SimulatedCamera("wall", model="sr4000", seed=1)
    with pytest.raises(tofcam.MismatchError, match="frame 1"):
        seq.frames = [cam.grab(), other.grab()]
    with pytest.raises(tofcam.MismatchError):
        seq.camera = other.info
    assert len(seq) == 1
    seq.frames = [cam.grab(), cam.grab()]
    assert len(tofcam.ImportedCamera(seq)) == 2
