// Parameters described once. Every config struct lists its parameters through visitParameters():
// the name (the node's ~parameter; select_views' option with '-' for '_'), the field that holds
// the default, the accepted range or choices and a one-line meaning. The node's loader, the
// command line of the tools, validation, selection.json's "params", the YAML check and the
// parameter docs are visitors over that one list, so a default is written in one place only.
#pragma once

#include "view_selection/core/exceptions.h"

#include <array>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace view_selection::core {

/// What a visitor learns about one parameter besides its value.
struct ParameterInfo {
  const char* name = "";
  const char* doc = "";  ///< one line, with the unit in brackets where there is one
  double min = 0.0;      ///< numbers: accepted range, inclusive
  double max = 0.0;
  std::vector<std::string> choices;  ///< strings: the accepted values (empty: any string)
};

/// Receives each parameter of a config with a reference to the field. A visitor may read the
/// value (to write or list it) or replace it (to load it); it must not keep the references.
class ParameterVisitor {
 public:
  virtual ~ParameterVisitor() = default;
  virtual void visit(const ParameterInfo& info, int& value) = 0;
  virtual void visit(const ParameterInfo& info, double& value) = 0;
  virtual void visit(const ParameterInfo& info, bool& value) = 0;
  virtual void visit(const ParameterInfo& info, std::string& value) = 0;
  /// A named group of parameters starts (e.g. a point source's own); visits until endGroup()
  /// belong to it. Readers that keep names flat may ignore groups.
  virtual void beginGroup(const char* /*name*/) {}
  virtual void endGroup() {}
  /// A heading for the parameters that follow, for documentation (the YAML file, the docs).
  virtual void section(const char* /*title*/) {}
};

/// An enumeration's names, in the order they are documented.
template <typename E, std::size_t N>
using EnumNames = std::array<std::pair<E, const char*>, N>;

template <typename E, std::size_t N>
const char* nameOf(E value, const EnumNames<E, N>& names) {
  for (const auto& [v, name] : names)
    if (v == value) return name;
  return "unknown";
}

/// The value named `text`; throws InvalidArgument listing the valid names otherwise.
template <typename E, std::size_t N>
E valueOf(const std::string& text, const EnumNames<E, N>& names, const char* what) {
  std::string valid;
  for (const auto& [v, name] : names) {
    if (text == name) return v;
    valid += (valid.empty() ? "" : ", ") + std::string(name);
  }
  throw InvalidArgument(std::string(what) + " must be one of " + valid + ", got '" + text + "'");
}

/// Visits an enumeration as a string with choices.
template <typename E, std::size_t N>
void visitChoice(ParameterVisitor& visitor, const char* name, E& value,
                 const EnumNames<E, N>& names, const char* doc) {
  ParameterInfo info;
  info.name = name;
  info.doc = doc;
  for (const auto& entry : names) info.choices.emplace_back(entry.second);
  std::string text = nameOf(value, names);
  visitor.visit(info, text);
  value = valueOf(text, names, name);
}

inline void visitInteger(ParameterVisitor& v, const char* name, int& value, double min, double max,
                         const char* doc) {
  v.visit(ParameterInfo{name, doc, min, max, {}}, value);
}
inline void visitReal(ParameterVisitor& v, const char* name, double& value, double min, double max,
                      const char* doc) {
  v.visit(ParameterInfo{name, doc, min, max, {}}, value);
}
inline void visitFlag(ParameterVisitor& v, const char* name, bool& value, const char* doc) {
  v.visit(ParameterInfo{name, doc, 0.0, 1.0, {}}, value);
}
inline void visitText(ParameterVisitor& v, const char* name, std::string& value,
                      std::vector<std::string> choices, const char* doc) {
  v.visit(ParameterInfo{name, doc, 0.0, 0.0, std::move(choices)}, value);
}

// ---------------------------------------------------------------------------------------------
// Values in force, as selection.json's "params" holds them.

/// One parameter and its value, or a named group of them.
struct Param {
  using Value = std::variant<bool, int, double, std::string>;
  std::string name;
  Value value;
  bool group = false;
  std::vector<Param> children;  ///< the group's parameters

  bool operator==(const Param& o) const {
    return name == o.name && value == o.value && group == o.group && children == o.children;
  }
};
using Params = std::vector<Param>;

/// The parameters of `config` with their current values, in visiting order.
template <typename Config>
Params paramsOf(Config config) {
  struct Writer : ParameterVisitor {
    std::vector<Params*> stack;
    void add(const ParameterInfo& info, Param::Value value) {
      Param p;
      p.name = info.name;
      p.value = std::move(value);
      stack.back()->push_back(std::move(p));
    }
    void visit(const ParameterInfo& i, int& v) override { add(i, v); }
    void visit(const ParameterInfo& i, double& v) override { add(i, v); }
    void visit(const ParameterInfo& i, bool& v) override { add(i, v); }
    void visit(const ParameterInfo& i, std::string& v) override { add(i, v); }
    void beginGroup(const char* name) override {
      Param g;
      g.name = name;
      g.group = true;
      stack.back()->push_back(std::move(g));
      stack.push_back(&stack.back()->back().children);
    }
    void endGroup() override { stack.pop_back(); }
  };
  Params out;
  Writer writer;
  writer.stack.push_back(&out);
  config.visitParameters(writer);
  return out;
}

/// Throws InvalidArgument naming the first parameter of `config` outside its range or choices.
template <typename Config>
void checkRanges(Config config);

/// The range check behind checkRanges, for use by other visitors.
class RangeChecker : public ParameterVisitor {
 public:
  void visit(const ParameterInfo& info, int& value) override;
  void visit(const ParameterInfo& info, double& value) override;
  void visit(const ParameterInfo& info, bool& value) override;
  void visit(const ParameterInfo& info, std::string& value) override;
};

template <typename Config>
void checkRanges(Config config) {
  RangeChecker checker;
  config.visitParameters(checker);
}

/// A number written as a person would (no trailing zeros): 0.1, 1e+09, 30.
std::string formatNumber(double value);

/// One parameter as the documentation shows it.
struct ParameterDoc {
  std::string section;  ///< the heading it falls under
  std::string name;
  std::string type;   ///< "int", "double", "bool", "string"
  std::string value;  ///< the default, as YAML writes it (doubles with a decimal point)
  std::string range;  ///< "1..1000", "paper | reachable", or ""
  std::string doc;
};

/// Every parameter of `config` with its default, in visiting order.
template <typename Config>
std::vector<ParameterDoc> describeParameters(Config config);

class ParameterDescriber : public ParameterVisitor {
 public:
  void visit(const ParameterInfo& info, int& value) override;
  void visit(const ParameterInfo& info, double& value) override;
  void visit(const ParameterInfo& info, bool& value) override;
  void visit(const ParameterInfo& info, std::string& value) override;
  void section(const char* title) override { section_ = title; }
  std::vector<ParameterDoc> docs;

 private:
  void add(const ParameterInfo& info, const char* type, std::string value, std::string range);
  std::string section_;
};

template <typename Config>
std::vector<ParameterDoc> describeParameters(Config config) {
  ParameterDescriber describer;
  config.visitParameters(describer);
  return describer.docs;
}

}  // namespace view_selection::core
