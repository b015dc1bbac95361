// `sglc ingest DIR|BAG`: a sequence directory, or a bag's drive, streamed to the server as one robot session.
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <deque>
#include <iostream>
#include <memory>
#include <thread>

#include "common.hpp"
#include "ingest_source.hpp"
#include "sglc/client/packing.hpp"

namespace sglc::cli {
namespace {

// Progress bar (stderr)

class Progress {
 public:
  Progress(bool enabled, std::size_t total) : enabled_(enabled), total_(total), t0_(std::chrono::steady_clock::now()) {}
  void update(std::size_t done, std::size_t loops) {
    if (!enabled_) return;
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
    const int width = 30;
    const int filled = total_ ? static_cast<int>(width * done / total_) : width;
    std::string bar(filled, '#');
    bar.resize(width, '.');
    std::fprintf(stderr, "\r\033[K[%s] %zu/%zu scans  %.1f/s  %zu loops", bar.c_str(), done, total_,
                 s > 0 ? done / s : 0.0, loops);
    std::fflush(stderr);
    shown_ = true;
  }
  // Removes the bar so that other output starts on a clean line.
  void clear() {
    if (!shown_) return;
    std::fprintf(stderr, "\r\033[K");
    std::fflush(stderr);
    shown_ = false;
  }
  void done() {
    if (!shown_) return;
    std::fprintf(stderr, "\n");
    shown_ = false;
  }

 private:
  bool enabled_;
  std::size_t total_;
  std::chrono::steady_clock::time_point t0_;
  bool shown_ = false;
};

// ---------------------------------------------------------------------------------------------------------
// Subcommands

struct IngestArgs {
  std::string map, robot, session;
  SourceOptions source;
  bool query = false;
  bool store_raw = false;
  bool progress = false, no_progress = false;
  int window = 4;
  int retries = 5;
  double chunk_mb = sc::kDefaultChunkBytes / 1e6;
  QueryFlags q;
};

// A break of the connection rather than an answer of the server: UNAVAILABLE, or a stream reset by a proxy whose
// upstream died (gRPC reports RST_STREAM as INTERNAL).
bool retryable(const sc::RpcError& e) {
  return e.code() == grpc::StatusCode::UNAVAILABLE ||
         (e.code() == grpc::StatusCode::INTERNAL && e.statusMessage().find("RST_STREAM") != std::string::npos);
}

// One robot session sent over IngestStream; when the stream breaks (the server, or the replica behind a
// balancer, went away), a new stream resends the scans not yet answered. Ingest is idempotent: a scan
// stored before the break is answered as stored, not stored twice.
class Feeder {
 public:
  Feeder(const Common& common, const IngestArgs& a, IngestSource& source, std::string session)
      : common_(common),
        a_(a),
        source_(source),
        session_(std::move(session)),
        client_(connectClient(common, static_cast<std::size_t>(a.chunk_mb * 1e6))),
        progress_(a.progress || (::isatty(STDERR_FILENO) == 1 && !a.no_progress), source.frames().size()) {
    options_.store_raw = a.store_raw;
    options_.query = a.query;
    options_.query_options = toQueryOptions(a.q);
  }

  void run() {
    client_.ensureMap(a_.map);
    progress_.update(0, 0);
    // The retry budget is per break: a stream that got answers before it broke starts the count again, so a long
    // drive survives any number of breaks that each recover.
    for (int attempt = 0;; ++attempt) {
      const auto answered = done_;
      try {
        stream();
        break;
      } catch (const sc::RpcError& e) {
        if (done_ > answered) attempt = 0;
        if (!retryable(e) || attempt >= a_.retries) fail(e.what());
        progress_.clear();
        std::cerr << "sglc ingest: " << e.what() << "; retrying " << pending_.size() << " unanswered scans ("
                  << attempt + 1 << "/" << a_.retries << ")\n";
        std::this_thread::sleep_for(std::chrono::milliseconds(200) * (1 << std::min(attempt, 5)));
      } catch (const std::exception& e) {
        fail(e.what());
      }
    }
    progress_.done();
    if (!common_.json)
      std::cout << "ingested " << done_ << " scans from " << a_.source.path << " into map " << a_.map << " (robot "
                << a_.robot << ", session " << session_ << ")"
                << (a_.query ? ", " + std::to_string(loops_) + " loops" : "") << "\n";
  }

