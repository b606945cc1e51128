#include "fusionloc/procman/procman_config.hpp"

#include <cctype>
#include <fstream>
#include <set>
#include <sstream>

#include "fusionloc/common/yaml_options.hpp"

namespace fl::procman {
namespace {

enum class Tok { kIdent, kString, kInteger, kOpen, kClose, kAssign, kSemicolon, kEnd };

struct Token {
  Tok type = Tok::kEnd;
  std::string text;
  int line = 1, column = 1;
};

std::string Describe(const Token& t) {
  switch (t.type) {
    case Tok::kEnd:
      return "the end of the file";
    case Tok::kString:
      return "string \"" + t.text + "\"";
    case Tok::kInteger:
      return "number " + t.text;
    default:
      return "'" + t.text + "'";
  }
}

class Parser {
 public:
  Parser(const std::string& text, const std::string& file) : text_(text), file_(file) {
    config_.file = file;
    Advance();
  }

  ProcmanConfig Parse() {
    while (next_.type != Tok::kEnd) {
      const Token t = Expect(Tok::kIdent, "'cmd', 'group' or 'script'");
      if (t.text == "cmd") {
        ParseCommand("", t);
      } else if (t.text == "group") {
        ParseGroup("");
      } else if (t.text == "script") {
        ParseScript(t);
      } else {
        Fail(t, "expected 'cmd', 'group' or 'script'");
      }
    }
    Check();
    return config_;
  }

 private:
  [[noreturn]] void Fail(const Token& at, const std::string& what) const {
    throw ConfigError(file_ + ":" + std::to_string(at.line) + ":" + std::to_string(at.column) +
                      ": " + what + ", found " + Describe(at));
  }
  [[noreturn]] void FailAt(int line, const std::string& what) const {
    throw ConfigError(file_ + ":" + std::to_string(line) + ": " + what);
  }

  // The tokenizer: next_ is the token ahead.
  char Peek() const { return pos_ < text_.size() ? text_[pos_] : '\0'; }
  char Get() {
    const char c = text_[pos_++];
    if (c == '\n') {
      ++line_;
      column_ = 1;
    } else {
      ++column_;
    }
    return c;
  }
  void Advance() {
    for (;;) {
      while (pos_ < text_.size() && std::isspace(static_cast<unsigned char>(Peek()))) Get();
      if (Peek() == '#') {
        while (pos_ < text_.size() && Peek() != '\n') Get();
        continue;
      }
      break;
    }
    Token t;
    t.line = line_;
    t.column = column_;
    if (pos_ >= text_.size()) {
      t.type = Tok::kEnd;
      next_ = t;
      return;
    }
    const char c = Get();
    t.text = std::string(1, c);
    switch (c) {
      case '{':
        t.type = Tok::kOpen;
        break;
      case '}':
        t.type = Tok::kClose;
        break;
      case '=':
        t.type = Tok::kAssign;
        break;
      case ';':
        t.type = Tok::kSemicolon;
        break;
      case '"': {
        t.type = Tok::kString;
        t.text.clear();
        for (;;) {
          if (pos_ >= text_.size() || Peek() == '\n') {
            throw ConfigError(file_ + ":" + std::to_string(t.line) + ":" +
                              std::to_string(t.column) +
                              ": unterminated string (a \" must close it on the same line)");
          }
          char d = Get();
          if (d == '"') break;
          if (d == '\\' && pos_ < text_.size()) {
            d = Get();
            if (d == 'n') d = '\n';
            if (d == 't') d = '\t';
            if (d == 'r') d = '\r';
          }
          t.text += d;
        }
        break;
      }
      default:
        if (std::isalpha(static_cast<unsigned char>(c)) || c == '_') {
          t.type = Tok::kIdent;
          while (std::isalnum(static_cast<unsigned char>(Peek())) || Peek() == '_' ||
                 Peek() == '-') {
            t.text += Get();
          }
        } else if (std::isdigit(static_cast<unsigned char>(c))) {
          t.type = Tok::kInteger;
          while (std::isdigit(static_cast<unsigned char>(Peek()))) t.text += Get();
        } else {
          throw ConfigError(file_ + ":" + std::to_string(t.line) + ":" + std::to_string(t.column) +
                            ": invalid character '" + t.text +
                            "' (expected a name, a \"string\", a number, { } = or ;)");
        }
    }
    next_ = t;
  }
  Token Take() {
    Token t = next_;
    Advance();
    return t;
  }
  Token Expect(Tok type, const std::string& what) {
    if (next_.type != type) Fail(next_, "expected " + what);
    return Take();
  }
  bool Accept(Tok type) {
    if (next_.type != type) return false;
    Take();
    return true;
  }

