// The YAML options loader (every program's --config): any text loads into one of the
// programs' options structs or throws fl::ConfigError naming the file and key; what loads
// saves and loads back to the same text.
#include "../fuzz_entry.hpp"
#include "fusionloc/base/base_driver.hpp"
#include "fusionloc/common/robot_description.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/fusion/fusion_config.hpp"
#include "fusionloc/importers/carmen.hpp"
#include "fusionloc/importers/kitti.hpp"
#include "fusionloc/rbpf_slam/options.hpp"
#include "fusionloc/stereo_vo/stereo_vo.hpp"

namespace {
template <class T>
void Load(const std::string& text) {
  try {
    const T value = fl::LoadYamlString<T>(text, "", "fuzz.yaml");
    const std::string saved = fl::SaveYamlString(value);
    const T again = fl::LoadYamlString<T>(saved, "", "saved.yaml");
    FL_FUZZ_CHECK(fl::SaveYamlString(again) == saved);
  } catch (const fl::ConfigError&) {
  }
}
}  // namespace

int Fuzz_yaml_options(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::Input in(data, size);
  const uint8_t which = in.Byte();
  const std::string text(in.Rest());
  switch (which % 7) {
    case 0: Load<fl::rbpf::RbpfSlamOptions>(text); break;
    case 1: Load<fl::vo::StereoVoOptions>(text); break;
    case 2: Load<fl::fusion::FusionProcessConfig>(text); break;
    case 3: Load<fl::importers::CarmenOptions>(text); break;
    case 4: Load<fl::importers::KittiOptions>(text); break;
    case 5: Load<fl::base::BaseDriverOptions>(text); break;
    default: Load<fl::RobotDescription>(text); break;
  }
  return 0;
}
