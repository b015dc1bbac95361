#include "sglc/loop_model.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace sglc {

extern const char* const kBuiltInLoopModel;  // generated from core/models/loop_model.txt

const std::vector<ModelFeature>& modelFeatures() {
  static const std::vector<ModelFeature> features{
      {"landmarks", +1, "1 - exp(-landmarks / 3): landmark pairs at the pose, saturating"},
      {"landmark_similarity", +1, "exp(-mean ground distance of the landmark pairs)"},
      {"agreement", +1, "near background agreement over the field"},
      {"wide_agreement", +1, "wide background agreement over the field"},
      {"pin", +1, "agreement drop 2-4 m along the weakest direction, clamped to [-0.2, 0.2]"},
      {"plane_overlap", +1, "band-plane overlap"},
      {"plane_tightness", +1, "1 / (1 + (rmse / 5 cm)^2) where planes were fitted, else 0"},
      {"constraint", +1, "log(1 + horizontal constraint of the planes)"},
      {"landmarks_x_agreement", +1, "landmarks x agreement"},
      {"translation", -1, "|t| / 10 m"},
      {"narrow", 0, "1 for a narrow view"},
      {"narrow_x_context", +1, "narrow x view-context similarity"},
      {"narrow_x_wide_agreement", 0, "narrow x wide agreement"},
      {"overlay", 0, "1 for a pose from a bird's-eye overlay (walls or view headings)"},
      {"consensus", 0, "1 for a pose from landmarks paired by geometry"},
  };
  return features;
}

std::vector<double> featureValues(const Evidence& e) {
  const double landmarks = 1.0 - std::exp(-e.landmarks / 3.0);
  const double narrow = e.narrow ? 1.0 : 0.0;
  const double u = e.plane_rmse_m / 0.05;
  return {landmarks,
          e.landmark_similarity,
          e.agreement,
          e.wide_agreement,
          std::clamp(e.pin, -0.2, 0.2),
          e.plane_overlap,
          e.plane_overlap > 0 ? 1.0 / (1.0 + u * u) : 0.0,
          std::log1p(std::max(0.0, e.constraint)),
          landmarks * e.agreement,
          e.translation_m / 10.0,
          narrow,
          narrow * e.context_similarity,
          narrow * e.wide_agreement,
          e.source == PoseSource::kWallHeadings || e.source == PoseSource::kViewHeadings ? 1.0 : 0.0,
          e.source == PoseSource::kConsensus ? 1.0 : 0.0};
}

LoopModel LoopModel::builtIn() {
  static const LoopModel model = parse(kBuiltInLoopModel, "the built-in loop model");
  return model;
}

LoopModel LoopModel::parse(const std::string& text, const std::string& origin) {
  const auto& features = modelFeatures();
  LoopModel m;
  m.weights_.assign(features.size(), std::nan(""));
  bool bias = false, header = false;
  std::istringstream in(text);
  std::string line;
  int number = 0;
  auto fail = [&](const std::string& what) {
    throw InputError(origin + ", line " + std::to_string(number) + ": " + what);
  };
  while (std::getline(in, line)) {
    ++number;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream words(line);
    std::string key, value, extra;
    words >> key >> value;
    if (value.empty() || (words >> extra)) fail("expected 'NAME VALUE', got '" + line + "'");
    if (!header) {
      if (key != "sglc-loop-model" || value != "1") fail("not an sglc loop model, version 1 ('sglc-loop-model 1')");
      header = true;
      continue;
    }
    if (key == "version") {
      m.version_ = value;
      continue;
    }
    std::size_t used = 0;
    double w = 0;
    try {
      w = std::stod(value, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != value.size() || !std::isfinite(w)) fail("weight of " + key + " is not a finite number: " + value);
    if (key == "bias") {
      if (bias) fail("bias given twice");
      m.bias_ = w;
      bias = true;
      continue;
    }
    std::size_t k = 0;
    while (k < features.size() && key != features[k].name) ++k;
    if (k == features.size()) fail("unknown feature '" + key + "'");
    if (!std::isnan(m.weights_[k])) fail("feature " + key + " given twice");
    if (w * features[k].sign < 0)
      fail("weight of " + key + " must be " + (features[k].sign > 0 ? ">= 0" : "<= 0") +
           " (more of it cannot make a loop " + (features[k].sign > 0 ? "less" : "more") + " likely)");
    m.weights_[k] = w;
  }
  if (!header) fail("empty: expected 'sglc-loop-model 1'");
  if (m.version_.empty()) fail("no 'version' line");
  if (!bias) fail("no 'bias' line");
  for (std::size_t k = 0; k < features.size(); ++k)
    if (std::isnan(m.weights_[k])) fail(std::string("feature ") + features[k].name + " has no weight");
  return m;
}

LoopModel LoopModel::load(const std::string& path) {
  if (path.empty()) return builtIn();
  // A regular file, read no further than the limit: a device, a pipe or a huge file is refused, never read whole.
  constexpr std::size_t kMaxBytes = 65536;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw InputError("loop model " + path + " is not a regular file" + (ec ? " (" + ec.message() + ")" : ""));
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError("cannot read the loop model " + path);
  std::string text(kMaxBytes + 1, '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<std::size_t>(in.gcount()));
  if (text.size() > kMaxBytes) throw InputError("loop model " + path + " is larger than 64 KiB");
  return parse(text, path);
}

double LoopModel::probability(const Evidence& e) const {
  if (e.source == PoseSource::kNone) return 0.0;
  const auto x = featureValues(e);
  double z = bias_;
  for (std::size_t k = 0; k < x.size(); ++k) z += weights_[k] * x[k];
  return 1.0 / (1.0 + std::exp(-z));
}

}  // namespace sglc
