// A command line split into words as a POSIX shell splits it, for running it without a shell
// (execvp): the `exec` of a procman command.
//
//   blanks (space, tab, newline) separate words;
//   'single quotes' keep everything up to the next ' literally;
//   "double quotes" keep blanks; in them a backslash escapes only $ " \ ` and newline;
//   a backslash outside quotes keeps the next character (backslash-newline joins lines);
//   ${NAME} (outside single quotes) is replaced by the value of NAME from `vars`, then from
//   the environment; the value stays inside its word (no further splitting); a $ not followed
//   by { is literal.
//
// Errors (false, *error says where and what to do): an unterminated quote or ${, an unknown
// variable, and an unquoted | & ; < > ( ) or `: these are shell syntax, and the command runs
// without a shell (write `sh -c '...'` to get one).
#pragma once

#include <map>
#include <string>
#include <vector>

namespace fl::procman {

bool SplitShellWords(const std::string& text, const std::map<std::string, std::string>& vars,
                     std::vector<std::string>* words, std::string* error);

}  // namespace fl::procman
