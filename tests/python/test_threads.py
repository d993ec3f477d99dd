"""The GIL is released while C++ works, so Python threads run alongside grabs and processing."""

import threading
import time

import numpy as np

import tofcam


def test_python_runs_while_another_thread_grabs():
    # The first grab of a VGA camera with 4 x 4 supersampling renders ~5 M rays (~0.2 s here).
    model = tofcam.CameraModel.builtin("generic640x480")
    cam = tofcam.SimulatedCamera("pavilion", model=model, supersampling=4, seed=1)
    times = {}

    def grab():
        times["before"] = time.perf_counter()
        cam.grab()
        times["after"] = time.perf_counter()

    t = threading.Thread(target=grab)
    t.start()
    while "before" not in times:
        time.sleep(0.001)
    # Sleeping hands the GIL to the grabbing thread, which enters C++. If the grab held the GIL,
    # this thread could not run again before the grab had returned and the other thread had
    # read the clock after it; with the GIL released it wakes while the grab is still running.
    time.sleep(0.005)
    woke = time.perf_counter()
    t.join()
    assert times["before"] < woke < times["after"], (
        f"woke {woke - times['before']:.3f} s after the grab started, which took "
        f"{times['after'] - times['before']:.3f} s")


def test_threads_with_their_own_cameras_give_the_sequential_results():
    def frames(seed, out, index):
        cam = tofcam.SimulatedCamera("hand", seed=seed)
        pipe = tofcam.Pipeline(cam.info, {"accuracy": {"scale": 0.2}})
        out[index] = [pipe.process(cam.grab()).frame.radial_distance_m for _ in range(3)]

    parallel = [None, None]
    threads = [threading.Thread(target=frames, args=(s, parallel, k)) for k, s in enumerate((1, 2))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    sequential = [None, None]
    frames(1, sequential, 0)
    frames(2, sequential, 1)
    for p, s in zip(parallel, sequential):
        for a, b in zip(p, s):
            np.testing.assert_array_equal(a, b)
