"""sglc.packing and sglc.results: arrays in and out of the wire format, checked."""
import numpy as np
import pytest

import sglc
from sglc import packing, results


def test_points_any_float_array_with_three_or_more_columns():
    xyz = np.float64([[1, -2, 0.5], [3, 4, 5]])
    kitti = np.hstack([xyz, np.full((2, 1), 0.7)])  # (N, 4) with reflectance
    assert packing.pack_points(kitti) == packing.pack_points(xyz) == np.float32(xyz).tobytes()
    assert packing.pack_points(np.int16([[1, 2, 3]])) == np.float32([[1, 2, 3]]).tobytes()
    assert packing.pack_points([[1.0, -2.0, 0.5]]) == bytes.fromhex("0000803f000000c00000003f")  # float32 LE


@pytest.mark.parametrize("bad, why", [(np.zeros((4, 2)), "shape"), (np.zeros(12), "shape"),
                                      (np.array([["a", "b", "c"]]), "numeric"),
                                      (np.float64([[0, np.nan, 0]]), "non-finite"),
                                      (np.float64([[0, 0, 1e39]]), "non-finite")])
def test_points_rejected_with_reason(bad, why):
    with np.errstate(all="raise"):  # no numpy warning on the way to the error either
        with pytest.raises(ValueError, match=why):
            packing.pack_points(bad)


def test_labels_any_integer_type():
    for dtype in (np.uint8, np.int16, np.uint16, np.int32, np.int64, np.uint64):
        assert packing.pack_labels(np.array([0, 40, 255], dtype=dtype)) == np.uint32([0, 40, 255]).tobytes()
    assert packing.pack_labels([0x00010028]) == bytes.fromhex("28000100")  # uint32 LE
    with pytest.raises(ValueError, match="integers"):
        packing.pack_labels(np.float32([1.5]))
    with pytest.raises(ValueError, match="uint32"):
        packing.pack_labels(np.int64([-1]))
    with pytest.raises(ValueError, match="uint32"):
        packing.pack_labels(np.uint64([2**32]))


def test_scan_counts_and_bytes():
    pts, lab = np.random.default_rng(1).normal(size=(50, 3)).astype(np.float32), np.arange(50, dtype=np.uint32)
    pb, lb = sglc.pack_scan(pts, lab)
    assert np.array_equal(sglc.unpack_points(pb), pts) and np.array_equal(sglc.unpack_labels(lb), lab)
    assert sglc.pack_scan(pb, lb) == (pb, lb)  # packed bytes pass through
    assert sglc.pack_scan(pts) == (pb, b"")    # no labels: the server labels the scan
    with pytest.raises(ValueError, match="50 points but 49 labels"):
        sglc.pack_scan(pts, lab[:-1])
    with pytest.raises(ValueError, match="multiple of 12"):
        sglc.pack_scan(b"\0" * 13)
    with pytest.raises(ValueError, match="multiple of 4"):
        packing.pack_labels(b"\0" * 6)


def test_transforms():
    c, s = np.cos(0.3), np.sin(0.3)
    M = np.array([[c, -s, 0, 1], [s, c, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]])
    assert np.array_equal(results.matrix(packing.transform_values(M)), M)
    for bad, why in ((np.diag([1.0, 1, -1, 1]), "determinant"), (np.diag([2.0, 1, 1, 1]), "orthonormal"),
                     (np.eye(3), "4x4"), (np.full((4, 4), np.nan), "non-finite")):
        with pytest.raises(ValueError, match=why):
            packing.transform_values(bad)
    assert np.array_equal(results.matrix([]), np.eye(4))
    with pytest.raises(ValueError, match="16"):
        results.matrix([0.0] * 15)
    assert results.information([]) is None
    with pytest.raises(ValueError, match="36"):
        results.information([1.0] * 5)


def test_read_kitti_scan(tmp_path):
    cloud = np.float32([[1, 2, 3, 0.5], [4, 5, 6, 0.1]])
    cloud.tofile(tmp_path / "a.bin")
    np.uint32([10, 40]).tofile(tmp_path / "a.label")
    p, lab = sglc.read_kitti_scan(tmp_path / "a.bin", tmp_path / "a.label")
    assert np.array_equal(p, cloud[:, :3]) and list(lab) == [10, 40]
    assert sglc.read_kitti_scan(tmp_path / "a.bin")[1] is None
    np.uint32([10]).tofile(tmp_path / "b.label")
    with pytest.raises(ValueError, match="1 labels for 2 points"):
        sglc.read_kitti_scan(tmp_path / "a.bin", tmp_path / "b.label")
    (tmp_path / "c.bin").write_bytes(b"\0" * 20)
    with pytest.raises(ValueError, match="multiple of 16"):
        sglc.read_kitti_scan(tmp_path / "c.bin")


def test_errors_by_status_code():
    import grpc
    assert sglc.error_class(grpc.StatusCode.NOT_FOUND) is sglc.NotFoundError
    assert sglc.error_class(grpc.StatusCode.UNAUTHENTICATED) is sglc.UnauthenticatedError
    for code in grpc.StatusCode:
        if code != grpc.StatusCode.OK:
            cls = sglc.error_class(code)
            assert cls is not sglc.SglcError and issubclass(cls, sglc.SglcError), code
            e = cls("MapAdmin.ListMaps", code, "why")
            assert e.code_name == code.name and "why" in str(e) and "MapAdmin.ListMaps" in str(e)


def test_memoryview_of_numbers_is_an_array_not_bytes():
    a = np.float64([[1, 2, 3], [4, 5, 6]])
    assert packing.pack_points(memoryview(a)) == np.float32(a).tobytes()  # converted, not passed through
    raw = np.float32(a).tobytes()
    assert packing.pack_points(memoryview(raw)) == raw  # a memoryview of bytes is packed bytes