  void ParseCommand(const std::string& group, const Token& at) {
    CommandConfig cmd;
    cmd.group = group;
    cmd.line = at.line;
    bool named = false;
    if (next_.type == Tok::kString) {
      const Token name = Take();
      if (name.text.find('/') != std::string::npos) Fail(name, "'/' is not allowed in a cmd name");
      if (name.text.empty()) Fail(name, "expected a non-empty cmd name");
      cmd.name = name.text;
      named = true;
    }
    Expect(Tok::kOpen, "'{' after cmd" + (named ? " \"" + cmd.name + "\"" : std::string()));
    std::set<std::string> seen;
    while (next_.type == Tok::kIdent) {
      const Token key = Take();
      static const std::set<std::string> kStrings = {"exec", "host", "deputy", "auto_respawn",
                                                     "group"};
      static const std::set<std::string> kIntegers = {"stop_signal", "stop_time_allowed"};
      const bool is_string = kStrings.count(key.text) > 0;
      if (!is_string && kIntegers.count(key.text) == 0) {
        Fail(key,
             "expected a cmd attribute (exec, host, deputy, auto_respawn, stop_signal, "
             "stop_time_allowed)");
      }
      const std::string canonical = key.text == "deputy" ? "host" : key.text;
      if (!seen.insert(canonical).second) Fail(key, "attribute given twice");
      Expect(Tok::kAssign, "'=' after " + key.text);
      const Token value = is_string ? Expect(Tok::kString, "a \"string\" for " + key.text)
                                    : Expect(Tok::kInteger, "an integer for " + key.text);
      Expect(Tok::kSemicolon, "';' after " + key.text + " = ...");
      if (canonical == "exec") {
        cmd.exec = value.text;
      } else if (canonical == "host") {
        cmd.host = value.text;
      } else if (canonical == "auto_respawn") {
        if (value.text != "true" && value.text != "false") {
          Fail(value, "expected auto_respawn = \"true\" or \"false\"");
        }
        cmd.auto_respawn = value.text == "true";
      } else if (canonical == "group") {
        // libbot2 writes the group as an attribute in files it saves.
        if (!group.empty() && value.text != group) {
          Fail(value, "expected no group attribute inside group \"" + group + "\"");
        }
        cmd.group = value.text;
      } else {
        const long v = std::stol(value.text.substr(0, 9));
        if (canonical == "stop_signal") {
          if (v < 1 || v > 64) Fail(value, "expected a signal number 1..64 for stop_signal");
          cmd.stop_signal = static_cast<int>(v);
        } else {
          if (v < 1) Fail(value, "expected stop_time_allowed >= 1 (seconds)");
          cmd.stop_time_allowed_s = static_cast<double>(v);
        }
      }
    }
    Expect(Tok::kClose, "a cmd attribute or '}'");
    if (cmd.exec.empty()) FailAt(at.line, "cmd \"" + cmd.name + "\" has no exec = \"...\";");
    if (cmd.host.empty()) {
      FailAt(at.line, "cmd \"" + cmd.name + "\" has no host = \"...\"; (the deputy to run it)");
    }
    if (!named) cmd.name = cmd.exec;
    if (!cmd.group.empty()) AddGroup(cmd.group);
    config_.commands.push_back(cmd);
  }

  void AddGroup(const std::string& path) {
    size_t slash = 0;
    while ((slash = path.find('/', slash + 1)) != std::string::npos) {
      AddGroup(path.substr(0, slash));
    }
    for (const std::string& g : config_.groups) {
      if (g == path) return;
    }
    config_.groups.push_back(path);
  }

