// sglc._engine: the SGLC engine in-process, for Python (sglc.Engine wraps it; see sglc/engine.py).
//
// The module takes checked, contiguous arrays (float32 (N, 3) points, uint32 (N,) labels) from the Python
// wrapper, runs sglc::Pipeline exactly as sglc-pair and the server do, and returns plain Python values. The GIL
// is released while the engine works, so several Python threads can fingerprint at once (Pipeline is const).
// sglc::InputError becomes ValueError with the engine's message.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <array>
#include <cstdint>
#include <cstring>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "sglc/bag_drive.hpp"
#include "sglc/config/engine_file.hpp"
#include "sglc/deskew.hpp"
#include "sglc/fingerprint.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/scan_file.hpp"
#include "sglc/version.hpp"

namespace py = pybind11;

namespace {

using PointArray = py::array_t<float, py::array::c_style>;
using LabelArray = py::array_t<std::uint32_t, py::array::c_style>;

// A fingerprint with where its labels came from and the engine's warnings about it.
struct PyFingerprint {
  sglc::Fingerprint fingerprint;
  sglc::ScanReport report;
};

const char* labelSourceName(sglc::ScanReport::LabelSource source) {
  switch (source) {
    case sglc::ScanReport::LabelSource::kComputed:
      return "computed";
    case sglc::ScanReport::LabelSource::kCompleted:
      return "completed";
    case sglc::ScanReport::LabelSource::kProvided:
      break;
  }
  return "provided";
}

sglc::LabelledScan toScan(const PointArray& points, const std::optional<LabelArray>& labels) {
  if (points.ndim() != 2 || points.shape(1) != 3)
    throw sglc::InputError("points must have shape (N, 3) (the wrapper passes the first three columns)");
  const auto n = static_cast<std::size_t>(points.shape(0));
  sglc::LabelledScan scan;
  scan.points.resize(n);
  const float* p = points.data();
  for (std::size_t i = 0; i < n; ++i) scan.points[i] = sglc::Vec3f(p[3 * i], p[3 * i + 1], p[3 * i + 2]);
  if (labels) {
    if (labels->ndim() != 1) throw sglc::InputError("labels must have shape (N,)");
    scan.labels.resize(static_cast<std::size_t>(labels->shape(0)));
    if (!scan.labels.empty())
      std::memcpy(scan.labels.data(), labels->data(), scan.labels.size() * sizeof(std::uint32_t));
  }
  sglc::validateScan(scan);  // one label per point (or none) and finite coordinates, as the server checks
  return scan;
}

template <int R, int C>
py::array_t<double> toArray(const Eigen::Matrix<double, R, C>& m) {
  py::array_t<double> out({R, C});
  auto v = out.mutable_unchecked<2>();
  for (int r = 0; r < R; ++r)
    for (int c = 0; c < C; ++c) v(r, c) = m(r, c);
  return out;
}

py::dict resultDict(const sglc::LoopResult& r) {
  py::dict d;
  d["is_loop"] = r.is_loop;
  d["score"] = r.score;
  d["T"] = toArray(r.T);
  d["information"] = toArray(r.information);
  d["refined"] = r.refined;
  d["inliers"] = r.inliers;
  d["matches"] = r.matches;
  d["graph_similarity"] = r.graph_similarity;
  d["background_similarity"] = r.background_similarity;
  d["fitness"] = r.fitness;
  d["rmse"] = r.rmse;
  d["reason"] = std::string(r.reason);
  d["probability"] = r.probability;
  const auto& e = r.evidence;
  py::dict ev;
  ev["source"] = std::string(sglc::poseSourceName(e.source));
  ev["landmarks"] = e.landmarks;
  ev["landmark_similarity"] = e.landmark_similarity;
  ev["field_deg"] = e.field_deg;
  ev["agreement"] = e.agreement;
  ev["wide_agreement"] = e.wide_agreement;
  ev["pin"] = e.pin;
  ev["plane_overlap"] = e.plane_overlap;
  ev["plane_rmse_m"] = e.plane_rmse_m;
  ev["constraint"] = e.constraint;
  ev["context_similarity"] = e.context_similarity;
  ev["translation_m"] = e.translation_m;
  d["evidence"] = ev;
  return d;
}

class PyEngine {
 public:
  explicit PyEngine(const std::string& config_yaml)
      : pipeline_(config_yaml.empty() ? sglc::Config{} : sglc::parseConfig(config_yaml)) {}

  std::shared_ptr<PyFingerprint> fingerprint(const PointArray& points, const std::optional<LabelArray>& labels) const {
    auto scan = toScan(points, labels);
    auto out = std::make_shared<PyFingerprint>();
    py::gil_scoped_release release;
    out->fingerprint = pipeline_.fingerprint(scan, &out->report);
    return out;
  }

