#include "fusionloc/procman/shell_words.hpp"

#include <cctype>
#include <cstdlib>

namespace fl::procman {
namespace {

bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\n'; }

std::string At(size_t i) { return "column " + std::to_string(i + 1); }

// Expands the ${NAME} that starts at text[i] (text[i] == '$', text[i+1] == '{'); moves i past
// the closing brace.
bool ExpandAt(const std::string& text, size_t* i, const std::map<std::string, std::string>& vars,
              std::string* word, std::string* error) {
  const size_t start = *i;
  const size_t close = text.find('}', start + 2);
  if (close == std::string::npos) {
    *error = "unterminated ${ at " + At(start) + " (write ${NAME})";
    return false;
  }
  const std::string name = text.substr(start + 2, close - start - 2);
  bool valid = !name.empty();
  for (char c : name) {
    valid = valid && (std::isalnum(static_cast<unsigned char>(c)) || c == '_');
  }
  if (!valid) {
    *error =
        "bad variable name '${" + name + "}' at " + At(start) + " (letters, digits and _ only)";
    return false;
  }
  if (auto it = vars.find(name); it != vars.end()) {
    *word += it->second;
  } else if (const char* env = std::getenv(name.c_str()); env != nullptr) {
    *word += env;
  } else {
    *error = "unknown variable ${" + name + "} at " + At(start) + ": give it with --var " + name +
             "=VALUE or set it in the environment";
    return false;
  }
  *i = close + 1;
  return true;
}

}  // namespace

bool SplitShellWords(const std::string& text, const std::map<std::string, std::string>& vars,
                     std::vector<std::string>* words, std::string* error) {
  words->clear();
  std::string word;
  bool in_word = false;  // a word has begun (even an empty '' one)
  size_t i = 0;
  const size_t n = text.size();
  auto end_word = [&] {
    if (in_word) words->push_back(word);
    word.clear();
    in_word = false;
  };
  while (i < n) {
    const char c = text[i];
    if (IsBlank(c)) {
      end_word();
      ++i;
    } else if (c == '\\') {
      if (i + 1 >= n) {
        *error = "a backslash ends the command at " + At(i) + " (write \\\\ for a backslash)";
        return false;
      }
      if (text[i + 1] != '\n') {
        word += text[i + 1];
        in_word = true;
      }
      i += 2;
    } else if (c == '\'') {
      const size_t close = text.find('\'', i + 1);
      if (close == std::string::npos) {
        *error = "unterminated single quote at " + At(i) + " (close it with ')";
        return false;
      }
      word += text.substr(i + 1, close - i - 1);
      in_word = true;
      i = close + 1;
    } else if (c == '"') {
      const size_t open = i++;
      in_word = true;
      for (;;) {
        if (i >= n) {
          *error = "unterminated double quote at " + At(open) + " (close it with \")";
          return false;
        }
        const char d = text[i];
        if (d == '"') {
          ++i;
          break;
        }
        if (d == '\\' && i + 1 < n &&
            (text[i + 1] == '$' || text[i + 1] == '"' || text[i + 1] == '\\' ||
             text[i + 1] == '`' || text[i + 1] == '\n')) {
          if (text[i + 1] != '\n') word += text[i + 1];
          i += 2;
        } else if (d == '$' && i + 1 < n && text[i + 1] == '{') {
          if (!ExpandAt(text, &i, vars, &word, error)) return false;
        } else {
          word += d;
          ++i;
        }
      }
    } else if (c == '$' && i + 1 < n && text[i + 1] == '{') {
      in_word = true;
      if (!ExpandAt(text, &i, vars, &word, error)) return false;
    } else if (c == '|' || c == '&' || c == ';' || c == '<' || c == '>' || c == '(' || c == ')' ||
               c == '`') {
      *error = std::string("unquoted '") + c + "' at " + At(i) +
               ": commands run without a shell; quote it, or write sh -c '...' for shell syntax";
      return false;
    } else {
      word += c;
      in_word = true;
      ++i;
    }
  }
  end_word();
  if (words->empty()) {
    *error = "the command is empty";
    return false;
  }
  return true;
}

}  // namespace fl::procman
