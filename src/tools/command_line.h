// A small command-line parser for the offline tools: "--name value", "--name=value" and flags,
// with one clear error message for every mistake, and runTool, the tools' common main. Header-only.
#pragma once

#include "view_selection/core/exceptions.h"
#include "view_selection/core/parameters.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace view_selection::tools {

/// A user mistake on the command line; the message is meant to be printed as is.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class CommandLine {
 public:
  /// `options` take a value, `flags` do not. Anything else is an error.
  CommandLine(int argc, char** argv, const std::set<std::string>& options,
              const std::set<std::string>& flags) {
    for (int q = 1; q < argc; ++q) {
      std::string arg = argv[q];
      if (arg == "-h") arg = "--help";
      if (arg.rfind("--", 0) != 0)
        throw UsageError("unexpected argument '" + arg + "' (options start with --; see --help)");
      std::string name = arg.substr(2), value;
      const size_t eq = name.find('=');
      const bool inline_value = eq != std::string::npos;
      if (inline_value) {
        value = name.substr(eq + 1);
        name = name.substr(0, eq);
      }
      if (flags.count(name)) {
        if (inline_value) throw UsageError("--" + name + " takes no value");
        flags_.insert(name);
      } else if (options.count(name)) {
        if (!inline_value) {
          if (q + 1 >= argc) throw UsageError("--" + name + " needs a value");
          value = argv[++q];
        }
        if (values_.count(name)) throw UsageError("--" + name + " given twice");
        values_[name] = value;
      } else {
        throw UsageError("unknown option '--" + name + "' (see --help)");
      }
    }
  }

  bool flag(const std::string& name) const { return flags_.count(name) > 0; }
  bool has(const std::string& name) const { return values_.count(name) > 0; }

  std::string text(const std::string& name, const std::string& fallback) const {
    const auto it = values_.find(name);
    return it == values_.end() ? fallback : it->second;
  }
  std::optional<std::string> text(const std::string& name) const {
    const auto it = values_.find(name);
    return it == values_.end() ? std::nullopt : std::optional<std::string>(it->second);
  }

  long integer(const std::string& name, long fallback, long min, long max) const {
    const auto it = values_.find(name);
    if (it == values_.end()) return fallback;
    char* end = nullptr;
    const long v = std::strtol(it->second.c_str(), &end, 10);
    if (it->second.empty() || *end != '\0')
      throw UsageError("--" + name + " expects an integer, got '" + it->second + "'");
    if (v < min || v > max)
      throw UsageError("--" + name + " must be between " + std::to_string(min) + " and " +
                       std::to_string(max) + ", got " + it->second);
    return v;
  }

  double real(const std::string& name, double fallback, double min, double max) const {
    const auto it = values_.find(name);
    if (it == values_.end()) return fallback;
    char* end = nullptr;
    const double v = std::strtod(it->second.c_str(), &end);
    if (it->second.empty() || *end != '\0' || !std::isfinite(v))
      throw UsageError("--" + name + " expects a number, got '" + it->second + "'");
    if (v < min || v > max)
      throw UsageError("--" + name + " must be between " + trim(min) + " and " + trim(max) +
                       ", got " + it->second);
    return v;
  }

  /// One of `choices`.
  std::string choice(const std::string& name, const std::string& fallback,
                     const std::vector<std::string>& choices) const {
    const std::string v = text(name, fallback);
    for (const auto& c : choices)
      if (c == v) return v;
    std::string list;
    for (const auto& c : choices) list += (list.empty() ? "" : "|") + c;
    throw UsageError("--" + name + " must be " + list + ", got '" + v + "'");
  }

 private:
  static std::string trim(double v) {
    std::string s = std::to_string(v);
    while (!s.empty() && s.back() == '0') s.pop_back();
    if (!s.empty() && s.back() == '.') s.pop_back();
    return s;
  }

  std::map<std::string, std::string> values_;
  std::set<std::string> flags_;
};

/// Option name of a parameter: "min_covisible_ratio" -> "min-covisible-ratio".
inline std::string optionName(const std::string& parameter) {
  std::string name = parameter;
  for (char& c : name)
    if (c == '_') c = '-';
  return name;
}

