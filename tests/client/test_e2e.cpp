// End to end against a real sglc-server started on a free loopback port with a fresh database.
// Skipped (with the reason) when the server binary or the real scans of ../shared/data are absent.
//
// The loop pair: KITTI 00 frames 52 (robot "a") and 4501 (robot "b"). pairs.txt gives T_a_b = T_52_4501,
// mapping 4501's points into 52's frame. A candidate's T maps the candidate into the query's frame, so:
//   query 4501, candidate 52  ->  T = T_4501_52 = inverse(T_a_b)
//   query 52,   candidate 4501 ->  T = T_a_b
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <set>

#include "client_test_util.hpp"

namespace sc = sglc::client;
namespace t = sglc::client::test;
namespace v1 = sglc::v1;
using json = nlohmann::json;

namespace {

class EndToEnd : public ::testing::Test {
 protected:
  void SetUp() override { startServer({}); }

  void startServer(const std::vector<std::string>& args) {
    if (!t::haveRealData())
      GTEST_SKIP() << "real scans not found under " << t::sharedData() << "; end-to-end test skipped";
    const auto ref = t::referenceT52from4501();
    ASSERT_TRUE(ref) << "pairs.txt has no 00 000052 004501 row";
    T_a_b_ = *ref;
    std::string why;
    server_ = t::ServerProcess::start(args, &why);
    if (!server_) GTEST_SKIP() << why;
  }

  // Runs `sglc ARGS --server ADDR`.
  t::RunResult cli(std::vector<std::string> args) const {
    std::vector<std::string> argv = {t::cliBinary()};
    argv.insert(argv.end(), args.begin(), args.end());
    argv.push_back("--server");
    argv.push_back(server_->address());
    return t::run(argv);
  }

  static void expectPose(const sglc::Mat4d& T, const sglc::Mat4d& ref, const std::string& what) {
    const auto [dt, dr] = t::poseError(T, ref);
    EXPECT_LT(dt, t::kMaxTranslationError) << what << ": translation error " << dt << " m\n" << T;
    EXPECT_LT(dr, t::kMaxRotationErrorDeg) << what << ": rotation error " << dr << " deg\n" << T;
    EXPECT_EQ(T.row(3), Eigen::RowVector4d(0, 0, 0, 1)) << what;
  }

  static sglc::Mat4d fromJson(const json& T) {
    sglc::Mat4d M;
    for (int k = 0; k < 16; ++k) M(k / 4, k % 4) = T.at(k).get<double>();
    return M;
  }

  std::optional<t::ServerProcess> server_;
  sglc::Mat4d T_a_b_;
};

v1::QueryOptions otherRobots() {
  v1::QueryOptions o;
  o.set_scope(v1::SCOPE_OTHER_ROBOTS);
  return o;
}

const v1::Candidate* findCandidate(const google::protobuf::RepeatedPtrField<v1::Candidate>& cs, std::int64_t id) {
  for (const auto& c : cs)
    if (c.scan_id() == id) return &c;
  return nullptr;
}

}  // namespace

