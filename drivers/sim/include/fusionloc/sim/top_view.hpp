// Top view of a simulated world (shapes, route, driven ground-truth trajectory) as a PNG, for
// docs/SIMULATOR.md and for checking a configuration at a glance.
#pragma once

#include <string>

#include "fusionloc/sim/sim_options.hpp"

namespace fl::sim {

// Runs the simulation without sensors to draw the driven trajectory; throws
// std::runtime_error if the image cannot be written.
void WriteTopView(const SimOptions& options, const std::string& png_path,
                  double pixels_per_m = 20.0);

// Writes the stereo pair seen at simulated time `time_s` (rounded to a step) as
// `<prefix>_left.png` and `<prefix>_right.png` (with the configured noise).
void WriteSnapshot(const SimOptions& options, double time_s, const std::string& prefix);

}  // namespace fl::sim
