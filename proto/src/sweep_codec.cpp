#include "sglc/wire/sweep_codec.hpp"

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>

namespace sglc::wire {
namespace {

static_assert(sizeof(float) == 4, "IEEE-754 single precision expected");

std::uint32_t toLittle(std::uint32_t v) {
  if constexpr (std::endian::native == std::endian::little) return v;
  return ((v & 0x000000FFu) << 24) | ((v & 0x0000FF00u) << 8) | ((v & 0x00FF0000u) >> 8) | ((v & 0xFF000000u) >> 24);
}

Eigen::Vector3d vector3(const google::protobuf::RepeatedField<double>& v, const char* name) {
  if (v.size() != 3)
    throw WireError(std::string("scan.twist.") + name + " has " + std::to_string(v.size()) + " values, expected 3");
  const Eigen::Vector3d out(v[0], v[1], v[2]);
  if (!out.allFinite()) throw WireError(std::string("scan.twist.") + name + " is not finite");
  return out;
}

}  // namespace

std::string packPointTimes(const std::vector<float>& times) {
  std::string out(times.size() * kTimeBytes, '\0');
  for (std::size_t i = 0; i < times.size(); ++i) {
    const std::uint32_t w = toLittle(std::bit_cast<std::uint32_t>(times[i]));
    std::memcpy(out.data() + i * kTimeBytes, &w, kTimeBytes);
  }
  return out;
}

std::vector<float> unpackPointTimes(std::string_view bytes) {
  if (bytes.size() % kTimeBytes != 0)
    throw WireError("scan.point_times has " + std::to_string(bytes.size()) +
                    " bytes, not a multiple of 4 (float32 per point)");
  std::vector<float> times(bytes.size() / kTimeBytes);
  for (std::size_t i = 0; i < times.size(); ++i) {
    std::uint32_t w;
    std::memcpy(&w, bytes.data() + i * kTimeBytes, kTimeBytes);
    times[i] = std::bit_cast<float>(toLittle(w));
  }
  return times;
}

void packTwist(const Twist& twist, v1::Twist* out) {
  out->clear_linear();
  out->clear_angular();
  for (int i = 0; i < 3; ++i) {
    out->add_linear(twist.linear[i]);
    out->add_angular(twist.angular[i]);
  }
}

void packSweep(const ScanSweep& sweep, v1::Scan* out) {
  const std::size_t points = out->points().size() / 12;
  if (!sweep.point_times.empty() && sweep.point_times.size() != points)
    throw WireError("scan has " + std::to_string(points) + " points but " + std::to_string(sweep.point_times.size()) +
                    " point times");
  *out->mutable_point_times() = packPointTimes(sweep.point_times);
  if (sweep.twist)
    packTwist(*sweep.twist, out->mutable_twist());
  else
    out->clear_twist();
}

ScanSweep decodeSweep(std::string_view point_times, const v1::Twist& twist, std::size_t point_count) {
  ScanSweep sweep;
  sweep.point_times = unpackPointTimes(point_times);
  if (!sweep.point_times.empty() && sweep.point_times.size() != point_count)
    throw WireError("scan has " + std::to_string(point_count) + " points but " +
                    std::to_string(sweep.point_times.size()) + " point times");
  for (std::size_t i = 0; i < sweep.point_times.size(); ++i)
    if (const float t = sweep.point_times[i]; !std::isfinite(t) || std::abs(t) > 1.0f)
      throw WireError("scan.point_times[" + std::to_string(i) + "] is " + std::to_string(t) +
                      " s, not within 1 s of the stamp");
  if (twist.linear_size() + twist.angular_size() > 0) {
    if (sweep.point_times.empty()) throw WireError("scan.twist is set but scan.point_times is empty");
    sweep.twist = Twist{vector3(twist.linear(), "linear"), vector3(twist.angular(), "angular")};
    if (const auto error = twistError(*sweep.twist); !error.empty()) throw WireError("scan.twist: " + error);
  }
  return sweep;
}

}  // namespace sglc::wire
