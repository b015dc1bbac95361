// MapStore: round trips, search filters, deletions, backups, and every error the issue lists.
#include <sqlite3.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <set>

#include "backend.hpp"
#include "older_formats.hpp"
#include "storage_test_util.hpp"

namespace sglc::storage {
namespace {

using testing::errorCode;
using testing::OnBothBackends;
using testing::options;
using testing::randomFingerprint;
using testing::TempDir;

std::vector<std::uint8_t> fileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Runs SQL on a database file behind the store's back (to fake foreign, newer or older files).
void execSql(const std::string& path, const char* sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  EXPECT_EQ(sqlite3_exec(db, sql, nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  sqlite3_close(db);
}

struct Stored {
  std::int64_t id;
  std::string robot, session;
  std::int64_t seq;
  double stamp;
  Fingerprint fp;
};

// Fills map "m" with robots r0..r(robots-1), sessions s0..s(sessions-1), `per` scans each.
std::vector<Stored> fill(MapStore& store, int robots, int sessions, int per, std::uint64_t seed = 1) {
  store.createMap("m", DescriptorLayout{}.scanDim());
  std::vector<Stored> out;
  for (int r = 0; r < robots; ++r)
    for (int s = 0; s < sessions; ++s)
      for (int q = 0; q < per; ++q) {
        Stored st{0, "r" + std::to_string(r), "s" + std::to_string(s),
                  q, 100.0 * s + q,           randomFingerprint(seed + out.size() * 7919)};
        NewScan ns;
        ns.map = "m";
        ns.robot = st.robot;
        ns.session = st.session;
        ns.seq = q;
        ns.stamp = st.stamp;
        ns.fingerprint = &st.fp;
        st.id = store.addScan(ns);
        out.push_back(std::move(st));
      }
  return out;
}

// Brute-force reference: the k nearest stored scans accepted by `keep`.
std::vector<std::int64_t> bruteForce(const std::vector<Stored>& all, const std::vector<float>& q, int k,
                                     const std::function<bool(const Stored&)>& keep) {
  std::vector<std::pair<float, std::int64_t>> d;
  for (const auto& s : all) {
    if (!keep(s)) continue;
    double sum = 0;
    for (std::size_t i = 0; i < q.size(); ++i) sum += double(q[i] - s.fp.descriptor[i]) * (q[i] - s.fp.descriptor[i]);
    d.emplace_back(static_cast<float>(std::sqrt(sum)), s.id);
  }
  std::sort(d.begin(), d.end());
  std::vector<std::int64_t> ids;
  for (int i = 0; i < k && i < static_cast<int>(d.size()); ++i) ids.push_back(d[i].second);
  return ids;
}

std::vector<std::int64_t> ids(const std::vector<SearchHit>& hits) {
  std::vector<std::int64_t> out;
  for (const auto& h : hits) out.push_back(h.scan_id);
  return out;
}

TEST_P(OnBothBackends, StoresAndFindsItsOwnDescriptorFirst) {
  auto store = MapStore::open(db().options());
  const auto all = fill(*store, 2, 2, 10);
  for (const auto& s : {all[0], all[17], all[39]}) {
    SearchRequest req;
    req.map = "m";
    req.descriptor = s.fp.descriptor;
    req.k = 5;
    const auto hits = store->search(req);
    ASSERT_EQ(hits.size(), 5u);
    EXPECT_EQ(hits[0].scan_id, s.id);
    EXPECT_NEAR(hits[0].distance, 0.0f, 1e-5f);
    EXPECT_TRUE(std::is_sorted(hits.begin(), hits.end(),
                               [](const SearchHit& a, const SearchHit& b) { return a.distance < b.distance; }));
  }
  const auto info = store->scanInfo(all[17].id);
  ASSERT_TRUE(info);
  EXPECT_EQ(info->robot, all[17].robot);
  EXPECT_EQ(info->session, all[17].session);
  EXPECT_EQ(info->seq, all[17].seq);
  ASSERT_TRUE(info->stamp);
  EXPECT_EQ(*info->stamp, all[17].stamp);
  EXPECT_EQ(store->findScan("m", all[17].robot, all[17].session, all[17].seq), all[17].id);
  EXPECT_FALSE(store->findScan("m", all[17].robot, all[17].session, 999));
  // The scan before a seq in its session: the largest seq below it, whether that seq is stored or not.
  EXPECT_EQ(store->previousScan("m", all[17].robot, all[17].session, all[17].seq + 1), all[17].id);
  EXPECT_EQ(store->previousScan("m", all[17].robot, all[17].session, all[17].seq + 100), all[19].id);
  EXPECT_EQ(store->previousScan("m", all[17].robot, all[17].session, all[10].seq), std::nullopt);
  EXPECT_EQ(store->previousScan("m", "nobody", all[17].session, all[17].seq), std::nullopt);
  const auto st = store->stats();
  EXPECT_EQ(st.scans, 40);
  EXPECT_EQ(st.index_entries, 40);
  EXPECT_EQ(st.robots, 2);
  EXPECT_EQ(st.sessions, 4);
  EXPECT_EQ(st.maps, 1);
}

TEST_P(OnBothBackends, RoundTripAcrossReopenWithAndWithoutSnapshot) {
  std::vector<Stored> all;
  std::vector<std::vector<std::int64_t>> before;
  Mat4d pose = Mat4d::Identity();
  pose.topRightCorner<3, 1>() = Vec3d(1.5, -2.25, 0.125);
  {
    auto store = MapStore::open(db().options());
    all = fill(*store, 2, 1, 15);
    NewScan ns;
    Fingerprint fp = randomFingerprint(424242);
    ns.map = "m";
    ns.robot = "posed";
    ns.session = "a";
    ns.odometry_pose = pose;
    ns.fingerprint = &fp;
    all.push_back({store->addScan(ns), "posed", "a", 0, 0, fp});
    for (const auto& s : all) {
      SearchRequest req{.map = "m", .descriptor = s.fp.descriptor, .k = 7};
      before.push_back(ids(store->search(req)));
    }
  }
  for (int pass = 0; pass < 2; ++pass) {
    if (pass == 1) db().forgetSnapshots();  // force a rebuild from SQLite
    auto store = MapStore::open(db().options());
    EXPECT_EQ(store->stats().index_entries, static_cast<std::int64_t>(all.size()));
    for (std::size_t i = 0; i < all.size(); ++i) {
      const auto fp = store->fingerprint(all[i].id);
      ASSERT_NE(fp, nullptr);
      EXPECT_EQ(serialize(*fp), serialize(all[i].fp)) << "scan " << all[i].id;
      SearchRequest req{.map = "m", .descriptor = all[i].fp.descriptor, .k = 7};
      EXPECT_EQ(ids(store->search(req)), before[i]) << "pass " << pass;
    }
    const auto info = store->scanInfo(all.back().id);
    ASSERT_TRUE(info && info->odometry_pose);
    EXPECT_TRUE(info->odometry_pose->isApprox(pose, 0.0));
  }
}

TEST_P(OnBothBackends, FiltersKeepTheFullTopK) {
  auto store = MapStore::open(db().options());
  const auto all = fill(*store, 3, 2, 12);
  const auto& q = all[5];
  const int k = 10;
  struct Case {
    const char* name;
    SearchRequest req;
    std::function<bool(const Stored&)> keep;
  };
  std::vector<Case> cases;
  {
    SearchRequest r{.map = "m", .descriptor = q.fp.descriptor, .k = k};
    r.robots = {"r1"};
    cases.push_back({"only r1", r, [](const Stored& s) { return s.robot == "r1"; }});
  }
  {
    SearchRequest r{.map = "m", .descriptor = q.fp.descriptor, .k = k};
    r.exclude_robots = {"r0"};
    cases.push_back({"other robots", r, [](const Stored& s) { return s.robot != "r0"; }});
  }
  {
    SearchRequest r{.map = "m", .descriptor = q.fp.descriptor, .k = k};
    r.sessions = {"r2/s1", "r0/s0"};
    cases.push_back({"sessions", r, [](const Stored& s) {
                       return (s.robot == "r2" && s.session == "s1") || (s.robot == "r0" && s.session == "s0");
                     }});
  }
  {
    SearchRequest r{.map = "m", .descriptor = q.fp.descriptor, .k = k};
    r.self_robot = q.robot;
    r.self_session = q.session;
    r.self_seq = q.seq;
    r.exclude_recent = 4;
    cases.push_back({"recent by count", r, [&](const Stored& s) {
                       return !(s.robot == q.robot && s.session == q.session && std::llabs(s.seq - q.seq) < 4);
                     }});
  }
  {
    SearchRequest r{.map = "m", .descriptor = q.fp.descriptor, .k = k};
    r.self_robot = q.robot;
    r.self_stamp = q.stamp;
    r.exclude_seconds = 150;
    cases.push_back({"recent by time", r,
                     [&](const Stored& s) { return !(s.robot == q.robot && std::abs(s.stamp - q.stamp) < 150); }});
  }
  {
    SearchRequest r{.map = "m", .descriptor = q.fp.descriptor, .k = k};
    r.exclude_scan_ids = {q.id};
    cases.push_back({"not itself", r, [&](const Stored& s) { return s.id != q.id; }});
  }
  {
    SearchRequest r{.map = "m", .descriptor = q.fp.descriptor, .k = k};
    r.robots = {"nobody"};
    cases.push_back({"unknown robot", r, [](const Stored&) { return false; }});
  }
  for (const auto& c : cases) {
    const auto got = ids(store->search(c.req));
    const auto want = bruteForce(all, q.fp.descriptor, k, c.keep);
    EXPECT_EQ(got, want) << c.name;
  }
}

// Sequence numbers come from clients and may span the whole int64 range: the recent-scan exclusion measures
// their distance without overflow (it wrapped, so the scans at the two ends counted as 1 apart).
TEST_P(OnBothBackends, RecentExclusionHoldsAtTheEndsOfTheSequenceRange) {
  auto store = MapStore::open(db().options());
  const auto fp = randomFingerprint(3);
  store->createMap("m", static_cast<int>(fp.descriptor.size()));
  constexpr auto kMin = std::numeric_limits<std::int64_t>::min(), kMax = std::numeric_limits<std::int64_t>::max();
  std::map<std::int64_t, std::int64_t> seq_of;
  for (const auto seq : {kMin, kMin + 3, std::int64_t{0}, kMax - 3, kMax})
    seq_of[store->addScan({.map = "m", .robot = "r", .session = "s", .seq = seq, .fingerprint = &fp})] = seq;
  auto seqsFound = [&](std::int64_t self_seq) {
    SearchRequest req{.map = "m", .descriptor = fp.descriptor, .k = 10};
    req.self_robot = "r";
    req.self_session = "s";
    req.self_seq = self_seq;
    req.exclude_recent = 5;
    std::set<std::int64_t> seqs;
    for (const auto& h : store->search(req)) seqs.insert(seq_of.at(h.scan_id));
    return seqs;
  };
  EXPECT_EQ(seqsFound(kMax), (std::set<std::int64_t>{kMin, kMin + 3, 0}));
  EXPECT_EQ(seqsFound(kMin), (std::set<std::int64_t>{0, kMax - 3, kMax}));
  EXPECT_EQ(seqsFound(2), (std::set<std::int64_t>{kMin, kMin + 3, kMax - 3, kMax}));
}

TEST_P(OnBothBackends, RejectsBadWritesAndLeavesNothingBehind) {
  auto store = MapStore::open(db().options());
  const auto all = fill(*store, 1, 1, 3);
  Fingerprint fp = randomFingerprint(99);
  NewScan ns{.map = "m", .robot = "r0", .session = "s0", .seq = 1, .fingerprint = &fp};
  EXPECT_EQ(errorCode([&] { store->addScan(ns); }), StorageError::Code::kAlreadyExists);
  ns.seq = 50;
  ns.map = "nope";
  EXPECT_EQ(errorCode([&] { store->addScan(ns); }), StorageError::Code::kNotFound);
  ns.map = "m";
  ns.robot = "";
  EXPECT_EQ(errorCode([&] { store->addScan(ns); }), StorageError::Code::kInvalidArgument);
  ns.robot = "fresh-robot";
  Fingerprint wrong = fp;
  wrong.descriptor.pop_back();
  ns.fingerprint = &wrong;
  EXPECT_EQ(errorCode([&] { store->addScan(ns); }), StorageError::Code::kInvalidArgument);
  Fingerprint nan = fp;
  nan.descriptor[3] = std::nanf("");
  ns.fingerprint = &nan;
  EXPECT_EQ(errorCode([&] { store->addScan(ns); }), StorageError::Code::kInvalidArgument);
  ns.fingerprint = nullptr;
  EXPECT_EQ(errorCode([&] { store->addScan(ns); }), StorageError::Code::kInvalidArgument);
  EXPECT_EQ(errorCode([&] { store->createMap("m", 17); }), StorageError::Code::kAlreadyExists);
  SearchRequest req{.map = "m", .descriptor = std::vector<float>(5, 0.0f), .k = 3};
  EXPECT_EQ(errorCode([&] { store->search(req); }), StorageError::Code::kInvalidArgument);
  req.map = "nope";
  EXPECT_EQ(errorCode([&] { store->search(req); }), StorageError::Code::kNotFound);
  // Nothing of the failed writes exists: no new robot, no new scan.
  const auto st = store->stats("m");
  EXPECT_EQ(st.scans, 3);
  EXPECT_EQ(st.index_entries, 3);
  EXPECT_EQ(store->listRobots("m").size(), 1u);
  EXPECT_EQ(store->integrityCheck(), "ok");
}

TEST_P(OnBothBackends, DeletesSessionsAndRobotsFromIndexAndDatabase) {
  std::vector<Stored> all;
  {
    auto store = MapStore::open(db().options());
    all = fill(*store, 2, 2, 5);
    EXPECT_EQ(store->deleteSession("m", "r0", "s1"), 5);
    EXPECT_EQ(store->deleteRobot("m", "r1"), 10);
    EXPECT_EQ(errorCode([&] { store->deleteRobot("m", "r1"); }), StorageError::Code::kNotFound);
    EXPECT_EQ(errorCode([&] { store->deleteSession("m", "r0", "zz"); }), StorageError::Code::kNotFound);
    // Ids are never reused: a scan stored after the deletes gets a new one.
    Fingerprint fp = randomFingerprint(777);
    NewScan ns{.map = "m", .robot = "r9", .session = "s", .seq = 0, .fingerprint = &fp};
    std::int64_t max_id = 0;
    for (const auto& s : all) max_id = std::max(max_id, s.id);
    EXPECT_GT(store->addScan(ns), max_id);
    store->deleteRobot("m", "r9");
  }
  for (int pass = 0; pass < 2; ++pass) {
    auto store = MapStore::open(db().options());
    const auto st = store->stats("m");
    EXPECT_EQ(st.scans, 5);
    EXPECT_EQ(st.index_entries, 5);
    EXPECT_EQ(st.robots, 1);
    EXPECT_EQ(st.sessions, 1);
    for (const auto& s : all) {
      const bool kept = s.robot == "r0" && s.session == "s0";
      EXPECT_EQ(store->fingerprint(s.id) != nullptr, kept) << s.robot << "/" << s.session;
      SearchRequest req{.map = "m", .descriptor = s.fp.descriptor, .k = 20};
      const auto hits = ids(store->search(req));
      EXPECT_EQ(hits.size(), 5u);
      EXPECT_EQ(std::count(hits.begin(), hits.end(), s.id), kept ? 1 : 0);
    }
    EXPECT_EQ(store->integrityCheck(), "ok");
  }
}

TEST_P(OnBothBackends, BackupIsACompleteMapAndNeverOverwrites) {
  auto store = MapStore::open(db().options());
  const auto all = fill(*store, 1, 2, 6);
  store->backup(db().file("backup.db"));
  EXPECT_EQ(errorCode([&] { store->backup(db().file("backup.db")); }), StorageError::Code::kAlreadyExists);
  auto copy = MapStore::open(db().restored(db().file("backup.db")));
  EXPECT_EQ(copy->stats().scans, 12);
  for (const auto& s : all) {
    const auto fp = copy->fingerprint(s.id);
    ASSERT_NE(fp, nullptr);
    EXPECT_EQ(serialize(*fp), serialize(s.fp));
  }
  EXPECT_EQ(copy->integrityCheck(), "ok");
}

// A backup that fails (here: into a directory that does not exist) leaves no file and no internals in its
// message, so the retry is not blocked and the caller learns nothing about the server's files.
TEST(MapStore, AFailedBackupLeavesNothingBehind) {
  TempDir dir;
  auto store = MapStore::open(options(dir.file("map.db")));
  fill(*store, 1, 1, 2);
  const auto dest = dir.file("missing-dir/backup.db");
  try {
    store->backup(dest);
    ADD_FAILURE() << "backup into a missing directory succeeded";
  } catch (const StorageError& e) {
    EXPECT_EQ(std::string(e.what()).find("VACUUM"), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find("missing-dir"), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find(dir.file("")), std::string::npos) << e.what();
    EXPECT_NE(e.detail().find("missing-dir"), std::string::npos) << e.detail();  // the operator's log has it
  }
  EXPECT_FALSE(std::filesystem::exists(dest));
  store->backup(dir.file("backup.db"));
  EXPECT_TRUE(std::filesystem::exists(dir.file("backup.db")));
}

// One process per database: a second open (another server, or this process again) is refused with the owner's
// pid, and the lock goes with the store.
TEST(MapStore, ADatabaseIsOpenedByOneStoreAtATime) {
  TempDir dir;
  const auto path = dir.file("map.db");
  {
    auto store = MapStore::open(options(path));
    try {
      MapStore::open(options(path));
      ADD_FAILURE() << "a second store opened the same database";
    } catch (const StorageError& e) {
      EXPECT_EQ(e.code(), StorageError::Code::kBusy);
      EXPECT_NE(std::string(e.what()).find("in use by process " + std::to_string(::getpid())), std::string::npos)
          << e.what();
    }
  }
  EXPECT_NO_THROW(MapStore::open(options(path)));  // released on close
}

TEST(MapStore, RefusesForeignCorruptAndNewerFilesWithoutTouchingThem) {
  TempDir dir;
  // Random bytes.
  const auto junk = dir.file("junk.db");
  {
    std::ofstream out(junk, std::ios::binary);
    for (int i = 0; i < 8192; ++i) out.put(static_cast<char>((i * 7919) & 0xFF));
  }
  const auto junk_before = fileBytes(junk);
  EXPECT_EQ(errorCode([&] { MapStore::open(options(junk)); }), StorageError::Code::kCorrupt);
  EXPECT_EQ(fileBytes(junk), junk_before);
  // Another application's SQLite database.
  const auto foreign = dir.file("foreign.db");
  execSql(foreign, "CREATE TABLE t(x); INSERT INTO t VALUES(1);");
  const auto foreign_before = fileBytes(foreign);
  EXPECT_EQ(errorCode([&] { MapStore::open(options(foreign)); }), StorageError::Code::kCorrupt);
  EXPECT_EQ(fileBytes(foreign), foreign_before);
  // One of ours, written by a newer version.
  const auto newer = dir.file("newer.db");
  { fill(*MapStore::open(options(newer)), 1, 1, 2); }
  execSql(newer, "PRAGMA user_version=99");
  const auto newer_before = fileBytes(newer);
  try {
    MapStore::open(options(newer));
    ADD_FAILURE() << "opened a newer schema";
  } catch (const StorageError& e) {
    EXPECT_EQ(e.code(), StorageError::Code::kNewerSchema);
    EXPECT_NE(std::string(e.what()).find("newer"), std::string::npos) << e.what();
  }
  EXPECT_EQ(fileBytes(newer), newer_before);
  // A directory where the file should be.
  std::filesystem::create_directory(dir.file("adir"));
  EXPECT_EQ(errorCode([&] { MapStore::open(options(dir.file("adir"))); }), StorageError::Code::kInvalidArgument);
}

TEST_P(OnBothBackends, FullDiskFailsTheWriteAndKeepsEverythingBefore) {
  auto opts = db().options();
  opts.max_db_mb = 0.5;  // a quota is how SQLite reports a full disk (SQLITE_FULL)
  opts.sync = StoreOptions::Sync::kFull;
  std::vector<std::int64_t> stored;
  {
    auto store = MapStore::open(opts);
    store->createMap("m", DescriptorLayout{}.scanDim());
    bool full = false;
    for (int i = 0; i < 1000 && !full; ++i) {
      Fingerprint fp = randomFingerprint(i + 1, 60);
      NewScan ns{.map = "m", .robot = "r", .session = "s", .seq = i, .fingerprint = &fp};
      try {
        stored.push_back(store->addScan(ns));
      } catch (const StorageError& e) {
        EXPECT_EQ(e.code(), StorageError::Code::kFull) << e.what();
        full = true;
      }
    }
    ASSERT_TRUE(full) << "quota never reached";
    ASSERT_GT(stored.size(), 3u);
    EXPECT_EQ(store->stats().scans, static_cast<std::int64_t>(stored.size()));
    EXPECT_EQ(store->stats().index_entries, static_cast<std::int64_t>(stored.size()));
  }
  opts.max_db_mb = 0;
  auto store = MapStore::open(opts);
  EXPECT_EQ(store->integrityCheck(), "ok");
  EXPECT_EQ(store->stats().scans, static_cast<std::int64_t>(stored.size()));
  for (auto id : stored) EXPECT_NE(store->fingerprint(id), nullptr);
}

TEST(MapStore, ReadOnlyDirectoryAndFileGiveAClearError) {
  TempDir dir;
  const auto ro_dir = dir.file("ro");
  std::filesystem::create_directory(ro_dir);
  { fill(*MapStore::open(options(ro_dir + "/existing.db")), 1, 1, 2); }
  const auto before = fileBytes(ro_dir + "/existing.db");
  std::filesystem::permissions(ro_dir + "/existing.db", std::filesystem::perms::owner_read);
  std::filesystem::permissions(ro_dir, std::filesystem::perms::owner_read | std::filesystem::perms::owner_exec);
  // Root ignores permission bits, so the check runs in a child that gives up root.
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    if (geteuid() == 0 && (setgid(65534) != 0 || setuid(65534) != 0)) _exit(3);
    int failures = 0;
    for (const auto& p : {ro_dir + "/new.db", ro_dir + "/existing.db"}) {
      try {
        MapStore::open(options(p));
        ++failures;
      } catch (const StorageError& e) {
        if (e.code() != StorageError::Code::kReadOnly) ++failures;
      } catch (...) {
        ++failures;
      }
    }
    _exit(failures);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  std::filesystem::permissions(ro_dir, std::filesystem::perms::owner_all);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "exit 3: could not drop privileges; otherwise the count of wrong answers";
  EXPECT_FALSE(std::filesystem::exists(ro_dir + "/new.db"));
  EXPECT_EQ(fileBytes(ro_dir + "/existing.db"), before);
}

TEST_P(OnBothBackends, CacheServesRepeatsAndStaysWithinItsBudget) {
  auto opts = db().options();
  opts.cache_mb = 0.05;  // room for a handful of fingerprints
  auto store = MapStore::open(opts);
  const auto all = fill(*store, 1, 1, 30);
  for (const auto& s : all) ASSERT_NE(store->fingerprint(s.id), nullptr);
  const auto misses = store->stats().cache_misses;
  EXPECT_EQ(misses, 30);
  ASSERT_NE(store->fingerprint(all.back().id), nullptr);
  EXPECT_EQ(store->stats().cache_hits, 1);
  EXPECT_LE(store->stats().cache_mb, 0.05 + 1e-9);
  EXPECT_GT(store->stats().cache_mb, 0.0);
}

// Stored scans' view contexts are kept apart from their fingerprints: with a cache of a handful of fingerprints,
// asking every scan's context again reads no fingerprint back; other settings get their own context; a deleted
// scan's context is forgotten.
TEST_P(OnBothBackends, ViewContextsOutliveTheirFingerprintsInTheCache) {
  auto opts = db().options();
  opts.cache_mb = 0.05;  // room for a handful of fingerprints, and their contexts in an eighth of it more
  auto store = MapStore::open(opts);
  const auto all = fill(*store, 1, 2, 15);
  const ViewSearchConfig cfg;
  std::vector<std::shared_ptr<const ViewContext>> first;
  for (const auto& s : all) {
    first.push_back(store->viewContext(s.id, cfg));
    ASSERT_NE(first.back(), nullptr);
    const auto want = viewContextOf(s.fp, cfg);
    const auto& got = *first.back();
    ASSERT_EQ(got.rings(), want->rings());
    EXPECT_EQ(got.merged, want->merged);
    EXPECT_EQ(got.seen.lo, want->seen.lo);
    EXPECT_EQ(got.seen.hi, want->seen.hi);
    for (int i = 0; i < want->rings(); ++i) {
      EXPECT_EQ(got.building[i].lo, want->building[i].lo);
      EXPECT_EQ(got.building[i].hi, want->building[i].hi);
      EXPECT_EQ(got.vegetation[i].lo, want->vegetation[i].lo);
      EXPECT_EQ(got.vegetation[i].hi, want->vegetation[i].hi);
    }
  }
  const auto misses = store->stats().cache_misses;
  EXPECT_EQ(misses, 30);                              // each fingerprint read once
  ASSERT_NE(store->fingerprint(all[0].id), nullptr);  // evicted since: read again
  EXPECT_EQ(store->stats().cache_misses, misses + 1);
  for (std::size_t k = 0; k < all.size(); ++k) EXPECT_EQ(store->viewContext(all[k].id, cfg), first[k]);
  EXPECT_EQ(store->stats().cache_misses, misses + 1);  // no fingerprint read for them
  ViewSearchConfig other = cfg;
  other.rings = 20;
  EXPECT_EQ(store->viewContext(all[0].id, other)->rings(), 20);
  EXPECT_EQ(store->viewContext(all[0].id, cfg), first[0]);
  ASSERT_EQ(store->deleteSession("m", all[0].robot, all[0].session), 15);
  EXPECT_EQ(store->viewContext(all[0].id, cfg), nullptr);
  EXPECT_EQ(store->viewContext(all[0].id, other), nullptr);
  EXPECT_EQ(store->viewContext(all.back().id, cfg), first.back());
}

TEST_P(OnBothBackends, ApproximateIndexAgreesWithExactSearch) {
  auto opts = db().options();
  std::vector<Stored> all;
  {
    auto store = MapStore::open(opts);
    all = fill(*store, 2, 1, 1000);
  }
  opts.index.type = IndexOptions::Type::kIvf;
  opts.index.ivf_min_scans = 1000;
  opts.index.ivf_nprobe = 16;
  auto store = MapStore::open(opts);
  int found = 0, total = 0;
  for (int i = 0; i < 2000; i += 97) {
    // Query near a stored scan: its own descriptor plus a little noise.
    std::vector<float> q = all[i].fp.descriptor;
    for (std::size_t d = 0; d < q.size(); ++d) q[d] += 0.001f * static_cast<float>((d * 31 + i) % 7);
    SearchRequest req{.map = "m", .descriptor = q, .k = 10};
    const auto got = ids(store->search(req));
    const auto want = bruteForce(all, q, 10, [](const Stored&) { return true; });
    ASSERT_EQ(got.size(), 10u);
    EXPECT_EQ(got[0], all[i].id);
    for (auto id : want) found += std::count(got.begin(), got.end(), id) > 0;
    total += 10;
    req.robots = {"r1"};
    for (auto id : ids(store->search(req))) EXPECT_GE(id, all[1000].id);  // r1's scans come second
  }
  EXPECT_GT(static_cast<double>(found) / total, 0.5) << "recall@10 of the IVF index on random descriptors";
}

}  // namespace
}  // namespace sglc::storage

namespace sglc::storage {
namespace {

Mat4d rigid(double yaw, double x, double y) {
  Mat4d T = Mat4d::Identity();
  T.block<3, 3>(0, 0) = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T(0, 3) = x;
  T(1, 3) = y;
  return T;
}

// Damage inside one of our files is named, not passed on: a descriptor size the index cannot have, a loop
// whose transform holds a NaN (only finite values are ever written).
TEST(MapStore, DamagedRowsAreCorruptNotServed) {
  TempDir dir;
  const auto path = dir.file("map.db");
  {
    auto store = MapStore::open(options(path));
    const auto all = fill(*store, 1, 1, 2);
    store->addLoop("m", {0, all[1].id, all[0].id, rigid(0.1, 1, 2), 0.8, 0.9, 0.05, 12});
  }
  // 12 doubles; the eighth (row 1, column 3) becomes a NaN: 0x7FF8000000000000, little-endian.
  execSql(path, "UPDATE loops SET t = substr(t, 1, 56) || x'000000000000F87F' || substr(t, 65)");
  {
    auto store = MapStore::open(options(path));
    EXPECT_EQ(errorCode([&] { store->loops("m"); }), StorageError::Code::kCorrupt);
  }
  execSql(path, "UPDATE maps SET descriptor_dim = 0");
  EXPECT_EQ(errorCode([&] { MapStore::open(options(path)); }), StorageError::Code::kCorrupt);
}

TEST_P(OnBothBackends, DeletesAWholeMapAndANewOneOfTheNameStartsEmpty) {
  std::vector<Stored> all;
  std::int64_t old_id = 0, old_session = 0;
  {
    auto store = MapStore::open(db().options());
    store->createMap("other", DescriptorLayout{}.scanDim());
    Fingerprint keep = randomFingerprint(4242);
    store->addScan({.map = "other", .robot = "x", .session = "s", .seq = 0, .fingerprint = &keep});
    all = fill(*store, 2, 2, 3);  // map "m", the newest id: 12 scans
    store->addLoop("m", {0, all[2].id, all[0].id, rigid(0.1, 1, 2), 0.8, 0.9, 0.05, 12});
    const auto nodes = store->graphNodes("m");
    old_id = store->findMap("m")->id;
    old_session = nodes[0].session_id;
    store->saveOptimised("m", old_id, {{all[0].id, rigid(0.2, 1, 0)}}, {{old_session, "", "", Mat4d::Identity(), true}},
                         1);
    store->snapshot();  // both maps get an index snapshot
    EXPECT_EQ(store->deleteMap("m"), 12);
    EXPECT_EQ(errorCode([&] { store->deleteMap("m"); }), StorageError::Code::kNotFound);
    EXPECT_EQ(errorCode([&] { store->stats("m"); }), StorageError::Code::kNotFound);
    EXPECT_FALSE(store->findMap("m"));
    for (const auto& st : all) EXPECT_EQ(store->fingerprint(st.id), nullptr);
  }
  // The same name again, in a session that writes no snapshot on close, with as many scans as the deleted map
  // had: the next open must rebuild its index, not load the deleted map's snapshot. It is a new map with a new id
  // (the deleted one was the newest, which SQLite would hand out again), also after a reopen, so that poses
  // solved for the deleted map are refused rather than written into it.
  std::vector<Fingerprint> fresh;
  for (int i = 0; i < 12; ++i) fresh.push_back(randomFingerprint(90000 + static_cast<std::uint64_t>(i)));
  std::vector<std::int64_t> fresh_ids;
  {
    auto o = db().options();
    o.snapshot_index = false;
    auto store = MapStore::open(o);
    store->createMap("m", DescriptorLayout{}.scanDim());
    EXPECT_EQ(store->stats("m").scans, 0);
    EXPECT_EQ(store->stats("m").index_entries, 0);
    EXPECT_TRUE(store->search({.map = "m", .descriptor = all[0].fp.descriptor, .k = 5}).empty());
    EXPECT_TRUE(store->loops("m", 0, 100).empty());
    EXPECT_TRUE(store->graphNodes("m").empty());
    EXPECT_EQ(store->graphVersion("m"), 0);
    EXPECT_GT(store->findMap("m")->id, old_id);
    for (int i = 0; i < 12; ++i)
      fresh_ids.push_back(
          store->addScan({.map = "m", .robot = "n", .session = "s", .seq = i, .fingerprint = &fresh[i]}));
  }
  auto store = MapStore::open(db().options());  // reopened: from the database and whatever snapshots remain
  const auto nodes = store->graphNodes("m");
  EXPECT_EQ(errorCode([&] {
              store->saveOptimised("m", old_id, {{fresh_ids[0], rigid(0.2, 1, 0)}},
                                   {{nodes[0].session_id, "", "", Mat4d::Identity(), true},
                                    {old_session, "", "", Mat4d::Identity(), true}},
                                   1);
            }),
            StorageError::Code::kNotFound);
  EXPECT_EQ(store->graphVersion("m"), 0);
  EXPECT_TRUE(store->optimisedPoses("m", "", "", 0, 100).empty());
  EXPECT_TRUE(store->sessionFrames("m").empty());
  store->createMap("later", DescriptorLayout{}.scanDim());  // after a reopen, too: past every id ever given
  EXPECT_GT(store->findMap("later")->id, store->findMap("m")->id);
  const auto hits = ids(store->search({.map = "m", .descriptor = fresh[5].descriptor, .k = 20}));
  EXPECT_EQ(hits.size(), 12u);
  EXPECT_EQ(hits.front(), fresh_ids[5]);
  for (const auto& st : all) EXPECT_EQ(std::count(hits.begin(), hits.end(), st.id), 0) << "deleted scan found";
  EXPECT_EQ(store->deleteMap("m"), 12);
  EXPECT_EQ(store->stats("other").scans, 1);  // the other map is untouched
  EXPECT_EQ(store->stats("other").index_entries, 1);
  EXPECT_EQ(store->stats().scans, 1);
  EXPECT_EQ(store->integrityCheck(), "ok");
}

TEST_P(OnBothBackends, PoseGraphRowsPersistAndFollowDeletes) {
  std::vector<Stored> all;
  std::int64_t id_a2 = 0;
  {
    auto store = MapStore::open(db().options());
    all = fill(*store, 2, 1, 3);  // r0/s0: all[0..2], r1/s0: all[3..5]
    EXPECT_EQ(store->graphVersion("m"), 0);
    EXPECT_EQ(store->optimisedThroughLoop("m"), 0);
    const LoopRecord a{0, all[2].id, all[0].id, rigid(0.1, 1, 2), 0.8, 0.9, 0.05, 12};
    const LoopRecord b{0, all[4].id, all[1].id, rigid(-0.2, 3, 0), 0.6, 0.7, 0.08, 7};
    const auto id_a = store->addLoop("m", a);
    store->addLoop("m", b);
    auto again = a;
    again.score = 0.9;
    id_a2 = store->addLoop("m", again);  // replaces the first
    EXPECT_GT(id_a2, id_a);
    EXPECT_EQ(errorCode([&] {
                store->addLoop("m", {0, all[0].id, 999999, Mat4d::Identity(), 0, 0, 0, 0});
              }),
              StorageError::Code::kNotFound);
    auto bad = a;
    bad.T(0, 3) = std::nan("");
    EXPECT_EQ(errorCode([&] { store->addLoop("m", bad); }), StorageError::Code::kInvalidArgument);
    EXPECT_EQ(errorCode([&] { store->addLoop("nomap", a); }), StorageError::Code::kNotFound);

    std::vector<OptimisedPose> poses;
    for (const auto& s : all) poses.push_back({s.id, rigid(0.01 * static_cast<double>(s.id), 1.0 * s.seq, 0)});
    const auto nodes = store->graphNodes("m");
    ASSERT_EQ(nodes.size(), all.size());
    EXPECT_EQ(nodes[3].robot, "r1");
    EXPECT_EQ(nodes[3].seq, 0);
    std::vector<SessionFrame> frames{{nodes[0].session_id, "", "", Mat4d::Identity(), true},
                                     {nodes[3].session_id, "", "", rigid(0.5, 10, -4), true}};
    const auto map_id = store->findMap("m")->id;
    EXPECT_EQ(store->saveOptimised("m", map_id, poses, frames, id_a), 1);
    EXPECT_EQ(store->optimisedThroughLoop("m"), id_a);
    EXPECT_EQ(store->saveOptimised("m", map_id, poses, frames, id_a2), 2);
  }
  {
    auto store = MapStore::open(db().options());  // everything survives a reopen
    EXPECT_EQ(store->graphVersion("m"), 2);
    EXPECT_EQ(store->optimisedThroughLoop("m"), id_a2);
    const auto loops = store->loops("m");
    ASSERT_EQ(loops.size(), 2u);
    EXPECT_EQ(loops[1].query_scan, all[2].id);
    EXPECT_DOUBLE_EQ(loops[1].score, 0.9);
    EXPECT_TRUE(loops[1].T.isApprox(rigid(0.1, 1, 2), 1e-15));
    EXPECT_EQ(store->loops("m", loops[0].id).size(), 1u);
    ASSERT_EQ(store->loops("m", 0, 1).size(), 1u);  // at most `limit`, from the first
    EXPECT_EQ(store->loops("m", 0, 1)[0].id, loops[0].id);
    const auto r1 = store->optimisedPoses("m", "r1", "", 0, 100);
    ASSERT_EQ(r1.size(), 3u);
    EXPECT_EQ(r1[0].scan_id, all[3].id);
    EXPECT_TRUE(r1[2].pose.isApprox(rigid(0.01 * static_cast<double>(all[5].id), 2, 0), 1e-15));
    EXPECT_EQ(store->optimisedPoses("m", "", "", all[1].id, 2).size(), 2u);  // paging
    const auto frames = store->sessionFrames("m");
    ASSERT_EQ(frames.size(), 2u);
    EXPECT_EQ(frames[1].robot, "r1");
    EXPECT_TRUE(frames[1].T_map_session.isApprox(rigid(0.5, 10, -4), 1e-15));
    // Deleting robot r1 takes its loop, poses and session frame along.
    store->deleteRobot("m", "r1");
    EXPECT_EQ(store->loops("m").size(), 1u);
    EXPECT_EQ(store->optimisedPoses("m", "", "", 0, 100).size(), 3u);
    EXPECT_EQ(store->sessionFrames("m").size(), 1u);
    EXPECT_EQ(store->integrityCheck(), "ok");
  }
}

TEST(MapStore, MigratesAVersion1FileForward) {
  TempDir dir;
  const auto path = dir.file("map.db");
  std::vector<Stored> all;
  {
    auto store = MapStore::open(options(path));
    all = fill(*store, 1, 1, 4);
  }
  // Turn it back into a version-1 file: no pose-graph tables, no graph_version or graph_loop column.
  execSql(
      path,
      "DROP TABLE places; ALTER TABLE maps DROP COLUMN retired_scans; ALTER TABLE maps DROP COLUMN retired_bytes; DROP "
      "TABLE loops; DROP TABLE optimised_poses; DROP TABLE session_frames;"
      " ALTER TABLE maps DROP COLUMN graph_version; ALTER TABLE maps DROP COLUMN graph_loop; PRAGMA user_version=1;");
  auto store = MapStore::open(options(path));
  EXPECT_EQ(store->stats("m").scans, 4);
  EXPECT_EQ(store->graphVersion("m"), 0);
  store->addLoop("m", {0, all[3].id, all[0].id, Mat4d::Identity(), 0.5, 0.5, 0.1, 5});
  EXPECT_EQ(store->loops("m").size(), 1u);
  for (const auto& s : all) EXPECT_EQ(serialize(*store->fingerprint(s.id)), serialize(s.fp));
  EXPECT_EQ(store->integrityCheck(), "ok");
}

// Rewrites scan `id`'s blob behind the store's back: `bytes`, or bytes of fingerprint format 1 made from `fp`.
void setBlob(const std::string& path, std::int64_t id, std::vector<std::uint8_t> bytes) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* st = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "UPDATE scan_blobs SET fingerprint = ? WHERE scan_id = ?", -1, &st, nullptr),
            SQLITE_OK);
  sqlite3_bind_blob(st, 1, bytes.data(), static_cast<int>(bytes.size()), SQLITE_TRANSIENT);
  sqlite3_bind_int64(st, 2, id);
  EXPECT_EQ(sqlite3_step(st), SQLITE_DONE) << sqlite3_errmsg(db);
  sqlite3_finalize(st);
  sqlite3_close(db);
}

void setDescriptor(const std::string& path, std::int64_t id, const std::vector<float>& d) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* st = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "UPDATE scans SET descriptor = ? WHERE id = ?", -1, &st, nullptr), SQLITE_OK);
  sqlite3_bind_blob(st, 1, d.data(), static_cast<int>(d.size() * sizeof(float)), SQLITE_TRANSIENT);
  sqlite3_bind_int64(st, 2, id);
  EXPECT_EQ(sqlite3_step(st), SQLITE_DONE) << sqlite3_errmsg(db);
  sqlite3_finalize(st);
  sqlite3_close(db);
}

