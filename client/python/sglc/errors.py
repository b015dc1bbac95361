"""Exceptions of the sglc package: one class per gRPC status code, all subclasses of SglcError.

    try:
        client.ingest(...)
    except sglc.AlreadyExistsError:   # another scan under a stored key
        ...
    except sglc.SglcError as e:       # anything else the server (or the channel) refused
        print(e.code_name, e.details)

Input the client rejects before sending raises ValueError instead.
"""
from __future__ import annotations

from typing import Dict, Optional, Type

import grpc


class SglcError(Exception):
    """A failed call. ``code`` is the grpc.StatusCode, ``code_name`` its name (e.g. "NOT_FOUND"),
    ``details`` the server's message, ``method`` the RPC ("MapAdmin.CreateMap")."""

    code_name = "UNKNOWN"

    def __init__(self, method: str, code: Optional[grpc.StatusCode], details: str = ""):
        self.method = method
        self.code = code
        self.code_name = code.name if code is not None else "UNKNOWN"
        self.details = details or ""
        text = f"{self.code_name}: {self.details}" if self.details else self.code_name
        super().__init__(f"{text} ({method})")

    @staticmethod
    def from_rpc(method: str, error: Exception) -> "SglcError":
        """The SglcError subclass for a grpc.RpcError's status code."""
        code = error.code() if hasattr(error, "code") else grpc.StatusCode.UNKNOWN
        details = error.details() if hasattr(error, "details") else str(error)
        return error_class(code)(method, code, details)


class CancelledError(SglcError):
    """CANCELLED: the call was cancelled (by this client, or the server stopping)."""


class UnknownError(SglcError):
    """UNKNOWN."""


class InvalidArgumentError(SglcError):
    """INVALID_ARGUMENT: the request is malformed (the message says which field and why)."""


class DeadlineExceededError(SglcError):
    """DEADLINE_EXCEEDED: the call's timeout passed."""


class NotFoundError(SglcError):
    """NOT_FOUND: no such map, robot, session or scan (or one the token does not cover)."""


class AlreadyExistsError(SglcError):
    """ALREADY_EXISTS: another scan is stored under this key, or a map exists with another layout."""


class PermissionDeniedError(SglcError):
    """PERMISSION_DENIED: the token does not allow this call or map."""


class ResourceExhaustedError(SglcError):
    """RESOURCE_EXHAUSTED: a limit was reached (scan size, streams, bytes in flight); retry later or send less."""


class FailedPreconditionError(SglcError):
    """FAILED_PRECONDITION: the server cannot do this in its current state (e.g. labeller off, no labels)."""


class AbortedError(SglcError):
    """ABORTED."""


class OutOfRangeError(SglcError):
    """OUT_OF_RANGE."""


class UnimplementedError(SglcError):
    """UNIMPLEMENTED: the server does not offer this call (an older server)."""


class InternalError(SglcError):
    """INTERNAL: the server failed; its log says why."""


class UnavailableError(SglcError):
    """UNAVAILABLE: the server cannot be reached or is shutting down; safe to retry (ingest is idempotent)."""


class DataLossError(SglcError):
    """DATA_LOSS: stored data is damaged."""


class UnauthenticatedError(SglcError):
    """UNAUTHENTICATED: no token, or a wrong one."""


_BY_CODE: Dict[str, Type[SglcError]] = {
    "CANCELLED": CancelledError, "UNKNOWN": UnknownError, "INVALID_ARGUMENT": InvalidArgumentError,
    "DEADLINE_EXCEEDED": DeadlineExceededError, "NOT_FOUND": NotFoundError, "ALREADY_EXISTS": AlreadyExistsError,
    "PERMISSION_DENIED": PermissionDeniedError, "RESOURCE_EXHAUSTED": ResourceExhaustedError,
    "FAILED_PRECONDITION": FailedPreconditionError, "ABORTED": AbortedError, "OUT_OF_RANGE": OutOfRangeError,
    "UNIMPLEMENTED": UnimplementedError, "INTERNAL": InternalError, "UNAVAILABLE": UnavailableError,
    "DATA_LOSS": DataLossError, "UNAUTHENTICATED": UnauthenticatedError,
}


def error_class(code: Optional[grpc.StatusCode]) -> Type[SglcError]:
    """The exception class of a status code (SglcError itself for a code it does not know)."""
    return _BY_CODE.get(code.name if code is not None else "UNKNOWN", SglcError)
