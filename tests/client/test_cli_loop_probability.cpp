// `sglc loops` and `sglc query` show the loop model's probability (unknown for loops recorded before it), and
// `--evidence` asks for and prints each candidate's evidence: against fake services on loopback.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <atomic>
#include <nlohmann/json.hpp>

#include "client_test_util.hpp"
#include "sglc/v1/sglc.grpc.pb.h"

namespace t = sglc::client::test;
namespace v1 = sglc::v1;

namespace {

// Two stored loops: one recorded with a probability, one before the loop model.
class FakePoseGraph final : public v1::PoseGraph::Service {
  grpc::Status GetLoops(grpc::ServerContext*, const v1::GetLoopsRequest*, v1::GetLoopsResponse* r) override {
    for (int id : {1, 2}) {
      auto* l = r->add_loops();
      l->set_id(id);
      l->mutable_query()->set_scan_id(10 + id);
      l->mutable_candidate()->set_scan_id(id);
      l->set_score(0.5);
      for (int k = 0; k < 16; ++k) l->mutable_t_query_candidate()->add_m(k % 5 == 0 ? 1.0 : 0.0);
      if (id == 1) l->set_probability(0.875);
    }
    return grpc::Status::OK;
  }
};

// One candidate with a probability, and its evidence when the request asks for it.
class FakeLoopClosure final : public v1::LoopClosure::Service {
 public:
  grpc::Status Query(grpc::ServerContext*, const v1::QueryRequest* q, v1::QueryResponse* r) override {
    asked_evidence = q->options().include_evidence();
    auto* c = r->add_candidates();
    c->set_scan_id(5);
    c->set_score(0.25);
    c->set_verified(false);
    c->set_probability(0.3125);
    if (asked_evidence) {
      c->mutable_evidence()->set_source(v1::EVIDENCE_SOURCE_VIEW);
      c->mutable_evidence()->set_agreement(0.625);
    }
    return grpc::Status::OK;
  }
  std::atomic<bool> asked_evidence{false};
};

class Fakes {
 public:
  Fakes() {
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port_);
    builder.RegisterService(&graph_);
    builder.RegisterService(&loops);
    server_ = builder.BuildAndStart();
  }
  ~Fakes() { server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(5)); }
  // sglc SUBCOMMAND --server (these fakes) ARGS...
  t::RunResult run(const std::vector<std::string>& args) {
    std::vector<std::string> argv{t::cliBinary(), args.at(0), "--server", "127.0.0.1:" + std::to_string(port_)};
    argv.insert(argv.end(), args.begin() + 1, args.end());
    return t::run(argv);
  }
  FakeLoopClosure loops;

 private:
  FakePoseGraph graph_;
  int port_ = 0;
  std::unique_ptr<grpc::Server> server_;
};

TEST(CliLoopProbability, LoopsShowTheProbabilityAndUnknownStaysUnknown) {
  Fakes fakes;
  const auto json = fakes.run({"loops", "--map", "m", "--format", "json"});
  ASSERT_EQ(json.exit_code, 0) << json.err;
  const auto lines = t::lines(json.out);
  ASSERT_EQ(lines.size(), 2u) << json.out;
  EXPECT_EQ(nlohmann::json::parse(lines[0]).at("probability").get<double>(), 0.875);
  EXPECT_TRUE(nlohmann::json::parse(lines[1]).at("probability").is_null());
  const auto csv = fakes.run({"loops", "--map", "m", "--format", "csv"});
  ASSERT_EQ(csv.exit_code, 0) << csv.err;
  const auto rows = t::lines(csv.out);
  ASSERT_EQ(rows.size(), 3u) << csv.out;
  EXPECT_NE(rows[0].find(",score,probability,"), std::string::npos) << rows[0];
  EXPECT_NE(rows[1].find(",0.5,0.875,"), std::string::npos) << rows[1];
  EXPECT_NE(rows[2].find(",0.5,,"), std::string::npos) << rows[2];
}

TEST(CliLoopProbability, QueryShowsTheProbabilityAndOnRequestTheEvidence) {
  Fakes fakes;
  const auto text = fakes.run({"query", "--map", "m", "--scan-id", "3", "--include-rejected"});
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_FALSE(fakes.loops.asked_evidence);
  EXPECT_NE(text.out.find("probability 0.312"), std::string::npos) << text.out;
  EXPECT_EQ(text.out.find("evidence"), std::string::npos) << text.out;
  const auto json = fakes.run({"query", "--map", "m", "--scan-id", "3", "--include-rejected", "--evidence", "--json"});
  ASSERT_EQ(json.exit_code, 0) << json.err;
  EXPECT_TRUE(fakes.loops.asked_evidence);
  const auto c = nlohmann::json::parse(json.out).at("candidates").at(0);
  EXPECT_EQ(c.at("probability").get<double>(), 0.3125);
  EXPECT_FALSE(c.at("verified").get<bool>());  // a rejected candidate carries its evidence too
  EXPECT_EQ(c.at("evidence").at("source"), "VIEW");
  EXPECT_EQ(c.at("evidence").at("agreement").get<double>(), 0.625);
}

}  // namespace
