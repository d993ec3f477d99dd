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



def test_messages_with_bytes_that_are_not_utf8_stay_tofcam_errors(tmp_path):
    # Messages quote paths and file contents; a strict UTF-8 decoding used to raise
    # UnicodeDecodeError in place of the tofcam error.
    import os
    garbage = tmp_path / "random.bin"
    garbage.write_bytes(bytes(range(128, 256)) * 4)
    with pytest.raises(tofcam.Error) as info:
        tofcam.load_calibration(garbage)
    assert "random.bin" in str(info.value)
    missing = tmp_path / os.fsdecode(b"\xff.h5")
    with pytest.raises(tofcam.NotFoundError) as info:
        tofcam.RecordingReader(missing)
    assert ".h5" in str(info.value)
