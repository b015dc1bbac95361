#include "backend.hpp"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <iostream>
#include <map>
#include <stdexcept>

#include "sglc/client/client.hpp"
#include "sglc/closing/loop_finder.hpp"
#include "sglc/elapsed.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::eval {
namespace {

const char* kRobot = "eval";
const char* kSession = "run";
const char* kMap = "eval";

// A fresh map database in `dir` (synchronous=OFF: a crashed evaluation is run again).
std::unique_ptr<storage::MapStore> openStore(const std::string& dir) {
  std::filesystem::create_directories(dir);
  storage::StoreOptions o;
  o.path = (std::filesystem::path(dir) / "eval.db").string();
  std::filesystem::remove(o.path);
  std::filesystem::remove_all(o.path + ".index");
  o.sync = storage::StoreOptions::Sync::kOff;
  return storage::MapStore::open(o);
}

class InProcess final : public Backend {
 public:
  InProcess(const Config& config, const std::string& dir)
      : pipeline_(config), store_(openStore(dir)), finder_(pipeline_, *store_) {
    store_->createMap(
        kMap, descriptorLayout(static_cast<int>(config.labels.node_classes.size()), config.graph, config.descriptor)
                  .scanDim());
  }
  std::string name() const override { return "in-process"; }

  void add(int frame, const LabelledScan& scan, StageTimes* t) override {
    const auto t0 = Clock::now();
    const auto fp = pipeline_.fingerprint(scan);
    t->fingerprint = msSince(t0);
    store(frame, fp, t);
    t->total = msSince(t0);
  }

  std::vector<Candidate> queryThenAdd(int frame, const LabelledScan& scan, const LoopQuery& q, StageTimes* t) override {
    const auto t0 = Clock::now();
    const auto fp = pipeline_.fingerprint(scan);
    t->fingerprint = msSince(t0);
    // What the server back-end asks for (Remote::queryThenAdd), through the same use case.
    auto out = find(fp, q, {kMap, kRobot, kSession, frame, std::nullopt, 0}, t);
    store(frame, fp, t);
    t->total = msSince(t0);
    return out;
  }

  std::vector<Candidate> query(const LabelledScan& scan, const LoopQuery& q, StageTimes* t) override {
    const auto t0 = Clock::now();
    const auto fp = pipeline_.fingerprint(scan);
    t->fingerprint = msSince(t0);
    // What the server does with a QueryRequest carrying a scan and no robot (Remote::query): nothing excluded.
    auto out = find(fp, q, {kMap, "", "", 0, std::nullopt, 0}, t);
    t->total = msSince(t0);
    return out;
  }

  std::vector<Candidate> verify(int query, const std::vector<int>& candidates, Refine refine, StageTimes* t) override {
    const auto t0 = Clock::now();
    const auto fp = store_->fingerprint(idOf(query));
    // The candidates as the service's verify_scan_ids gives them, without its limit of 200 per call.
    std::vector<std::int64_t> ids;
    for (int c : candidates) ids.push_back(idOf(c));
    const auto hits = finder_.listed(*fp, kMap, ids, ids.size());
    closing::Ranking ranking;
    ranking.top_k = hits.size();
    ranking.include_rejected = true;
    ranking.refine = refine != Refine::none;
    ranking.known_loops = refine == Refine::known_loops;
    closing::QueryTiming qt;
    auto out = convert(finder_.verify(*fp, hits, ranking, {}, &qt));
    times(qt, t);
    t->total = msSince(t0);
    return out;
  }

 private:
  // Searches, verifies and refines as the service does for `origin` (its robot's recent scans are excluded).
  std::vector<Candidate> find(const Fingerprint& fp, const LoopQuery& q, const closing::QueryOrigin& origin,
                              StageTimes* t) const {
    closing::QueryOptions o;
    o.top_k = static_cast<std::uint32_t>(q.candidates);
    o.candidates = static_cast<std::uint32_t>(q.candidates);
    o.include_rejected = true;
    o.refine = q.refine;
    o.exclude_recent = q.exclude_recent;
    closing::QueryTiming qt;
    const auto found = finder_.find(fp, origin, o, {}, &qt);
    times(qt, t);
    return convert(found);
  }
  std::int64_t idOf(int frame) const {
    const auto it = ids_.find(frame);
    if (it == ids_.end()) throw std::logic_error("frame " + std::to_string(frame) + " is not stored");
    return it->second;
  }
  void store(int frame, const Fingerprint& fp, StageTimes* t) {
    const auto t0 = Clock::now();
    storage::NewScan ns{.map = kMap, .robot = kRobot, .session = kSession, .seq = frame, .fingerprint = &fp};
    const auto id = store_->addScan(ns);
    ids_[frame] = id;
    frames_[id] = frame;
    t->store = msSince(t0);
  }
  static void times(const closing::QueryTiming& in, StageTimes* t) {
    t->search = in.search_ms;
    t->verify = in.verify_ms;
    t->refine = in.refine_ms;
  }
  std::vector<Candidate> convert(const std::vector<closing::FoundLoop>& found) const {
    std::vector<Candidate> out;
    for (const auto& f : found) {
      const auto& r = f.result;
      out.push_back({frames_.at(f.scan_id), r.score, r.is_loop, r.refined, r.inliers, r.T, f.descriptor_distance,
                     r.probability, r.considered});
    }
    return out;
  }