 private:
  // One stream: first the scans a broken stream left unanswered, then the rest. Every answer is reported, even
  // when the stream then fails.
  void stream() {
    sc::IngestSession stream = client_.openSession();
    std::size_t resent = 0;
    try {
      for (; resent < pending_.size(); ++resent) send(stream, pending_[resent]);
      while (next_ < source_.frames().size()) {
        const std::size_t i = next_++;  // counted as sent before anything can throw: a break resends it once
        pending_.push_back(i);
        send(stream, i);
        while (stream.outstanding() >= static_cast<std::size_t>(a_.window)) handle(stream.next());
      }
      while (stream.outstanding() > 0) handle(stream.next());
    } catch (const sc::RpcError&) {
      // What the server answered before the break is in order on the stream: report it, resend the rest.
      handleAnswered(stream);
      throw;
    } catch (const std::exception&) {
      // A scan that cannot be read: the scans sent before it are answered (and counted as stored) first.
      handleAnswered(stream);
      throw;
    }
    stream.finish();
  }

  // Reports the answers to the scans still outstanding, up to the first failure (which the caller reports).
  void handleAnswered(sc::IngestSession& stream) {
    try {
      while (stream.outstanding() > 0) handle(stream.next());
    } catch (const std::exception&) {
    }
  }

  void send(sc::IngestSession& stream, std::size_t i) {
    const auto& f = source_.frames()[i];
    const sglc::LabelledScan scan = source_.scan(i);
    auto o = options_;
    o.stamp = f.stamp;
    o.odometry_pose = f.pose;
    stream.send(sc::makeKey(a_.map, a_.robot, session_, f.number), scan, o);
  }

  void handle(const v1::IngestResponse& r) {
    const std::string frame = source_.frames()[pending_.front()].name;
    pending_.pop_front();
    ++done_;
    loops_ += r.loops_size();
    if (common_.json) {
      json j;
      j["scan_id"] = r.scan_id();
      j["frame"] = frame;
      j["loops"] = json::array();
      for (const auto& c : r.loops()) j["loops"].push_back(candidateJson(c));
      progress_.clear();
      std::cout << j.dump() << std::endl;
    } else if (r.loops_size() > 0) {
      progress_.clear();
      for (const auto& c : r.loops())
        std::cout << "frame " << frame << " (scan " << r.scan_id() << "): loop with " << candidateText(c) << "\n";
      std::cout.flush();
    }
    progress_.update(done_, loops_);
  }

  [[noreturn]] void fail(const std::string& why) {
    progress_.clear();
    throw std::runtime_error(why + " (after " + std::to_string(done_) + " of " +
                             std::to_string(source_.frames().size()) + " scans were stored)");
  }