std::uint32_t blobVersion(const std::string& path, std::int64_t id) {
  sqlite3* db = nullptr;
  EXPECT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* st = nullptr;
  sqlite3_prepare_v2(db, "SELECT fingerprint FROM scan_blobs WHERE scan_id = ?", -1, &st, nullptr);
  sqlite3_bind_int64(st, 1, id);
  std::uint32_t version = 0;
  if (sqlite3_step(st) == SQLITE_ROW && sqlite3_column_bytes(st, 0) >= 8)
    std::memcpy(&version, static_cast<const std::uint8_t*>(sqlite3_column_blob(st, 0)) + 4, 4);
  sqlite3_finalize(st);
  sqlite3_close(db);
  return version;
}

// A file of schema 4 holds fingerprints of format 1 (hard-binned edges), one of schema 5 of format 2 (a ring
// key): both had other scan descriptors. Opening the file recomputes every indexed descriptor (a saved index
// snapshot of the old ones is not used) and leaves a blob that does not load as it was.
TEST(MapStore, MigratesOlderFingerprintsToTheCurrentDescriptor) {
  for (const std::uint32_t format : {1u, 2u}) {
    SCOPED_TRACE("format " + std::to_string(format));
    TempDir dir;
    const auto path = dir.file("map.db");
    std::vector<Stored> all;
    {
      auto store = MapStore::open(options(path));  // snapshot_index: the close saves an index of the old values
      all = fill(*store, 1, 1, 5);
    }
    const std::vector<float> old(all[0].fp.descriptor.size(), 0.05f);
    for (std::size_t k = 0; k + 1 < all.size(); ++k) {
      setBlob(path, all[k].id, test::olderFormatBlob(all[k].fp, format, old));
      setDescriptor(path, all[k].id, old);
    }
    setBlob(path, all.back().id, {1, 2, 3});
    execSql(path, format == 1
                      ? "DROP TABLE places; ALTER TABLE maps DROP COLUMN retired_scans; ALTER TABLE maps DROP COLUMN "
                        "retired_bytes; ALTER TABLE loops DROP COLUMN probability; PRAGMA user_version=4;"
                      : "DROP TABLE places; ALTER TABLE maps DROP COLUMN retired_scans; ALTER TABLE maps DROP COLUMN "
                        "retired_bytes; ALTER TABLE loops DROP COLUMN probability; PRAGMA user_version=5;");
    auto store = MapStore::open(options(path));
    for (std::size_t k = 0; k + 1 < all.size(); ++k) {
      // Recomputed from the stored nodes and background view, with the spectrum's default settings.
      const auto& f = all[k].fp;
      const DescriptorConfig defaults;
      const auto expected = scanDescriptor(
          f.nodes, structureSpectrum(f.background, f.background_cell, f.layout.rings, f.layout.orders, defaults),
          f.layout, f.d_max, f.d_i, defaults.background_weight);
      const auto fp = store->fingerprint(all[k].id);
      ASSERT_TRUE(fp);
      ASSERT_EQ(fp->descriptor.size(), expected.size());
      for (std::size_t i = 0; i < expected.size(); ++i) EXPECT_NEAR(fp->descriptor[i], expected[i], 1e-6) << i;
      EXPECT_EQ(blobVersion(path, all[k].id), format);  // the blob stays: it is upgraded whenever it is read
      SearchRequest q;
      q.map = "m";
      q.descriptor = fp->descriptor;
      q.k = 1;
      const auto hits = store->search(q);
      ASSERT_EQ(hits.size(), 1u);
      EXPECT_EQ(hits[0].scan_id, all[k].id);
      EXPECT_LT(hits[0].distance, 1e-3f);
    }
    EXPECT_EQ(errorCode([&] { store->fingerprint(all.back().id); }), StorageError::Code::kCorrupt);
    EXPECT_EQ(store->stats("m").scans, static_cast<std::int64_t>(all.size()));
  }
}

