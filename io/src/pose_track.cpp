#include "pose_track.hpp"

#include <algorithm>

namespace sglc {

void PoseTrack::sort() {
  std::stable_sort(samples_.begin(), samples_.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  samples_.erase(
      std::unique(samples_.begin(), samples_.end(), [](const auto& a, const auto& b) { return a.first == b.first; }),
      samples_.end());
}

std::optional<Mat4d> PoseTrack::at(std::int64_t t, std::int64_t slack_ns) const {
  if (samples_.empty()) return std::nullopt;
  if (t <= samples_.front().first) {
    if (samples_.front().first - t > slack_ns) return std::nullopt;
    return samples_.front().second;
  }
  if (t >= samples_.back().first) {
    if (t - samples_.back().first > slack_ns) return std::nullopt;
    return samples_.back().second;
  }
  const auto hi =
      std::lower_bound(samples_.begin(), samples_.end(), t, [](const auto& s, std::int64_t v) { return s.first < v; });
  const auto lo = hi - 1;
  const double a = static_cast<double>(t - lo->first) / static_cast<double>(hi->first - lo->first);
  const Eigen::Quaterniond q0(lo->second.topLeftCorner<3, 3>()), q1(hi->second.topLeftCorner<3, 3>());
  Mat4d T = Mat4d::Identity();
  T.topLeftCorner<3, 3>() = q0.slerp(a, q1).toRotationMatrix();
  T.topRightCorner<3, 1>() = (1 - a) * lo->second.topRightCorner<3, 1>() + a * hi->second.topRightCorner<3, 1>();
  return T;
}

void TfTree::addStatic(const std::string& parent, const std::string& child, const Mat4d& T) {
  Edge& e = up_[child];
  e.parent = parent;
  e.fixed = true;
  e.T = T;
}

void TfTree::addDynamic(const std::string& parent, const std::string& child, std::int64_t stamp_ns, const Mat4d& T) {
  Edge& e = up_[child];
  if (e.fixed) return;  // a static edge wins
  e.parent = parent;
  e.track.add(stamp_ns, T);
}

void TfTree::sort() {
  for (auto& [child, e] : up_) e.track.sort();
}

bool TfTree::has(const std::string& frame) const {
  if (up_.count(frame)) return true;
  return std::any_of(up_.begin(), up_.end(), [&](const auto& kv) { return kv.second.parent == frame; });
}

std::optional<Mat4d> TfTree::lookup(const std::string& ancestor, const std::string& frame, std::int64_t t,
                                    std::int64_t slack_ns) const {
  Mat4d T = Mat4d::Identity();
  std::string at = frame, chain = frame;
  for (std::size_t hops = 0; at != ancestor; ++hops) {
    const auto e = up_.find(at);
    if (e == up_.end() || hops > up_.size())
      throw InputError("frame " + ancestor + " is not above " + frame + " in the bag's tf tree (its chain: " + chain +
                       ")");
    Mat4d step;
    if (e->second.fixed) {
      step = e->second.T;
    } else {
      const auto p = e->second.track.at(t, slack_ns);
      if (!p) return std::nullopt;
      step = *p;
    }
    T = step * T;
    at = e->second.parent;
    chain += " -> " + at;
  }
  return T;
}

}  // namespace sglc
