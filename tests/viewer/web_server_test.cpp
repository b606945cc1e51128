#include "fusionloc/viewer/web_server.hpp"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "test_paths.hpp"

namespace fl::viewer {
namespace {

TEST(TokenAccepted, NeedsTheTokenInTheQueryOrTheCookieWhenThereIsOne) {
  EXPECT_TRUE(TokenAccepted("", nullptr, nullptr));
  EXPECT_TRUE(TokenAccepted("secret-123", "token=secret-123", nullptr));
  EXPECT_TRUE(TokenAccepted("secret-123", "a=1&token=secret-123", nullptr));
  EXPECT_TRUE(TokenAccepted("secret-123", nullptr, "x=1; fl_viewer_token=secret-123"));
  EXPECT_FALSE(TokenAccepted("secret-123", nullptr, nullptr));
  EXPECT_FALSE(TokenAccepted("secret-123", "token=secret-12", nullptr));
  EXPECT_FALSE(TokenAccepted("secret-123", "token=secret-1234", nullptr));
  EXPECT_FALSE(TokenAccepted("secret-123", "tok=secret-123", "fl_viewer_token=nope"));
}

// GET `path` from 127.0.0.1:port; returns the whole response ("" if it cannot connect).
std::string Get(int port, const std::string& path) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0) {
    close(fd);
    return "";
  }
  const std::string req = "GET " + path + " HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n";
  if (write(fd, req.data(), req.size()) != static_cast<ssize_t>(req.size())) {
    close(fd);
    return "";
  }
  std::string out;
  char buf[4096];
  ssize_t n;
  while ((n = read(fd, buf, sizeof(buf))) > 0) out.append(buf, static_cast<size_t>(n));
  close(fd);
  return out;
}

ServerOptions TestOptions(const test::TempDir& dir) {
  for (const char* f : {"index.html", "viewer.js", "viewer.css"}) {
    std::ofstream(dir.file(f)) << "<!-- " << f << " -->";
  }
  std::filesystem::create_directories(dir.file("three/examples/js/controls"));
  std::ofstream(dir.file("three/three.min.js")) << "// three";
  std::ofstream(dir.file("three/examples/js/controls/OrbitControls.js")) << "// orbit";
  ServerOptions o;
  o.port = 0;
  o.web_dir = dir.path();
  o.three_dir = dir.file("three");
  return o;
}

TEST(WebServer, ServesThePageAndThreeJsAndNothingElse) {
  test::TempDir dir;
  WebServer server(TestOptions(dir), nullptr);
  ASSERT_TRUE(server.Start().ok());
  ASSERT_GT(server.port(), 0);
  EXPECT_EQ(server.url(), "http://127.0.0.1:" + std::to_string(server.port()) + "/");
  std::string r = Get(server.port(), "/");
  EXPECT_NE(r.find("200 OK"), std::string::npos) << r;
  EXPECT_NE(r.find("<!-- index.html -->"), std::string::npos);
  EXPECT_NE(r.find("text/html"), std::string::npos);
  r = Get(server.port(), "/three/three.min.js");
  EXPECT_NE(r.find("// three"), std::string::npos) << r;
  r = Get(server.port(), "/three/OrbitControls.js");
  EXPECT_NE(r.find("// orbit"), std::string::npos) << r;
  EXPECT_NE(Get(server.port(), "/../../etc/passwd").find("404"), std::string::npos);
  EXPECT_NE(Get(server.port(), "/viewer_main.cpp").find("404"), std::string::npos);
  EXPECT_EQ(server.stats().clients, 0);
}

TEST(WebServer, WithATokenRefusesRequestsWithoutItAndSetsTheCookie) {
  test::TempDir dir;
  ServerOptions o = TestOptions(dir);
  o.token = "abcdefgh12";
  WebServer server(o, nullptr);
  ASSERT_TRUE(server.Start().ok());
  EXPECT_NE(server.url().find("?token=abcdefgh12"), std::string::npos);
  std::string r = Get(server.port(), "/");
  EXPECT_NE(r.find("403"), std::string::npos) << r;
  EXPECT_EQ(r.find("<!-- index.html -->"), std::string::npos);
  r = Get(server.port(), "/?token=abcdefgh12");
  EXPECT_NE(r.find("<!-- index.html -->"), std::string::npos) << r;
  EXPECT_NE(r.find("Set-Cookie: fl_viewer_token=abcdefgh12"), std::string::npos);
}

TEST(WebServer, MissingFilesAndBusyPortsAreClearErrors) {
  test::TempDir dir;
  ServerOptions o = TestOptions(dir);
  o.three_dir = dir.file("nowhere");
  WebServer no_three(o, nullptr);
  const Status s = no_three.Start();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("libjs-three"), std::string::npos) << s.message();

  WebServer first(TestOptions(dir), nullptr);
  ASSERT_TRUE(first.Start().ok());
  ServerOptions same = TestOptions(dir);
  same.port = first.port();
  WebServer second(same, nullptr);
  const Status busy = second.Start();
  ASSERT_FALSE(busy.ok());
  EXPECT_NE(busy.message().find("cannot listen on 127.0.0.1:" + std::to_string(first.port())),
            std::string::npos)
      << busy.message();
}

}  // namespace
}  // namespace fl::viewer