  Pipeline pipeline_;
  std::unique_ptr<storage::MapStore> store_;
  closing::LoopFinder finder_;
  std::map<int, std::int64_t> ids_;
  std::map<std::int64_t, int> frames_;
};

class Remote final : public Backend {
 public:
  Remote(const std::string& address, const std::string& token, std::string map, bool keep_map)
      : client_(client::Client::connect(address, {.token = token, .default_deadline = std::chrono::minutes(5)})),
        map_(std::move(map)),
        keep_map_(keep_map) {
    client_.createMap(map_);
  }
  ~Remote() override {
    if (keep_map_) return;
    try {
      client_.deleteMap(map_);
    } catch (const std::exception& e) {
      std::cerr << "sglc-eval: warning: could not delete map " << map_ << " on the server: " << e.what() << "\n";
    }
  }
  Remote(const Remote&) = delete;
  Remote& operator=(const Remote&) = delete;
  std::string name() const override { return "server"; }

  void add(int frame, const LabelledScan& scan, StageTimes* t) override {
    const auto r = client_.ingest(client::makeKey(map_, kRobot, kSession, frame), scan);
    record(frame, r.scan_id());
    times(r.timing(), t);
  }

  std::vector<Candidate> queryThenAdd(int frame, const LabelledScan& scan, const LoopQuery& q, StageTimes* t) override {
    client::IngestOptions io;
    io.query = true;
    io.query_options = searchOptions(q);
    const auto r = client_.ingest(client::makeKey(map_, kRobot, kSession, frame), scan, io);
    record(frame, r.scan_id());
    times(r.timing(), t);
    return convert(r.loops());
  }

  std::vector<Candidate> query(const LabelledScan& scan, const LoopQuery& q, StageTimes* t) override {
    // No robot in the request: no scan is excluded.
    const auto r = client_.queryScan(map_, scan, searchOptions(q));
    times(r.timing(), t);
    return convert(r.candidates());
  }

  std::vector<Candidate> verify(int query, const std::vector<int>& candidates, Refine refine, StageTimes* t) override {
    std::vector<Candidate> out;
    StageTimes sum;
    for (std::size_t first = 0; first < candidates.size(); first += 100) {  // top_k is at most 100
      const auto last = std::min(candidates.size(), first + 100);
      auto o = options(refine, static_cast<int>(last - first));
      for (auto i = first; i < last; ++i) o.add_verify_scan_ids(ids_.at(candidates[i]));
      const auto r = client_.queryScanId(map_, ids_.at(query), o);
      StageTimes part;
      times(r.timing(), &part);
      sum.search += part.search;
      sum.verify += part.verify;
      sum.refine += part.refine;
      sum.total += part.total;
      const auto c = convert(r.candidates());
      out.insert(out.end(), c.begin(), c.end());
    }
    *t = sum;
    return out;
  }

 private:
  static v1::QueryOptions options(Refine refine, int n) {
    v1::QueryOptions o;
    o.set_top_k(static_cast<std::uint32_t>(n));
    o.set_include_rejected(true);
    o.set_refine(refine != Refine::none);
    o.set_refine_set(true);
    o.set_known_loops(refine == Refine::known_loops);
    return o;
  }
  // A search of the whole map, as InProcess::find runs it.
  static v1::QueryOptions searchOptions(const LoopQuery& q) {
    auto o = options(q.refine ? Refine::verified : Refine::none, q.candidates);
    o.set_scope(v1::SCOPE_WHOLE_MAP);
    o.set_exclude_recent(q.exclude_recent);
    o.set_candidates(static_cast<std::uint32_t>(q.candidates));
    return o;
  }
  static void times(const v1::Timing& in, StageTimes* t) {
    t->fingerprint = in.fingerprint_ms();
    t->search = in.search_ms();
    t->verify = in.verify_ms();
    t->refine = in.refine_ms();
    t->store = in.store_ms();
    t->total = in.total_ms();
  }
  void record(int frame, std::int64_t id) {
    ids_[frame] = id;
    frames_[id] = frame;
  }
  std::vector<Candidate> convert(const google::protobuf::RepeatedPtrField<v1::Candidate>& in) const {
    std::vector<Candidate> out;
    for (const auto& c : in) {
      const auto it = frames_.find(c.scan_id());
      if (it == frames_.end()) continue;  // not one of ours (the map is new, so this does not happen)
      Candidate e{it->second,  c.score(),         c.verified(),           c.refined(),
                  c.inliers(), Mat4d::Identity(), c.descriptor_distance()};
      if (client::isSet(c.t_query_candidate())) e.T = client::toMatrix(c.t_query_candidate());
      out.push_back(e);
    }
    return out;
  }

  client::Client client_;
  std::string map_;
  bool keep_map_ = false;
  std::map<int, std::int64_t> ids_;
  std::map<std::int64_t, int> frames_;
};

}  // namespace

std::unique_ptr<Backend> inProcessBackend(const Config& config, const std::string& scratch_dir) {
  return std::make_unique<InProcess>(config, scratch_dir);
}

std::unique_ptr<Backend> serverBackend(const std::string& address, const std::string& token, const std::string& map,
                                       bool keep_map) {
  return std::make_unique<Remote>(address, token, map, keep_map);
}

}  // namespace sglc::eval
