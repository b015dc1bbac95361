// The pose graph's export: read back by a g2o reader written here from g2o's own definitions (not the server's
// code) and solved with Ceres, it gives the server's optimised poses; every scan with an odometry pose is a
// vertex in frame order; loops that cannot join the graph are listed, not dropped.
#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "../storage/storage_test_util.hpp"
#include "drive.hpp"
#include "sglc/posegraph/graph_export.hpp"

namespace sglc::posegraph {
namespace {

using storage::testing::options;
using storage::testing::TempDir;
using testing::drive;
using testing::driveOptions;

// g2o's SE3 vertex and edge (types_slam3d): pose = (t, q); an edge's error is (t, q.vec) of
// measurement^-1 * (Ti^-1 * Tj) with q.w made positive, weighted by the information over (x, y, z, qx, qy, qz).
struct G2oGraph {
  std::map<int, std::array<double, 7>> vertices;  // qx qy qz qw x y z: Ceres' quaternion then translation
  struct Edge {
    int i, j;
    Eigen::Quaterniond q;
    Eigen::Vector3d t;
    Mat6d information;
  };
  std::vector<Edge> edges;
};

G2oGraph readG2o(const std::string& text) {
  G2oGraph g;
  std::istringstream in(text);
  std::string tag;
  while (in >> tag) {
    if (tag == "VERTEX_SE3:QUAT") {
      int id;
      double x, y, z, qx, qy, qz, qw;
      in >> id >> x >> y >> z >> qx >> qy >> qz >> qw;
      g.vertices[id] = {qx, qy, qz, qw, x, y, z};
    } else if (tag == "EDGE_SE3:QUAT") {
      G2oGraph::Edge e;
      double x, y, z, qx, qy, qz, qw;
      in >> e.i >> e.j >> x >> y >> z >> qx >> qy >> qz >> qw;
      e.t = {x, y, z};
      e.q = Eigen::Quaterniond(qw, qx, qy, qz).normalized();
      for (int r = 0; r < 6; ++r)
        for (int c = r; c < 6; ++c) {
          in >> e.information(r, c);
          e.information(c, r) = e.information(r, c);
        }
      g.edges.push_back(e);
    } else {
      ADD_FAILURE() << "unexpected g2o tag " << tag;
      break;
    }
  }
  return g;
}

struct G2oEdgeError {
  G2oGraph::Edge e;
  Mat6d sqrt_info;
  template <typename T>
  bool operator()(const T* a, const T* b, T* r) const {
    Eigen::Map<const Eigen::Quaternion<T>> qa(a), qb(b);
    Eigen::Map<const Eigen::Matrix<T, 3, 1>> ta(a + 4), tb(b + 4);
    const Eigen::Quaternion<T> q_rel = qa.conjugate() * qb;
    const Eigen::Matrix<T, 3, 1> t_rel = qa.conjugate() * (tb - ta);
    const Eigen::Quaternion<T> m_inv = e.q.template cast<T>().conjugate();
    Eigen::Quaternion<T> dq = m_inv * q_rel;
    const Eigen::Matrix<T, 3, 1> dt = m_inv * (t_rel - e.t.template cast<T>());
    if (dq.w() < T(0)) dq.coeffs() = -dq.coeffs();
    Eigen::Matrix<T, 6, 1> err;
    err << dt, dq.vec();
    Eigen::Map<Eigen::Matrix<T, 6, 1>> out(r);
    out = sqrt_info.template cast<T>() * err;
    return true;
  }
};

// Solves the file's graph from its odometry chain (vertex 0 fixed, as g2o's gauge), plain least squares.
std::map<int, Mat4d> solveG2o(G2oGraph g) {
  // Start every vertex from the chain of odometry edges (i, i + 1) off vertex 0, not from the file's poses.
  for (const auto& e : g.edges) {
    if (e.j != e.i + 1) continue;
    const auto& a = g.vertices.at(e.i);
    const Eigen::Quaterniond qa(a[3], a[0], a[1], a[2]);
    const Eigen::Quaterniond qb = qa * e.q;
    const Eigen::Vector3d tb = Eigen::Vector3d(a[4], a[5], a[6]) + qa * e.t;
    g.vertices[e.j] = {qb.x(), qb.y(), qb.z(), qb.w(), tb.x(), tb.y(), tb.z()};
  }
  ceres::Problem problem;
  for (const auto& e : g.edges) {
    const Mat6d sqrt_info = Eigen::LLT<Mat6d>(e.information).matrixU();
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<G2oEdgeError, 6, 7, 7>(new G2oEdgeError{e, sqrt_info}),
                             nullptr, g.vertices.at(e.i).data(), g.vertices.at(e.j).data());
  }
  for (auto& [id, v] : g.vertices)
    problem.SetManifold(v.data(),
                        new ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>());
  problem.SetParameterBlockConstant(g.vertices.at(0).data());
  ceres::Solver::Options o;
  o.max_num_iterations = 200;
  o.function_tolerance = 1e-12;
  o.gradient_tolerance = 1e-12;
  o.parameter_tolerance = 1e-12;
  ceres::Solver::Summary summary;
  ceres::Solve(o, &problem, &summary);
  EXPECT_TRUE(summary.IsSolutionUsable()) << summary.BriefReport();
  std::map<int, Mat4d> out;
  for (const auto& [id, v] : g.vertices) {
    Mat4d T = Mat4d::Identity();
    T.topLeftCorner<3, 3>() = Eigen::Quaterniond(v[3], v[0], v[1], v[2]).normalized().toRotationMatrix();
    T.topRightCorner<3, 1>() = Eigen::Vector3d(v[4], v[5], v[6]);
    out[id] = T;
  }
  return out;
}

TEST(GraphExport, G2oSolvedElsewhereGivesTheServersPoses) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  const auto d = drive(*store);
  // A scan without odometry pose (no graph node) with a verified loop to the drive: listed, never dropped.
  const auto fp = storage::testing::randomFingerprint(7);
  const auto lone = store->addScan({.map = "m", .robot = "walker", .session = "w", .seq = 0, .fingerprint = &fp});
  const auto lone_loop = store->addLoop("m", {0, lone, d.ids[10], Mat4d::Identity(), 0.8, 0.9, 0.02, 20});
  GraphOptimiser graph(*store, driveOptions());
  graph.optimiseNow("m", GraphOptimiser::Scope::kGlobal);

