"""The answers' dataclasses built from sglc.v1 messages: the loop model's probability and evidence (no server)."""
import numpy as np

import sglc
from sglc import pb2


def candidate(**fields):
    c = pb2.Candidate(scan_id=3, robot="r", session="s", seq=9, score=0.5, verified=True, **fields)
    c.t_query_candidate.m.extend([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1])
    return c


def test_a_loop_carries_its_probability_and_on_request_its_evidence():
    ev = pb2.Evidence(source=pb2.EVIDENCE_SOURCE_WALLS, landmarks=4, landmark_similarity=0.5, field_deg=270.0,
                      agreement=0.625, wide_agreement=0.5, pin=0.125, plane_overlap=0.75, plane_rmse_m=0.0625,
                      constraint=3.5, context_similarity=0.875, translation_m=4.25)
    # Through the bytes, as the client receives it.
    wire = pb2.QueryResponse(candidates=[candidate(probability=0.9375, evidence=ev), candidate()])
    q = sglc.QueryResult.from_proto(pb2.QueryResponse.FromString(wire.SerializeToString()))
    first, second = q.candidates
    assert first.probability == 0.9375
    assert first.evidence == sglc.Evidence("walls", 4, 0.5, 270.0, 0.625, 0.5, 0.125, 0.75, 0.0625, 3.5, 0.875, 4.25)
    assert second.probability is None and second.evidence is None  # an older server: unknown, not 0


def test_a_rejected_candidate_keeps_its_evidence_and_probability():
    c = candidate(probability=0.0, evidence=pb2.Evidence(source=pb2.EVIDENCE_SOURCE_NONE))
    c.verified = False
    loop = sglc.Loop.from_proto(c)
    assert not loop.verified and loop.probability == 0.0 and loop.evidence.source == "none"


def test_a_stored_loop_without_probability_is_unknown():
    e = pb2.LoopEdge(id=1, score=0.5, probability=0.25)
    assert sglc.LoopEdge.from_proto(e).probability == 0.25
    e.ClearField("probability")
    assert sglc.LoopEdge.from_proto(e).probability is None


def test_include_evidence_is_sent_when_asked():
    c = sglc.Client("127.0.0.1:1", timeout=1)
    assert c.query_options(include_evidence=True).include_evidence
    assert not c.query_options().include_evidence
    req = c.ingest_request("m", "r", "s", 1, np.zeros((10, 3), np.float32), query=True, include_evidence=True)
    assert req.query_options.include_evidence
    c.close()
