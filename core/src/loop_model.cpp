#include "sglc/loop_model.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
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

double FeatureCurve::operator()(double x) const {
  if (knots.empty()) return slope * x;
  if (!(x > knots.front().first)) return knots.front().second;  // NaN too: never past the knots
  if (x >= knots.back().first) return knots.back().second;
  const auto hi = std::upper_bound(knots.begin(), knots.end(), x,
                                   [](double v, const std::pair<double, double>& k) { return v < k.first; });
  const auto lo = hi - 1;
  return lo->second + (hi->second - lo->second) * (x - lo->first) / (hi->first - lo->first);
}

namespace {

// A number filling the whole word, at most 1e6 in size (a larger weight, knot or term is no model of evidence in
// [0, 10], and sums of such numbers could overflow), else nullopt.
std::optional<double> number(const std::string& word) {
  std::size_t used = 0;
  double v = 0;
  try {
    v = std::stod(word, &used);
  } catch (const std::exception&) {
    return std::nullopt;
  }
  if (used != word.size() || !std::isfinite(v) || std::abs(v) > 1e6) return std::nullopt;
  return v;
}

}  // namespace

LoopModel LoopModel::parse(const std::string& text, const std::string& origin) {
  const auto& features = modelFeatures();
  LoopModel m;
  m.curves_.assign(features.size(), {});
  std::vector<bool> given(features.size(), false);
  bool bias = false, header = false;
  std::istringstream in(text);
  std::string line;
  int number_of_line = 0;
  auto fail = [&](const std::string& what) {
    throw InputError(origin + ", line " + std::to_string(number_of_line) + ": " + what);
  };
  while (std::getline(in, line)) {
    ++number_of_line;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream words(line);
    std::string key, word;
    std::vector<std::string> values;
    words >> key;
    while (words >> word) values.push_back(word);
    if (!header) {
      if (key != "sglc-loop-model" || values.size() != 1 || (values[0] != "1" && values[0] != "2"))
        fail("not an sglc loop model, version 1 or 2 ('sglc-loop-model 2')");
      header = true;
      continue;
    }
    if (values.empty()) fail("expected 'NAME VALUE' or 'NAME X1:T1 X2:T2 ...', got '" + line + "'");
    if (key == "version" || key == "bias") {
      if (values.size() != 1) fail("expected '" + key + " VALUE', got '" + line + "'");
      if (key == "version") {
        m.version_ = values[0];
        continue;
      }
      const auto b = number(values[0]);
      if (!b) fail("bias is not a number within +-1e6: " + values[0]);
      if (bias) fail("bias given twice");
      m.bias_ = *b;
      bias = true;
      continue;
    }
    std::size_t k = 0;
    while (k < features.size() && key != features[k].name) ++k;
    if (k == features.size()) fail("unknown feature '" + key + "'");
    if (given[k]) fail("feature " + key + " given twice");
    given[k] = true;
    const int sign = features[k].sign;
    const std::string direction =
        sign > 0 ? "more of it cannot make a loop less likely" : "more of it cannot make a loop more likely";
    auto& curve = m.curves_[k];
    if (values.size() == 1 && values[0].find(':') == std::string::npos) {
      const auto w = number(values[0]);
      if (!w) fail("weight of " + key + " is not a number within +-1e6: " + values[0]);
      if (*w * sign < 0) fail("weight of " + key + " must be " + (sign > 0 ? ">= 0" : "<= 0") + " (" + direction + ")");
      curve.slope = *w;
      continue;
    }
    if (values.size() < 2) fail("curve of " + key + " needs at least 2 knots X:T");
    for (const auto& v : values) {
      const auto colon = v.find(':');
      const auto x = colon == std::string::npos ? std::nullopt : number(v.substr(0, colon));
      const auto t = colon == std::string::npos ? std::nullopt : number(v.substr(colon + 1));
      if (!x || !t) fail("knot of " + key + " is not X:T with numbers within +-1e6: " + v);
      if (!curve.knots.empty() && *x <= curve.knots.back().first)
        fail("knots of " + key + " must have increasing X: " + v);
      if (!curve.knots.empty() && (*t - curve.knots.back().second) * sign < 0)
        fail("curve of " + key + " must be " + (sign > 0 ? "non-decreasing" : "non-increasing") + " (" + direction +
             "): " + v);
      curve.knots.emplace_back(*x, *t);
    }
  }
  if (!header) fail("empty: expected 'sglc-loop-model 2'");
  if (m.version_.empty()) fail("no 'version' line");
  if (!bias) fail("no 'bias' line");
  for (std::size_t k = 0; k < features.size(); ++k)
    if (!given[k]) fail(std::string("feature ") + features[k].name + " has no weight or curve");
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
  for (std::size_t k = 0; k < x.size(); ++k) z += curves_[k](x[k]);
  if (std::isnan(z)) return 0.0;  // evidence that is not a number speaks for nothing
  return 1.0 / (1.0 + std::exp(-z));
}

}  // namespace sglc
