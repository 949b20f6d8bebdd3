#include "view_selection/core/parameters.h"

#include <cmath>
#include <sstream>

namespace view_selection::core {

namespace {

[[noreturn]] void outOfRange(const ParameterInfo& info, double value) {
  throw InvalidArgument(std::string(info.name) + " = " + formatNumber(value) +
                        " is out of range [" + formatNumber(info.min) + ", " +
                        formatNumber(info.max) + "]");
}

}  // namespace

std::string formatNumber(double value) {
  std::ostringstream s;
  s.precision(15);
  s << value;
  return s.str();
}

void RangeChecker::visit(const ParameterInfo& info, int& value) {
  if (value < info.min || value > info.max) outOfRange(info, value);
}

void RangeChecker::visit(const ParameterInfo& info, double& value) {
  if (!std::isfinite(value) || value < info.min || value > info.max) outOfRange(info, value);
}

void RangeChecker::visit(const ParameterInfo&, bool&) {}

void RangeChecker::visit(const ParameterInfo& info, std::string& value) {
  if (info.choices.empty()) return;
  std::string valid;
  for (const auto& c : info.choices) {
    if (c == value) return;
    valid += (valid.empty() ? "" : ", ") + c;
  }
  throw InvalidArgument(std::string(info.name) + " = '" + value + "' is not one of: " + valid);
}

void ParameterDescriber::add(const ParameterInfo& info, const char* type, std::string value,
                             std::string range) {
  docs.push_back({section_, info.name, type, std::move(value), std::move(range), info.doc});
}

void ParameterDescriber::visit(const ParameterInfo& info, int& value) {
  add(info, "int", std::to_string(value), formatNumber(info.min) + ".." + formatNumber(info.max));
}

void ParameterDescriber::visit(const ParameterInfo& info, double& value) {
  std::string text = formatNumber(value);
  if (text.find_first_of(".e") == std::string::npos) text += ".0";  // YAML reads "10" as an int
  add(info, "double", text, formatNumber(info.min) + ".." + formatNumber(info.max));
}

void ParameterDescriber::visit(const ParameterInfo& info, bool& value) {
  add(info, "bool", value ? "true" : "false", "");
}

void ParameterDescriber::visit(const ParameterInfo& info, std::string& value) {
  std::string range;
  for (const auto& c : info.choices) range += (range.empty() ? "" : " | ") + c;
  add(info, "string", value.empty() ? "\"\"" : value, range);
}

}  // namespace view_selection::core
