#include "sglc/client/export_formats.hpp"

#include <cmath>
#include <cstdio>
#include <map>

#include "sglc/types.hpp"
#include "sglc/wire/geometry_codec.hpp"

namespace sglc::client {
namespace {

nlohmann::ordered_json endJson(const v1::LoopEnd& e) {
  return {{"scan_id", e.scan_id()}, {"robot", e.robot()}, {"session", e.session()}, {"seq", e.seq()}};
}

Mat6d informationOf(const v1::LoopEdge& l) {
  Mat6d info = Mat6d::Zero();
  if (l.information_size() == 36) {
    for (int k = 0; k < 36; ++k) info(k / 6, k % 6) = l.information(k);
    return info;
  }
  const double st = 0.1, sr = M_PI / 180.0;
  info.diagonal() << 1 / (st * st), 1 / (st * st), 1 / (st * st), 1 / (sr * sr), 1 / (sr * sr), 1 / (sr * sr);
  return info;
}

// "x y z qx qy qz qw" of a pose, as g2o writes it.
std::string poseG2o(const Mat4d& T) {
  const Eigen::Quaterniond q(Eigen::Matrix3d(T.topLeftCorner<3, 3>()));
  char buf[256];
  std::snprintf(buf, sizeof buf, "%.9g %.9g %.9g %.9g %.9g %.9g %.9g", T(0, 3), T(1, 3), T(2, 3), q.x(), q.y(), q.z(),
                q.w());
  return buf;
}

}  // namespace

nlohmann::ordered_json loopJson(const v1::LoopEdge& l) {
  nlohmann::ordered_json j;
  j["id"] = l.id();
  j["query"] = endJson(l.query());
  j["candidate"] = endJson(l.candidate());
  j["score"] = l.score();
  // null: recorded before the loop model (unknown).
  j["probability"] = l.has_probability() ? nlohmann::ordered_json(l.probability()) : nlohmann::ordered_json(nullptr);
  j["inliers"] = l.inliers();
  j["fitness"] = l.fitness();
  j["rmse"] = l.rmse();
  j["T"] = std::vector<double>(l.t_query_candidate().m().begin(), l.t_query_candidate().m().end());
  if (l.information_size() > 0) j["information"] = std::vector<double>(l.information().begin(), l.information().end());
  return j;
}

void writeLoopsCsv(const std::vector<v1::LoopEdge>& loops, std::ostream& out) {
  // Robot and session names may hold commas or quotes: quoted per RFC 4180.
  auto quoted = [](const std::string& s) {
    std::string q = "\"";
    for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
    return q + "\"";
  };
  out << "id,query_scan,query_robot,query_session,query_seq,candidate_scan,candidate_robot,candidate_session,"
         "candidate_seq,score,probability,inliers,fitness,rmse";
  for (int k = 0; k < 16; ++k) out << ",T" << k / 4 << k % 4;
  out << ",has_information\n";
  char buf[64];
  for (const auto& l : loops) {
    out << l.id() << "," << l.query().scan_id() << "," << quoted(l.query().robot()) << ","
        << quoted(l.query().session()) << "," << l.query().seq() << "," << l.candidate().scan_id() << ","
        << quoted(l.candidate().robot()) << "," << quoted(l.candidate().session()) << "," << l.candidate().seq();
    std::snprintf(buf, sizeof buf, ",%.9g,", l.score());
    out << buf;
    if (l.has_probability()) {  // empty: recorded before the loop model (unknown)
      std::snprintf(buf, sizeof buf, "%.17g", l.probability());
      out << buf;
    }
    for (double v : {double(l.inliers()), l.fitness(), l.rmse()}) {
      std::snprintf(buf, sizeof buf, ",%.9g", v);
      out << buf;
    }
    for (double v : l.t_query_candidate().m()) {
      std::snprintf(buf, sizeof buf, ",%.17g", v);  // round-trips a double
      out << buf;
    }
    out << "," << (l.information_size() == 36 ? 1 : 0) << "\n";
  }
}

std::size_t writeLoopsG2o(const std::vector<v1::LoopEdge>& loops, const std::vector<v1::ScanPose>& vertices,
                          std::ostream& out) {
  std::map<std::int64_t, Mat4d> poses;
  for (const auto& v : vertices) poses[v.scan_id()] = wire::toMatrix(v.t_map_scan());
  std::size_t without_pose = 0;
  for (const auto& l : loops)
    for (const auto id : {l.query().scan_id(), l.candidate().scan_id()})
      without_pose += poses.emplace(id, Mat4d::Identity()).second;
  for (const auto& [id, T] : poses) out << "VERTEX_SE3:QUAT " << id << " " << poseG2o(T) << "\n";
  Eigen::Matrix<double, 6, 1> scale;
  scale << 1, 1, 1, 2, 2, 2;
  char buf[64];
  for (const auto& l : loops) {
    const Mat6d info = scale.asDiagonal() * informationOf(l) * scale.asDiagonal();
    out << "EDGE_SE3:QUAT " << l.query().scan_id() << " " << l.candidate().scan_id() << " "
        << poseG2o(wire::toMatrix(l.t_query_candidate()));
    for (int r = 0; r < 6; ++r)
      for (int c = r; c < 6; ++c) {
        std::snprintf(buf, sizeof buf, " %.9g", 0.5 * (info(r, c) + info(c, r)));
        out << buf;
      }
    out << "\n";
  }
  return without_pose;
}

}  // namespace sglc::client