  py::dict match(const PyFingerprint& a, const PyFingerprint& b, bool known_loop) const {
    sglc::LoopResult result;
    {
      py::gil_scoped_release release;
      result = pipeline_.verify(a.fingerprint, b.fingerprint);
      pipeline_.refine(a.fingerprint, b.fingerprint, result, known_loop);
    }
    return resultDict(result);
  }

  std::string config() const { return sglc::dumpConfig(pipeline_.config()); }

 private:
  sglc::Pipeline pipeline_;
};

py::array_t<float> pointArray(const sglc::Points& points) {
  py::array_t<float> out({static_cast<py::ssize_t>(points.size()), py::ssize_t{3}});
  float* o = out.mutable_data();
  for (std::size_t i = 0; i < points.size(); ++i) {
    o[3 * i] = points[i].x();
    o[3 * i + 1] = points[i].y();
    o[3 * i + 2] = points[i].z();
  }
  return out;
}

template <typename T>
py::object vectorArray(const std::vector<T>& v, bool none_when_empty) {
  if (v.empty() && none_when_empty) return py::none();
  py::array_t<T> out(static_cast<py::ssize_t>(v.size()));
  if (!v.empty()) std::memcpy(out.mutable_data(), v.data(), v.size() * sizeof(T));
  return out;
}

py::object poseArray(const std::optional<sglc::Mat4d>& T) {
  if (!T) return py::none();
  py::array_t<double> out({py::ssize_t{4}, py::ssize_t{4}});
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) out.mutable_at(r, c) = (*T)(r, c);
  return out;
}

// A bag's drive (sglc/bag_drive.hpp): its keyframes by index, each decoded when asked for.
class PyBag {
 public:
  PyBag(const std::string& path, const std::string& points_topic, const std::string& odom_topic,
        const std::string& tf_frame, double keyframe_m, double keyframe_deg, bool deskew)
      : drive_(path, options(points_topic, odom_topic, tf_frame, keyframe_m, keyframe_deg, deskew)) {}
  std::size_t size() const { return drive_.frames().size(); }
  std::size_t clouds() const { return drive_.clouds(); }
  std::vector<std::string> warnings() const { return drive_.warnings(); }
  py::dict get(std::size_t i) {
    if (i >= drive_.frames().size())
      throw py::index_error("keyframe " + std::to_string(i) + " of " + std::to_string(size()));
    const auto& f = drive_.frames()[i];
    sglc::RosCloud c;
    {
      py::gil_scoped_release release;
      c = drive_.cloud(i);
    }
    py::dict d;
    d["index"] = f.number;
    d["stamp"] = static_cast<double>(f.stamp_ns) * 1e-9;
    d["stamp_ns"] = f.stamp_ns;
    d["frame_id"] = c.frame_id;
    d["pose"] = poseArray(f.pose);
    d["points"] = pointArray(c.points);
    d["intensities"] = vectorArray(c.intensities, true);
    d["times"] = vectorArray(c.times, true);
    d["deskewed"] = c.deskewed;
    d["dropped"] = c.dropped;
    return d;
  }

 private:
  static sglc::BagDriveOptions options(const std::string& points_topic, const std::string& odom_topic,
                                       const std::string& tf_frame, double keyframe_m, double keyframe_deg,
                                       bool deskew) {
    sglc::BagDriveOptions o;
    o.points_topic = points_topic;
    o.odom_topic = odom_topic;
    o.tf_frame = tf_frame;
    o.keyframe_m = keyframe_m;
    o.keyframe_deg = keyframe_deg;
    o.deskew = deskew;
    return o;
  }
  sglc::BagDrive drive_;
};

}  // namespace

