// The client library against an in-process fake of both services: which RPC carries a scan (single
// message or chunks), what the chunks add up to, the bearer token, deadlines, status codes, and the
// ordering and failure behaviour of an IngestSession. The real server is exercised in test_e2e.cpp.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <algorithm>

#include <mutex>
#include <thread>

#include "sglc/client/client.hpp"

namespace sc = sglc::client;
namespace v1 = sglc::v1;

namespace {

std::string authorization(const grpc::ServerContext* context) {
  const auto& md = context->client_metadata();
  const auto it = md.find("authorization");
  return it == md.end() ? "" : std::string(it->second.data(), it->second.size());
}

// Stores nothing; answers with scan_id = running count, echoes seq. Robot "reject" gets INVALID_ARGUMENT.
class FakeLoopClosure final : public v1::LoopClosure::Service {
 public:
  struct Received {
    std::string rpc;
    v1::IngestRequest request;  // for IngestChunked: the header with the reassembled scan
    std::size_t chunks = 0;
  };

  grpc::Status Ingest(grpc::ServerContext* context, const v1::IngestRequest* request,
                      v1::IngestResponse* response) override {
    return store("Ingest", context, *request, 0, response);
  }

  grpc::Status IngestChunked(grpc::ServerContext* context, grpc::ServerReader<v1::IngestChunk>* reader,
                             v1::IngestResponse* response) override {
    v1::IngestChunk chunk;
    v1::IngestRequest request;
    std::size_t n = 0;
    while (reader->Read(&chunk)) {
      if (n++ == 0) {
        if (!chunk.has_header()) return {grpc::StatusCode::INVALID_ARGUMENT, "first chunk without header"};
        request = chunk.header();
      } else if (chunk.has_header()) {
        return {grpc::StatusCode::INVALID_ARGUMENT, "header in a later chunk"};
      }
      request.mutable_scan()->mutable_points()->append(chunk.points());
      request.mutable_scan()->mutable_labels()->append(chunk.labels());
    }
    return store("IngestChunked", context, request, n, response);
  }

  grpc::Status IngestStream(grpc::ServerContext* context,
                            grpc::ServerReaderWriter<v1::IngestResponse, v1::IngestRequest>* stream) override {
    v1::IngestRequest request;
    while (stream->Read(&request)) {
      v1::IngestResponse response;
      const grpc::Status status = store("IngestStream", context, request, 0, &response);
      if (!status.ok()) return status;
      stream->Write(response);
    }
    return grpc::Status::OK;
  }

  grpc::Status Query(grpc::ServerContext* context, const v1::QueryRequest* request,
                     v1::QueryResponse* response) override {
    std::lock_guard lock(mutex_);
    last_token_ = authorization(context);
    last_query_ = *request;
    auto* c = response->add_candidates();
    c->set_scan_id(request->has_scan() ? -1 : request->scan_id());
    return grpc::Status::OK;
  }

  std::vector<Received> received() {
    std::lock_guard lock(mutex_);
    return received_;
  }
  std::string lastToken() {
    std::lock_guard lock(mutex_);
    return last_token_;
  }
  v1::QueryRequest lastQuery() {
    std::lock_guard lock(mutex_);
    return last_query_;
  }

 private:
  grpc::Status store(const char* rpc, grpc::ServerContext* context, const v1::IngestRequest& request,
                     std::size_t chunks, v1::IngestResponse* response) {
    std::lock_guard lock(mutex_);
    last_token_ = authorization(context);
    if (request.key().robot() == "reject") return {grpc::StatusCode::INVALID_ARGUMENT, "robot 'reject' is refused"};
    received_.push_back({rpc, request, chunks});
    response->set_scan_id(static_cast<std::int64_t>(received_.size()));
    response->set_seq(request.key().seq());
    return grpc::Status::OK;
  }

