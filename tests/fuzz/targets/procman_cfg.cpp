// procman .cfg parser (fl-procman-sheriff, fl-procman-deputy): any text parses or throws
// fl::ConfigError naming file:line; what parses resolves its own names.
#include "../fuzz_entry.hpp"
#include "fusionloc/common/yaml_options.hpp"
#include "fusionloc/procman/procman_config.hpp"

int Fuzz_procman_cfg(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const fl::procman::ProcmanConfig config = fl::procman::ParseProcmanConfig(text, "fuzz.cfg");
    for (size_t i = 0; i < config.commands.size(); ++i) {
      bool ambiguous = false;
      const auto found = config.Resolve(fl::procman::TargetKind::kCmd,
                                        config.commands[i].path(), &ambiguous);
      FL_FUZZ_CHECK(!found.empty());
      for (size_t k : found) FL_FUZZ_CHECK(k < config.commands.size());
    }
    for (const auto& s : config.scripts) FL_FUZZ_CHECK(config.FindScript(s.name) != nullptr);
  } catch (const fl::ConfigError&) {
  }
  return 0;
}
