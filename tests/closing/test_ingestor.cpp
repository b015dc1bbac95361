// The ingest use case: store, retries, loops before storing, loops recorded for the pose graph.
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <zlib.h>

#include <cstring>
#include <limits>
#include <vector>

#include "closing_test_util.hpp"
#include "older_formats.hpp"
#include "sglc/closing/ingestor.hpp"
#include "sglc/rigid.hpp"

namespace sglc::closing {
namespace {

using storage::StorageError;

class IngestorTest : public ::testing::Test, public test::TwoStreets {
 protected:
  IngestorTest() : scan(test::viewFrom(test::makeStreetWorld(7), test::kQueryPose)) {}

  IngestInput input(std::int64_t seq, bool with_pose = true) const {
    IngestInput in;
    in.key = {"m", "r3", "t", seq};
    in.stamp = 12.5;
    if (with_pose) in.odometry_pose = test::kQueryPose;
    in.query = true;
    return in;
  }
  Ingested ingest(const Ingestor& ingestor, const IngestInput& in) const {
    return ingestor.commit(ingestor.compute(scan, in, {}), scan);
  }

  LabelledScan scan;
  std::vector<std::string> told;  // maps the ingestor reported recorded loops for
  Ingestor::LoopsRecorded recorder() {
    return [this](const std::string& map) { told.push_back(map); };
  }
};

TEST_F(IngestorTest, StoresTheScanAndAnswersItsLoopsFoundBeforeIt) {
  const Ingestor ingestor(pipeline, *store);
  const auto done = ingest(ingestor, input(0));
  EXPECT_GT(done.scan_id, 0);
  EXPECT_FALSE(done.already_stored);
  EXPECT_EQ(done.report.label_source, ScanReport::LabelSource::kProvided);
  ASSERT_EQ(done.loops.size(), 2u);  // the two stored views of this street
  for (const auto& l : done.loops) EXPECT_TRUE(scans.at(l.scan_id).same_place);
  const auto info = store->scanInfo(done.scan_id);
  ASSERT_TRUE(info);
  EXPECT_EQ(info->robot, "r3");
  EXPECT_EQ(info->stamp, 12.5);
  EXPECT_EQ(info->odometry_pose, test::kQueryPose);
  EXPECT_FALSE(info->has_raw);
  EXPECT_TRUE(store->loops("m").empty());  // no pose graph was given: nothing recorded
}

TEST_F(IngestorTest, AnIdenticalRetryAnswersAsTheFirstCallAndADifferentScanIsRefused) {
  const Ingestor ingestor(pipeline, *store);
  const auto first = ingest(ingestor, input(0));
  const auto again = ingest(ingestor, input(0));
  EXPECT_TRUE(again.already_stored);
  EXPECT_EQ(again.scan_id, first.scan_id);
  ASSERT_EQ(again.loops.size(), first.loops.size());  // the stored copy of itself is not a loop
  for (std::size_t i = 0; i < first.loops.size(); ++i) EXPECT_EQ(again.loops[i].scan_id, first.loops[i].scan_id);
  auto changed = input(0);
  changed.stamp = 13.0;
  int reports = 0;  // the scan's report comes as soon as it is fingerprinted, before the retry check fails
  try {
    ingestor.compute(scan, changed, {}, [&](const ScanReport&) { ++reports; });
    FAIL() << "a different scan under a stored key was accepted";
  } catch (const StorageError& e) {
    EXPECT_EQ(e.code(), StorageError::Code::kAlreadyExists);
    EXPECT_NE(std::string(e.what()).find("already holds a different scan"), std::string::npos) << e.what();
  }
  EXPECT_EQ(reports, 1);
}

// A scan stored before fingerprint format 3 is read back with its descriptor recomputed and no height band,
// so it differs from a fresh fingerprint of the same scan: an identical retry after the upgrade still answers
// as the first call did.
TEST_F(IngestorTest, AnIdenticalRetryAfterAFormatUpgradeAnswersAsTheFirstCall) {
  const auto first = ingest(Ingestor(pipeline, *store), input(0));
  store.reset();
  const auto path = dir.file("map.db");
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
    sqlite3_stmt* st = nullptr;
    ASSERT_EQ(sqlite3_prepare_v2(db, "SELECT fingerprint FROM scan_blobs WHERE scan_id = ?", -1, &st, nullptr),
              SQLITE_OK);
    sqlite3_bind_int64(st, 1, first.scan_id);
    ASSERT_EQ(sqlite3_step(st), SQLITE_ROW);
    const auto* p = static_cast<const std::uint8_t*>(sqlite3_column_blob(st, 0));
    const Fingerprint written = deserialize(std::span<const std::uint8_t>(p, sqlite3_column_bytes(st, 0)));
    sqlite3_finalize(st);
    // Format 2, with the descriptor it had then (whatever it was: it is recomputed on reading).
    const auto blob = test::olderFormatBlob(written, 2, std::vector<float>(written.descriptor.size(), 0.05f));
    ASSERT_EQ(sqlite3_prepare_v2(db, "UPDATE scan_blobs SET fingerprint = ? WHERE scan_id = ?", -1, &st, nullptr),
              SQLITE_OK);
    sqlite3_bind_blob(st, 1, blob.data(), static_cast<int>(blob.size()), SQLITE_TRANSIENT);
    sqlite3_bind_int64(st, 2, first.scan_id);
    EXPECT_EQ(sqlite3_step(st), SQLITE_DONE);
    sqlite3_finalize(st);
    // A schema-5 file: without the columns later schemas add.
    EXPECT_EQ(
        sqlite3_exec(db,
                     "DROP TABLE places; ALTER TABLE maps DROP COLUMN retired_scans; ALTER TABLE maps DROP COLUMN "
                     "retired_bytes; ALTER TABLE loops DROP COLUMN probability; PRAGMA user_version=5",
                     nullptr, nullptr, nullptr),
        SQLITE_OK);
    sqlite3_close(db);
  }
  storage::StoreOptions o;
  o.path = path;
  store = storage::MapStore::open(o);
  const auto stored = store->fingerprint(first.scan_id);
  ASSERT_TRUE(stored);
  const auto fresh = pipeline.fingerprint(scan);
  EXPECT_NE(serialize(*stored), serialize(fresh));  // the bytes differ: a byte comparison would refuse the retry
  const auto again = ingest(Ingestor(pipeline, *store), input(0));
  EXPECT_TRUE(again.already_stored);
  EXPECT_EQ(again.scan_id, first.scan_id);
}

// Two calls with the same scan race: both computed before either stored. The second to commit answers as a
// retry, without the first's copy among its loops.
TEST_F(IngestorTest, ARacingIdenticalCallAnswersAsARetry) {
  const Ingestor ingestor(pipeline, *store);
  auto a = ingestor.compute(scan, input(0), {});
  auto b = ingestor.compute(scan, input(0), {});
  const auto first = ingestor.commit(std::move(a), scan);
  // Had b searched after a was stored, a's copy would be among its loops: put it there, commit must drop it.
  b.outcome.loops.push_back(FoundLoop{first.scan_id});
  const auto second = ingestor.commit(std::move(b), scan);
  EXPECT_FALSE(first.already_stored);
  EXPECT_TRUE(second.already_stored);
  EXPECT_EQ(second.scan_id, first.scan_id);
  ASSERT_EQ(second.loops.size(), first.loops.size());
  for (const auto& l : second.loops) EXPECT_NE(l.scan_id, first.scan_id);
}

TEST_F(IngestorTest, VerifiedLoopsOfAScanWithAPoseAreRecordedForThePoseGraph) {
  const Ingestor ingestor(pipeline, *store, recorder());
  auto in = input(0);
  in.query_options.include_rejected = true;
  const auto done = ingest(ingestor, in);
  EXPECT_TRUE(done.unrecorded_loops.empty());
  ASSERT_EQ(told, std::vector<std::string>{"m"});
  const auto recorded = store->loops("m");
  ASSERT_EQ(recorded.size(), 2u);  // the two accepted ones, not the rejected ones
  for (const auto& r : recorded) {
    EXPECT_EQ(r.query_scan, done.scan_id);
    const auto it = std::find_if(done.loops.begin(), done.loops.end(),
                                 [&](const FoundLoop& l) { return l.scan_id == r.candidate_scan; });
    ASSERT_NE(it, done.loops.end());
    EXPECT_TRUE(it->result.is_loop);
    EXPECT_EQ(r.T, orthonormalised(it->result.T));
    EXPECT_EQ(r.score, it->result.score);
    EXPECT_EQ(r.inliers, it->result.inliers);
    ASSERT_TRUE(r.information);
    EXPECT_EQ(*r.information, it->result.information);
  }
  // Without an odometry pose the scan is no pose-graph node, but its loops are still the map's: recorded, so
  // that listing and exporting them shows every loop ingest reported (the pose graph leaves them out).
  told.clear();
  const auto no_pose = ingest(ingestor, input(1, false));
  const auto verified =
      std::count_if(no_pose.loops.begin(), no_pose.loops.end(), [](const FoundLoop& l) { return l.result.is_loop; });
  EXPECT_GT(verified, 0);
  EXPECT_EQ(told, std::vector<std::string>{"m"});
  EXPECT_EQ(store->loops("m").size(), 2u + static_cast<std::size_t>(verified));
}

// A scan sent without labels (the engine labels it) is kept as it came: its raw cloud has no labels.
TEST_F(IngestorTest, AnUnlabelledRawCloudIsKeptWithoutLabels) {
  const Ingestor ingestor(pipeline, *store);
  LabelledScan unlabelled;
  unlabelled.points = scan.points;
  auto in = input(0);
  in.store_raw = true;
  in.query = false;
  const auto done = ingestor.commit(ingestor.compute(unlabelled, in, {}), unlabelled);
  EXPECT_EQ(done.report.label_source, ScanReport::LabelSource::kComputed);
  const auto raw = store->rawScan(done.scan_id);
  ASSERT_TRUE(raw);
  EXPECT_EQ(raw->points, unlabelled.points);
  EXPECT_TRUE(raw->labels.empty());
}

TEST_F(IngestorTest, ANonFiniteStampIsRefused) {
  const Ingestor ingestor(pipeline, *store);
  auto in = input(0);
  in.stamp = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(ingestor.compute(scan, in, {}), InputError);
  EXPECT_FALSE(store->findScan("m", "r3", "t", 0));
}

TEST_F(IngestorTest, RawCloudsAreKeptOnlyWhenAsked) {
  const Ingestor ingestor(pipeline, *store);
  auto in = input(0);
  in.store_raw = true;
  in.query = false;
  const auto done = ingest(ingestor, in);
  EXPECT_TRUE(done.loops.empty());
  const auto raw = store->rawScan(done.scan_id);
  ASSERT_TRUE(raw);
  EXPECT_EQ(raw->points.size(), scan.points.size());
}

}  // namespace
}  // namespace sglc::closing