  std::mutex mutex_;
  std::vector<Received> received_;
  std::string last_token_;
  v1::QueryRequest last_query_;
};

class FakeMapAdmin final : public v1::MapAdmin::Service {
 public:
  grpc::Status CreateMap(grpc::ServerContext*, const v1::CreateMapRequest* request, v1::MapInfo* response) override {
    std::lock_guard lock(mutex_);
    // As the real server: creating an existing map answers OK (its layout is the same here).
    if (std::find(maps_.begin(), maps_.end(), request->name()) == maps_.end()) maps_.push_back(request->name());
    response->set_name(request->name());
    return grpc::Status::OK;
  }
  grpc::Status ListMaps(grpc::ServerContext*, const v1::ListMapsRequest*, v1::ListMapsResponse* response) override {
    std::lock_guard lock(mutex_);
    ++list_calls;
    if (unavailable > 0) {  // a replica going away, as a balancer reports it
      --unavailable;
      return {grpc::StatusCode::UNAVAILABLE, "upstream connect error"};
    }
    for (const auto& m : maps_) response->add_maps()->set_name(m);
    return grpc::Status::OK;
  }
  int unavailable = 0, list_calls = 0;  // under mutex_
  grpc::Status ListRobots(grpc::ServerContext*, const v1::ListRobotsRequest* request,
                          v1::ListRobotsResponse*) override {
    return {grpc::StatusCode::NOT_FOUND, "unknown map '" + request->map() + "'"};
  }
  // Map "slow" answers only when the call is cancelled (deadline tests).
  grpc::Status GetStats(grpc::ServerContext* context, const v1::GetStatsRequest* request,
                        v1::GetStatsResponse* response) override {
    if (request->map() == "slow") {
      for (int i = 0; i < 3000 && !context->IsCancelled(); ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    response->set_scans(11);
    response->set_maps(2);
    return grpc::Status::OK;
  }
  grpc::Status DeleteSession(grpc::ServerContext*, const v1::DeleteSessionRequest* request,
                             v1::DeleteResponse* response) override {
    response->set_scans_removed(request->session() == "s" ? 4 : 0);
    return grpc::Status::OK;
  }
  grpc::Status DeleteRobot(grpc::ServerContext*, const v1::DeleteRobotRequest*, v1::DeleteResponse* response) override {
    response->set_scans_removed(9);
    return grpc::Status::OK;
  }

 public:
  std::mutex mutex_;

 private:
  std::vector<std::string> maps_;
};

// A pose-graph service whose paging is broken: every page names the same next token.
class StuckPoseGraph final : public v1::PoseGraph::Service {
 public:
  grpc::Status GetPoses(grpc::ServerContext*, const v1::GetPosesRequest*, v1::GetPosesResponse* resp) override {
    resp->add_poses()->set_scan_id(1);
    resp->set_next_page_token(1);
    return grpc::Status::OK;
  }
  grpc::Status GetLoops(grpc::ServerContext*, const v1::GetLoopsRequest*, v1::GetLoopsResponse* resp) override {
    resp->add_loops()->set_id(7);
    resp->set_next_page_token(7);
    return grpc::Status::OK;
  }
};

class FakeServer : public ::testing::Test {
 protected:
  void SetUp() override {
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port_);
    builder.RegisterService(&loop_);
    builder.RegisterService(&admin_);
    builder.RegisterService(&graph_);
    server_ = builder.BuildAndStart();
    ASSERT_TRUE(server_ && port_ > 0) << "in-process server did not start";
  }
  void TearDown() override {
    if (server_) server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(5));
  }
  sc::Client client(std::size_t chunk_bytes = sc::kDefaultChunkBytes, const std::string& token = "") const {
    sc::ConnectOptions o;
    o.chunk_bytes = chunk_bytes;
    o.token = token;
    return sc::Client::connect("127.0.0.1:" + std::to_string(port_), o);
  }
  static sglc::LabelledScan scanOf(std::size_t n) {
    sglc::LabelledScan s;
    for (std::size_t i = 0; i < n; ++i) {
      s.points.emplace_back(static_cast<float>(i), 0.5f, -1.0f);
      s.labels.push_back(static_cast<std::uint32_t>(i * 7));
    }
    return s;
  }

