"""The pipeline's filters as functions.

Each takes a MetricFrame, or the arrays it needs as keyword arguments (float32 (H, W) distances
in metres and register-unit amplitudes, uint16 flags), plus the filter's options under the names
of the `filters` section of the configuration file (docs/pipeline.md), and returns the uint16
(H, W) flags it raises. Pixels already rejected in the frame's flags are not used as support by
the neighbourhood filters.
"""

from ._tofcam import MetricFrame, _filter

__all__ = ["range", "amplitude", "saturation", "accuracy", "flying_pixel", "jump_edge",
           "weingarten"]


def _frame(frame, radial_distance_m, amplitude, intensity, delta_l_m, flags):
    if frame is not None:
        if not isinstance(frame, MetricFrame):
            raise TypeError("frame must be a tofcam.MetricFrame (or pass arrays by keyword)")
        given = [name for name, array in (("radial_distance_m", radial_distance_m),
                                          ("amplitude", amplitude), ("intensity", intensity),
                                          ("delta_l_m", delta_l_m), ("flags", flags))
                 if array is not None]
        if given:
            raise TypeError("pass a MetricFrame or arrays, not both (got the frame and " +
                            ", ".join(given) + ")")
        return frame
    if radial_distance_m is None:
        raise TypeError("pass a MetricFrame or radial_distance_m=...")
    import numpy as np

    if amplitude is None:
        amplitude = np.zeros_like(radial_distance_m)
    return MetricFrame(radial_distance_m=radial_distance_m, amplitude=amplitude,
                       intensity=intensity, flags=flags, delta_l_m=delta_l_m)


def _make(name, needs_intrinsics, doc):
    def function(frame=None, *, radial_distance_m=None, amplitude=None, intensity=None,
                 delta_l_m=None, flags=None, intrinsics=None, **options):
        f = _frame(frame, radial_distance_m, amplitude, intensity, delta_l_m, flags)
        return _filter(name, f, intrinsics, options)

    function.__name__ = name
    function.__qualname__ = name
    function.__doc__ = doc + ("\n\nNeeds intrinsics=CameraIntrinsics of the frame."
                              if needs_intrinsics else "")
    return function


range = _make("range", False,  # noqa: A001 (the configuration section's name)
              "kOutOfRange outside [min_distance_m, max_distance_m] (m).")
amplitude = _make("amplitude", False,
                  "kLowAmplitude below min_amplitude (register units; the vendor driver's rule).")
saturation = _make("saturation", False,
                   "kSaturated at max_intensity, max_amplitude or intensity + amplitude >= "
                   "max_peak (register units).")
accuracy = _make("accuracy", False,
                 "kHighDeltaL where ΔL > max_delta_l_m (m; the paper's accuracy filter). Needs "
                 "delta_l_m.")
flying_pixel = _make("flying_pixel", False,
                     "kFlyingPixel: the edge-aware flying-pixel filter (libfreenect2 style; "
                     "min_amplitude_contrast, amplitude_mean_floor, min_close_delta_m, ...).")
jump_edge = _make("jump_edge", True,
                  "kJumpEdge: May's jump-edge filter (max_angle_deg, degrees).")
weingarten = _make("weingarten", True,
                   "kSparseCell: Weingarten's occupied cells (voxel_size_m, min_points).")
