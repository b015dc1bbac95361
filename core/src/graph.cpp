#include "sglc/graph.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace sglc {

Node makeNode(const Points& points, const Cluster& cluster) {
  double mx = 0, my = 0;
  float zmin = std::numeric_limits<float>::max(), zmax = std::numeric_limits<float>::lowest();
  for (auto i : cluster.points) {
    mx += points[i].x();
    my += points[i].y();
    zmin = std::min(zmin, points[i].z());
    zmax = std::max(zmax, points[i].z());
  }
  const double n = static_cast<double>(cluster.points.size());
  mx /= n;
  my /= n;
  double cxx = 0, cxy = 0, cyy = 0;
  for (auto i : cluster.points) {
    const double dx = points[i].x() - mx, dy = points[i].y() - my;
    cxx += dx * dx;
    cxy += dx * dy;
    cyy += dy * dy;
  }
  // Principal horizontal axis; extents along it and across it do not depend on the viewing yaw.
  const double theta = 0.5 * std::atan2(2.0 * cxy, cxx - cyy);
  const double c = std::cos(theta), s = std::sin(theta);
  double umin = 1e30, umax = -1e30, vmin = 1e30, vmax = -1e30;
  for (auto i : cluster.points) {
    const double dx = points[i].x() - mx, dy = points[i].y() - my;
    const double u = c * dx + s * dy, v = -s * dx + c * dy;
    umin = std::min(umin, u);
    umax = std::max(umax, u);
    vmin = std::min(vmin, v);
    vmax = std::max(vmax, v);
  }
  const double uc = 0.5 * (umin + umax), vc = 0.5 * (vmin + vmax);
  Node node;
  node.center =
      Vec3f(static_cast<float>(mx + c * uc - s * vc), static_cast<float>(my + s * uc + c * vc), 0.5f * (zmin + zmax));
  const float l = static_cast<float>(umax - umin), w = static_cast<float>(vmax - vmin);
  node.size = Vec3f(std::max(l, w), std::min(l, w), zmax - zmin);
  node.cls = static_cast<std::uint8_t>(cluster.cls);
  return node;
}

std::vector<Node> buildNodes(const Points& points, const std::vector<Cluster>& clusters, const GraphConfig& config,
                             std::vector<int>* kept_clusters) {
  // Fragments first go; then, if there are still too many, the clusters with most points stay.
  std::vector<int> order;
  std::vector<Node> all(clusters.size());
  const float min_extent = static_cast<float>(config.min_extent_m);
  for (std::size_t i = 0; i < clusters.size(); ++i) {
    all[i] = makeNode(points, clusters[i]);
    if (std::max(all[i].size.x(), all[i].size.z()) >= min_extent) order.push_back(static_cast<int>(i));
  }
  if (static_cast<int>(order.size()) > config.max_nodes) {
    std::stable_sort(order.begin(), order.end(),
                     [&](int a, int b) { return clusters[a].points.size() > clusters[b].points.size(); });
    order.resize(config.max_nodes);
    std::sort(order.begin(), order.end());
  }
  std::vector<Node> nodes;
  nodes.reserve(order.size());
  for (int i : order) nodes.push_back(std::move(all[i]));
  if (kept_clusters) *kept_clusters = order;
  return nodes;
}

Eigen::MatrixXd adjacency(const std::vector<Node>& nodes, double d_max) {
  const int n = static_cast<int>(nodes.size());
  Eigen::MatrixXd A = Eigen::MatrixXd::Identity(n, n);
  const float d2 = static_cast<float>(d_max * d_max);
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      if ((nodes[i].center - nodes[j].center).squaredNorm() < d2) A(i, j) = A(j, i) = 1.0;
  return A;
}

}  // namespace sglc
