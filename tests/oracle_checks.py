"""The one agreement check of cast results against the float64 oracle, shared by the tests: the
bounds are pyclray.reference.error_model's (pyclray_tolerances: K_ORACLE eps (t + L) plus the oracle's own
eps64 (t + W), over |cos|), and the rays set apart are its silhouettes, near ties and edges."""
import numpy as np

from pyclray.reference import error_model
from pyclray.reference import oracle


def judge(scene, origins, directions, result, precision, reference_point=None):
    """(truth, cos, judged, explained, depth tolerance, normal tolerance) of a cast's result."""
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    truth = oracle.trace(scene, origins, unit, aovs=("depth", "normal", "id", "second"))
    cos = oracle.incidence_cosine(scene, unit, truth["id"], truth["normal"])
    depth_tolerance, normal_tolerance = error_model.pyclray_tolerances(scene, truth, cos, origins, precision, reference_point, unit)
    with np.errstate(invalid="ignore"):
        farthest = np.fmax(np.where(np.isfinite(truth["depth"]), truth["depth"], 0.0),
                           np.where(np.isfinite(result["depth"]), result["depth"].astype(np.float64), 0.0))
    band, _ = error_model.pyclray_tolerances(scene, {"depth": farthest, "id": truth["id"]}, cos, origins, precision,
                                          reference_point, unit, flat=False)  # edges: the position error
    edge = error_model.at_edges(scene, origins, unit, [(truth["id"], truth["depth"]), (result["id"], result["depth"])],
                             band * cos)
    truth["cos"] = cos
    near_tie = error_model.near_ties(truth, lambda t, ids, c: error_model.pyclray_tolerances(
        scene, {"depth": t, "id": ids}, c, origins, precision, reference_point, unit)[0])
    radius = error_model.curvature_radii(scene)[np.maximum(truth["id"], 0)]
    explained = error_model.silhouettes(truth["id"], cos, depth_tolerance, radius) | near_tie | edge
    judged = (result["id"] == truth["id"]) & (truth["id"] >= 0) & ~explained
    return truth, cos, judged, explained, depth_tolerance, normal_tolerance


def assert_agrees_with_oracle(scene, origins, directions, result, precision, min_judged=0.1, reference_point=None):
    """Ids exact except where explained; depth and normal within the error model where judged;
    the miss convention (inf, (0, 0, 0), -1 together); unit normals. reference_point: a render's
    eye (its kernel's frame); None: the rays are a cast's."""
    truth, cos, judged, explained, depth_tolerance, normal_tolerance = judge(scene, origins, directions, result, precision,
                                                                             reference_point)
    wrong = (result["id"] != truth["id"]) & ~explained
    assert not wrong.any(), f"{wrong.sum()} unexplained id disagreements, e.g. ray {np.argmax(wrong)}"
    assert judged.sum() > min_judged * len(origins), f"too few hits ({judged.sum()}) for the test to mean anything"
    with np.errstate(invalid="ignore"):  # inf - inf where both miss
        depth_error = np.abs(result["depth"].astype(np.float64) - truth["depth"])
    ratio = np.where(judged, depth_error / depth_tolerance, 0.0)
    assert ratio.max() <= 1.0, f"depth off by {ratio.max():.3g} x the tolerance at ray {np.argmax(ratio)}"
    angle = error_model.angle_between(result["normal"], truth["normal"])
    ratio = np.where(judged, angle / normal_tolerance, 0.0)
    assert ratio.max() <= 1.0, f"normal off by {ratio.max():.3g} x the tolerance at ray {np.argmax(ratio)}"
    miss = result["id"] < 0
    assert np.all(np.isinf(result["depth"][miss])) and np.all(result["normal"][miss] == 0)
    assert np.all(np.isfinite(result["depth"][~miss])) and np.all(result["depth"][~miss] > 0)
    eps = error_model.EPSILON[precision]
    assert np.allclose(np.linalg.norm(result["normal"][~miss].astype(np.float64), axis=1), 1.0, rtol=0, atol=8 * eps)
    return truth, cos, judged, depth_tolerance


def assert_primitives_agree(scene, origins, directions, frame, truth, judged):
    """The primitive image against the float64 oracle's: on the judged pixels, the index within its
    shape of the primitive the oracle hits (the triangle of a mesh, the sphere of a batch); -1 on a
    miss."""
    primitive = frame["primitive"].reshape(-1)
    expected = np.full(len(directions), -1)
    for index, shape in enumerate(scene.shapes):
        mine = truth["id"] == index
        expected[mine] = shape.oracle_hits(origins[mine], directions[mine])[1]
    assert np.all(primitive[judged] == expected[judged])
    assert np.all(primitive[frame["id"].reshape(-1) < 0] == -1)