  void ParseGroup(const std::string& parent) {
    const Token name = Expect(Tok::kString, "a group name (\"name\")");
    if (name.text.find('/') != std::string::npos) Fail(name, "'/' is not allowed in a group name");
    if (name.text.empty()) Fail(name, "expected a non-empty group name");
    const std::string path = parent.empty() ? name.text : parent + "/" + name.text;
    AddGroup(path);
    Expect(Tok::kOpen, "'{' after group \"" + name.text + "\"");
    while (next_.type == Tok::kIdent) {
      const Token t = Take();
      if (t.text == "cmd") {
        ParseCommand(path, t);
      } else if (t.text == "group") {
        ParseGroup(path);
      } else {
        Fail(t, "expected 'cmd', 'group' or '}' in group \"" + path + "\"");
      }
    }
    Expect(Tok::kClose, "'cmd', 'group' or '}' in group \"" + path + "\"");
  }

  std::string ExpectStatus() {
    const Token s = Expect(Tok::kString, "\"running\" or \"stopped\"");
    if (s.text != "running" && s.text != "stopped") Fail(s, "expected \"running\" or \"stopped\"");
    return s.text;
  }

  void ParseScript(const Token& at) {
    ScriptConfig script;
    script.line = at.line;
    script.name = Expect(Tok::kString, "a script name (\"name\")").text;
    if (config_.FindScript(script.name) != nullptr) {
      FailAt(at.line, "script \"" + script.name + "\" is defined twice");
    }
    Expect(Tok::kOpen, "'{' after script \"" + script.name + "\"");
    while (next_.type == Tok::kIdent) {
      const Token t = Take();
      ScriptAction a;
      a.line = t.line;
      if (t.text == "start" || t.text == "stop" || t.text == "restart") {
        a.kind = t.text == "start"  ? ActionKind::kStart
                 : t.text == "stop" ? ActionKind::kStop
                                    : ActionKind::kRestart;
        const Token what = Expect(Tok::kIdent, "'cmd', 'group' or 'everything'");
        if (what.text == "everything") {
          a.target = TargetKind::kEverything;
        } else if (what.text == "cmd" || what.text == "group") {
          a.target = what.text == "cmd" ? TargetKind::kCmd : TargetKind::kGroup;
          a.ident = Expect(Tok::kString, "the " + what.text + "'s name (\"name\")").text;
        } else {
          Fail(what, "expected 'cmd', 'group' or 'everything'");
        }
        if (!Accept(Tok::kSemicolon)) {
          if (next_.type != Tok::kIdent || next_.text != "wait") {
            Fail(next_, "expected ';' or 'wait'");
          }
          Take();
          a.wait_status = ExpectStatus();
          Expect(Tok::kSemicolon, "';'");
        }
      } else if (t.text == "wait") {
        const Token what = Expect(Tok::kIdent, "'ms', 'cmd' or 'group' after wait");
        if (what.text == "ms") {
          a.kind = ActionKind::kWaitMs;
          const Token ms = Expect(Tok::kInteger, "a number of milliseconds");
          a.wait_ms = static_cast<int>(std::stol(ms.text.substr(0, 9)));
        } else if (what.text == "cmd" || what.text == "group") {
          a.kind = ActionKind::kWaitStatus;
          a.target = what.text == "cmd" ? TargetKind::kCmd : TargetKind::kGroup;
          a.ident = Expect(Tok::kString, "the " + what.text + "'s name (\"name\")").text;
          const Token st = Expect(Tok::kIdent, "'status'");
          if (st.text != "status") Fail(st, "expected 'status'");
          a.wait_status = ExpectStatus();
        } else {
          Fail(what, "expected 'ms', 'cmd' or 'group' after wait");
        }
        Expect(Tok::kSemicolon, "';'");
      } else if (t.text == "run_script") {
        a.kind = ActionKind::kRunScript;
        a.ident = Expect(Tok::kString, "the script's name (\"name\")").text;
        Expect(Tok::kSemicolon, "';'");
      } else {
        Fail(t, "expected a script action (start, stop, restart, wait, run_script)");
      }
      script.actions.push_back(a);
    }
    Expect(Tok::kClose, "a script action (start, stop, restart, wait, run_script) or '}'");
    config_.scripts.push_back(script);
  }

