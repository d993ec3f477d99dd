"""Frames and their channels: dtypes, zero-copy views, lifetimes, validation."""

import gc

import numpy as np
import pytest

import tofcam

L_SR2 = 299792458.0 / (2 * 20e6)


def make_frame(h=4, w=5):
    d = np.arange(h * w, dtype=np.uint16).reshape(h, w) * 100
    a = np.full((h, w), 1000, np.uint16)
    i = np.full((h, w), 4000, np.uint16)
    return tofcam.Frame(distance=d, amplitude=a, intensity=i)


def test_frame_channels_have_the_register_dtypes():
    f = make_frame()
    assert f.distance.dtype == np.uint16 and f.distance.shape == (4, 5)
    assert f.amplitude.dtype == np.uint16 and f.intensity.dtype == np.uint16
    assert f.source_flags is None  # the source reports no flags
    assert f.truth is None
    assert (f.width, f.height) == (5, 4)


def test_writing_through_a_view_changes_the_cpp_frame():
    f = make_frame()
    view = f.distance
    assert np.shares_memory(view, f.distance)  # two views, one C++ buffer
    view[1, 2] = 32768
    # C++ reads the changed register: metric conversion maps it to L / 2.
    m = tofcam.to_metric(f)
    assert m.radial_distance_m[1, 2] == pytest.approx(L_SR2 / 2, rel=1e-6)


def test_setter_copies_into_the_existing_buffer():
    f = make_frame()
    view = f.amplitude
    f.amplitude = np.full((4, 5), 7, np.uint16)
    assert view[0, 0] == 7  # the earlier view sees the new values: same buffer
    with pytest.raises(ValueError, match="shape"):
        f.amplitude = np.zeros((3, 5), np.uint16)


def test_a_view_outlives_its_frame_object():
    cam = tofcam.SimulatedCamera("wall?distance_m=1.5", seed=3, supersampling=1)
    d = cam.grab().distance  # the Frame object is dropped at once
    truth = cam.grab().truth.radial_distance_m
    del cam
    gc.collect()
    assert isinstance(d.base, tofcam.Frame)
    # Reading after every other reference is gone (ASan would flag a use after free).
    assert d.sum() > 0 and np.isfinite(truth).any()
    assert float(truth[62, 80]) == pytest.approx(1.5, abs=0.05)  # the wall at 1.5 m


def test_wrong_dtypes_shapes_and_layouts_are_rejected_clearly():
    good = np.zeros((4, 5), np.uint16)
    with pytest.raises(TypeError, match="distance must have dtype uint16, got float64"):
        tofcam.Frame(distance=np.zeros((4, 5)), amplitude=good)
    with pytest.raises(TypeError, match="numpy.ndarray"):
        tofcam.Frame(distance=[[1, 2]], amplitude=good)
    with pytest.raises(ValueError, match=r"\(height, width\)"):
        tofcam.Frame(distance=np.zeros(20, np.uint16), amplitude=good)
    with pytest.raises(ValueError, match="C-contiguous"):
        tofcam.Frame(distance=np.zeros((5, 4), np.uint16).T, amplitude=good)
    with pytest.raises(tofcam.InvalidArgumentError):
        tofcam.Frame(distance=good, amplitude=np.zeros((3, 5), np.uint16))


def test_frame_without_intensity_says_so():
    f = tofcam.Frame(distance=np.zeros((2, 2), np.uint16), amplitude=np.ones((2, 2), np.uint16))
    assert not f.info.has_intensity
    assert not tofcam.to_metric(f).has_intensity


def test_metric_frame_from_arrays_and_valid_mask():
    d = np.array([[1.0, 2.0]], np.float32)
    flags = np.array([[0, int(tofcam.Flag.HIGH_DELTA_L)]], np.uint16)
    m = tofcam.MetricFrame(radial_distance_m=d, amplitude=np.ones_like(d), flags=flags)
    assert m.intensity is None and m.delta_l_m is None
    assert m.valid().tolist() == [[True, False]]
    with pytest.raises(ValueError, match="shape of radial_distance_m"):
        tofcam.MetricFrame(radial_distance_m=d, amplitude=np.ones((2, 2), np.float32))


def test_flags_match_the_cpp_bits():
    assert int(tofcam.Flag.INVALID) == 1 and int(tofcam.Flag.LOW_CONFIDENCE) == 1 << 15
    assert tofcam.flags_to_string(int(tofcam.Flag.SATURATED) | int(tofcam.Flag.JUMP_EDGE)) == \
        "saturated|jump-edge"
    assert tofcam.flag_name(tofcam.Flag.HIGH_DELTA_L) == "high-delta-l"
    assert tofcam.REJECT_MASK & int(tofcam.Flag.SPARSE_CELL)
    assert not tofcam.REJECT_MASK & int(tofcam.Flag.MIXED)


def test_info_is_a_live_reference_and_reprs_read_well():
    f = make_frame()
    f.info.sequence = 42
    assert f.info.sequence == 42
    assert "sequence=42" in repr(f) and "Frame(" in repr(f)
    assert "CameraInfo(model='SR-2'" in repr(tofcam.CameraInfo())
    info = tofcam.CameraInfo()
    assert info.unambiguous_range_m == pytest.approx(L_SR2)
    assert info.integration_time_us(4) == pytest.approx(4 * 255.0)


def test_rays_are_unit_vectors_through_the_principal_point():
    k = tofcam.CameraIntrinsics.sr2()
    rays = k.rays()
    assert rays.shape == (124, 160, 3)
    np.testing.assert_allclose(np.linalg.norm(rays, axis=2), 1.0, atol=1e-6)
    # The principal point lies between pixels (79.5, 61.5): the four centre rays are symmetric.
    np.testing.assert_allclose(rays[61, 79, :2], -rays[62, 80, :2], atol=1e-6)


def test_a_new_channel_takes_the_frames_size_and_none_is_refused():
    d = np.ones((4, 5), np.float32)
    f = tofcam.MetricFrame(radial_distance_m=d, amplitude=d)
    assert f.intensity is None
    with pytest.raises(ValueError, match=r"\(2, 2\).*\(4, 5\)"):
        f.intensity = np.ones((2, 2), np.float32)
    assert f.intensity is None and not f.has_intensity
    f.intensity = np.full((4, 5), 7, np.float32)
    assert f.has_intensity and f.intensity[3, 4] == 7
    with pytest.raises(TypeError, match="cannot be removed"):
        f.intensity = None


def test_arrays_after_pickle_have_an_equal_dtype_and_byte_order_still_counts():
    import pickle
    d = pickle.loads(pickle.dumps(np.ones((4, 5), np.float32)))
    f = tofcam.MetricFrame(radial_distance_m=d, amplitude=d)
    assert f.width == 5
    with pytest.raises(TypeError, match="dtype"):
        tofcam.MetricFrame(radial_distance_m=d.astype(">f4"), amplitude=d)
