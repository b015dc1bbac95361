// sensor_msgs/PointCloud2 of any field layout (sglc/ros_messages.hpp).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>

#include "ros_reader.hpp"
#include "sglc/ros_messages.hpp"

namespace sglc {
namespace {

struct Field {
  std::string name;
  std::uint32_t offset = 0;
  std::uint8_t type = 0;
  std::uint32_t count = 0;
};

std::size_t sizeOf(std::uint8_t type) {
  static constexpr std::size_t kSizes[] = {0, 1, 1, 2, 2, 4, 4, 4, 8};
  return type >= 1 && type <= 8 ? kSizes[type] : 0;
}

// One scalar of a field at `p`, as double.
double value(const std::uint8_t* p, std::uint8_t type, bool big) {
  std::uint8_t b[8];
  const std::size_t n = sizeOf(type);
  std::memcpy(b, p, n);
  if (big) std::reverse(b, b + n);
  switch (type) {
    case 1:
      return static_cast<std::int8_t>(b[0]);
    case 2:
      return b[0];
    case 3: {
      std::int16_t v;
      std::memcpy(&v, b, 2);
      return v;
    }
    case 4: {
      std::uint16_t v;
      std::memcpy(&v, b, 2);
      return v;
    }
    case 5: {
      std::int32_t v;
      std::memcpy(&v, b, 4);
      return v;
    }
    case 6: {
      std::uint32_t v;
      std::memcpy(&v, b, 4);
      return v;
    }
    case 7: {
      float v;
      std::memcpy(&v, b, 4);
      return v;
    }
    default: {
      double v;
      std::memcpy(&v, b, 8);
      return v;
    }
  }
}

const char* const kTypeNames[] = {"?", "int8", "uint8", "int16", "uint16", "int32", "uint32", "float32", "float64"};

// Seconds after the stamp from a time field's value, by the field's convention.
double secondsAfter(const std::string& field, double v, std::int64_t stamp_ns) {
  if (field == "t" || field == "offset_time") return v * 1e-9;
  if (field == "time") return v;
  // "timestamp": absolute ns, absolute s, or relative s, by size.
  if (v > 1e14) return (v - static_cast<double>(stamp_ns)) * 1e-9;
  if (v > 1e6) return v - static_cast<double>(stamp_ns) * 1e-9;
  return v;
}

}  // namespace

RosCloud decodePointCloud2(const std::vector<std::uint8_t>& bytes, MessageEncoding encoding, std::size_t max_points,
                           const std::string& what) {
  RosReader r(bytes.data(), bytes.size(), encoding, what);
  RosCloud c;
  c.stamp_ns = r.header(&c.frame_id);
  c.height = r.get<std::uint32_t>("height");
  c.width = r.get<std::uint32_t>("width");
  std::vector<Field> fields(r.count("fields", 9));
  for (auto& f : fields) {
    f.name = r.string("field name");
    f.offset = r.get<std::uint32_t>("field offset");
    f.type = r.get<std::uint8_t>("field datatype");
    f.count = r.get<std::uint32_t>("field count");
  }
  const bool big = r.get<std::uint8_t>("is_bigendian") != 0;
  const auto point_step = r.get<std::uint32_t>("point_step");
  const auto row_step = r.get<std::uint32_t>("row_step");
  std::size_t data_size = 0;
  const std::uint8_t* data = r.bytes("data", &data_size);

  const std::uint64_t n = std::uint64_t(c.width) * c.height;
  if (n > max_points)
    throw InputError(what + ": " + std::to_string(c.width) + " x " + std::to_string(c.height) + " = " +
                     std::to_string(n) + " points, more than the limit of " + std::to_string(max_points));
  if (n > 0 &&
      (std::uint64_t(row_step) < std::uint64_t(c.width) * point_step || std::uint64_t(row_step) * c.height > data_size))
    throw InputError(what + ": the layout lies about its sizes: " + std::to_string(c.height) + " rows of " +
                     std::to_string(c.width) + " points, point_step " + std::to_string(point_step) + ", row_step " +
                     std::to_string(row_step) + ", but " + std::to_string(data_size) + " bytes of data");
  auto find = [&](const std::string& name) -> const Field* {
    for (const auto& f : fields)
      if (f.name == name) {
        if (sizeOf(f.type) == 0 || f.count == 0)
          throw InputError(what + ": field " + name + " has datatype " + std::to_string(f.type) + " and count " +
                           std::to_string(f.count));
        if (std::uint64_t(f.offset) + sizeOf(f.type) > point_step)
          throw InputError(what + ": field " + name + " at offset " + std::to_string(f.offset) + " (" +
                           kTypeNames[f.type] + ") lies outside the point_step of " + std::to_string(point_step));
        return &f;
      }
    return nullptr;
  };
  const Field* xyz[3] = {find("x"), find("y"), find("z")};
  std::string names;
  for (const auto& f : fields) names += (names.empty() ? "" : " ") + f.name;
  for (const Field* f : xyz)
    if (!f) throw InputError(what + ": no x, y, z fields (fields: " + (names.empty() ? "none" : names) + ")");
  const Field* intensity = find("intensity");
  const Field* time = nullptr;
  for (const char* name : {"t", "time", "offset_time", "timestamp"})
    if ((time = find(name))) break;
  if (time) c.time_field = time->name;

  const bool plain_float = !big && xyz[0]->type == 7 && xyz[1]->type == 7 && xyz[2]->type == 7;
  c.points.reserve(n);
  if (intensity) c.intensities.reserve(n);
  if (time) c.times.reserve(n);
  for (std::uint32_t row = 0; row < c.height; ++row) {
    const std::uint8_t* line = data + std::size_t(row) * row_step;
    for (std::uint32_t col = 0; col < c.width; ++col) {
      const std::uint8_t* p = line + std::size_t(col) * point_step;
      // Finite as float32: a float64 beyond float range (1e300) would become infinite, so it is dropped too.
      Vec3f point;
      if (plain_float) {  // the common layout, read without conversions
        std::memcpy(&point.x(), p + xyz[0]->offset, 4);
        std::memcpy(&point.y(), p + xyz[1]->offset, 4);
        std::memcpy(&point.z(), p + xyz[2]->offset, 4);
      } else {
        point = Vec3f(static_cast<float>(value(p + xyz[0]->offset, xyz[0]->type, big)),
                      static_cast<float>(value(p + xyz[1]->offset, xyz[1]->type, big)),
                      static_cast<float>(value(p + xyz[2]->offset, xyz[2]->type, big)));
      }
      if (!point.allFinite()) {
        ++c.dropped;
        continue;
      }
      c.points.push_back(point);
      if (intensity) c.intensities.push_back(static_cast<float>(value(p + intensity->offset, intensity->type, big)));
      if (time) {
        const double s = secondsAfter(time->name, value(p + time->offset, time->type, big), c.stamp_ns);
        if (!std::isfinite(s) || std::abs(s) > 10.0)
          throw InputError(what + ": point " + std::to_string(std::size_t(row) * c.width + col) + "'s " + time->name +
                           " puts it " + std::to_string(s) + " s from the stamp (a sweep lasts well under 10 s)");
        c.times.push_back(static_cast<float>(s));
      }
    }
  }
  return c;
}

}  // namespace sglc
