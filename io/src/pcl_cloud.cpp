#include "sglc/pcl_cloud.hpp"

#include <pcl/PCLPointCloud2.h>
#include <pcl/console/print.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <optional>

#include "cloud_header.hpp"

namespace sglc {
namespace {

[[noreturn]] void fail(const std::string& path, const std::string& what) { throw InputError(path + ": " + what); }

const pcl::PCLPointField* findField(const pcl::PCLPointCloud2& cloud, const std::string& name) {
  for (const auto& f : cloud.fields)
    if (f.name == name) return &f;
  return nullptr;
}

std::size_t fieldBytes(std::uint8_t type) {
  using F = pcl::PCLPointField;
  switch (type) {
    case F::INT8:
    case F::UINT8:
      return 1;
    case F::INT16:
    case F::UINT16:
      return 2;
    case F::INT32:
    case F::UINT32:
    case F::FLOAT32:
      return 4;
    case F::FLOAT64:
      return 8;
    default:
      return 0;
  }
}

// The value of field `f` of point `i`, whatever its type (PCL stores host byte order).
double fieldValue(const pcl::PCLPointCloud2& cloud, const pcl::PCLPointField& f, std::size_t i) {
  const std::uint8_t* p = cloud.data.data() + i * cloud.point_step + f.offset;
  using F = pcl::PCLPointField;
  switch (f.datatype) {
    case F::INT8: {
      std::int8_t v;
      std::memcpy(&v, p, 1);
      return v;
    }
    case F::UINT8:
      return *p;
    case F::INT16: {
      std::int16_t v;
      std::memcpy(&v, p, 2);
      return v;
    }
    case F::UINT16: {
      std::uint16_t v;
      std::memcpy(&v, p, 2);
      return v;
    }
    case F::INT32: {
      std::int32_t v;
      std::memcpy(&v, p, 4);
      return v;
    }
    case F::UINT32: {
      std::uint32_t v;
      std::memcpy(&v, p, 4);
      return v;
    }
    case F::FLOAT32: {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
    default: {
      double v;
      std::memcpy(&v, p, 8);
      return v;
    }
  }
}

const pcl::PCLPointField& requireField(const pcl::PCLPointCloud2& cloud, const std::string& name,
                                       const std::string& path) {
  const auto* f = findField(cloud, name);
  if (!f) {
    std::string names;
    for (const auto& g : cloud.fields) names += (names.empty() ? "" : " ") + g.name;
    fail(path, "no '" + name + "' field (fields: " + (names.empty() ? "none" : names) + ")");
  }
  const std::size_t bytes = fieldBytes(f->datatype);
  if (bytes == 0) fail(path, "field '" + name + "' has an unknown data type");
  if (std::size_t(f->offset) + bytes > cloud.point_step) fail(path, "field '" + name + "' lies outside the point");
  return *f;
}

pcl::PCLPointCloud2 readCloud2(const std::string& path) {
  // The checks read the file (InputError when it is missing, a directory or unreadable) before PCL does.
  const std::string ext = std::filesystem::path(path).extension().string();
  ext == ".pcd" ? detail::checkPcdHeader(path) : detail::checkPlyHeader(path);
  // PCL reports its parse errors on stderr; the InputError below says what failed.
  pcl::console::setVerbosityLevel(pcl::console::L_ALWAYS);
  pcl::PCLPointCloud2 cloud;
  int rc = -1;
  try {
    if (ext == ".pcd") {
      pcl::PCDReader reader;
      rc = reader.read(path, cloud);
    } else {
      pcl::PLYReader reader;
      rc = reader.read(path, cloud);
    }
  } catch (const std::exception& e) {
    fail(path, std::string("not a readable ") + (ext == ".pcd" ? "PCD" : "PLY") + " file (" + e.what() + ")");
  }
  if (rc < 0) fail(path, std::string("not a readable ") + (ext == ".pcd" ? "PCD" : "PLY") + " file");
  const std::size_t n = std::size_t(cloud.width) * cloud.height;
  if (cloud.point_step == 0 && n > 0) fail(path, "points of zero size");
  if (n > 0 && cloud.data.size() / cloud.point_step < n)
    fail(path, "holds " + std::to_string(cloud.data.size()) + " bytes for " + std::to_string(n) + " points");
  return cloud;
}

}  // namespace

LabelledScan readPclCloud(const std::string& path, const std::string& label_field) {
  const pcl::PCLPointCloud2 cloud = readCloud2(path);
  const std::size_t n = std::size_t(cloud.width) * cloud.height;
  LabelledScan scan;
  scan.points.resize(n);
  if (n == 0) return scan;
  const auto& fx = requireField(cloud, "x", path);
  const auto& fy = requireField(cloud, "y", path);
  const auto& fz = requireField(cloud, "z", path);
  for (std::size_t i = 0; i < n; ++i) {
    const double x = fieldValue(cloud, fx, i), y = fieldValue(cloud, fy, i), z = fieldValue(cloud, fz, i);
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
      fail(path, "point " + std::to_string(i) + " has a non-finite coordinate (remove NaN points first)");
    scan.points[i] = Vec3f(float(x), float(y), float(z));
  }
  if (label_field.empty() || !findField(cloud, label_field)) return scan;
  const auto& fl = requireField(cloud, label_field, path);
  scan.labels.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double v = fieldValue(cloud, fl, i);
    if (!(v >= 0 && v <= 4294967295.0) || v != std::floor(v))
      fail(path, "label " + std::to_string(i) + " in field '" + label_field + "' is not an integer in 0..2^32-1");
    scan.labels[i] = static_cast<std::uint32_t>(v);
  }
  return scan;
}

void writePcd(const std::string& path, const LabelledScan& scan, bool binary) {
  if (!scan.labels.empty() && scan.labels.size() != scan.points.size())
    fail(path, std::to_string(scan.labels.size()) + " labels for " + std::to_string(scan.points.size()) + " points");
  pcl::PCLPointCloud2 cloud;
  const bool labelled = !scan.labels.empty();
  const char* names[] = {"x", "y", "z", "label"};
  for (int k = 0; k < (labelled ? 4 : 3); ++k) {
    pcl::PCLPointField f;
    f.name = names[k];
    f.offset = static_cast<std::uint32_t>(4 * k);
    f.datatype = k < 3 ? pcl::PCLPointField::FLOAT32 : pcl::PCLPointField::UINT32;
    f.count = 1;
    cloud.fields.push_back(f);
  }
  cloud.point_step = labelled ? 16 : 12;
  cloud.width = static_cast<std::uint32_t>(scan.points.size());
  cloud.height = 1;
  cloud.row_step = cloud.point_step * cloud.width;
  cloud.is_dense = true;
  cloud.data.resize(std::size_t(cloud.row_step));
  for (std::size_t i = 0; i < scan.points.size(); ++i) {
    std::uint8_t* p = cloud.data.data() + i * cloud.point_step;
    std::memcpy(p, scan.points[i].data(), 12);
    if (labelled) std::memcpy(p + 12, &scan.labels[i], 4);
  }
  pcl::PCDWriter writer;
  if (writer.write(path, cloud, Eigen::Vector4f::Zero(), Eigen::Quaternionf::Identity(), binary) < 0)
    fail(path, "cannot write the PCD file");
}

}  // namespace sglc
