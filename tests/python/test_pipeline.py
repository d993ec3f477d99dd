"""The pipeline from Python equals `tofcam run` on the same inputs; options round-trip the YAML
configuration; results are views that follow `out=` reuse."""

import csv

import numpy as np
import pytest

import tofcam
from conftest import read_ply

# Every value that `tofcam run` would otherwise measure per camera is pinned, so both sides run
# the same configuration.
CONFIG = {
    "accuracy": {"scale": 0.2},
    "filters": {"jump_edge": {"enabled": True}, "amplitude": {"enabled": True,
                                                            "min_amplitude": 50.0}},
    "controller": {"kind": "may-incremental", "target_intensity": 16000.0,
                   "gain_register_per_intensity": 0.002, "bias_register": 30},
}


def test_results_equal_the_cli_on_the_same_frames(cli, tmp_path):
    options = tofcam.PipelineOptions.from_dict(CONFIG)
    config = tmp_path / "config.yaml"
    config.write_text(options.to_yaml())
    out = tmp_path / "run"
    cli("run", "--camera", "sim:hand", "--seed", 11, "--frames", 4, "--config", config,
        "--out", out, "--ply-every", 1)
    rows = list(csv.DictReader(open(out / "frames.csv")))

    cam = tofcam.SimulatedCamera("hand", seed=11)
    pipe = tofcam.Pipeline(cam, options)
    cam.integration_time_register = pipe.initial_integration_register
    for k in range(4):
        res = pipe.process(cam.grab())
        cam.integration_time_register = res.next_integration_register
        # The CLI's cloud (valid points, binary PLY) equals ours bit for bit.
        ply = read_ply(out / f"frame_{k:06d}.ply")
        cloud = res.cloud
        valid = cloud.flags == 0
        valid &= np.isfinite(cloud.x)
        np.testing.assert_array_equal(ply["x"], cloud.x[valid])
        np.testing.assert_array_equal(ply["z"], cloud.z[valid])
        np.testing.assert_array_equal(ply["delta_l"], cloud.delta_l_m[valid])
        np.testing.assert_array_equal(ply["flags"], cloud.flags[valid])
        row = rows[k]
        assert int(row["integration_register"]) == res.stats.integration_time_register
        assert int(row["next_register"]) == res.next_integration_register
        assert int(row["kept_pixels"]) == res.stats.kept_pixels
        assert float(row["mean_intensity"]) == pytest.approx(res.stats.mean_intensity, rel=1e-5)


def test_options_round_trip_dict_and_yaml():
    o = tofcam.PipelineOptions.from_dict(CONFIG)
    d = o.to_dict()
    assert d["filters"]["jump_edge"]["enabled"] is True
    assert d["accuracy"]["scale"] == 0.2
    assert d["controller"]["bias_register"] == 30 and isinstance(d["controller"]["bias_register"],
                                                                  int)
    assert tofcam.PipelineOptions.from_dict(d) == o
    assert tofcam.PipelineOptions.from_yaml(o.to_yaml()) == o
    assert "max_delta_l_m" in o.to_yaml()
    # Defaults leave the camera-specific keys out (measured per camera), like --print-config.
    assert "scale" not in tofcam.PipelineOptions().to_dict()["accuracy"]
    merged = tofcam.merge_options(o, {"filters": {"jump_edge": {"max_angle_deg": 150.0}}})
    assert merged.to_dict()["filters"]["jump_edge"] == {"enabled": True, "max_angle_deg": 150.0}
    assert merged.to_dict()["accuracy"]["scale"] == 0.2


def test_option_errors_name_the_key():
    with pytest.raises(tofcam.FormatError, match="max_delta_l"):
        tofcam.PipelineOptions(filters={"accuracy": {"max_delta_l": 0.1}})
    with pytest.raises(tofcam.FormatError, match="kind"):
        tofcam.PipelineOptions(controller={"kind": "pid"})
    with pytest.raises(tofcam.InvalidArgumentError, match="max_delta_l_m"):
        tofcam.PipelineOptions(filters={"accuracy": {"max_delta_l_m": -1.0}})
    with pytest.raises(TypeError, match="unsupported type"):
        tofcam.PipelineOptions(filters={"accuracy": {"max_delta_l_m": object()}})
    with pytest.raises(TypeError):
        tofcam.Pipeline(tofcam.CameraInfo(), options=3)