TEST_F(EndToEnd, InterRobotLoopThroughTheLibrary) {
  const auto client = server_->client();
  EXPECT_EQ(client.createMap("loops").name(), "loops");
  const auto a = client.ingest(sc::makeKey("loops", "a", "00", 52), t::realScan("000052"));
  EXPECT_EQ(a.seq(), 52);
  EXPECT_EQ(a.loops_size(), 0);  // no query requested

  // Robot b arrives at the place robot a saw: its scan is the query, a's scan the candidate.
  sc::IngestOptions o;
  o.query = true;
  o.query_options = otherRobots();
  const auto b = client.ingest(sc::makeKey("loops", "b", "00", 4501), t::realScan("004501"), o);
  EXPECT_NE(b.scan_id(), a.scan_id());
  ASSERT_GE(b.loops_size(), 1) << "no inter-robot loop found; server log:\n" << server_->log();
  const auto& loop = b.loops(0);
  EXPECT_EQ(loop.scan_id(), a.scan_id());
  EXPECT_EQ(loop.robot(), "a");
  EXPECT_EQ(loop.session(), "00");
  EXPECT_EQ(loop.seq(), 52);
  EXPECT_TRUE(loop.verified());
  EXPECT_GT(loop.inliers(), 0);
  EXPECT_GT(loop.score(), 0.0);
  EXPECT_LE(loop.score(), 1.0);
  expectPose(sc::toMatrix(loop.t_query_candidate()), T_a_b_.inverse(), "query 4501, candidate 52");

  // The other direction, by id: 52 queries, 4501 is the candidate.
  const auto q = client.queryScanId("loops", a.scan_id(), otherRobots());
  const auto* c = findCandidate(q.candidates(), b.scan_id());
  ASSERT_NE(c, nullptr) << "4501 not among the candidates of 52";
  EXPECT_TRUE(c->verified());
  EXPECT_EQ(c->robot(), "b");
  expectPose(sc::toMatrix(c->t_query_candidate()), T_a_b_, "query 52, candidate 4501");

  // Relocalization with a scan that is not stored: 4501's cloud again, scope whole map.
  const auto reloc = client.queryScan("loops", t::realScan("004501"));
  const auto* r = findCandidate(reloc.candidates(), a.scan_id());
  ASSERT_NE(r, nullptr) << "52 not found by relocalization";
  expectPose(sc::toMatrix(r->t_query_candidate()), T_a_b_.inverse(), "relocalization of 4501, candidate 52");

  // Scope: robot b asking only about its own scans sees no loop with a.
  v1::QueryOptions same;
  same.set_scope(v1::SCOPE_SAME_ROBOT);
  EXPECT_EQ(findCandidate(client.queryScanId("loops", b.scan_id(), same).candidates(), a.scan_id()), nullptr);
}

