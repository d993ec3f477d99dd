"""tofcam: time-of-flight cameras for mobile robots, from Python.

The C++ library's cameras (the physically based simulator, recordings, importers of real
cameras), the pipeline of May et al. (IROS 2006) and every stage, with frames as NumPy views
that share memory with the C++ objects. See docs/python.md.

    import tofcam
    cam = tofcam.SimulatedCamera("hand", seed=1)
    pipe = tofcam.Pipeline(cam)
    cam.integration_time_register = pipe.initial_integration_register
    for frame in (cam.grab() for _ in range(30)):
        res = pipe.process(frame)
        cam.integration_time_register = res.next_integration_register
    print(res.stats, res.frame.radial_distance_m.shape)

Units are in the names (_m metres, _us microseconds, _hz hertz, _rad radians); registers are the
camera's raw 16-bit values. Errors are tofcam.Error subclasses carrying the C++ message.
"""

from ._tofcam import *  # noqa: F401,F403  (the extension defines __all__-worthy names only)
from ._tofcam import __version__  # noqa: F401
from . import filters  # noqa: F401


def merge_options(options, changes):
    """A PipelineOptions with `changes` (a nested dict) merged into `options`.

    options: a PipelineOptions, a dict or None (defaults)."""
    from ._tofcam import PipelineOptions

    base = (options.to_dict() if isinstance(options, PipelineOptions)
            else dict(options or {}))

    def merge(a, b):
        out = dict(a)
        for key, value in b.items():
            out[key] = merge(out.get(key, {}), value) if isinstance(value, dict) else value
        return out

    return PipelineOptions.from_dict(merge(base, changes))
