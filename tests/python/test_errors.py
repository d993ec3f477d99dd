"""tofcam.Error subclasses carry the C++ error code and message."""

import pytest

import tofcam

CASES = [
    ("invalid-argument", tofcam.InvalidArgumentError, ValueError),
    ("not-found", tofcam.NotFoundError, FileNotFoundError),
    ("io", tofcam.IoError, OSError),
    ("format", tofcam.FormatError, ValueError),
    ("mismatch", tofcam.MismatchError, ValueError),
    ("unsupported", tofcam.UnsupportedError, NotImplementedError),
    ("internal", tofcam.InternalError, RuntimeError),
]


@pytest.mark.parametrize("code,cls,builtin", CASES)
def test_each_code_maps_to_its_class(code, cls, builtin):
    with pytest.raises(cls) as info:
        tofcam._tofcam._raise(code, "the message")
    assert str(info.value) == "the message"
    assert info.value.code == code
    assert isinstance(info.value, tofcam.Error) and isinstance(info.value, builtin)


def test_real_errors_keep_the_cpp_message():
    with pytest.raises(tofcam.NotFoundError) as info:
        tofcam.Scene.builtin("no-such-scene")
    assert "no-such-scene" in str(info.value) and info.value.code == "not-found"
    with pytest.raises(tofcam.MismatchError):
        info = tofcam.CameraInfo()
        pipe = tofcam.Pipeline(info)
        small = tofcam.SimulatedCamera("wall", model=tofcam.CameraModel.builtin("sr4000"))
        pipe.process(small.grab())
