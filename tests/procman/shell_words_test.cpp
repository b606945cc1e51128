#include "fusionloc/procman/shell_words.hpp"

#include <gtest/gtest.h>
#include <stdlib.h>

namespace fl::procman {
namespace {

std::vector<std::string> Split(const std::string& text,
                               const std::map<std::string, std::string>& vars = {}) {
  std::vector<std::string> words;
  std::string error;
  EXPECT_TRUE(SplitShellWords(text, vars, &words, &error)) << text << ": " << error;
  return words;
}

std::string ErrorOf(const std::string& text) {
  std::vector<std::string> words;
  std::string error;
  if (SplitShellWords(text, {}, &words, &error)) return "no error";
  return error;
}

using W = std::vector<std::string>;

TEST(ShellWords, BlanksSeparateWords) {
  EXPECT_EQ(Split("  a\tbb \n ccc  "), (W{"a", "bb", "ccc"}));
}

TEST(ShellWords, SingleQuotesAreLiteral) {
  EXPECT_EQ(Split("sh -c 'sleep 1; exit 3'"), (W{"sh", "-c", "sleep 1; exit 3"}));
  EXPECT_EQ(Split("echo 'a\\b \"c\" ${X}'"), (W{"echo", "a\\b \"c\" ${X}"}));
  EXPECT_EQ(Split("x '' y"), (W{"x", "", "y"}));  // an empty quoted word is a word
}

TEST(ShellWords, DoubleQuotesKeepBlanksAndEscapeFewCharacters) {
  EXPECT_EQ(Split("echo \"a  b\" \"q\\\"q\" \"back\\\\slash\" \"\\n stays\""),
            (W{"echo", "a  b", "q\"q", "back\\slash", "\\n stays"}));
  EXPECT_EQ(Split("a\"b c\"'d e'f"), (W{"ab cd ef"}));  // quotes join inside one word
}

TEST(ShellWords, BackslashOutsideQuotes) {
  EXPECT_EQ(Split("a\\ b c\\'d \\\\"), (W{"a b", "c'd", "\\"}));
  EXPECT_EQ(Split("a \\\nb"), (W{"a", "b"}));  // backslash-newline joins lines
}

TEST(ShellWords, VariablesFromVarsThenEnvironment) {
  setenv("FL_SHELL_WORDS_TEST", "from env", 1);
  EXPECT_EQ(Split("${BIN}/fl-sim --url=${URL} \"${FL_SHELL_WORDS_TEST}\" '${BIN}'",
                  {{"BIN", "/opt/bin"}, {"URL", "udpm://x?ttl=0"}}),
            (W{"/opt/bin/fl-sim", "--url=udpm://x?ttl=0", "from env", "${BIN}"}));
  // A value with blanks stays one word; vars win over the environment; $ alone is literal.
  EXPECT_EQ(Split("a${FL_SHELL_WORDS_TEST}b $HOME", {{"FL_SHELL_WORDS_TEST", "1 2"}}),
            (W{"a1 2b", "$HOME"}));
  unsetenv("FL_SHELL_WORDS_TEST");
}

TEST(ShellWords, ErrorsSayWhereAndTheFix) {
  EXPECT_NE(ErrorOf("sh -c 'oops").find("unterminated single quote at column 7"),
            std::string::npos);
  EXPECT_NE(ErrorOf("echo \"oops").find("unterminated double quote at column 6"),
            std::string::npos);
  EXPECT_NE(ErrorOf("echo ${NOPE_FL_X}").find("--var NOPE_FL_X=VALUE"), std::string::npos);
  EXPECT_NE(ErrorOf("echo ${BAD").find("unterminated ${"), std::string::npos);
  EXPECT_NE(ErrorOf("echo ${a-b}").find("bad variable name"), std::string::npos);
  EXPECT_NE(ErrorOf("a | b").find("without a shell"), std::string::npos);
  EXPECT_NE(ErrorOf("a > f").find("unquoted '>' at column 3"), std::string::npos);
  EXPECT_NE(ErrorOf("a; b").find("unquoted ';'"), std::string::npos);
  EXPECT_NE(ErrorOf("end\\").find("backslash ends"), std::string::npos);
  EXPECT_NE(ErrorOf("   ").find("empty"), std::string::npos);
  EXPECT_EQ(Split("a '|' \\> \";\""), (W{"a", "|", ">", ";"}));  // quoted: plain characters
}

}  // namespace
}  // namespace fl::procman