  FakeLoopClosure loop_;
  FakeMapAdmin admin_;
  StuckPoseGraph graph_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
};

}  // namespace

TEST_F(FakeServer, SmallScansGoInOneMessageLargeOnesInChunks) {
  const auto c = client(16 * 1000);  // chunk limit: 1000 points
  const auto small = scanOf(1000), large = scanOf(2500);
  EXPECT_EQ(c.ingest(sc::makeKey("m", "r", "s", 1), small).seq(), 1);
  const auto r = c.ingest(sc::makeKey("m", "r", "s", 2), large);
  EXPECT_EQ(r.seq(), 2);
  const auto got = loop_.received();
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].rpc, "Ingest");
  EXPECT_EQ(got[1].rpc, "IngestChunked");
  EXPECT_EQ(got[1].chunks, 1u + 3u);  // header, then 1000 + 1000 + 500 points
  EXPECT_EQ(got[1].request.key().seq(), 2);
  EXPECT_EQ(sc::unpackScan(got[1].request.scan()).labels, large.labels);
  EXPECT_EQ(got[1].request.scan().points(), sc::packPoints(large.points));
}

TEST_F(FakeServer, DefaultLimitIsThreeMegabytes) {
  EXPECT_EQ(client().options().chunk_bytes, 3'000'000u);
  const auto c = client();
  c.ingest(sc::makeKey("m", "r", "s", 1), scanOf(187'500));  // exactly 3 MB packed: one message
  c.ingest(sc::makeKey("m", "r", "s", 2), scanOf(187'501));  // 16 bytes over: chunked
  const auto got = loop_.received();
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].rpc, "Ingest");
  EXPECT_EQ(got[1].rpc, "IngestChunked");
}

TEST_F(FakeServer, BearerTokenIsSentOnEveryKindOfCall) {
  const auto c = client(16 * 10, "s3cret");
  c.ingest(sc::makeKey("m", "r", "s", 1), scanOf(5));
  EXPECT_EQ(loop_.lastToken(), "Bearer s3cret");
  c.ingest(sc::makeKey("m", "r", "s", 2), scanOf(50));  // chunked
  EXPECT_EQ(loop_.lastToken(), "Bearer s3cret");
  auto session = c.openSession();
  session.ingest(sc::makeIngestRequest(sc::makeKey("m", "r", "s", 3), scanOf(5)));
  session.finish();
  EXPECT_EQ(loop_.lastToken(), "Bearer s3cret");
  c.queryScanId("m", 1);
  EXPECT_EQ(loop_.lastToken(), "Bearer s3cret");
  client().queryScanId("m", 1);
  EXPECT_EQ(loop_.lastToken(), "");
}

TEST_F(FakeServer, QueryRequestsAreBuiltAsDocumented) {
  const auto c = client();
  v1::QueryOptions o;
  o.set_scope(v1::SCOPE_OTHER_ROBOTS);
  o.set_top_k(7);
  EXPECT_EQ(c.queryScanId("map1", 42, o).candidates(0).scan_id(), 42);
  auto q = loop_.lastQuery();
  EXPECT_EQ(q.map(), "map1");
  EXPECT_EQ(q.source_case(), v1::QueryRequest::kScanId);
  EXPECT_EQ(q.options().scope(), v1::SCOPE_OTHER_ROBOTS);
  EXPECT_EQ(q.options().top_k(), 7u);
  const auto scan = scanOf(3);
  EXPECT_EQ(c.queryScan("map2", scan).candidates(0).scan_id(), -1);
  q = loop_.lastQuery();
  EXPECT_EQ(q.source_case(), v1::QueryRequest::kScan);
  EXPECT_EQ(q.scan().points(), sc::packPoints(scan.points));
}

TEST_F(FakeServer, ServerErrorsCarryTheStatus) {
  const auto c = client();
  try {
    c.listRobots("nowhere");
    FAIL() << "no error";
  } catch (const sc::RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::NOT_FOUND);
    EXPECT_EQ(e.statusMessage(), "unknown map 'nowhere'");
    EXPECT_EQ(e.method(), "MapAdmin.ListRobots");
  }
  try {
    c.ingest(sc::makeKey("m", "reject", "s", 1), scanOf(3));
    FAIL() << "no error";
  } catch (const sc::RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::INVALID_ARGUMENT);
  }
  // An RPC the fake does not implement.
  try {
    c.backup("/tmp/x");
    FAIL() << "no error";
  } catch (const sc::RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::UNIMPLEMENTED);
  }
}

