// `sglc ingest DIR`: a sequence directory streamed to the server as one robot session.
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <deque>
#include <iostream>
#include <memory>

#include "common.hpp"
#include "sglc/client/packing.hpp"
#include "sglc/io.hpp"
#include "sglc/sequence.hpp"

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
  std::string map, robot, session, dir, frames;
  std::string label_field = "label";
  int every = 1;
  bool query = false;
  bool store_raw = false;
  bool progress = false, no_progress = false;
  int window = 4;
  double chunk_mb = sc::kDefaultChunkBytes / 1e6;
  QueryFlags q;
};

int runIngest(const Common& common, const IngestArgs& a) {
  if (a.map.empty()) throw UsageError("--map is empty");
  if (a.robot.empty()) throw UsageError("--robot is empty");
  if (a.window < 1) throw UsageError("--window must be at least 1");
  if (!(a.chunk_mb >= 0.001 && a.chunk_mb <= 2000)) throw UsageError("--chunk-mb must be between 0.001 and 2000");
  const v1::QueryOptions query_options = toQueryOptions(a.q);
  const sglc::Sequence seq = sglc::openSequence(a.dir, sglc::FrameSelection::parse(a.frames), a.every);
  const std::string session = a.session.empty() ? seq.name : a.session;
  if (session.empty()) throw UsageError("cannot name the session after " + a.dir + ": give --session");

  const sc::Client client = connectClient(common, static_cast<std::size_t>(a.chunk_mb * 1e6));
  client.ensureMap(a.map);

  const bool tty = ::isatty(STDERR_FILENO) == 1;
  Progress progress(a.progress || (tty && !a.no_progress), seq.frames.size());
  progress.update(0, 0);

  sc::IngestSession stream = client.openSession();
  std::deque<std::string> pending_frames;
  std::size_t done = 0, loops = 0;
  auto handle = [&](const v1::IngestResponse& r) {
    const std::string frame = pending_frames.front();
    pending_frames.pop_front();
    ++done;
    loops += r.loops_size();
    if (common.json) {
      json j;
      j["scan_id"] = r.scan_id();
      j["frame"] = frame;
      j["loops"] = json::array();
      for (const auto& c : r.loops()) j["loops"].push_back(candidateJson(c));
      progress.clear();
      std::cout << j.dump() << std::endl;
    } else if (r.loops_size() > 0) {
      progress.clear();
      for (const auto& c : r.loops())
        std::cout << "frame " << frame << " (scan " << r.scan_id() << "): loop with " << candidateText(c) << "\n";
      std::cout.flush();
    }
    progress.update(done, loops);
  };

  std::string failure;
  try {
    for (const auto& f : seq.frames) {
      const sglc::LabelledScan scan = sglc::readScan(f.scan_path, f.label_path, a.label_field);
      sc::IngestOptions o;
      o.stamp = f.stamp;
      o.odometry_pose = f.pose;
      o.store_raw = a.store_raw;
      o.query = a.query;
      o.query_options = query_options;
      stream.send(sc::makeKey(a.map, a.robot, session, f.number), scan, o);
      pending_frames.push_back(f.name);
      while (stream.outstanding() >= static_cast<std::size_t>(a.window)) handle(stream.next());
    }
  } catch (const std::exception& e) {
    failure = e.what();
  }
  // Report every scan the server answered, even after a failure, then close the stream.
  try {
    while (stream.outstanding() > 0) handle(stream.next());
    stream.finish();
  } catch (const std::exception& e) {
    if (failure.empty()) failure = e.what();
  }
  if (!failure.empty()) {
    progress.clear();
    throw std::runtime_error(failure + " (after " + std::to_string(done) + " of " + std::to_string(seq.frames.size()) +
                             " scans were stored)");
  }
  progress.done();
  if (!common.json)
    std::cout << "ingested " << done << " scans from " << a.dir << " into map " << a.map << " (robot " << a.robot
              << ", session " << session << ")" << (a.query ? ", " + std::to_string(loops) + " loops" : "") << "\n";
  return 0;
}

}  // namespace

void addIngest(CLI::App& app, Common& common, Commands& out) {
  auto a = std::make_shared<IngestArgs>();
  auto* c = app.add_subcommand("ingest", "Store a sequence directory (any one scan format) as one robot session");
  addCommon(c, common);
  c->add_option("--map", a->map, "Map name (created if missing)")->required();
  c->add_option("--robot", a->robot, "Robot name")->required();
  c->add_option("--session", a->session, "Session name (default: the directory's base name)");
  c->add_option("--frames", a->frames,
                "Frame numbers: a, a:b (b exclusive; a: and :b open-ended), a:b:s, or a comma-separated list");
  c->add_option("--every", a->every, "Ingest every N-th frame")->capture_default_str();
  c->add_option("--label-field", a->label_field, "Label field of PCD/PLY scans")->capture_default_str();
  c->add_flag("--query", a->query, "Look for loops before each scan is stored and report them");
  c->add_flag("--store-raw", a->store_raw, "Also keep the raw clouds on the server");
  c->add_flag("--progress", a->progress, "Show the progress bar even when stderr is not a terminal");
  c->add_flag("--no-progress", a->no_progress, "Never show the progress bar");
  c->add_option("--window", a->window, "Scans in flight on the stream")->capture_default_str();
  c->add_option("--chunk-mb", a->chunk_mb,
                "Scans larger than this (packed) go through IngestChunked in pieces this size")
      ->capture_default_str();
  addQueryFlags(c, a->q, false);
  c->add_option("DIR", a->dir,
                "Sequence directory: velodyne/NNNNNN.{bin,pcd,ply,npy}, optional labels/ (.label or .npy), "
                "poses.txt (KITTI or TUM), times.txt")
      ->required();
  out.push_back({c, [&common, a] { return runIngest(common, *a); }});
}

}  // namespace sglc::cli