  // What can only be checked once the whole file is read.
  void Check() const {
    std::set<std::string> paths;
    for (const CommandConfig& c : config_.commands) {
      if (!paths.insert(c.path()).second) {
        FailAt(c.line, "cmd \"" + c.path() + "\" is defined twice (names must be unique)");
      }
    }
    for (const CommandConfig& c : config_.commands) {
      for (const std::string& g : config_.groups) {
        if (g == c.path()) {
          FailAt(c.line, "\"" + g + "\" is both a cmd and a group (rename one)");
        }
      }
    }
    for (const ScriptConfig& s : config_.scripts) {
      for (const ScriptAction& a : s.actions) {
        const std::string where = "script \"" + s.name + "\"";
        if (a.kind == ActionKind::kRunScript) {
          if (config_.FindScript(a.ident) == nullptr) {
            FailAt(a.line, where + ": run_script \"" + a.ident + "\": no such script");
          }
          continue;
        }
        if (a.kind == ActionKind::kWaitMs || a.target == TargetKind::kEverything) continue;
        bool ambiguous = false;
        if (config_.Resolve(a.target, a.ident, &ambiguous).empty()) {
          const std::string kind = a.target == TargetKind::kCmd ? "cmd" : "group";
          FailAt(a.line, where + ": " + kind + " \"" + a.ident + "\" " +
                             (ambiguous ? "names several commands (write its group/name)"
                                        : "is not defined in this file"));
        }
      }
    }
    for (const ScriptConfig& s : config_.scripts) CheckNoCycle(s, {});
  }

  void CheckNoCycle(const ScriptConfig& s, std::vector<std::string> stack) const {
    for (const std::string& n : stack) {
      if (n == s.name) {
        std::string chain;
        for (const std::string& m : stack) chain += m + " -> ";
        FailAt(s.line, "run_script loop: " + chain + s.name);
      }
    }
    stack.push_back(s.name);
    for (const ScriptAction& a : s.actions) {
      if (a.kind == ActionKind::kRunScript) CheckNoCycle(*config_.FindScript(a.ident), stack);
    }
  }

  const std::string& text_;
  std::string file_;
  size_t pos_ = 0;
  int line_ = 1, column_ = 1;
  Token next_;
  ProcmanConfig config_;
};

}  // namespace

const ScriptConfig* ProcmanConfig::FindScript(const std::string& name) const {
  for (const ScriptConfig& s : scripts) {
    if (s.name == name) return &s;
  }
  return nullptr;
}

std::vector<size_t> ProcmanConfig::Resolve(TargetKind kind, const std::string& ident,
                                           bool* ambiguous) const {
  std::vector<size_t> out;
  if (ambiguous) *ambiguous = false;
  if (kind == TargetKind::kEverything) {
    for (size_t i = 0; i < commands.size(); ++i) out.push_back(i);
    return out;
  }
  if (kind == TargetKind::kGroup) {
    for (size_t i = 0; i < commands.size(); ++i) {
      const std::string& g = commands[i].group;
      if (g == ident || (g.size() > ident.size() && g.compare(0, ident.size(), ident) == 0 &&
                         g[ident.size()] == '/')) {
        out.push_back(i);
      }
    }
    return out;
  }
  for (size_t i = 0; i < commands.size(); ++i) {
    if (commands[i].path() == ident) return {i};
  }
  for (size_t i = 0; i < commands.size(); ++i) {
    if (commands[i].name == ident) out.push_back(i);
  }
  if (out.size() > 1) {
    if (ambiguous) *ambiguous = true;
    out.clear();
  }
  return out;
}

ProcmanConfig ParseProcmanConfig(const std::string& text, const std::string& file) {
  return Parser(text, file).Parse();
}

ProcmanConfig LoadProcmanConfig(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ConfigError("cannot read procman config '" + path + "' (check the path)");
  std::stringstream s;
  s << in.rdbuf();
  return ParseProcmanConfig(s.str(), path);
}

}  // namespace fl::procman
