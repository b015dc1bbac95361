// `sglc` command-line errors that need no server: every one exits non-zero with exactly one line on
// stderr that says what is wrong, and prints nothing on stdout.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>

#include "client_test_util.hpp"
#include "sglc/v1/sglc.grpc.pb.h"

namespace t = sglc::client::test;

namespace {

// Runs sglc with arguments and checks the one-line-error contract; returns the error line.
std::string expectOneLineError(const std::vector<std::string>& args, const std::string& must_mention) {
  std::vector<std::string> argv = {t::cliBinary()};
  argv.insert(argv.end(), args.begin(), args.end());
  const auto r = t::run(argv);
  std::string joined;
  for (const auto& a : args) joined += " " + a;
  EXPECT_NE(r.exit_code, 0) << "sglc" << joined;
  EXPECT_NE(r.exit_code, -1) << "sglc" << joined << " crashed or hung";
  const auto err = t::lines(r.err);
  EXPECT_EQ(err.size(), 1u) << "sglc" << joined << " stderr: " << r.err;
  EXPECT_EQ(r.out, "") << "sglc" << joined;
  const std::string line = err.empty() ? "" : err[0];
  EXPECT_EQ(line.rfind("sglc: error: ", 0), 0u) << line;
  EXPECT_NE(line.find(must_mention), std::string::npos)
      << "sglc" << joined << ": '" << line << "' lacks '" << must_mention << "'";
  return line;
}

// A sequence directory with one (tiny, valid) scan.
std::string tinySequence(const t::TempDir& tmp) {
  const auto dir = tmp.path() / "seq";
  std::filesystem::create_directories(dir / "velodyne");
  std::filesystem::create_directories(dir / "labels");
  sglc::writeKittiBin((dir / "velodyne/000000.bin").string(), {{1, 2, 3}}, {0.5f});
  sglc::writeLabels((dir / "labels/000000.label").string(), {40});
  return dir.string();
}

}  // namespace

TEST(CliErrors, CommandLineMistakes) {
  expectOneLineError({}, "subcommand");
  expectOneLineError({"frobnicate"}, "frobnicate");
  expectOneLineError({"maps", "--bogus"}, "--bogus");
  expectOneLineError({"ingest", "--robot", "r", "/tmp"}, "--map");
  expectOneLineError({"ingest", "--map", "m", "/tmp"}, "--robot");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r"}, "DIR");
  expectOneLineError({"robots"}, "--map");
  expectOneLineError({"delete", "--map", "m"}, "--robot");
  expectOneLineError({"backup"}, "NAME");
  expectOneLineError({"loops", "--map", "m", "--format", "xml"}, "--format must be json or csv");
  expectOneLineError({"loops", "--map", "m", "--format", "g2o"}, "sglc export --map m --format g2o");
  expectOneLineError({"export", "--map", "m", "--format", "xml", "--out", "d"}, "--format must be g2o, json or mcap");
  expectOneLineError({"trajectory", "--map", "m", "--robot", "r", "--out", "x", "--format", "g2o"}, "kitti or tum");
  expectOneLineError({"create-map"}, "MAP");
  expectOneLineError({"stats", "--top-k", "3"}, "--top-k");
  expectOneLineError({"query", "--map", "m", "--scan-id", "notanumber"}, "notanumber");
}

TEST(CliErrors, BadIngestInput) {
  t::TempDir tmp;
  const auto dir = tinySequence(tmp);
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", tmp / "missing"}, "not a directory");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", tmp.path().string()}, "velodyne");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", "--frames", "9:3", dir}, "frame selection");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", "--frames", "x", dir}, "frame selection");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", "--frames", "5:9", dir}, "no scans in frame selection");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", "--every", "0", dir}, "--every");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", "--scope", "galaxy", dir}, "galaxy");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", "--scope", "sessions", dir}, "--sessions");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", "--scope", "sessions", "--sessions", "a/b,nobody", dir},
                     "'nobody' is not robot/session");
  expectOneLineError({"ingest", "--map", "", "--robot", "r", dir}, "--map");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", "--chunk-mb", "0", dir}, "--chunk-mb");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", "--window", "0", dir}, "--window");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", "--poses", tmp / "odom.txt", dir}, "odom.txt");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", "--poses-frame", "imu", dir}, "imu");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", "--poses-frame", "camera", dir}, "poses");
  // Labels all present or all absent (velodyne/ only is an unlabelled sequence): one missing is an error.
  sglc::writeKittiBin(dir + "/velodyne/000001.bin", {{1, 2, 3}}, {0.5f});
  sglc::writeLabels(dir + "/labels/000001.label", {40});
  std::filesystem::remove(dir + "/labels/000000.label");
  expectOneLineError({"ingest", "--map", "m", "--robot", "r", dir}, "000000.label");
}

