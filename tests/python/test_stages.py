"""Stages as functions, checked against hand-computed values (the paper's formulas)."""

import math

import numpy as np
import pytest

import tofcam
from conftest import small_metric_frame

C = 299792458.0
L = C / (2 * 20e6)  # eq. 3 at 20 MHz


def test_delta_l_is_eq_2():
    a = np.array([[1000.0, 250.0]])
    i = np.array([[4000.0, 9000.0]])
    m = small_metric_frame(np.ones((1, 2)), a, i)
    dl = tofcam.delta_l(m)
    expected = L / math.sqrt(8) * np.sqrt(i) / (2 * a)  # eq. 2, hand-evaluated
    np.testing.assert_allclose(dl, expected, rtol=1e-6)
    np.testing.assert_allclose(tofcam.delta_l(m, scale=0.5), 0.5 * expected, rtol=1e-6)
    # Amplitude-only form without intensity: I = intensity_per_amplitude x A.
    m2 = small_metric_frame(np.ones((1, 2)), a)
    np.testing.assert_allclose(tofcam.delta_l(m2, intensity_per_amplitude=4.0),
                               L / math.sqrt(8) * np.sqrt(4.0 * a) / (2 * a), rtol=1e-6)


def test_pixel_filters_flag_what_their_rule_says():
    d = np.array([[0.01, 1.0, 9.0]])
    a = np.array([[500.0, 50.0, 500.0]])
    m = small_metric_frame(d, a, delta_l=[[0.01, 0.2, 0.05]])
    rng = tofcam.filters.range(m, min_distance_m=0.05, max_distance_m=7.5)
    assert rng.tolist() == [[int(tofcam.Flag.OUT_OF_RANGE), 0, int(tofcam.Flag.OUT_OF_RANGE)]]
    amp = tofcam.filters.amplitude(m, min_amplitude=100.0)
    assert amp.tolist() == [[0, int(tofcam.Flag.LOW_AMPLITUDE), 0]]
    acc = tofcam.filters.accuracy(m, max_delta_l_m=0.07)
    assert acc.tolist() == [[0, int(tofcam.Flag.HIGH_DELTA_L), 0]]
    # The same from bare arrays.
    acc2 = tofcam.filters.accuracy(radial_distance_m=d.astype(np.float32),
                                   delta_l_m=np.array([[0.01, 0.2, 0.05]], np.float32),
                                   max_delta_l_m=0.07)
    np.testing.assert_array_equal(acc, acc2)
    with pytest.raises(ValueError, match="delta_l_m"):
        tofcam.filters.accuracy(small_metric_frame(d, a))
    with pytest.raises(TypeError, match="float32"):
        tofcam.filters.range(radial_distance_m=d)  # float64
    with pytest.raises(TypeError, match="enabled"):
        tofcam.filters.range(m, enabled=True)


def test_jump_edge_flags_the_pixels_at_a_depth_step():
    # A wall at 2 m with its right half at 4 m. For the far pixel p next to the step, the vector
    # to its near neighbour n points back towards the camera: the angle between p and n - p is
    # close to 180 degrees (> 160): flagged. For the near pixel the angle is close to 0: kept.
    k = tofcam.CameraIntrinsics.sr2()
    d = np.full((124, 160), 2.0, np.float32)
    d[:, 80:] = 4.0
    m = small_metric_frame(d, np.full_like(d, 1000.0))
    flags = tofcam.filters.jump_edge(m, intrinsics=k, max_angle_deg=160.0)
    edge = (flags & int(tofcam.Flag.JUMP_EDGE)) != 0
    assert edge[:, 80].all()  # the far side of the step
    assert not edge[:, :80].any() and not edge[:, 81:].any()  # the near side and flat parts
    with pytest.raises(ValueError, match="intrinsics"):
        tofcam.filters.jump_edge(m)
    small = tofcam.CameraIntrinsics()
    small.width = 10
    with pytest.raises(tofcam.MismatchError):
        tofcam.filters.jump_edge(m, intrinsics=small)


