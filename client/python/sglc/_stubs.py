"""The generated sglc.v1 stubs (sglc_pb2, sglc_pb2_grpc), which the build writes into this package's v1/.

They exist in a built package (``<build dir>/python/sglc`` or an installed wheel), not in the source tree:
importing sglc from client/python directly fails here with the way out.
"""
try:
    from .v1 import sglc_pb2 as pb2
    from .v1 import sglc_pb2_grpc as pb2_grpc
except ImportError as e:  # pragma: no cover - depends on how the package was reached
    raise ImportError(
        "sglc: the generated stubs (sglc/v1/sglc_pb2.py) are missing: this is the source tree. Use the built "
        "package: `pip install ./client/python`, or PYTHONPATH=<build dir>/python after building the project "
        f"({e})") from e

__all__ = ["pb2", "pb2_grpc"]
