// LCM log reader (fl-replay, fl-log-info, every log: URL): any bytes are read to the end with
// corrupt or truncated parts counted, never a crash; every message of a known type is decoded.
#include "../fuzz_entry.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/importers/log_info.hpp"

int Fuzz_lcm_log(const uint8_t* data, size_t size) {
  fl::fuzz::QuietLogs();
  fl::fuzz::MemFile file(data, size);
  int64_t events = 0;
  {
    fl::LcmLogReader reader(file.path());
    fl::LcmLogEvent event;
    while (reader.Next(&event)) {
      ++events;
      FL_FUZZ_CHECK(event.data.size() <= size);
    }
    FL_FUZZ_CHECK(reader.corrupt_bytes_skipped() <= static_cast<int64_t>(size));
  }
  const fl::importers::LogInfo info = fl::importers::InspectLcmLog(file.path());
  FL_FUZZ_CHECK(info.events == events);
  (void)info.ToText();
  (void)info.ToJson();
  return 0;
}
