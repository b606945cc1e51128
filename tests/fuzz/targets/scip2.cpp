// SCIP 2.0 decoder (fl-urg-driver): a byte stream from the sensor is split into responses and
// each is decoded as status, info and scan data; wrong checksums and garbage give errors.
#include <map>

#include "../fuzz_entry.hpp"
#include "fusionloc/urg/scip2.hpp"

namespace scip2 = fl::urg::scip2;

int Fuzz_scip2(const uint8_t* data, size_t size) {
  fl::fuzz::Input in(data, size);
  scip2::ResponseReader reader;
  // The stream arrives in chunks of any size.
  while (!in.empty()) {
    reader.Feed(in.Bytes(1 + in.Byte() % 64));
    scip2::Response r;
    while (reader.Next(&r)) {
      if (r.lines.empty()) continue;
      std::string status;
      if (scip2::ParseStatus(r, &status).ok()) {
        (void)scip2::DescribeStatus(r.echo().substr(0, 2), status);
      }
      std::map<std::string, std::string> info;
      (void)scip2::ParseInfo(r, &info);
      scip2::ScanCommand command;
      if (scip2::ParseScanEcho(r.echo(), &command)) {
        (void)scip2::ValuesInScan(command);
        scip2::ScanData scan;
        if (scip2::DecodeScanResponse(r, command.encoding, &scan).ok()) {
          // What decodes re-encodes to the same values.
          const std::string block = scip2::EncodeDataBlock(scan.values, command.encoding);
          FL_FUZZ_CHECK(!block.empty() || scan.values.empty());
        }
      }
      for (int enc : {2, 3}) {
        scip2::ScanData scan;
        (void)scip2::DecodeScanResponse(r, enc, &scan);
      }
    }
  }
  return 0;
}