def test_process_with_out_reuses_the_buffers():
    cam = tofcam.SimulatedCamera("pavilion", seed=2)
    pipe = tofcam.Pipeline(cam.info, {"accuracy": {"scale": 0.2}})
    first = pipe.process(cam.grab())
    before = first.frame.radial_distance_m
    kept = before.copy()
    second = pipe.process(cam.grab(), out=first)
    assert second is first
    assert np.shares_memory(before, second.frame.radial_distance_m)
    assert not np.array_equal(kept, before)  # the old view now shows the new frame's noise
    third = pipe.process(cam.grab())  # a fresh result: independent buffers
    assert not np.shares_memory(third.frame.radial_distance_m, before)


def test_cloud_is_distance_times_ray():
    cam = tofcam.SimulatedCamera("wall", seed=1)
    pipe = tofcam.Pipeline(cam.info, {"accuracy": {"scale": 0.2},
                                      "point_cloud": {"nan_flags": []}})
    res = pipe.process(cam.grab())
    rays = cam.info.intrinsics.rays()
    d = res.frame.radial_distance_m
    np.testing.assert_allclose(res.cloud.xyz(), d[..., None] * rays, rtol=1e-6, atol=1e-6)
    assert res.cloud.valid_points().shape == (res.cloud.count_valid(), 3)


def test_rendering_and_stats():
    cam = tofcam.SimulatedCamera("hand", seed=1)
    pipe = tofcam.Pipeline(cam)
    res = pipe.process(cam.grab())
    raw, filtered = pipe.render_raw(res), pipe.render_filtered(res)
    assert raw.dtype == np.uint8 and raw.shape[1:] == (160, 3) and raw.shape[0] >= 124
    # Filtered images black out at least the pixels the filters rejected.
    rejected = (res.frame.flags & tofcam.REJECT_MASK) != 0
    assert (filtered[:124][rejected] == 0).all()
    s = res.stats
    assert s.pixels == 160 * 124 and 0 <= s.valid_fraction <= 1
    assert s.kept_pixels == int((~rejected).sum())
    assert pipe.controller_name == "may-incremental"  # the default
    assert "Pipeline(camera='SR-2'" in repr(pipe)


def test_denoising_before_the_pair_lowers_delta_l_and_is_judged_again():
    # The same frames (same seed, fixed exposure) with and without the `denoise` section: a
    # 3x3 inverse-variance mean has about a third of one reading's σ where all nine take part,
    # so the median ΔL of the kept pixels falls well below half, and the accuracy threshold,
    # judged on it again, rejects fewer pixels.
    # The fitted plane (fit_plane) has the mean's σ on a wall facing the camera, so the same holds.
    def run(denoise, fit_plane=False):
        cam = tofcam.SimulatedCamera("wall", seed=3)
        options = {"accuracy": {"scale": 0.165}, "controller": {"enabled": False},
                   "denoise": {"enabled": denoise, "fit_plane": fit_plane}}
        pipe = tofcam.Pipeline(cam.info, options)
        cam.integration_time_register = 8
        res = pipe.process(cam.grab())
        kept = (res.frame.flags & tofcam.REJECT_MASK) == 0
        return np.median(res.frame.delta_l_m[kept]), int(kept.sum()), res.frame.radial_distance_m

    plain_sigma, plain_kept, _ = run(False)
    distances = {}
    for fit_plane in (False, True):
        sigma, kept, distances[fit_plane] = run(True, fit_plane)
        assert sigma < 0.5 * plain_sigma
        assert kept > plain_kept
    # The option reaches the stage: the plane's distances are not the mean's.
    assert not np.array_equal(distances[False], distances[True])
    with pytest.raises(tofcam.InvalidArgumentError, match="support_sigma"):
        tofcam.PipelineOptions(denoise={"support_sigma": 0})


def test_the_neighbours_prediction_judges_residuals_and_combines_kept_pixels():
    # The `prediction` section from Python: the same frame (same seed, fixed exposure) with the
    # uncertainty judging ΔL alone and judging each reading's residual against its neighbours'
    # prediction, kept pixels then combined with it. On a wall, the combination's spread is far
    # below the readings' (the prediction averages up to 48 neighbours; measured 15 against 43
    # mm). The spread, not the RMS: this uncalibrated pipeline reads the wall 4 cm long, and no
    # average of neighbours can know that.
    def run(prediction):
        cam = tofcam.SimulatedCamera("wall", seed=3)
        options = {"accuracy": {"scale": 0.165}, "controller": {"enabled": False},
                   "uncertainty": {"enabled": True}, "prediction": {"enabled": prediction}}
        pipe = tofcam.Pipeline(cam.info, options)
        cam.integration_time_register = 8
        res = pipe.process(cam.grab())
        kept = (res.frame.flags & tofcam.REJECT_MASK) == 0
        error = res.frame.radial_distance_m - res.frame.truth.radial_distance_m
        return kept, error

    plain_kept, plain_error = run(False)
    kept, error = run(True)
    both = plain_kept & kept
    assert both.sum() > plain_kept.size / 10
    assert np.std(error[both]) < 0.5 * np.std(plain_error[both])
    with pytest.raises(tofcam.InvalidArgumentError, match="radius_px"):
        tofcam.PipelineOptions(prediction={"radius_px": 9})
    with pytest.raises(tofcam.InvalidArgumentError, match="judge_combination"):
        tofcam.Pipeline(tofcam.SimulatedCamera("wall").info,
                        {"uncertainty": {"judge_combination": True}})