  const auto g = exportGraph(*store, "m", driveOptions());
  ASSERT_EQ(g.nodes.size(), d.ids.size());
  for (std::size_t i = 0; i < g.nodes.size(); ++i) {
    EXPECT_EQ(g.nodes[i].scan_id, d.ids[i]) << "vertices in frame order";
    EXPECT_TRUE(g.nodes[i].optimised);
  }
  ASSERT_EQ(g.left_out.size(), 1u);
  EXPECT_EQ(g.left_out[0].loop.id, lone_loop);
  EXPECT_NE(g.left_out[0].reason.find("no odometry pose"), std::string::npos) << g.left_out[0].reason;
  const auto loops = store->loops("m").size() - 1;
  EXPECT_EQ(g.edges.size(), (d.ids.size() - 1) + loops);

  std::ostringstream g2o, ids, left;
  writeG2o(g, g2o, ids);
  writeLeftOutCsv(g, left);
  const auto solved = solveG2o(readG2o(g2o.str()));
  ASSERT_EQ(solved.size(), g.nodes.size());
  // The server anchors the session's first scan where its odometry puts it; vertex 0 is that scan.
  double worst_t = 0, worst_r = 0;
  for (std::size_t i = 0; i < g.nodes.size(); ++i) {
    const Mat4d D = g.nodes[i].pose.inverse() * solved.at(static_cast<int>(i));
    worst_t = std::max(worst_t, D.topRightCorner<3, 1>().norm());
    worst_r = std::max(worst_r, Eigen::AngleAxisd(Eigen::Matrix3d(D.topLeftCorner<3, 3>())).angle());
  }
  std::cout << "g2o solved elsewhere vs the server's poses: worst " << worst_t << " m, " << worst_r * 180 / M_PI
            << " deg over " << g.nodes.size() << " scans\n";
  EXPECT_LT(worst_t, 0.005);
  EXPECT_LT(worst_r * 180 / M_PI, 0.01);
  // Against the drift it corrects: the odometry ends metres off, so agreement is not a coincidence.
  EXPECT_GT((d.odom.back().topRightCorner<3, 1>() - d.gt.back().topRightCorner<3, 1>()).norm(), 20 * worst_t);

