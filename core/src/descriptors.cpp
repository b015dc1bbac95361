#include "sglc/descriptors.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

namespace sglc {
namespace {

template <typename V>
void l2normalise(V&& v) {
  const auto n = v.norm();
  if (n > 0) v /= n;
}

// Soft binning (ours): a distance's count is shared between the two nearest bin centres, so a neighbour whose
// distance moves by a few decimetres (a car labelled in part, a new viewpoint) shifts weight smoothly instead
// of jumping to the next bin. A NaN distance falls into the first bin rather than into undefined behaviour.
struct SoftBin {
  int lo, hi;
  float w;  // weight of hi; lo gets 1 - w
};

SoftBin softBin(float d, float inv_bin, int bins) {
  const float x = std::max(0.0f, d * inv_bin - 0.5f);
  const int lo = std::min(static_cast<int>(x), bins - 1), hi = std::min(lo + 1, bins - 1);
  return {lo, hi, std::min(1.0f, x - static_cast<float>(lo))};
}

}  // namespace

DescriptorLayout descriptorLayout(int num_classes, const GraphConfig& graph, const DescriptorConfig& config) {
  DescriptorLayout layout;
  layout.num_classes = num_classes;
  layout.bins = static_cast<int>(std::ceil(graph.d_max / config.d_i - 1e-9));
  layout.k_eigen = config.k_eigen;
  layout.rings = config.rings;
  layout.orders = config.orders;
  return layout;
}

int edgeType(int a, int b, int num_classes) {
  if (a > b) std::swap(a, b);
  // Row-major index into the upper triangle (a <= b).
  return a * num_classes - a * (a - 1) / 2 + (b - a);
}

Eigen::MatrixXf nodeDescriptors(const std::vector<Node>& nodes, const DescriptorLayout& layout, double d_max,
                                double d_i) {
  const int n = static_cast<int>(nodes.size());
  const int local = layout.num_classes * layout.bins;
  Eigen::MatrixXf f = Eigen::MatrixXf::Zero(n, layout.nodeDim());
  if (n == 0) return f;
  const float inv_bin = static_cast<float>(1.0 / d_i);
  const float dmax = static_cast<float>(d_max);
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j) {
      const float d = (nodes[i].center - nodes[j].center).norm();
      if (d >= dmax) continue;
      const auto [lo, hi, w] = softBin(d, inv_bin, layout.bins);
      f(i, nodes[j].cls * layout.bins + lo) += 1.0f - w;  // neighbour's class (the reference used its own)
      f(i, nodes[j].cls * layout.bins + hi) += w;
      f(j, nodes[i].cls * layout.bins + lo) += 1.0f - w;
      f(j, nodes[i].cls * layout.bins + hi) += w;
    }
  // Square roots of the counts (ours; the reference normalises raw counts): a crowd of neighbours in one bin
  // (a row of parked cars, a mislabelled hedge broken into pieces) no longer swamps the rest of the histogram,
  // which keeps true node pairs above the cosine floor under label noise.
  f.leftCols(local) = f.leftCols(local).cwiseSqrt();
  for (int i = 0; i < n; ++i) l2normalise(f.row(i).head(local));

  // Spectral part: eigenvectors of the k largest eigenvalues of A, row i, absolute values, L1-normalised.
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(adjacency(nodes, d_max));
  const Eigen::MatrixXd& Q = eig.eigenvectors();  // eigenvalues ascending
  const int k = std::min(layout.k_eigen, n);
  for (int i = 0; i < n; ++i) {
    double sum = 0;
    for (int c = 0; c < k; ++c) sum += std::abs(Q(i, n - 1 - c));
    if (sum <= 0) continue;
    for (int c = 0; c < k; ++c) f(i, local + c) = static_cast<float>(std::abs(Q(i, n - 1 - c)) / sum);
  }
  return f;
}

std::vector<float> scanDescriptor(const std::vector<Node>& nodes, const std::vector<float>& spectrum,
                                  const DescriptorLayout& layout, double d_max, double d_i, double background_weight) {
  const int C = layout.num_classes;
  Eigen::VectorXf counts = Eigen::VectorXf::Zero(C);
  Eigen::VectorXf edges = Eigen::VectorXf::Zero(layout.edgeTypes() * layout.bins);
  const float inv_bin = static_cast<float>(1.0 / d_i);
  const float dmax = static_cast<float>(d_max);
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    counts[nodes[i].cls] += 1.0f;
    for (std::size_t j = i + 1; j < nodes.size(); ++j) {
      const float d = (nodes[i].center - nodes[j].center).norm();
      if (d >= dmax) continue;
      // Soft bins as in nodeDescriptors (fingerprint format 1 had hard bins here).
      const auto [lo, hi, w] = softBin(d, inv_bin, layout.bins);
      const int base = edgeType(nodes[i].cls, nodes[j].cls, C) * layout.bins;
      edges[base + lo] += 1.0f - w;
      edges[base + hi] += w;
    }
  }
  l2normalise(counts);
  l2normalise(edges);
  Eigen::VectorXf fg(C + edges.size());
  fg << counts, edges;
  l2normalise(fg);
  Eigen::VectorXf bg = Eigen::Map<const Eigen::VectorXf>(spectrum.data(), static_cast<Eigen::Index>(spectrum.size()));
  l2normalise(bg);  // zero stays zero: no NaN for scans without structure
  Eigen::VectorXf all(fg.size() + bg.size());
  all << fg, static_cast<float>(background_weight) * bg;
  l2normalise(all);
  return std::vector<float>(all.data(), all.data() + all.size());
}

}  // namespace sglc
