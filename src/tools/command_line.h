// A small command-line parser for the offline tools: "--name value", "--name=value" and flags,
// with one clear error message for every mistake, and runTool, the tools' common main. Header-only.
#pragma once

#include "view_selection/core/exceptions.h"

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

/// A tool's main: runs `body`, and turns what it throws into one line on stderr and the exit
/// code: 2 for a usage mistake, 1 for an error (view_selection::Error or anything else).
template <typename Body>
int runTool(const char* name, Body body) {
  try {
    return body();
  } catch (const UsageError& e) {
    std::fprintf(stderr, "%s: %s\n", name, e.what());
    return 2;
  } catch (const Error& e) {
    std::fprintf(stderr, "%s: error: %s\n", name, e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: unexpected error: %s\n", name, e.what());
    return 1;
  }
}

}  // namespace view_selection::tools