  // The side files: one row per vertex naming its scan; the left-out loop with its reason.
  std::istringstream rows(ids.str());
  std::string line;
  std::getline(rows, line);
  EXPECT_EQ(line, "id,scan_id,robot,session,seq,stamp,optimised");
  std::getline(rows, line);
  EXPECT_EQ(line, "0," + std::to_string(d.ids[0]) + ",\"r\",\"s\",0,,1");
  std::size_t n = 1;
  while (std::getline(rows, line)) ++n;
  EXPECT_EQ(n, g.nodes.size());
  EXPECT_NE(left.str().find(std::to_string(lone_loop) + "," + std::to_string(lone) + ","), std::string::npos)
      << left.str();

  // JSON: the same graph.
  std::ostringstream js;
  writeGraphJson(g, js);
  const auto j = nlohmann::json::parse(js.str());
  EXPECT_EQ(j["nodes"].size(), g.nodes.size());
  EXPECT_EQ(j["edges"].size(), g.edges.size());
  EXPECT_EQ(j["left_out"].size(), 1u);
  EXPECT_EQ(j["edges"].back()["kind"], "loop");
}

// A false loop the server's robust loss discounts keeps that discount in the file (as its weight), so a plain
// least-squares back-end is not wrecked by it either.
TEST(GraphExport, AFalseLoopTheServerDiscountsStaysDiscounted) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  const auto d = drive(*store);
  const auto false_loop =
      store->addLoop("m", {0, d.ids[200], d.ids[20], testing::pose(0.0, 1.0, 0.0), 0.9, 0.9, 0.02, 30});
  GraphOptimiser graph(*store, driveOptions());
  EXPECT_GE(graph.optimiseNow("m", GraphOptimiser::Scope::kGlobal).rejected_loops, 1);
  const auto g = exportGraph(*store, "m", driveOptions());
  const auto it = std::find_if(g.edges.begin(), g.edges.end(), [&](const auto& e) { return e.loop_id == false_loop; });
  ASSERT_NE(it, g.edges.end());
  EXPECT_LT(it->weight, 0.01);
  std::vector<double> true_weights;
  for (const auto& e : g.edges)
    if (e.loop_id && e.loop_id != false_loop) true_weights.push_back(e.weight);
  std::nth_element(true_weights.begin(), true_weights.begin() + true_weights.size() / 2, true_weights.end());
  EXPECT_GT(true_weights[true_weights.size() / 2], 0.5) << "the median true loop keeps most of its weight";
  std::ostringstream g2o, ids;
  writeG2o(g, g2o, ids);
  const auto solved = solveG2o(readG2o(g2o.str()));
  double worst = 0;
  for (std::size_t i = 0; i < g.nodes.size(); ++i)
    worst = std::max(worst, (g.nodes[i].pose.inverse() * solved.at(static_cast<int>(i))).topRightCorner<3, 1>().norm());
  EXPECT_LT(worst, 0.01) << "the file's solution is the server's, false loop and all";
}

TEST(GraphExport, ARobotFilterKeepsItsScansAndListsLoopsToOthers) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  const auto d = drive(*store);
  const auto fp = storage::testing::randomFingerprint(8);
  const auto other = store->addScan({.map = "m",
                                     .robot = "q",
                                     .session = "s",
                                     .seq = 0,
                                     .odometry_pose = testing::pose(0.0, 40.0, 0.0),
                                     .fingerprint = &fp});
  store->addLoop("m", {0, other, d.ids[0], Mat4d::Identity(), 0.8, 0.9, 0.02, 20});
  const auto all = exportGraph(*store, "m", driveOptions());
  EXPECT_EQ(all.nodes.size(), d.ids.size() + 1);
  EXPECT_TRUE(all.left_out.empty());
  const auto only_r = exportGraph(*store, "m", driveOptions(), {"r"});
  EXPECT_EQ(only_r.nodes.size(), d.ids.size());
  ASSERT_EQ(only_r.left_out.size(), 1u);
  EXPECT_NE(only_r.left_out[0].reason.find("robot 'q'"), std::string::npos) << only_r.left_out[0].reason;
}

}  // namespace
}  // namespace sglc::posegraph
