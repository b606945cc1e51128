// SCIP 2.0 encoding, checksums and response parsing against the examples of Hokuyo's
// specification (C-42-03320B) and replies of a real URG-04LX.
#include "fusionloc/urg/scip2.hpp"

#include <gtest/gtest.h>

#include <random>

namespace fl::urg::scip2 {
namespace {

TEST(Scip2, EncodingsOfTheSpecificationsExamples) {
  EXPECT_EQ(Encode(1234, 2), "CB");        // 2-character example
  EXPECT_EQ(Encode(5432, 3), "1Dh");       // figure 4
  EXPECT_EQ(Encode(16000000, 4), "m2@0");  // figure 6
  uint32_t v = 0;
  ASSERT_TRUE(Decode("CB", &v));
  EXPECT_EQ(v, 1234u);
  ASSERT_TRUE(Decode("1Dh", &v));
  EXPECT_EQ(v, 5432u);
  ASSERT_TRUE(Decode("m2@0", &v));
  EXPECT_EQ(v, 16000000u);
  EXPECT_FALSE(Decode("1D\x7f", &v));  // outside 0x30..0x6F
  EXPECT_FALSE(Decode("", &v));
}

TEST(Scip2, EncodeDecodeRoundTrips) {
  uint32_t v = 0;
  for (uint32_t x = 0; x < 4096; ++x) {
    ASSERT_TRUE(Decode(Encode(x, 2), &v));
    ASSERT_EQ(v, x);
  }
  std::mt19937 rng(3);
  for (int i = 0; i < 20000; ++i) {
    const uint32_t x3 = rng() & 0x3FFFF, x4 = rng() & 0xFFFFFF;
    ASSERT_TRUE(Decode(Encode(x3, 3), &v));
    ASSERT_EQ(v, x3);
    ASSERT_TRUE(Decode(Encode(x4, 4), &v));
    ASSERT_EQ(v, x4);
  }
}

TEST(Scip2, ChecksumsOfARealUrg04lxsReplies) {
  EXPECT_EQ(Checksum("00"), 'P');
  EXPECT_EQ(Checksum("99"), 'b');
  // VV, PP and II lines as a URG-04LX sends them; the sum covers KEY:VALUE, not the ';'.
  const char* lines[] = {"VEND:Hokuyo Automatic Co.,Ltd.;[",
                         "PROD:SOKUIKI Sensor URG-04LX;[",
                         "FIRM:3.1.00(18/Jan./2007);`",
                         "PROT:SCIP 2.0;N",
                         "SERI:H0614967;V",
                         "MODL:URG-04LX(Hokuyo Automatic Co.,Ltd.);N",
                         "DMIN:20;4",
                         "DMAX:5600;_",
                         "ARES:1024;\\",
                         "AMIN:44;7",
                         "AMAX:725;o",
                         "AFRT:384;6",
                         "SCAN:600;e",
                         "LASR:OFF;7",
                         "MESM:IDLE;:",
                         "STAT:Sensor works well.;8"};
  for (const std::string line : lines) {
    const size_t semi = line.rfind(';');
    EXPECT_EQ(Checksum(line.substr(0, semi)), line.back()) << line;
    EXPECT_EQ(FormatInfoLine(line.substr(0, line.find(':')),
                             line.substr(line.find(':') + 1, semi - line.find(':') - 1)),
              line + "\n");
  }
}

TEST(Scip2, ParsesAPpReplyAndRejectsABadChecksum) {
  ResponseReader reader;
  reader.Feed(
      "PP\n00P\nMODL:URG-04LX(Hokuyo Automatic Co.,Ltd.);N\nDMIN:20;4\nDMAX:5600;_\n"
      "ARES:1024;\\\nAMIN:44;7\nAMAX:725;o\nAFRT:384;6\nSCAN:600;e\n\n");
  Response r;
  ASSERT_TRUE(reader.Next(&r));
  std::string status;
  ASSERT_TRUE(ParseStatus(r, &status).ok());
  EXPECT_EQ(status, "00");
  std::map<std::string, std::string> info;
  ASSERT_TRUE(ParseInfo(r, &info).ok());
  EXPECT_EQ(info["AMIN"], "44");
  EXPECT_EQ(info["AFRT"], "384");
  EXPECT_EQ(info["MODL"], "URG-04LX(Hokuyo Automatic Co.,Ltd.)");
  r.lines[3] = "DMIN:20;5";
  const Status bad = ParseInfo(r, &info);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("checksum error in line 'DMIN:20;5'"), std::string::npos)
      << bad.message();
  // A checksum character that is ';' itself (the timer value decides it).
  r.lines[3] = "TIME:000002;;";
  ASSERT_EQ(Checksum("TIME:000002"), ';');
  ASSERT_TRUE(ParseInfo(r, &info).ok()) << ParseInfo(r, &info).message();
  EXPECT_EQ(info["TIME"], "000002");
  r.lines[3] = "DMIN 20";
  EXPECT_NE(ParseInfo(r, &info).message().find("malformed line 'DMIN 20'"), std::string::npos);
}

TEST(Scip2, ReaderAcceptsCrLfAndBytesInAnyPieces) {
  const std::string text = "BM\r\n00P\r\n\r\nQT\n00P\n\n";
  for (size_t piece = 1; piece <= text.size(); ++piece) {
    ResponseReader reader;
    for (size_t i = 0; i < text.size(); i += piece) reader.Feed(text.substr(i, piece));
    Response a, b, c;
    ASSERT_TRUE(reader.Next(&a));
    ASSERT_TRUE(reader.Next(&b));
    EXPECT_FALSE(reader.Next(&c));
    EXPECT_EQ(a.lines, (std::vector<std::string>{"BM", "00P"}));
    EXPECT_EQ(b.lines, (std::vector<std::string>{"QT", "00P"}));
  }
}

TEST(Scip2, ReaderDropsAnOverlongLine) {
  ResponseReader reader;
  reader.Feed(std::string(1000, 'x'));
  reader.Feed("\nQT\n00P\n\n");
  Response r;
  ASSERT_TRUE(reader.Next(&r));
  EXPECT_EQ(r.echo(), "QT");
  EXPECT_GE(reader.overlong_lines(), 1);
}

TEST(Scip2, StatusLineIsChecked) {
  Response r;
  r.lines = {"BM", "00Q"};
  std::string status;
  const Status s = ParseStatus(r, &status);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("checksum error"), std::string::npos) << s.message();
  r.lines = {"BM", "0"};
  EXPECT_NE(ParseStatus(r, &status).message().find("malformed status line '0'"), std::string::npos);
  r.lines = {"BM", "02R"};
  ASSERT_TRUE(ParseStatus(r, &status).ok());
  EXPECT_EQ(DescribeStatus("BM", status), "laser is already on");
  EXPECT_EQ(DescribeStatus("MD0044072501000", "04"), "End Step is out of range");
}

