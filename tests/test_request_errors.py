"""Issue 42 item 6: every bad argument to cast, occluded and render (and the handle's methods, and
the cluster's) is a pyclray.RequestError, a ValueError, with one line naming the argument, as
docs/python.md's table of errors says (not a bare PyclrayError)."""
import numpy as np
import pytest

import pyclray

SCENE = pyclray.Scene(pyclray.Camera((0, 0, 5), (0, 0, 0)), pyclray.Image(8, 6),
                      (pyclray.Sphere((0, 0, 0), 1.0),))
GOOD = [[0.0, 0.0, 5.0]], [[0.0, 0.0, -1.0]]


@pytest.mark.parametrize("origins,directions,keys,message", [
    ([[0, 0, 5], [0, 0, 5]], [[0, 0, -1]], {}, "origins: expected shape"),
    ([[0, 0, 5]], [[0, 0, -1, 0]], {}, "directions: expected an array of shape (..., 3)"),
    ([[0, 0, 5]], [["a", "b", "c"]], {}, "directions: expected an array"),
    ([[0, 0, 5]], [[0, 0, 0]], {}, "directions: row 0 has zero length"),
    ([[0, 0, 5]], [[0, np.nan, -1]], {}, "directions: row 0 is not finite"),
    ([[0, np.inf, 5]], [[0, 0, -1]], {}, "origins: row 0 is not finite"),
    ([[0, 0, 5]], [[0, 0, -1]], {"tmax": -1.0}, "tmax: expected numbers > 0"),
    ([[0, 0, 5]], [[0, 0, -1]], {"tmax": [1.0, 2.0]}, "tmax: expected one number"),
    ([[0, 0, 5]], [[0, 0, -1]], {"tmax": "far"}, "tmax: expected a number"),
    ([[0, 0, 1e300]], [[0, 0, -1]], {}, "too far"),
])
@pytest.mark.parametrize("query", ["cast", "occluded"])
def test_bad_rays_are_request_errors(query, origins, directions, keys, message):
    with pytest.raises(pyclray.RequestError) as error:
        getattr(pyclray, query)(SCENE, origins, directions, **keys)
    assert isinstance(error.value, ValueError)
    assert message in str(error.value) and "\n" not in str(error.value), str(error.value)


@pytest.mark.parametrize("window", [(0, 0, 9, 6), (-1, 0, 2, 2), (0, 0, 0, 1), ("a", 0, 1, 1), (7, 5, 2, 2), 3])
def test_a_window_outside_the_image_is_a_request_error(window):
    with pytest.raises(pyclray.RequestError, match="window: expected"):
        pyclray.render(SCENE, window=window)


def test_the_handle_and_acceleration_say_request_error_too():
    with pyclray.prepare(SCENE) as tracer:
        with pytest.raises(pyclray.RequestError, match="directions: row 0 has zero length"):
            tracer.cast([[0, 0, 5]], [[0, 0, 0]])
        with pytest.raises(pyclray.RequestError, match="window"):
            tracer.render(window=(0, 0, 100, 1))
    with pytest.raises(pyclray.RequestError, match="acceleration: expected one of"):
        pyclray.render(SCENE, acceleration="kd-tree")


def test_the_clusters_bad_arguments_are_request_errors_before_any_task():
    """pyclray.cluster's checks run before the client is used (None here: no cluster needed)."""
    from pyclray import cluster

    with pytest.raises(pyclray.RequestError, match="views: item 0"):
        next(cluster.render_views(None, SCENE, ["not a camera"]))
    with pytest.raises(pyclray.RequestError, match="rows: expected"):
        next(cluster.render_bands(None, SCENE, rows=0))
    with pytest.raises(pyclray.RequestError, match="device: on a cluster"):
        next(cluster.render_views(None, SCENE, [SCENE.camera], device=0))
