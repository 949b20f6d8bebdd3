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

}  // namespace view_selection::core
