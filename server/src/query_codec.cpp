#include "query_codec.hpp"

#include "evidence_codec.hpp"
#include "sglc/wire/geometry_codec.hpp"

namespace sglc::server {
namespace {

closing::Scope scopeOf(v1::Scope scope) {
  switch (scope) {
    case v1::SCOPE_UNSPECIFIED:
    case v1::SCOPE_WHOLE_MAP:
      return closing::Scope::kWholeMap;
    case v1::SCOPE_SAME_ROBOT:
      return closing::Scope::kSameRobot;
    case v1::SCOPE_OTHER_ROBOTS:
      return closing::Scope::kOtherRobots;
    case v1::SCOPE_SESSIONS:
      return closing::Scope::kSessions;
    default:
      return closing::Scope::kUnknown;  // refused by the finder, in its order of checks
  }
}

}  // namespace

closing::QueryOptions fromWire(const v1::QueryOptions& o) {
  closing::QueryOptions q;
  q.top_k = o.top_k();
  q.candidates = o.candidates();
  q.exclude_recent = o.has_exclude_recent() ? o.exclude_recent() : kDefaultExcludeRecent;
  q.exclude_seconds = o.exclude_seconds();
  q.refine = o.refine_set() ? o.refine() : true;
  q.known_loops = o.known_loops();
  q.include_rejected = o.include_rejected();
  if (o.has_min_score()) q.min_score = o.min_score();
  q.scope = scopeOf(o.scope());
  q.sessions.assign(o.sessions().begin(), o.sessions().end());
  for (const auto& r : o.session_refs()) q.session_refs.push_back({r.robot(), r.session()});
  q.verify_scan_ids.assign(o.verify_scan_ids().begin(), o.verify_scan_ids().end());
  return q;
}

void toWire(const std::vector<closing::FoundLoop>& loops, google::protobuf::RepeatedPtrField<v1::Candidate>* out,
            bool include_evidence) {
  for (const auto& loop : loops) {
    const auto& r = loop.result;
    auto* c = out->Add();
    c->set_scan_id(loop.scan_id);
    c->set_robot(loop.robot);
    c->set_session(loop.session);
    c->set_seq(loop.seq);
    c->set_score(r.score);
    c->set_probability(r.probability);
    c->set_reason(r.reason);
    if (include_evidence) toWire(r.evidence, c->mutable_evidence());
    c->set_verified(r.is_loop);
    c->set_inliers(r.inliers);
    c->set_fitness(r.fitness);
    c->set_rmse(r.rmse);
    c->set_refined(r.refined);
    if (r.refined && !r.information.isZero()) wire::encodeInformation(r.information, c);
    c->set_descriptor_distance(loop.descriptor_distance);
    wire::toTransform(r.T, c->mutable_t_query_candidate());
  }
}

void toWire(const closing::QueryTiming& timing, v1::Timing* out) {
  out->set_search_ms(timing.search_ms);
  out->set_verify_ms(timing.verify_ms);
  out->set_refine_ms(timing.refine_ms);
}

}  // namespace sglc::server
