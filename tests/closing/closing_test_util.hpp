// A small map for the use-case tests: views of two different streets, stored by two robots, and a query view.
#pragma once

#include <map>
#include <memory>

#include "sglc/closing/loop_query.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/storage/map_store.hpp"
#include "test_util.hpp"

namespace sglc::closing::test {

using namespace sglc::test;

inline const Mat4d kQueryPose = makeT(8.0, 3.0, 0.6, 0.0);

struct StoredView {
  std::string robot;
  std::int64_t seq = 0;
  Mat4d pose = Mat4d::Identity();  // sensor -> street
  bool same_place = false;         // a view of the query's street
};

// Another place: an open square with poles and trunks on a ring and parked cars, nothing like the street.
inline LabelledScan makeSquare() {
  LabelledScan w;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  addPoints(w, makeFloor(-30, 30, -30, 30, -1.7, 0.5), kRoad);
  addPoints(w, makeWall(25, -30, 25, 30, -1.7, 10, 0.4), kBuilding);
  addPoints(w, makeWall(-30, -22, 25, -22, -1.7, 4, 0.4), kBuilding);
  for (int k = 0; k < 11; ++k) {
    const double a = k * 0.57 + 0.2 * u(rng), r = 9.0 + 4.0 * u(rng);
    addPoints(w, makePole(r * std::cos(a), r * std::sin(a), -1.7, 4.0 + u(rng)), k % 2 ? kTrunk : kPole);
  }
  for (int k = 0; k < 4; ++k)
    addPoints(w, makeBoxSurface({-18.0 + 3.0 * k, 15.0 - 6.0 * k, -1.0}, {2.1, 0.9, 0.7}, 40.0 * k, 0.1), kCar);
  return w;
}

// Map "m": r1/s seq 0 and r2/s seq 0 see the query's street, r1/s seq 1 and r2/s seq 1 a square elsewhere.
struct TwoStreets {
  TwoStreets() {
    storage::StoreOptions o;
    o.path = dir.file("map.db");
    o.sync = storage::StoreOptions::Sync::kOff;
    store = storage::MapStore::open(o);
    const auto& c = pipeline.config();
    store->createMap("m",
                     descriptorLayout(static_cast<int>(c.labels.node_classes.size()), c.graph, c.descriptor).scanDim());
    const auto street = makeStreetWorld(7), other = makeSquare();
    const StoredView views[] = {{"r1", 0, makeT(0.0, 0.0, 0.0, 0.0), true},
                                {"r1", 1, makeT(0.0, 0.0, 0.0, 0.0), false},
                                {"r2", 0, makeT(-15.0, 12.0, -1.0, 0.0), true},
                                {"r2", 1, makeT(20.0, -6.0, 0.5, 0.0), false}};
    for (const auto& v : views) {
      const auto fp = pipeline.fingerprint(viewFrom(v.same_place ? street : other, v.pose));
      const auto id = store->addScan({.map = "m", .robot = v.robot, .session = "s", .seq = v.seq, .fingerprint = &fp});
      scans[id] = v;
      if (v.same_place && v.robot == "r1") same_place_id = id;
      if (!v.same_place && v.robot == "r1") other_place_id = id;
    }
    query = pipeline.fingerprint(viewFrom(street, kQueryPose));
  }

  QueryOrigin origin(const std::string& robot) const { return {"m", robot, "s", 500, std::nullopt, 0}; }

  TempDir dir;
  Pipeline pipeline;
  std::unique_ptr<storage::MapStore> store;
  std::map<std::int64_t, StoredView> scans;
  std::int64_t same_place_id = 0, other_place_id = 0;
  Fingerprint query;
};

}  // namespace sglc::closing::test