TEST(Scip2, ScanCommandsAndEchoes) {
  ScanCommand c;
  EXPECT_EQ(FormatScanCommand(c), "MD0044072501000\n");
  c.encoding = 2;
  c.cluster = 3;
  c.skip = 1;
  c.scans = 5;
  c.tag = "abc";
  EXPECT_EQ(FormatScanCommand(c), "MS0044072503105;abc\n");
  ScanCommand e;
  ASSERT_TRUE(ParseScanEcho("MS0044072503104;abc", &e));
  EXPECT_EQ(e.encoding, 2);
  EXPECT_EQ(e.cluster, 3);
  EXPECT_EQ(e.scans, 4);
  EXPECT_EQ(e.tag, "abc");
  EXPECT_EQ(ValuesInScan(e), 228);  // ceil(682 / 3)
  c.kind = 'G';
  c.tag.clear();
  EXPECT_EQ(FormatScanCommand(c), "GS0044072503\n");
  ASSERT_TRUE(ParseScanEcho("GD0044072501", &e));
  EXPECT_EQ(e.kind, 'G');
  EXPECT_FALSE(ParseScanEcho("MD00440725010", &e));
  EXPECT_FALSE(ParseScanEcho("VV", &e));
}

// A full URG-04LX scan: 682 values in 3 characters = 2046 characters, 31 lines of 64 and one
// of 62. 64 is not a multiple of 3, so values straddle line ends and must be joined first.
TEST(Scip2, DecodesAScanWithValuesSplitAcrossLines) {
  std::vector<uint32_t> values;
  for (int i = 0; i < 682; ++i) values.push_back(static_cast<uint32_t>(20 + (i * 37) % 5580));
  const std::string block = EncodeDataBlock(values, 3);
  const std::string ts = Encode(0xABCDEF, 4);
  ResponseReader reader;
  reader.Feed("MD0044072501000\n99b\n" + ts + Checksum(ts) + "\n" + block + "\n");
  Response r;
  ASSERT_TRUE(reader.Next(&r));
  ASSERT_EQ(r.lines.size(), 3u + 32u);  // echo, status, timestamp, data
  EXPECT_EQ(r.lines[3].size(), 65u);    // 64 data characters and the checksum
  // Value 21 is made of the last character of data line 1 and two of data line 2.
  EXPECT_EQ(r.lines[3].substr(63, 1) + r.lines[4].substr(0, 2), Encode(values[21], 3));
  ScanData scan;
  ASSERT_TRUE(DecodeScanResponse(r, 3, &scan).ok());
  EXPECT_EQ(scan.timestamp_ms, 0xABCDEFu);
  EXPECT_EQ(scan.values, values);

  // A bad checksum anywhere drops the scan, and says where.
  Response bad = r;
  bad.lines[10].back() = bad.lines[10].back() == '0' ? '1' : '0';
  const Status s = DecodeScanResponse(bad, 3, &scan);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("data line 8: checksum error"), std::string::npos) << s.message();
  // A line missing: the block is no longer a whole number of values.
  Response cut = r;
  cut.lines.erase(cut.lines.begin() + 5);
  EXPECT_NE(DecodeScanResponse(cut, 3, &scan).message().find("not a multiple of 3"),
            std::string::npos);
}

}  // namespace
}  // namespace fl::urg::scip2