/// The option names of every parameter a config lists (core/parameters.h).
template <typename Config>
std::set<std::string> parameterOptions(Config config) {
  struct Names : core::ParameterVisitor {
    std::set<std::string> names;
    void add(const core::ParameterInfo& i) { names.insert(optionName(i.name)); }
    void visit(const core::ParameterInfo& i, int&) override { add(i); }
    void visit(const core::ParameterInfo& i, double&) override { add(i); }
    void visit(const core::ParameterInfo& i, bool&) override { add(i); }
    void visit(const core::ParameterInfo& i, std::string&) override { add(i); }
  } names;
  config.visitParameters(names);
  return names.names;
}

/// Sets every parameter of `config` given on the command line as --option-name VALUE (booleans
/// as true/false), with the documented range; the rest keep their defaults. Throws UsageError.
template <typename Config>
void readParameters(const CommandLine& cli, Config& config) {
  struct Reader : core::ParameterVisitor {
    const CommandLine& cli;
    explicit Reader(const CommandLine& c) : cli(c) {}
    void visit(const core::ParameterInfo& i, int& v) override {
      v = static_cast<int>(
          cli.integer(optionName(i.name), v, static_cast<long>(i.min), static_cast<long>(i.max)));
    }
    void visit(const core::ParameterInfo& i, double& v) override {
      v = cli.real(optionName(i.name), v, i.min, i.max);
    }
    void visit(const core::ParameterInfo& i, bool& v) override {
      const std::string name = optionName(i.name);
      const std::string text = cli.choice(name, v ? "true" : "false", {"true", "false"});
      v = text == "true";
    }
    void visit(const core::ParameterInfo& i, std::string& v) override {
      v = i.choices.empty() ? cli.text(optionName(i.name), v)
                            : cli.choice(optionName(i.name), v, i.choices);
    }
  } reader(cli);
  config.visitParameters(reader);
}

/// "  --option VALUE   meaning (default: x; range or choices)" for every parameter of `config`.
template <typename Config>
std::string parameterHelp(Config config) {
  struct Help : core::ParameterVisitor {
    std::string text;
    void line(const core::ParameterInfo& i, const std::string& value, const std::string& range) {
      std::string head = "  --" + optionName(i.name) + " " +
                         (i.choices.empty() ? std::string("X") : "{" + join(i.choices, "|") + "}");
      if (head.size() < 34) head.resize(34, ' ');
      text +=
          head + " " + i.doc + " (default " + value + (range.empty() ? "" : "; " + range) + ")\n";
    }
    static std::string join(const std::vector<std::string>& list, const char* sep) {
      std::string out;
      for (const auto& s : list) out += (out.empty() ? "" : sep) + s;
      return out;
    }
    static std::string range(const core::ParameterInfo& i) {
      return core::formatNumber(i.min) + ".." + core::formatNumber(i.max);
    }
    void visit(const core::ParameterInfo& i, int& v) override {
      line(i, std::to_string(v), range(i));
    }
    void visit(const core::ParameterInfo& i, double& v) override {
      line(i, core::formatNumber(v), range(i));
    }
    void visit(const core::ParameterInfo& i, bool& v) override {
      line(i, v ? "true" : "false", "");
    }
    void visit(const core::ParameterInfo& i, std::string& v) override { line(i, v, ""); }
  } help;
  config.visitParameters(help);
  return help.text;
}

/// A tool's main: runs `body`, and turns what it throws into one line on stderr and the exit
/// code: 2 for a usage mistake, 1 for an error (view_selection::Error or anything else).
template <typename Body>
int runTool(const char* name, Body body) {
  try {
    return body();
  } catch (const UsageError& e) {
    std::fprintf(stderr, "%s: %s\n", name, e.what());
    return 2;
  } catch (const core::Error& e) {
    std::fprintf(stderr, "%s: error: %s\n", name, e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: unexpected error: %s\n", name, e.what());
    return 1;
  }
}

}  // namespace view_selection::tools