Mat6d someInformation() {
  Mat6d A;
  for (int k = 0; k < 36; ++k) A(k / 6, k % 6) = 0.1 * k - 1.3;
  return A * A.transpose() + Mat6d::Identity();  // symmetric positive definite, not diagonal
}

TEST(MapStore, LoopInformationRoundTripsAndMigratesFromVersion2) {
  TempDir dir;
  const auto path = dir.file("map.db");
  std::vector<Stored> all;
  {
    auto store = MapStore::open(options(path));
    all = fill(*store, 1, 1, 4);
    store->addLoop("m", {0, all[3].id, all[0].id, rigid(0.1, 1, 2), 0.5, 0.5, 0.1, 5});  // no information
  }
  // Back to a version-2 file: no information column, no graph_loop.
  execSql(path,
          "DROP TABLE places; ALTER TABLE maps DROP COLUMN retired_scans; ALTER TABLE maps DROP COLUMN retired_bytes; "
          "ALTER TABLE loops DROP COLUMN information; ALTER TABLE loops DROP COLUMN probability;"
          " ALTER TABLE maps DROP COLUMN graph_loop; PRAGMA user_version=2;");
  const Mat6d info = someInformation();
  {
    auto store = MapStore::open(options(path));
    auto loops = store->loops("m");
    ASSERT_EQ(loops.size(), 1u);
    EXPECT_FALSE(loops[0].information.has_value());  // recorded before: none
    EXPECT_EQ(store->optimisedThroughLoop("m"), 0);  // schema 4's column, added by the migration
    LoopRecord with{0, all[2].id, all[1].id, rigid(-0.2, 3, 0), 0.6, 0.7, 0.08, 7};
    with.information = info;
    store->addLoop("m", with);
    auto bad = with;
    bad.information->coeffRef(2, 4) = std::numeric_limits<double>::infinity();
    EXPECT_EQ(errorCode([&] { store->addLoop("m", bad); }), StorageError::Code::kInvalidArgument);
  }
  auto store = MapStore::open(options(path));
  const auto loops = store->loops("m");
  ASSERT_EQ(loops.size(), 2u);
  ASSERT_TRUE(loops[1].information.has_value());
  EXPECT_TRUE((loops[1].information->array() == info.array()).all());  // bit-exact
  EXPECT_EQ(store->integrityCheck(), "ok");
}

}  // namespace
}  // namespace sglc::storage

namespace sglc::storage {
namespace {

INSTANTIATE_TEST_SUITE_P(MapStore, OnBothBackends, ::testing::Values("sqlite", "postgresql"),
                         [](const ::testing::TestParamInfo<std::string>& info) { return info.param; });

}  // namespace
}  // namespace sglc::storage