TEST(CliErrors, BadQueryInput) {
  t::TempDir tmp;
  expectOneLineError({"query", "--map", "m"}, "--scan-id");
  expectOneLineError({"query", "--map", "m", "--scan-id", "3", "--scan", "a.bin", "--labels", "a.label"}, "either");
  expectOneLineError({"query", "--map", "m", "--labels", "a.label"}, "--labels goes with --scan");
  expectOneLineError({"query", "--map", "m", "--scan", "a.xyz"}, "unsupported format: '.xyz'");
  expectOneLineError({"query", "--map", "m", "--scan", "a.bin"}, "a.bin: cannot open");
  expectOneLineError({"query", "--map", "m", "--scan", tmp / "none.bin", "--labels", tmp / "none.label"}, "none.bin");
  expectOneLineError({"query", "--map", "m", "--scan-id", "3", "--exclude-recent", "-1"}, "--exclude-recent");
  expectOneLineError({"query", "--map", "m", "--scan-id", "3", "--known-loops", "--no-refine"}, "--known-loops");
  expectOneLineError({"query", "--map", "m", "--scan-id", "3", "--verify", "x"}, "--verify");
  expectOneLineError({"query", "--map", "m", "--scan-id", "3", "--sessions", "a/b"}, "--scope sessions");
}

TEST(CliErrors, ConnectionProblemsNameTheStatus) {
  t::TempDir tmp;
  const std::string nobody = "127.0.0.1:" + std::to_string(t::freePort());
  expectOneLineError({"maps", "--server", nobody}, "UNAVAILABLE");
  expectOneLineError({"stats", "--json", "--server", nobody}, "UNAVAILABLE");
  expectOneLineError({"--server", nobody, "robots", "--map", "m"}, "UNAVAILABLE");
  expectOneLineError({"ingest", "--server", nobody, "--map", "m", "--robot", "r", tinySequence(tmp)}, "UNAVAILABLE");
  expectOneLineError({"maps", "--tls-ca", tmp / "nothere.pem"}, "nothere.pem");
  t::writeFile(tmp / "junk.pem", "not a certificate");
  expectOneLineError({"maps", "--tls-ca", tmp / "junk.pem"}, "PEM");
  expectOneLineError({"maps", "--server", ""}, "--server");
}

TEST(Cli, HelpListsEverySubcommand) {
  const auto r = t::run({t::cliBinary(), "--help"});
  EXPECT_EQ(r.exit_code, 0);
  for (const char* sub : {"ingest", "query", "maps", "robots", "stats", "delete", "backup", "create-map", "loops",
                          "trajectory", "health"})
    EXPECT_NE(r.out.find(sub), std::string::npos) << sub;
}

TEST(Cli, VersionAndHealthOfAServerThatIsNotThere) {
  const auto v = t::run({t::cliBinary(), "--version"});
  EXPECT_EQ(v.exit_code, 0);
  EXPECT_EQ(v.out.rfind("sglc ", 0), 0u) << v.out;
  // Nothing listens on port 1: the probe fails with exit 1 and names the status.
  const auto h = t::run({t::cliBinary(), "health", "--server", "127.0.0.1:1", "--timeout", "5"});
  EXPECT_EQ(h.exit_code, 1);
  EXPECT_NE(h.err.find("UNAVAILABLE"), std::string::npos) << h.err;
}

namespace {

// An IngestStream whose first stream answers three scans, reads one more and fails with UNAVAILABLE (a replica
// that went away); later streams answer every scan. It records the seqs each stream received.
class BreakingLoopClosure final : public sglc::v1::LoopClosure::Service {
 public:
  grpc::Status IngestStream(
      grpc::ServerContext*,
      grpc::ServerReaderWriter<sglc::v1::IngestResponse, sglc::v1::IngestRequest>* stream) override {
    std::size_t n;
    {
      std::lock_guard lock(mutex);
      n = received.size();
      received.emplace_back();
    }
    sglc::v1::IngestRequest r;
    for (int answered = 0; stream->Read(&r);) {
      {
        std::lock_guard lock(mutex);
        received[n].push_back(r.key().seq());
      }
      if (n == 0 && answered == 3) return {grpc::StatusCode::UNAVAILABLE, "the replica went away"};
      sglc::v1::IngestResponse response;
      response.set_scan_id(1000 + r.key().seq());
      stream->Write(response);
      ++answered;
    }
    return grpc::Status::OK;
  }
  std::mutex mutex;
  std::vector<std::vector<std::int64_t>> received;
};

class AcceptingMapAdmin final : public sglc::v1::MapAdmin::Service {
  grpc::Status CreateMap(grpc::ServerContext*, const sglc::v1::CreateMapRequest* request,
                         sglc::v1::MapInfo* info) override {
    info->set_name(request->name());
    return grpc::Status::OK;
  }
};

// A server on a free loopback port with the fake services given; port 0 when it could not start.
std::unique_ptr<grpc::Server> serveFakes(std::initializer_list<grpc::Service*> services, int& port) {
  grpc::ServerBuilder builder;
  builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port);
  for (auto* service : services) builder.RegisterService(service);
  return builder.BuildAndStart();
}

}  // namespace

