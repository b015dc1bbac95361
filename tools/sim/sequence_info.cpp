#include "sim/sequence_info.hpp"

#include <fstream>
#include <nlohmann/json.hpp>

namespace sglc::sim {
namespace {

using Json = nlohmann::ordered_json;

// Per-class IoU of the written labels against the true ones (SemanticKITTI single-scan scoring: moving
// classes count as static ones); classes absent from both are left out.
Json labelIouJson(const LabelIouCounts& counts) {
  Json iou = Json::object();
  for (int k = 0; k < kEvalClasses; ++k)
    if (counts.present(k)) iou[kEvalClassTable[k].name] = counts.iou(k);
  return iou;
}

Json sensorJson(const SensorConfig& s) {
  Json j = {{"name", s.name},
            {"beams", s.beams()},
            {"elevation_deg", s.elevation_deg},
            {"columns", s.columns},
            {"max_range", s.max_range},
            {"min_range", s.min_range},
            {"range_noise", s.range_noise},
            {"dropout", s.dropout},
            {"far_dropout", s.far_dropout},
            {"grazing_dropout", s.grazing_dropout},
            {"glass_dropout", s.glass_dropout},
            {"intensity_noise", s.intensity_noise}};
  // Realism knobs (render.cpp, sensor.hpp); a rosette's beams x columns are its pseudo range image.
  j["laser_offsets"] = s.laser_offsets;
  j["mixed_pixel_rate"] = s.mixed_pixel_rate;
  j["motion_distortion"] = s.motion_distortion;
  if (s.isRosette())
    j["rosette"] = {{"rays", s.rosette_rays}, {"fov_h_deg", s.rosette_fov_h_deg}, {"fov_v_deg", s.rosette_fov_v_deg}};
  return j;
}

// The world's settings, its drawn style and what it holds; content_hash pins the exact content.
Json worldJson(const WorldConfig& cfg, const World& world) {
  const auto& st = world.style();
  const auto& ws = world.stats();
  return {{"sensor_height", cfg.sensor_height},
          {"moving_objects", cfg.moving_objects},
          {"path_extension", cfg.path_extension},
          {"turnover", cfg.turnover},
          {"epoch", cfg.epoch},
          {"aliasing", cfg.aliasing},
          {"parking_slots", ws.parking_slots},
          {"temporary_sites", ws.temporary_sites},
          {"aliased_lots", ws.aliased_lots},
          {"lane_width", st.lane_width},
          {"road_half_width", st.road_half_width},
          {"parking_width", st.parking_width},
          {"sidewalk_width", st.sidewalk_width},
          {"path_length_m", ws.path_length_m},
          {"primitives", ws.primitives},
          {"buildings", ws.buildings},
          {"fences", ws.fences},
          {"hedges", ws.hedges},
          {"trees", ws.trees},
          {"bushes", ws.bushes},
          {"poles", ws.poles},
          {"signs", ws.signs},
          {"parked_vehicles", ws.parked_vehicles},
          {"moving_agents", ws.moving_agents},
          {"memory_bytes", ws.memory_bytes},
          {"build_seconds", ws.build_seconds},
          {"content_hash", world.contentHash()}};
}

// The ground-truth files' settings and counts.
void addGroundTruth(Json& info, const SequenceOptions& opt, const SequenceSummary& summary) {
  info["odometry_noise"] = {{"translation", opt.odometry.translation},
                            {"rotation_deg_per_m", opt.odometry.rotation_deg_per_m}};
  info["pairs_distance"] = {
      {"positive_m", opt.pairs.positive_m}, {"negative_m", opt.pairs.negative_m},
      {"min_gap", opt.pairs.min_gap},       {"negatives_per_positive", opt.pairs.negatives_per_positive},
      {"positives", summary.positives},     {"negatives", summary.negatives}};
  info["loop_distance4"] = {
      {"max_m", opt.loop_pose_m}, {"rows", summary.loop_rows}, {"reverse_rows", summary.reverse_loop_rows}};
}

Json conventionsJson() {
  return {{"points", "sensor (LiDAR) frame: x forward, y left, z up; float32 x y z intensity"},
          {"labels",
           "SemanticKITTI raw class id in the low 16 bits, instance id in the high 16 bits (vehicles, "
           "persons, trunks, poles, traffic signs)"},
          {"poses", "LiDAR -> world, world = LiDAR frame of trajectory frame 0; row k = output frame k"},
          {"loop_distance4", "p_j = T * p_i (T maps points of the earlier frame i into the later frame j)"},
          {"pairs_distance", "i later, j earlier; horizontal (x, y) distance"}};
}

}  // namespace

std::vector<double> poseRow12(const Mat4d& T) {
  std::vector<double> v;
  for (int k = 0; k < 12; ++k) v.push_back(T(k / 4, k % 4));
  return v;
}

void writeSimInfo(const std::string& path, const Simulator& sim, const SequenceOptions& opt,
                  const SequenceSummary& summary) {
  const SimConfig& cfg = sim.config();
  const Trajectory& traj = sim.trajectory();
  const int n = static_cast<int>(opt.frames.size());
  Json info;
  info["generator"] = "sglc-sim";
  info["format_version"] = 1;
  info["seed"] = cfg.seed;
  info["source"] = traj.source;
  info["Tr"] = poseRow12(traj.Tr);
  info["frame_dt"] = traj.frame_dt;
  info["trajectory_frames"] = sim.numFrames();
  info["selection"] = opt.selection_spec;
  info["frames"] = n;
  info["sensor"] = sensorJson(cfg.sensor);
  info["world"] = worldJson(cfg.world, sim.world());
  info["label_noise"] = {{"model", cfg.label_noise.modelName()},
                         {"confusion", cfg.label_noise.confusion},
                         {"bleed", cfg.label_noise.bleed},
                         {"miss", cfg.label_noise.miss}};
  info["label_iou"] = labelIouJson(summary.label_iou);
  info["label_miou"] = summary.label_iou.meanIou();
  addGroundTruth(info, opt, summary);
  info["conventions"] = conventionsJson();
  info["summary"] = {{"points", summary.points},
                     {"points_per_frame", static_cast<double>(summary.points) / n},
                     {"seconds", summary.seconds},
                     {"frames_per_second", summary.frames_per_second}};
  std::ofstream f(path, std::ios::trunc);
  if (!f) throw InputError(path + ": cannot create");
  f << info.dump(2) << '\n';
  f.close();
  if (!f) throw InputError(path + ": write failed");
}

}  // namespace sglc::sim