TEST_F(EndToEnd, AdminCallsAndErrors) {
  const auto client = server_->client();
  client.createMap("m1");
  const auto s52 = client.ingest(sc::makeKey("m1", "a", "run1", 52), t::realScan("000052"));
  const auto s88 = client.ingest(sc::makeKey("m1", "a", "run2", 88), t::realScan("000088"));
  client.ingest(sc::makeKey("m1", "b", "run1", 4501), t::realScan("004501"));

  const auto maps = client.listMaps();
  ASSERT_EQ(maps.size(), 1u);
  EXPECT_EQ(maps[0].name(), "m1");
  EXPECT_EQ(maps[0].scans(), 3);
  EXPECT_EQ(maps[0].robots(), 2);
  EXPECT_EQ(maps[0].sessions(), 3);

  const auto robots = client.listRobots("m1");
  ASSERT_EQ(robots.size(), 2u);
  for (const auto& r : robots) EXPECT_EQ(r.scans(), r.name() == "a" ? 2 : 1) << r.name();
  const auto sessions = client.listSessions("m1", "a");
  ASSERT_EQ(sessions.size(), 2u);
  EXPECT_EQ(client.listSessions("m1").size(), 3u);

  const auto info = client.getScan(s88.scan_id());
  EXPECT_EQ(info.key().map(), "m1");
  EXPECT_EQ(info.key().robot(), "a");
  EXPECT_EQ(info.key().session(), "run2");
  EXPECT_EQ(info.key().seq(), 88);
  EXPECT_GT(info.fingerprint_bytes(), 0);
  EXPECT_FALSE(sc::isSet(info.odometry_pose()));

  auto stats = client.getStats();
  EXPECT_EQ(stats.maps(), 1);
  EXPECT_EQ(stats.robots(), 2);
  EXPECT_EQ(stats.scans(), 3);

  // Errors carry the documented status codes.
  auto code = [](auto&& call) {
    try {
      call();
    } catch (const sc::RpcError& e) {
      return e.code();
    }
    return grpc::StatusCode::OK;
  };
  EXPECT_EQ(code([&] { client.listRobots("nosuchmap"); }), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(code([&] { client.queryScanId("m1", 999999); }), grpc::StatusCode::NOT_FOUND);
  // The identical scan again is a retry (OK, the stored scan); another scan under a stored key is refused.
  EXPECT_EQ(code([&] { client.ingest(sc::makeKey("m1", "a", "run1", 52), t::realScan("000052")); }),
            grpc::StatusCode::OK);
  EXPECT_EQ(code([&] { client.ingest(sc::makeKey("m1", "a", "run1", 52), t::realScan("000088")); }),
            grpc::StatusCode::ALREADY_EXISTS);
  EXPECT_EQ(code([&] { client.ingest(sc::makeKey("m1", "a", "run1", 53), sglc::LabelledScan{}); }),
            grpc::StatusCode::INVALID_ARGUMENT);
  sglc::LabelledScan nan_scan = t::realScan("000052");
  nan_scan.points[10].x() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(code([&] { client.ingest(sc::makeKey("m1", "a", "run1", 54), nan_scan); }),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(client.getStats().scans(), 3) << "a failed call stored something";

  // Deletes.
  EXPECT_EQ(client.deleteSession("m1", "a", "run1"), 1);
  EXPECT_EQ(code([&] { client.getScan(s52.scan_id()); }), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client.deleteRobot("m1", "b"), 1);
  stats = client.getStats("m1");
  EXPECT_EQ(stats.scans(), 1);
  EXPECT_EQ(stats.robots(), 1);

  // Backup: a new file on the server's machine (here the same one). A plain file name is the one form
  // every server accepts (this one writes it into its backup directory and returns the full path).
  const auto backup = client.backup("backup-e2e.db");
  EXPECT_GT(backup.bytes(), 0);
  EXPECT_FALSE(backup.path().empty());
  if (std::filesystem::path(backup.path()).is_absolute()) {
    EXPECT_TRUE(std::filesystem::exists(backup.path())) << backup.path();
  }
  EXPECT_NE(code([&] { client.backup("backup-e2e.db"); }), grpc::StatusCode::OK) << "backup over an existing file";
}

TEST_F(EndToEnd, ChunkedIngestAndStreamSession) {
  // A 256 kB limit sends every real scan (~2 MB packed) through IngestChunked.
  const auto chunked = server_->client("", 256 * 1024);
  chunked.createMap("c");
  const auto a = chunked.ingest(sc::makeKey("c", "a", "00", 52), t::realScan("000052"));
  chunked.getScan(a.scan_id());

  // A robot's run over the stream: robot a revisits (frame 4501 of the same session) and the
  // pipelined second response reports the loop with the scan the chunked call stored.
  const auto client = server_->client();
  client.ensureMap("c");  // exists: not an error
  auto session = client.openSession();
  sc::IngestOptions o;
  o.query = true;
  o.query_options.set_scope(v1::SCOPE_SAME_ROBOT);
  o.query_options.set_exclude_recent(50);
  session.send(sc::makeKey("c", "a", "01", 88), t::realScan("000088"), o);
  session.send(sc::makeKey("c", "a", "01", 4501), t::realScan("004501"), o);
  const auto r88 = session.next();
  const auto r4501 = session.next();
  EXPECT_TRUE(session.finish().empty());
  EXPECT_EQ(r88.seq(), 88);
  EXPECT_EQ(r4501.seq(), 4501);
  const auto* loop = findCandidate(r4501.loops(), a.scan_id());
  ASSERT_NE(loop, nullptr) << "the chunked scan 52 was not found from 4501";
  expectPose(sc::toMatrix(loop->t_query_candidate()), T_a_b_.inverse(), "stream 4501 vs chunked 52");

  // Another scan under a stored key ends the stream with ALREADY_EXISTS; the scan before it is stored.
  auto again = client.openSession();
  again.send(sc::makeKey("c", "a", "02", 850), t::realScan("000850"));
  again.send(sc::makeKey("c", "a", "01", 88), t::realScan("000850"));
  EXPECT_EQ(again.next().seq(), 850);
  try {
    again.next();
    FAIL() << "duplicate accepted";
  } catch (const sc::RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::ALREADY_EXISTS) << e.what();
  }
  EXPECT_EQ(client.getStats("c").scans(), 4);
}

TEST_F(EndToEnd, CommandLine) {
  const std::string dir = t::sequence00();
  auto r = cli({"create-map", "cli"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("cli"), std::string::npos);

  // Robot a drives past frame 52.
  r = cli({"ingest", "--map", "cli", "--robot", "a", "--frames", "52", dir, "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto out = t::lines(r.out);
  ASSERT_EQ(out.size(), 1u) << r.out;
  const json first = json::parse(out[0]);
  ASSERT_TRUE(first.at("scan_id").is_number_integer());
  EXPECT_EQ(first.at("frame"), "000052");
  EXPECT_TRUE(first.at("loops").is_array() && first.at("loops").empty());
  const std::int64_t id52 = first.at("scan_id");

  // Robot b at frame 4501 asks for inter-robot loops as it goes (--frames from 4000 on: only 4501).
  r = cli({"ingest", "--map", "cli", "--robot", "b", "--frames", "4000:", "--query", "--scope", "other", "--top-k", "3",
           "--json", dir});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  out = t::lines(r.out);
  ASSERT_EQ(out.size(), 1u) << r.out;
  const json second = json::parse(out[0]);
  EXPECT_EQ(second.at("frame"), "004501");
  ASSERT_TRUE(second.at("scan_id").is_number_integer());
  ASSERT_GE(second.at("loops").size(), 1u) << out[0];
  const json& loop = second["loops"][0];
  EXPECT_TRUE(loop.at("scan_id").is_number_integer());
  EXPECT_EQ(loop.at("scan_id").get<std::int64_t>(), id52);
  EXPECT_EQ(loop.at("robot"), "a");
  EXPECT_EQ(loop.at("session"), "00");
  EXPECT_TRUE(loop.at("score").is_number_float());
  EXPECT_TRUE(loop.at("inliers").is_number_integer());
  ASSERT_TRUE(loop.at("T").is_array());
  ASSERT_EQ(loop.at("T").size(), 16u);
  for (const auto& v : loop["T"]) EXPECT_TRUE(v.is_number());
  expectPose(fromJson(loop["T"]), T_a_b_.inverse(), "sglc ingest --query: 4501 vs 52");
  ASSERT_TRUE(loop.at("refined").get<bool>());
  ASSERT_EQ(loop.at("information").size(), 36u);  // the loop pose's information matrix, row-major
  for (int i = 0; i < 6; ++i) EXPECT_GT(loop["information"][7 * i].get<double>(), 0.0) << "diagonal " << i;
  const std::set<std::string> keys = {"scan_id", "frame", "loops"};
  for (const auto& [k, v] : second.items()) EXPECT_TRUE(keys.count(k)) << "unexpected key " << k;

  // Text mode of the same (another session name, every frame of the directory): loops are reported.
  r = cli({"ingest", "--map", "cli", "--robot", "c", "--session", "again", "--every", "2", "--query", "--scope",
           "other", "--chunk-mb", "0.5", dir});  // and through IngestChunked (scans are ~1.9 MB packed)
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("ingested 2 scans"), std::string::npos) << r.out;     // frames 52 and 850 of 52, 88, 850, 4501
  EXPECT_NE(r.out.find("frame 000052 (scan "), std::string::npos) << r.out;  // its loops with a's 52 and b's 4501
  EXPECT_NE(r.out.find("robot b, session 00, seq 4501"), std::string::npos) << r.out;

  // Query by id: 52 asks, 4501 answers with T_a_b.
  r = cli({"query", "--map", "cli", "--scan-id", std::to_string(id52), "--scope", "other", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json q = json::parse(r.out);
  bool found = false;
  for (const auto& c : q.at("candidates"))
    if (c.at("scan_id") == second.at("scan_id")) {
      found = true;
      expectPose(fromJson(c.at("T")), T_a_b_, "sglc query --scan-id 52: candidate 4501");
    }
  EXPECT_TRUE(found) << r.out;

  // Exactly one named scan, told it is a loop: 4501 alone, with its pose.
  r = cli({"query", "--map", "cli", "--scan-id", std::to_string(id52), "--verify",
           std::to_string(second.at("scan_id").get<std::int64_t>()), "--known-loops", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json qv = json::parse(r.out);
  ASSERT_EQ(qv.at("candidates").size(), 1u) << r.out;
  EXPECT_EQ(qv["candidates"][0].at("scan_id"), second.at("scan_id"));
  EXPECT_TRUE(qv["candidates"][0].at("refined").get<bool>());
  expectPose(fromJson(qv["candidates"][0].at("T")), T_a_b_, "sglc query --verify 4501 --known-loops");

  // Scope sessions: only b/00 (which holds 4501), the list given before a positional-free command.
  r = cli({"query", "--map", "cli", "--scope", "sessions", "--sessions", "b/00,c/nosuch", "--scan-id",
           std::to_string(id52), "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json qs = json::parse(r.out);
  ASSERT_FALSE(qs.at("candidates").empty()) << r.out;
  for (const auto& c : qs["candidates"]) EXPECT_EQ(c.at("robot"), "b") << r.out;

  // Query by scan file (text).
  r = cli({"query", "--map", "cli", "--scan", dir + "/velodyne/004501.bin", "--labels", dir + "/labels/004501.label"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("candidate"), std::string::npos) << r.out;

  // Stats, maps, robots, sessions, scan.
  r = cli({"stats", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  json stats = json::parse(r.out);
  EXPECT_EQ(stats.at("scans"), 4);
  EXPECT_EQ(stats.at("robots"), 3);
  EXPECT_EQ(stats.at("maps"), 1);
  r = cli({"stats", "--map", "cli"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("scans"), std::string::npos);
  r = cli({"maps", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out).at("maps").at(0).at("name"), "cli");
  r = cli({"maps"});
  EXPECT_NE(r.out.find("cli"), std::string::npos) << r.out;
  r = cli({"robots", "--map", "cli", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out).at("robots").size(), 3u);
  r = cli({"sessions", "--map", "cli", "--robot", "c"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("again"), std::string::npos) << r.out;
  r = cli({"scan", std::to_string(id52), "--json", "--graph"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out).at("seq"), 52);

  // Delete a session, then a robot.
  r = cli({"delete", "--map", "cli", "--robot", "c", "--session", "again", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out).at("scans_removed"), 2);
  r = cli({"delete", "--map", "cli", "--robot", "b"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("removed 1 scans of robot b"), std::string::npos) << r.out;
  r = cli({"stats", "--json"});
  stats = json::parse(r.out);
  EXPECT_EQ(stats.at("scans"), 1);

  // Backup.
  r = cli({"backup", "cli-backup.db", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json backup = json::parse(r.out);
  EXPECT_GT(backup.at("bytes").get<std::int64_t>(), 0);
  if (std::filesystem::path(backup.at("path").get<std::string>()).is_absolute()) {
    EXPECT_TRUE(std::filesystem::exists(backup.at("path").get<std::string>())) << r.out;
  }

  // Server-side errors: non-zero exit, one line naming the status.
  for (const auto& args : std::vector<std::vector<std::string>>{{"robots", "--map", "nosuchmap"},
                                                                {"query", "--map", "cli", "--scan-id", "987654"},
                                                                {"query", "--map", "nosuchmap", "--scan-id", "1"}}) {
    r = cli(args);
    EXPECT_NE(r.exit_code, 0) << args[0];
    const auto err = t::lines(r.err);
    ASSERT_EQ(err.size(), 1u) << r.err;
    EXPECT_TRUE(err[0].find("NOT_FOUND") != std::string::npos || err[0].find("ALREADY_EXISTS") != std::string::npos)
        << err[0];
  }
}

class EndToEndAuth : public EndToEnd {
 protected:
  void SetUp() override {
    tokens_ = std::make_unique<t::TempDir>();
    t::writeFile(*tokens_ / "tokens", "admin-token *\nlimited-token m1\n");
    startServer({"--tokens", *tokens_ / "tokens"});
  }
  std::unique_ptr<t::TempDir> tokens_;
};

TEST_F(EndToEndAuth, BearerTokens) {
  auto code = [](auto&& call) {
    try {
      call();
    } catch (const sc::RpcError& e) {
      return e.code();
    }
    return grpc::StatusCode::OK;
  };
  const auto admin = server_->client("admin-token");
  admin.createMap("m1");
  admin.createMap("m2");
  EXPECT_EQ(admin.listMaps().size(), 2u);

  EXPECT_EQ(code([&] { server_->client().listRobots("m1"); }), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(code([&] { server_->client("wrong").listRobots("m1"); }), grpc::StatusCode::UNAUTHENTICATED);
  const auto limited = server_->client("limited-token");
  EXPECT_EQ(code([&] { limited.listRobots("m1"); }), grpc::StatusCode::OK);
  EXPECT_EQ(code([&] { limited.listRobots("m2"); }), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(code([&] { limited.ingest(sc::makeKey("m2", "a", "s", 52), t::realScan("000052")); }),
            grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(code([&] { limited.ingest(sc::makeKey("m1", "a", "s", 52), t::realScan("000052")); }),
            grpc::StatusCode::OK);

  // The command line passes --token.
  std::vector<std::string> base = {t::cliBinary(), "robots", "--map", "m1", "--json", "--server", server_->address()};
  auto r = t::run(base);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("UNAUTHENTICATED"), std::string::npos) << r.err;
  EXPECT_EQ(t::lines(r.err).size(), 1u) << r.err;
  base.push_back("--token");
  base.push_back("limited-token");
  r = t::run(base);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out).at("robots").size(), 1u);
}