// A stream that breaks mid-run is reopened and only the unanswered scans are sent again, each once: every frame
// is answered exactly once (a frame was sent twice after each break before).
TEST(Cli, IngestResendsEachUnansweredScanOnceAfterTheStreamBreaks) {
  t::TempDir tmp;
  const auto dir = tmp.path() / "seq";
  std::filesystem::create_directories(dir / "velodyne");
  const int frames = 12;
  for (int i = 0; i < frames; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "%06d.bin", i);
    sglc::writeKittiBin((dir / "velodyne" / name).string(), {{1.0f * i, 2, 3}}, {0.5f});
  }
  BreakingLoopClosure loop;
  AcceptingMapAdmin admin;
  int port = 0;
  const auto server = serveFakes({&loop, &admin}, port);
  ASSERT_TRUE(server && port > 0);
  const auto r = t::run({t::cliBinary(), "ingest", "--server", "127.0.0.1:" + std::to_string(port), "--map", "m",
                         "--robot", "r", "--json", "--no-progress", "--window", "4", dir.string()});
  server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(5));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  std::multiset<std::string> answered;
  for (const auto& line : t::lines(r.out)) answered.insert(nlohmann::json::parse(line).at("frame").get<std::string>());
  EXPECT_EQ(answered.size(), static_cast<std::size_t>(frames));
  for (const auto& frame : answered) EXPECT_EQ(answered.count(frame), 1u) << "frame " << frame << " answered twice";
  std::lock_guard lock(loop.mutex);
  ASSERT_GE(loop.received.size(), 2u) << "the first stream did not break";
  std::set<std::int64_t> all;
  for (std::size_t s = 1; s < loop.received.size(); ++s) {
    const auto& seqs = loop.received[s];
    EXPECT_EQ(std::set<std::int64_t>(seqs.begin(), seqs.end()).size(), seqs.size()) << "a seq sent twice on a stream";
    all.insert(seqs.begin(), seqs.end());
  }
  for (int i = 3; i < frames; ++i) EXPECT_TRUE(all.count(i)) << "seq " << i << " never resent";
}

namespace {

// Answers every scan, except that it ends the stream with INVALID_ARGUMENT on the seq `reject` (as the server
// does on a scan it refuses).
class AnsweringLoopClosure final : public sglc::v1::LoopClosure::Service {
 public:
  explicit AnsweringLoopClosure(std::int64_t reject) : reject_(reject) {}
  grpc::Status IngestStream(
      grpc::ServerContext*,
      grpc::ServerReaderWriter<sglc::v1::IngestResponse, sglc::v1::IngestRequest>* stream) override {
    sglc::v1::IngestRequest r;
    while (stream->Read(&r)) {
      if (r.key().seq() == reject_) return {grpc::StatusCode::INVALID_ARGUMENT, "scan is empty"};
      sglc::v1::IngestResponse response;
      response.set_scan_id(1000 + r.key().seq());
      stream->Write(response);
    }
    return grpc::Status::OK;
  }

 private:
  std::int64_t reject_;
};

// Runs `sglc ingest` over four frames (window 4) against the fakes; frame `corrupt` is a truncated .bin.
t::RunResult ingestFour(std::int64_t reject, int corrupt) {
  t::TempDir tmp;
  const auto dir = tmp.path() / "seq";
  std::filesystem::create_directories(dir / "velodyne");
  for (int i = 0; i < 4; ++i) {
    const auto path = (dir / "velodyne" / ("00000" + std::to_string(i) + ".bin")).string();
    sglc::writeKittiBin(path, {{1.0f * i, 2, 3}}, {0.5f});
    if (i == corrupt) std::filesystem::resize_file(path, 10);
  }
  AnsweringLoopClosure loop(reject);
  AcceptingMapAdmin admin;
  int port = 0;
  const auto server = serveFakes({&loop, &admin}, port);
  EXPECT_TRUE(server && port > 0);
  auto r = t::run({t::cliBinary(), "ingest", "--server", "127.0.0.1:" + std::to_string(port), "--map", "m", "--robot",
                   "r", "--no-progress", "--window", "4", dir.string()});
  server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(5));
  return r;
}

}  // namespace

// The count in "after N of M scans were stored" is the scans the server acknowledged: those sent before a scan
// that cannot be read are answered first (it said 0 while two were stored).
TEST(Cli, IngestFailureCountsTheScansActuallyStored) {
  const auto unreadable = ingestFour(-1, 2);
  EXPECT_EQ(unreadable.exit_code, 1) << unreadable.err;
  EXPECT_NE(unreadable.err.find("000002.bin"), std::string::npos) << unreadable.err;
  EXPECT_NE(unreadable.err.find("after 2 of 4 scans were stored"), std::string::npos) << unreadable.err;
  const auto refused = ingestFour(1, -1);
  EXPECT_EQ(refused.exit_code, 1) << refused.err;
  EXPECT_NE(refused.err.find("INVALID_ARGUMENT"), std::string::npos) << refused.err;
  EXPECT_NE(refused.err.find("after 1 of 4 scans were stored"), std::string::npos) << refused.err;
}