PYBIND11_MODULE(_engine, m) {
  m.doc() = "The SGLC engine in-process (use sglc.Engine).";
  m.attr("__version__") = sglc::kVersion;
  py::register_exception<sglc::InputError>(m, "InputError", PyExc_ValueError);

  py::class_<PyFingerprint, std::shared_ptr<PyFingerprint>>(m, "Fingerprint")
      // Pickled as the engine's own serialisation (checksummed, versioned: sglc/fingerprint.hpp) with where its
      // labels came from and its warnings; a damaged or foreign state is a ValueError.
      .def(py::pickle(
          [](const PyFingerprint& f) {
            const auto blob = sglc::serialize(f.fingerprint);
            return py::make_tuple(py::bytes(reinterpret_cast<const char*>(blob.data()), blob.size()),
                                  static_cast<int>(f.report.label_source), f.report.warnings);
          },
          [](const py::tuple& t) {
            if (t.size() != 3) throw sglc::InputError("Fingerprint state: expected 3 items");
            const auto blob = t[0].cast<std::string>();
            auto f = std::make_shared<PyFingerprint>();
            f->fingerprint = sglc::deserialize(
                std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(blob.data()), blob.size()));
            const int source = t[1].cast<int>();
            using Source = sglc::ScanReport::LabelSource;
            if (source != static_cast<int>(Source::kProvided) && source != static_cast<int>(Source::kComputed) &&
                source != static_cast<int>(Source::kCompleted))
              throw sglc::InputError("Fingerprint state: unknown label source " + std::to_string(source));
            f->report.label_source = static_cast<Source>(source);
            f->report.warnings = t[2].cast<std::vector<std::string>>();
            return f;
          }))
      .def_property_readonly("nodes", [](const PyFingerprint& f) { return f.fingerprint.nodes.size(); })
      .def_property_readonly("num_points", [](const PyFingerprint& f) { return f.fingerprint.num_points; })
      .def_property_readonly("label_source",
                             [](const PyFingerprint& f) { return std::string(labelSourceName(f.report.label_source)); })
      .def_property_readonly("warnings", [](const PyFingerprint& f) { return f.report.warnings; })
      .def_property_readonly("descriptor", [](const PyFingerprint& f) {
        const auto& d = f.fingerprint.descriptor;
        py::array_t<float> out(static_cast<py::ssize_t>(d.size()));
        if (!d.empty()) std::memcpy(out.mutable_data(), d.data(), d.size() * sizeof(float));
        return out;
      });

  m.def(
      "read_scan",
      [](const std::string& path, const std::string& labels, const std::string& label_field) {
        sglc::LabelledScan scan;
        {
          py::gil_scoped_release release;
          scan = sglc::readScan(path, labels, label_field);
        }
        return py::make_tuple(pointArray(scan.points), vectorArray(scan.labels, true));
      },
      py::arg("path"), py::arg("labels") = std::string(), py::arg("label_field") = std::string("label"));

  m.def(
      "deskew",
      [](const PointArray& points, const py::array_t<float, py::array::c_style>& times,
         const std::array<double, 3>& linear, const std::array<double, 3>& angular) {
        auto scan = toScan(points, std::nullopt);
        if (times.ndim() != 1) throw sglc::InputError("point_times must have shape (N,)");
        std::vector<float> t(times.data(), times.data() + times.shape(0));
        const sglc::Twist twist{Eigen::Vector3d(linear[0], linear[1], linear[2]),
                                Eigen::Vector3d(angular[0], angular[1], angular[2])};
        {
          py::gil_scoped_release release;
          sglc::deskew(scan.points, t, twist);
        }
        return pointArray(scan.points);
      },
      py::arg("points"), py::arg("point_times"), py::arg("linear"), py::arg("angular"));
  m.def(
      "twist_between",
      [](const py::array_t<double, py::array::c_style>& from, const py::array_t<double, py::array::c_style>& to,
         double dt) {
        const auto pose = [](const py::array_t<double, py::array::c_style>& a, const char* name) {
          if (a.ndim() != 2 || a.shape(0) != 4 || a.shape(1) != 4)
            throw sglc::InputError(std::string(name) + " must be a 4x4 pose");
          sglc::Mat4d M;
          for (int k = 0; k < 16; ++k) M(k / 4, k % 4) = a.data()[k];
          return M;
        };
        const auto t = sglc::twistBetween(pose(from, "pose_from"), pose(to, "pose_to"), dt);
        return py::make_tuple(std::array<double, 3>{t.linear.x(), t.linear.y(), t.linear.z()},
                              std::array<double, 3>{t.angular.x(), t.angular.y(), t.angular.z()});
      },
      py::arg("pose_from"), py::arg("pose_to"), py::arg("dt"));

  py::class_<PyBag>(m, "Bag")
      .def(py::init<const std::string&, const std::string&, const std::string&, const std::string&, double, double,
                    bool>(),
           py::arg("path"), py::arg("points_topic"), py::arg("odom_topic") = std::string(),
           py::arg("tf_frame") = std::string(), py::arg("keyframe_m") = 1.0, py::arg("keyframe_deg") = 10.0,
           py::arg("deskew") = true)
      .def("__len__", &PyBag::size)
      .def("__getitem__", &PyBag::get)
      .def_property_readonly("clouds", &PyBag::clouds)
      .def_property_readonly("warnings", &PyBag::warnings);

  py::class_<PyEngine>(m, "Engine")
      .def(py::init<const std::string&>(), py::arg("config_yaml") = std::string())
      .def("fingerprint", &PyEngine::fingerprint, py::arg("points"), py::arg("labels") = py::none())
      .def("match", &PyEngine::match, py::arg("a"), py::arg("b"), py::arg("known_loop") = false)
      .def("config", &PyEngine::config);
}