  const Common& common_;
  const IngestArgs& a_;
  IngestSource& source_;
  const std::string session_;
  const sc::Client client_;
  Progress progress_;
  sc::IngestOptions options_;
  std::deque<std::size_t> pending_;  // frames sent and not yet answered, in order
  std::size_t next_ = 0;             // the next frame never sent
  std::size_t done_ = 0, loops_ = 0;
};

int runIngest(const Common& common, const IngestArgs& a) {
  if (a.map.empty()) throw UsageError("--map is empty");
  if (a.robot.empty()) throw UsageError("--robot is empty");
  if (a.window < 1) throw UsageError("--window must be at least 1");
  if (a.retries < 0 || a.retries > 100) throw UsageError("--retries must be between 0 and 100");
  if (!(a.chunk_mb >= 0.001 && a.chunk_mb <= 2000)) throw UsageError("--chunk-mb must be between 0.001 and 2000");
  const auto source = openSource(a.source);
  const std::string session = a.session.empty() ? source->name() : a.session;
  if (session.empty()) throw UsageError("cannot name the session after " + a.source.path + ": give --session");
  Feeder(common, a, *source, session).run();
  return 0;
}

}  // namespace

void addIngest(CLI::App& app, Common& common, Commands& out) {
  auto a = std::make_shared<IngestArgs>();
  auto* c = app.add_subcommand(
      "ingest",
      "Store a sequence directory (any one scan format) or a bag's drive (MCAP, rosbag2) as one robot session");
  addCommon(c, common);
  c->add_option("--map", a->map, "Map name (created if missing)")->required();
  c->add_option("--robot", a->robot, "Robot name")->required();
  c->add_option("--session", a->session, "Session name (default: the directory's or bag's base name)");
  c->add_option("--frames", a->source.frames,
                "Frame numbers (a bag's: each cloud's index on its topic): a, a:b (b exclusive; a: and :b "
                "open-ended), a:b:s, or a comma-separated list");
  c->add_option("--every", a->source.every, "Ingest every N-th frame")->capture_default_str();
  c->add_option("--label-field", a->source.label_field, "Label field of PCD/PLY scans")->capture_default_str();
  c->add_option("--poses", a->source.poses,
                "Odometry file (KITTI 3x4 or TUM) instead of DIR/poses.txt: a line per frame number or per scan");
  c->add_option(
       "--poses-frame", a->source.poses_frame,
       "auto: a KITTI poses file next to a calib.txt holds camera poses (turned into LiDAR poses with its Tr), "
       "anything else LiDAR poses; lidar: as they are; camera: apply calib.txt's Tr")
      ->check(CLI::IsMember({"auto", "lidar", "camera"}))
      ->capture_default_str();
  c->add_flag("--query", a->query, "Look for loops before each scan is stored and report them");
  c->add_flag("--store-raw", a->store_raw, "Also keep the raw clouds on the server");
  c->add_flag("--progress", a->progress, "Show the progress bar even when stderr is not a terminal");
  c->add_flag("--no-progress", a->no_progress, "Never show the progress bar");
  c->add_option("--window", a->window, "Scans in flight on the stream")->capture_default_str();
  c->add_option(
       "--retries", a->retries,
       "When the stream breaks (UNAVAILABLE, or reset by a proxy), reopen it and resend the unanswered scans this "
       "many times "
       "(ingest is idempotent)")
      ->capture_default_str();
  c->add_option("--chunk-mb", a->chunk_mb,
                "Scans larger than this (packed) go through IngestChunked in pieces this size")
      ->capture_default_str();
  addQueryFlags(c, a->q, false);
  c->add_option("--points-topic", a->source.bag.points_topic, "A bag's sensor_msgs/PointCloud2 topic");
  c->add_option("--odom-topic", a->source.bag.odom_topic,
                "A bag's nav_msgs/Odometry topic (the sensor's extrinsic from /tf_static)");
  c->add_option("--tf", a->source.bag.tf_frame,
                "Or: the fixed frame (odom, map) to look the cloud's frame up in, over /tf");
  c->add_option("--keyframe-m", a->source.bag.keyframe_m,
                "With poses, a bag's cloud is sent when the sensor moved this far since the last one sent")
      ->capture_default_str();
  c->add_option("--keyframe-deg", a->source.bag.keyframe_deg, "... or turned this much (both 0: every cloud)")
      ->capture_default_str();
  c->add_flag(
      "--no-deskew", [a](std::int64_t) { a->source.bag.deskew = false; },
      "Send scans with per-point times (a directory's point_times/, a bag's time field) as they are; by "
      "default they are de-skewed with the motion the poses give");
  c->add_option("DIR", a->source.path,
                "Sequence directory (velodyne/NNNNNN.{bin,pcd,ply,npy}, optional labels/ (.label or .npy), "
                "poses.txt (KITTI or TUM), times.txt, calib.txt), or a bag: an MCAP file, a rosbag2 .db3 file or "
                "directory")
      ->required();
  out.push_back({c, [&common, a] { return runIngest(common, *a); }});
}

}  // namespace sglc::cli
