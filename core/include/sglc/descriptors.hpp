// Node descriptors (local edge histogram + spectral embedding) and the scan descriptor for retrieval.
#pragma once

#include <vector>

#include "sglc/config.hpp"
#include "sglc/graph.hpp"

namespace sglc {

struct DescriptorLayout {
  int num_classes = 3;
  int bins = 30;  // d_max / d_i
  int k_eigen = 30;
  int rings = 8;   // of the background spectrum
  int orders = 2;  // of the background spectrum: orders 0..orders per ring and part
  int nodeDim() const { return num_classes * bins + k_eigen; }
  int edgeTypes() const { return num_classes * (num_classes + 1) / 2; }
  int spectrumDim() const { return 2 * rings * (orders + 1); }
  int scanDim() const { return num_classes + edgeTypes() * bins + spectrumDim(); }
};

DescriptorLayout descriptorLayout(int num_classes, const GraphConfig& graph, const DescriptorConfig& config);

// N x nodeDim(): [f_l (class of neighbour x distance bin, L2) | f_g (|eigenvector rows| of the k largest
// eigenvalues of A, L1)].
Eigen::MatrixXf nodeDescriptors(const std::vector<Node>& nodes, const DescriptorLayout& layout, double d_max,
                                double d_i);

// Index of the unordered class pair (a, b) among the layout's edge types.
int edgeType(int a, int b, int num_classes);

// scanDim() floats: L2([L2([L2(node counts) | L2(edge histogram)]) | background_weight * L2(spectrum)]), with
// `spectrum` from structureSpectrum (spectrumDim() values, may be all zero). The edge histogram is soft-binned
// by distance like the node descriptors.
std::vector<float> scanDescriptor(const std::vector<Node>& nodes, const std::vector<float>& spectrum,
                                  const DescriptorLayout& layout, double d_max, double d_i, double background_weight);

}  // namespace sglc
