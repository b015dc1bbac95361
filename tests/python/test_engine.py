"""sglc.Engine (the pybind11 module) against the C++ engine: the same numbers as sglc-pair on real scans."""
import json
import os
import subprocess
import threading

import numpy as np
import pytest

import sglc
from conftest import BUILD, pose_error

try:
    from sglc import _engine  # noqa: F401
except ImportError as e:
    pytest.skip(f"sglc._engine is not built in {BUILD} (sanitizer builds do not build it): {e}",
                allow_module_level=True)


def sglc_pair(kitti_dir, a, b, labels=True, extra=()):
    binary = os.environ.get("SGLC_PAIR_BIN") or os.path.join(BUILD, "bin", "sglc-pair")
    if not os.access(binary, os.X_OK):
        pytest.skip("sglc-pair is not built")
    cmd = [binary, "--scan-a", os.path.join(kitti_dir, "velodyne", a + ".bin"),
           "--scan-b", os.path.join(kitti_dir, "velodyne", b + ".bin"), *extra]
    if labels:
        cmd += ["--labels-a", os.path.join(kitti_dir, "labels", a + ".label"),
                "--labels-b", os.path.join(kitti_dir, "labels", b + ".label")]
    return json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True, timeout=120).stdout)


@pytest.mark.parametrize("labels", [True, False], ids=["labelled", "labeller"])
def test_same_result_as_sglc_pair(kitti, kitti_dir, reference_pose, labels):
    engine = sglc.Engine()
    (pa, la), (pb, lb) = kitti("000052"), kitti("004501")
    fa = engine.fingerprint(pa, la if labels else None)
    fb = engine.fingerprint(pb, lb if labels else None)
    m = engine.match(fa, fb)
    ref = sglc_pair(kitti_dir, "000052", "004501", labels)
    assert m.is_loop == ref["is_loop"] is True
    assert m.score == ref["score"] and m.inliers == ref["inliers"] and m.refined == ref["refined"]
    assert np.array_equal(m.T.ravel(), np.array(ref["T_a_b"]))  # bit for bit: the same code on the same input
    assert (fa.nodes, fb.nodes) == (ref["nodes_a"], ref["nodes_b"])
    assert fa.label_source == ref["labels_a"] == ("provided" if labels else "computed")
    dt, dr = pose_error(m.T, reference_pose)
    assert dt < 0.2 and dr < 1.0
    info = m.information
    assert info.shape == (6, 6) and np.allclose(info, info.T, atol=1e-6 * abs(info).max())
    assert np.linalg.eigvalsh(info).min() > 0


def test_negative_pair_and_known_loop(kitti, kitti_dir):
    engine = sglc.Engine()
    fa, fb = engine.fingerprint(*kitti("000052")), engine.fingerprint(*kitti("000850"))
    m = engine.match(fa, fb)
    ref = sglc_pair(kitti_dir, "000052", "000850")
    assert m.is_loop == ref["is_loop"] is False and m.reason == ref["reason"] and m.reason
    k = engine.match(fa, fb, known_loop=True)
    ref = sglc_pair(kitti_dir, "000052", "000850", extra=["--known-loop"])
    assert k.is_loop is False and k.refined == ref["refined"]
    assert np.array_equal(k.T.ravel(), np.array(ref["T_a_b"]))


def test_inputs_and_errors(kitti):
    engine = sglc.Engine()
    p, lab = kitti("000052")
    kitti4 = np.hstack([p, np.ones((len(p), 1), np.float32)]).astype(np.float64)  # (N, 4) float64
    f1, f2 = engine.fingerprint(p, lab), engine.fingerprint(kitti4, lab.astype(np.int64))
    assert np.array_equal(f1.descriptor, f2.descriptor) and f1.num_points == len(p)
    with pytest.raises(ValueError, match="points but"):
        engine.fingerprint(p, lab[:-1])
    bad = p.copy()
    bad[7, 1] = np.nan
    with pytest.raises(ValueError, match="7"):
        engine.fingerprint(bad, lab)
    with pytest.raises(ValueError, match="shape"):
        engine.fingerprint(p[:, :2])
    with pytest.raises(TypeError):
        engine.match(f1, "not a fingerprint")
    # A scan without points is refused as the server refuses it (not fingerprinted into an empty one).
    with pytest.raises(ValueError, match="scan is empty"):
        engine.fingerprint(np.zeros((0, 3), np.float32))
    with pytest.raises(ValueError, match="scan is empty"):
        engine.fingerprint(np.zeros((0, 3), np.float32), np.zeros(0, np.uint32))


def test_config(tmp_path, kitti):
    assert "labels:" in sglc.Engine().config()
    cfg = tmp_path / "engine.yaml"
    cfg.write_text("labeller:\n  mode: off\n")
    engine = sglc.Engine(cfg)
    assert "mode: off" in engine.config()
    with pytest.raises(ValueError):
        engine.fingerprint(kitti("000052")[0])  # labeller off: an unlabelled scan is refused
    with pytest.raises(ValueError):
        sglc.Engine("labeller:\n  mode: sometimes\n")
    with pytest.raises(ValueError, match="neither a file nor YAML"):
        sglc.Engine("/no/such/file.yaml")


def test_threads_give_the_same_result(kitti):
    """The GIL is released while the engine works; results do not depend on threads."""
    engine = sglc.Engine()
    scans = [kitti(f) for f in ("000052", "004501")]
    ref = [engine.fingerprint(*s).descriptor for s in scans]
    out = [None] * 8

    def run(k):
        out[k] = engine.fingerprint(*scans[k % 2]).descriptor

    threads = [threading.Thread(target=run, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(np.array_equal(out[k], ref[k % 2]) for k in range(8))


def test_fingerprints_pickle(kitti):
    """A fingerprint saved with pickle loads as the same fingerprint (descriptor, matches); a damaged one is a
    ValueError, not a crash."""
    import pickle
    engine = sglc.Engine()
    fp = engine.fingerprint(*kitti("000052"))
    back = pickle.loads(pickle.dumps(fp))
    assert np.array_equal(back.descriptor, fp.descriptor)
    assert (back.nodes, back.num_points, back.label_source, back.warnings) == \
        (fp.nodes, fp.num_points, fp.label_source, fp.warnings)
    assert engine.match(fp, back).score == engine.match(fp, fp).score
    blob, source, warnings = fp.__getstate__()
    damaged = bytearray(blob)
    damaged[len(damaged) // 2] ^= 0xFF
    with pytest.raises(ValueError):
        type(fp).__new__(type(fp)).__setstate__((bytes(damaged), source, warnings))
    with pytest.raises(ValueError):
        type(fp).__new__(type(fp)).__setstate__((blob, 99, warnings))