def test_unmixing_edge_pixels_only_adds_low_confidence_flags():
    # `uncertainty.unmix_edges` from Python: the same frame of the pavilion (a poster and pillars
    # in front of far walls; same seed, fixed exposure) with and without it. The unmixing only
    # adds an edge term (the uncertainty is the larger of the two), so every pixel flagged
    # without it is flagged with it, and the option must reach the stage: some edge pixel whose
    # area lies mostly across a step is flagged only with it.
    def run(unmix):
        cam = tofcam.SimulatedCamera("pavilion", seed=5)
        options = {"accuracy": {"scale": 0.165}, "controller": {"enabled": False},
                   "uncertainty": {"enabled": True, "extrapolate_edges": True,
                                   "unmix_edges": unmix}}
        pipe = tofcam.Pipeline(cam.info, options)
        cam.integration_time_register = 8
        res = pipe.process(cam.grab())
        return (res.frame.flags & int(tofcam.Flag.LOW_CONFIDENCE)) != 0

    without, with_unmixing = run(False), run(True)
    assert not (without & ~with_unmixing).any()
    assert (with_unmixing & ~without).sum() > 0


def test_out_of_another_layout_is_refused_not_freed_under_its_views():
    # Filling `out` from a frame of another size or with other channels would replace buffers
    # that views of it still point into (a use-after-free that crashed the interpreter).
    small = tofcam.SimulatedCamera("wall", seed=1)
    res = tofcam.Pipeline(small.info).process(small.grab())
    view = res.frame.radial_distance_m
    kept = view.copy()
    big = tofcam.SimulatedCamera("wall", model="sr4000", seed=1)
    with pytest.raises(tofcam.MismatchError, match="size"):
        tofcam.Pipeline(big.info).process(big.grab(), out=res)
    without_accuracy = tofcam.Pipeline(
        small.info, {"accuracy": {"enabled": False}, "filters": {"accuracy": {"enabled": False}}})
    with pytest.raises(tofcam.MismatchError, match="ΔL"):
        without_accuracy.process(small.grab(), out=res)
    # Channels set by hand on an empty result, then a view of one: refused as well.
    handmade = tofcam.PipelineResult()
    handmade.frame.intensity = np.ones((124, 160), np.float32)
    held = handmade.frame.intensity
    with pytest.raises(tofcam.MismatchError, match="by hand"):
        tofcam.Pipeline(small.info).process(small.grab(), out=handmade)
    assert held[0, 0] == 1.0
    assert np.array_equal(view, kept)  # nothing was written through the refused calls
    tofcam.Pipeline(small.info).process(small.grab(), out=res)  # same layout: in place
    assert np.shares_memory(view, res.frame.radial_distance_m)


def test_options_take_numpy_scalars_and_compare_with_other_types():
    o = tofcam.PipelineOptions(filters={"range": {"enabled": np.bool_(True),
                                                  "max_distance_m": np.float32(5.5)}},
                               controller={"bias_register": np.int64(40)})
    d = o.to_dict()
    assert d["filters"]["range"]["max_distance_m"] == 5.5
    assert d["filters"]["range"]["enabled"] is True
    assert d["controller"]["bias_register"] == 40
    assert (o == None) is False  # noqa: E711 (the operator itself is under test)
    assert o != "options"
    with pytest.raises(TypeError, match="max_distance_m"):
        tofcam.PipelineOptions(filters={"range": {"max_distance_m": np.zeros(2)}})


def test_render_shape_is_the_image_and_the_legend_below():
    cam = tofcam.SimulatedCamera("wall", seed=1)
    pipe = tofcam.Pipeline(cam.info)
    res = pipe.process(cam.grab())
    for rgb in (pipe.render_raw(res), pipe.render_filtered(res)):
        assert rgb.dtype == np.uint8
        assert rgb.shape[1:] == (160, 3) and rgb.shape[0] > 124  # the legend adds rows
