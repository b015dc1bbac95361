// sglc-pair: loop verification and relative pose between two labelled scans, printed as one JSON object.
#include <CLI/CLI.hpp>
#include <array>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>

#include "sglc/bag_drive.hpp"
#include "sglc/config/engine_file.hpp"
#include "sglc/elapsed.hpp"
#include "sglc/io.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/version.hpp"

namespace {

using sglc::msSince;

// The JSON object sglc-pair prints; ms: fingerprint A, fingerprint B, verify, refine.
nlohmann::ordered_json resultJson(const sglc::LoopResult& result, const sglc::Fingerprint& fa,
                                  const sglc::Fingerprint& fb, const sglc::ScanReport& report_a,
                                  const sglc::ScanReport& report_b, const std::array<double, 4>& ms) {
  nlohmann::ordered_json out;
  out["is_loop"] = result.is_loop;
  out["probability"] = result.probability;
  out["score"] = result.score;
  out["inliers"] = result.inliers;
  std::vector<double> T(16);
  for (int k = 0; k < 16; ++k) T[k] = result.T(k / 4, k % 4);
  out["T_a_b"] = T;
  out["matches"] = result.matches;
  out["graph_similarity"] = result.graph_similarity;
  out["background_similarity"] = result.background_similarity;
  out["refined"] = result.refined;
  out["fitness"] = result.fitness;
  out["rmse"] = result.rmse;
  if (!result.is_loop) out["reason"] = std::string(result.reason);
  // What the probability came from (sglc/evidence.hpp), at verification's pose.
  const auto& e = result.evidence;
  out["evidence"] = {{"source", sglc::poseSourceName(e.source)},
                     {"landmarks", e.landmarks},
                     {"landmark_similarity", e.landmark_similarity},
                     {"field_deg", e.field_deg},
                     {"agreement", e.agreement},
                     {"wide_agreement", e.wide_agreement},
                     {"pin", e.pin},
                     {"plane_overlap", e.plane_overlap},
                     {"plane_rmse_m", e.plane_rmse_m},
                     {"constraint", e.constraint},
                     {"context_similarity", e.context_similarity},
                     {"translation_m", e.translation_m}};
  auto source = [](const sglc::ScanReport& r) {
    return r.label_source == sglc::ScanReport::LabelSource::kComputed    ? "computed"
           : r.label_source == sglc::ScanReport::LabelSource::kCompleted ? "completed"
                                                                         : "provided";
  };
  out["labels_a"] = source(report_a);
  out["labels_b"] = source(report_b);
  out["nodes_a"] = fa.nodes.size();
  out["nodes_b"] = fb.nodes.size();
  std::vector<std::string> warnings;
  for (const auto& w : report_a.warnings) warnings.push_back("scan A: " + w);
  for (const auto& w : report_b.warnings) warnings.push_back("scan B: " + w);
  if (!warnings.empty()) out["warnings"] = warnings;
  auto& timings = out["timings_ms"];
  timings["fingerprint_a"] = ms[0];
  timings["fingerprint_b"] = ms[1];
  timings["verify"] = ms[2];
  timings["refine"] = ms[3];
  return out;
}

// A scan file, held to the rules the server applies to a scan (not empty, ...): InputError naming the file.
sglc::LabelledScan readChecked(const std::string& path, const std::string& labels, const std::string& label_field) {
  auto scan = sglc::readScan(path, labels, label_field);
  try {
    sglc::validateScan(scan);
  } catch (const sglc::InputError& e) {
    throw sglc::InputError(path + ": " + e.what());
  }
  return scan;
}

// Which cloud of a bag: its index on the topic, or the one whose stamp is nearest `stamp` (seconds).
struct BagPick {
  std::string topic, odom;
  std::int64_t index = -1;
  double stamp = -1;
};

// A cloud of a bag (sglc/bag_drive.hpp), de-skewed when the odometry gives its motion and it has per-point times.
sglc::LabelledScan readFromBag(const std::string& path, const BagPick& pick, const char* which) {
  if (pick.topic.empty()) throw sglc::InputError(path + " is a bag: give --points-topic");
  if ((pick.index >= 0) == (pick.stamp >= 0))
    throw sglc::InputError(std::string("scan ") + which + " is in a bag: give its --index-" + which + " or --stamp-" +
                           which + " (one of them)");
  sglc::BagDriveOptions o;
  o.points_topic = pick.topic;
  o.odom_topic = pick.odom;
  o.keyframe_m = o.keyframe_deg = 0;
  sglc::BagDrive drive(path, o);
  std::size_t best = 0;
  for (std::size_t i = 0; i < drive.frames().size(); ++i) {
    const auto& f = drive.frames()[i];
    if (pick.index >= 0 ? f.number == pick.index
                        : std::abs(static_cast<double>(f.stamp_ns) * 1e-9 - pick.stamp) <
                              std::abs(static_cast<double>(drive.frames()[best].stamp_ns) * 1e-9 - pick.stamp))
      best = i;
  }
  if (pick.index >= 0 && drive.frames()[best].number != pick.index)
    throw sglc::InputError(path + ": " + pick.topic + " has no cloud " + std::to_string(pick.index) +
                           (pick.odom.empty() ? "" : " with a pose") + " (" + std::to_string(drive.clouds()) +
                           " clouds)");
  sglc::LabelledScan scan{drive.cloud(best).points, {}};
  try {
    sglc::validateScan(scan);
  } catch (const sglc::InputError& e) {
    throw sglc::InputError(path + ": " + e.what());
  }
  return scan;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Checks whether two labelled LiDAR scans close a loop and estimates T_a_b (maps B into A)."};
  app.set_version_flag("--version", std::string("sglc-pair ") + sglc::kVersion);
  std::string scan_a, labels_a, scan_b, labels_b, config_path, label_field = "label";
  bool dump = false, known_loop = false;
  app.add_flag("--dump-config", dump, "Print the effective configuration as YAML and exit");
  app.add_option("--scan-a", scan_a, "Scan A (the query): .bin (KITTI), .pcd, .ply or .npy");
  app.add_option("--labels-a", labels_a,
                 "Labels of scan A: .label (1, 2 or 4 bytes per point) or .npy; absent: a PCD/PLY file's own "
                 "label field, else the labeller");
  app.add_option("--scan-b", scan_b, "Scan B (the candidate), in any of the same formats");
  app.add_option("--labels-b", labels_b, "Labels of scan B (as --labels-a)");
  app.add_option("--label-field", label_field, "Label field of PCD/PLY scans")->capture_default_str();
  app.add_flag("--known-loop", known_loop,
               "The scans are known to show the same place: estimate T_a_b even when verification rejects the pair "
               "(is_loop keeps the decision, refined says whether a pose was found)");
  app.add_option("--config", config_path, "YAML file overriding engine parameters (see --dump-config)");
  BagPick pick_a, pick_b;
  app.add_option("--points-topic", pick_a.topic,
                 "When a scan is a bag (MCAP, .db3, rosbag2 directory, ROS 1 .bag): its "
                 "PointCloud2 topic");
  app.add_option("--odom-topic", pick_a.odom, "... and its Odometry topic (clouds with per-point times are de-skewed)");
  app.add_option("--index-a", pick_a.index, "Scan A's cloud in its bag: its index on the topic");
  app.add_option("--stamp-a", pick_a.stamp, "... or the cloud whose stamp (s) is nearest");
  app.add_option("--index-b", pick_b.index, "Scan B's cloud in its bag (as --index-a)");
  app.add_option("--stamp-b", pick_b.stamp, "... or by stamp (as --stamp-a)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "sglc-pair: error: " << e.what() << " (see --help)" << std::endl;
    return 2;
  }
  try {
    const sglc::Pipeline pipeline(config_path.empty() ? sglc::Config{} : sglc::loadConfig(config_path));
    if (dump) {
      std::cout << sglc::dumpConfig(pipeline.config());
      return 0;
    }
    if (scan_a.empty() || scan_b.empty()) throw sglc::InputError("--scan-a and --scan-b are required");
    pick_b.topic = pick_a.topic;
    pick_b.odom = pick_a.odom;
    const auto a = sglc::isBag(scan_a) ? readFromBag(scan_a, pick_a, "a") : readChecked(scan_a, labels_a, label_field);
    const auto b = sglc::isBag(scan_b) ? readFromBag(scan_b, pick_b, "b") : readChecked(scan_b, labels_b, label_field);
    auto t0 = std::chrono::steady_clock::now();
    sglc::ScanReport report_a, report_b;
    const auto fa = pipeline.fingerprint(a, &report_a);
    const double t_fa = msSince(t0);
    t0 = std::chrono::steady_clock::now();
    const auto fb = pipeline.fingerprint(b, &report_b);
    const double t_fb = msSince(t0);
    t0 = std::chrono::steady_clock::now();
    auto result = pipeline.verify(fa, fb);
    const double t_verify = msSince(t0);
    t0 = std::chrono::steady_clock::now();
    pipeline.refine(fa, fb, result, known_loop);
    const double t_refine = msSince(t0);

    std::cout << resultJson(result, fa, fb, report_a, report_b, {t_fa, t_fb, t_verify, t_refine}).dump() << std::endl;
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "sglc-pair: error: " << e.what() << std::endl;
    return 1;
  }
}