def test_apply_filters_is_the_union_of_the_enabled_filters():
    k = tofcam.CameraIntrinsics.sr2()
    rng = np.random.default_rng(1)
    d = rng.uniform(0.5, 5.0, (124, 160)).astype(np.float32)
    a = rng.uniform(10, 2000, (124, 160)).astype(np.float32)
    m = small_metric_frame(d, a, a * 3)
    m.delta_l_m = tofcam.delta_l(m)
    union = tofcam.apply_filters(m, k, amplitude={"enabled": True, "min_amplitude": 100.0},
                                 jump_edge={"enabled": True}, saturation={"enabled": False},
                                 accuracy={"enabled": True, "max_delta_l_m": 0.05})
    parts = (tofcam.filters.amplitude(m, min_amplitude=100.0)
             | tofcam.filters.accuracy(m, max_delta_l_m=0.05))
    # Neighbourhood filters skip pixels the per-pixel filters rejected (docs/filters.md), so
    # the union is at least the per-pixel part and the jump-edge bits come on top.
    assert ((union & parts) == parts).all()
    assert ((union & ~np.uint16(int(tofcam.Flag.JUMP_EDGE))) == parts).all()


def test_false_color_follows_the_paper_hsv_law():
    d = np.array([[0.0, 7.49]], np.float32)
    m = small_metric_frame(d, np.full_like(d, 1000.0))
    img = tofcam.false_color(m, near_m=0.0, far_m=7.5)
    assert img.shape == (1, 2, 3) and img.dtype == np.uint8
    assert img[0, 0].tolist() == [255, 255, 0]  # hue 60°: yellow near
    assert img[0, 1, 2] >= 250 and img[0, 1, 0] <= 5  # towards hue 240°: blue far
    with_legend = tofcam.false_color(small_metric_frame(np.ones((40, 40)), np.ones((40, 40))),
                                     legend=True)
    assert with_legend.shape[0] > 40


def test_point_cloud_nan_for_rejected_points():
    k = tofcam.CameraIntrinsics.sr2()
    d = np.full((124, 160), 2.0, np.float32)
    flags = np.zeros((124, 160), np.uint16)
    flags[0, 0] = int(tofcam.Flag.HIGH_DELTA_L)
    m = small_metric_frame(d, np.ones_like(d), flags=flags)
    cloud = tofcam.point_cloud(m, k)
    assert math.isnan(cloud.x[0, 0]) and not math.isnan(cloud.x[0, 1])
    np.testing.assert_allclose(np.linalg.norm(cloud.xyz()[1:], axis=2), 2.0, rtol=1e-6)
    kept = tofcam.point_cloud(m, k, nan_flags=[])
    assert not math.isnan(kept.x[0, 0])


def test_controllers_follow_their_printed_laws():
    # Ī = 20000 everywhere; I_A = 16000, V_p = 0.001, c_0 = 40: c = -0.001 * 4000 + 40 = 36.
    m = small_metric_frame(np.ones((4, 4)), np.full((4, 4), 1000.0), np.full((4, 4), 20000.0))
    p = tofcam.Controller("may-proportional", target_intensity=16000.0,
                          gain_register_per_intensity=0.001, bias_register=40)
    assert p.update(m) == 36 and p.update(m) == 36  # position form: no memory
    inc = tofcam.Controller("may-incremental", target_intensity=16000.0,
                            gain_register_per_intensity=0.001, bias_register=40)
    assert [inc.update(m) for _ in range(3)] == [36, 32, 28]  # c_t - V_p D_t, step by step
    inc.reset(100)
    assert inc.update(m) == 96
    assert tofcam.mean_control_intensity(m) == pytest.approx(20000.0)
    with pytest.raises(tofcam.FormatError, match="kind"):
        tofcam.Controller("pid")


def test_noise_fit_recovers_a_known_scale():
    # Static frames with Gaussian noise of σ = 0.3 x ΔL(scale 1) per pixel.
    rng = np.random.default_rng(4)
    a = rng.uniform(300, 3000, (40, 50))
    i = 3 * a
    sigma = 0.3 * L / math.sqrt(8) * np.sqrt(i) / (2 * a)
    frames = [small_metric_frame(2.0 + sigma * rng.standard_normal(a.shape), a, i)
              for _ in range(16)]
    for f in frames:
        f.delta_l_m = tofcam.delta_l(f)
    fit = tofcam.fit_delta_l_scale(frames)
    assert fit["scale"] == pytest.approx(0.3, rel=0.05)  # 2000 px x 16 frames: ~1 % spread


def test_none_among_frames_and_a_frame_with_arrays_are_type_errors():
    with pytest.raises(TypeError, match="MetricFrame"):
        tofcam.fit_delta_l_scale([None])
    f = small_metric_frame(np.full((4, 5), 2.0), np.full((4, 5), 100.0), np.full((4, 5), 300.0))
    with pytest.raises(TypeError, match="not both.*radial_distance_m"):
        tofcam.filters.range(f, radial_distance_m=np.zeros((2, 2), np.float32))