TEST_F(FakeServer, AdminCalls) {
  const auto c = client();
  EXPECT_EQ(c.createMap("a").name(), "a");
  EXPECT_EQ(c.createMap("a").name(), "a");  // idempotent
  EXPECT_NO_THROW(c.ensureMap("a"));
  EXPECT_NO_THROW(c.ensureMap("b"));
  const auto maps = c.listMaps();
  ASSERT_EQ(maps.size(), 2u);
  EXPECT_EQ(maps[1].name(), "b");
  EXPECT_EQ(c.getStats().scans(), 11);
  EXPECT_EQ(c.deleteSession("a", "r", "s"), 4);
  EXPECT_EQ(c.deleteRobot("a", "r"), 9);
}

TEST_F(FakeServer, DeadlinesApplyPerCall) {
  const auto c = client();
  try {
    c.getStats("slow", sc::CallOptions{std::chrono::milliseconds(100)});
    FAIL() << "no deadline error";
  } catch (const sc::RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  }
  EXPECT_EQ(c.getStats("fast", sc::CallOptions{std::chrono::milliseconds(30'000)}).scans(), 11);
}

// UNAVAILABLE is retried by gRPC's retry policy (ConnectOptions::max_attempts); other errors and a client that
// asks for one attempt are not.
TEST_F(FakeServer, UnavailableIsRetriedUpToMaxAttempts) {
  const auto address = "127.0.0.1:" + std::to_string(port_);
  auto set = [&](int unavailable) {
    std::lock_guard lock(admin_.mutex_);
    admin_.unavailable = unavailable;
    admin_.list_calls = 0;
  };
  auto calls = [&] {
    std::lock_guard lock(admin_.mutex_);
    return admin_.list_calls;
  };
  set(2);
  EXPECT_NO_THROW(client().listMaps());
  EXPECT_EQ(calls(), 3);
  set(5);
  try {
    client().listMaps();
    FAIL() << "five UNAVAILABLE answers gave no error";
  } catch (const sc::RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::UNAVAILABLE);
  }
  EXPECT_EQ(calls(), 5);
  sc::ConnectOptions once;
  once.max_attempts = 1;
  set(1);
  EXPECT_THROW(sc::Client::connect(address, once).listMaps(), sc::RpcError);
  EXPECT_EQ(calls(), 1);
  once.max_attempts = 6;
  EXPECT_THROW(sc::Client::connect(address, once), sglc::InputError);
}

TEST_F(FakeServer, UnreachableServerIsUnavailable) {
  const int port = port_;
  server_->Shutdown();
  server_.reset();
  const auto c = sc::Client::connect("127.0.0.1:" + std::to_string(port));
  try {
    c.listMaps();
    FAIL() << "no error";
  } catch (const sc::RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::UNAVAILABLE);
    EXPECT_NE(std::string(e.what()).find("UNAVAILABLE"), std::string::npos);
  }
}

TEST_F(FakeServer, SessionPipelinesInOrderAndRoutesLargeScansThroughChunks) {
  const auto c = client(16 * 100);
  auto session = c.openSession();
  session.send(sc::makeKey("m", "r", "s", 10), scanOf(10));
  session.send(sc::makeKey("m", "r", "s", 11), scanOf(10));
  session.send(sc::makeKey("m", "r", "s", 12), scanOf(250));  // too large for the stream
  session.send(sc::makeKey("m", "r", "s", 13), scanOf(10));
  EXPECT_EQ(session.outstanding(), 4u);
  EXPECT_EQ(session.next().seq(), 10);
  EXPECT_EQ(session.next().seq(), 11);
  const auto rest = session.finish();
  ASSERT_EQ(rest.size(), 2u);
  EXPECT_EQ(rest[0].seq(), 12);
  EXPECT_EQ(rest[1].seq(), 13);
  const auto got = loop_.received();
  ASSERT_EQ(got.size(), 4u);
  EXPECT_EQ(got[0].rpc, "IngestStream");
  EXPECT_EQ(got[1].rpc, "IngestStream");
  EXPECT_EQ(got[2].rpc, "IngestChunked");  // after 10 and 11 were processed: order kept
  EXPECT_EQ(got[2].request.key().seq(), 12);
  EXPECT_EQ(got[3].rpc, "IngestStream");
  EXPECT_THROW(session.send(sc::makeKey("m", "r", "s", 14), scanOf(1)), std::logic_error);
}

TEST_F(FakeServer, SessionFailureKeepsEarlierResponsesThenThrows) {
  const auto c = client();
  auto session = c.openSession();
  session.send(sc::makeKey("m", "r", "s", 1), scanOf(4));
  session.send(sc::makeKey("m", "r", "s", 2), scanOf(4));
  session.send(sc::makeKey("m", "reject", "s", 3), scanOf(4));
  EXPECT_EQ(session.next().seq(), 1);
  EXPECT_EQ(session.next().seq(), 2);
  try {
    session.next();
    FAIL() << "the rejected scan got a response";
  } catch (const sc::RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_EQ(e.method(), "LoopClosure.IngestStream");
  }
  EXPECT_THROW(session.finish(), sc::RpcError);
  EXPECT_THROW(session.send(sc::makeKey("m", "r", "s", 4), scanOf(4)), sc::RpcError);
  EXPECT_EQ(loop_.received().size(), 2u);
}

TEST_F(FakeServer, SessionIngestAndMisuse) {
  const auto c = client();
  auto session = c.openSession();
  EXPECT_THROW(session.next(), std::logic_error);
  EXPECT_EQ(session.ingest(sc::makeIngestRequest(sc::makeKey("m", "r", "s", 5), scanOf(3))).seq(), 5);
  session.send(sc::makeKey("m", "r", "s", 6), scanOf(3));
  EXPECT_THROW(session.ingest(sc::makeIngestRequest(sc::makeKey("m", "r", "s", 7), scanOf(3))), std::logic_error);
  auto moved = std::move(session);
  EXPECT_EQ(moved.next().seq(), 6);
  EXPECT_TRUE(moved.finish().empty());
}

TEST_F(FakeServer, AbandonedSessionIsCancelledCleanly) {
  const auto c = client();
  {
    auto session = c.openSession();
    session.send(sc::makeKey("m", "r", "s", 1), scanOf(3));
  }                                     // destroyed without finish()
  EXPECT_EQ(c.getStats().scans(), 11);  // the channel still works
}

TEST_F(FakeServer, APageTokenThatDoesNotGrowEndsPagingWithAnError) {
  const auto c = client();
  for (const auto& call :
       {std::function<void()>([&] { c.getPoses("m"); }), std::function<void()>([&] { c.getLoops("m"); })}) {
    try {
      call();
      FAIL() << "paged forever or accepted a token that does not grow";
    } catch (const sc::RpcError& e) {
      EXPECT_EQ(e.code(), grpc::StatusCode::INTERNAL);
      EXPECT_NE(std::string(e.what()).find("does not follow"), std::string::npos) << e.what();
    }
  }
}
