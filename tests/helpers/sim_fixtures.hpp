// Simulated sensor data for tests of the estimators and the fusion (link fl_sim).
//
//   auto frames = fl::test::Simulate("corridor", 5.0);            // 51 frames, all sensors
//   auto frames = fl::test::Simulate("paper", 30.0, 1, /*laser=*/true, /*camera=*/false);
//   for (const auto& f : frames) { if (f.laser) slam.AddScan(*f.laser, *f.odometry); ... }
//
// Each frame holds the ground truth (f.T_world_base), the noisy odometry and the messages due
// at that step (see fusionloc/sim/simulator.hpp). Rendering costs ~0.1 s per stereo pair, so
// keep camera runs short (a pair every 0.5 s simulated).
#pragma once

#include <string>
#include <vector>

#include "fusionloc/sim/simulator.hpp"

namespace fl::test {

inline sim::SimOptions SimOptionsFor(const std::string& world, double duration_s, int64_t seed = 1,
                                     bool laser = true, bool camera = true) {
  sim::SimOptions o = sim::DefaultOptionsForWorld(world);
  o.duration_s = duration_s;
  o.seed = seed;
  o.laser.enabled = laser;
  o.camera.enabled = camera;
  return o;
}

inline std::vector<sim::SimFrame> Simulate(const sim::SimOptions& options) {
  sim::Simulator simulator(options);
  std::vector<sim::SimFrame> frames;
  sim::SimFrame f;
  while (simulator.Step(&f)) frames.push_back(std::move(f));
  return frames;
}

inline std::vector<sim::SimFrame> Simulate(const std::string& world, double duration_s,
                                           int64_t seed = 1, bool laser = true,
                                           bool camera = true) {
  return Simulate(SimOptionsFor(world, duration_s, seed, laser, camera));
}

}  // namespace fl::test
