#include "view_selection/io/params_json.h"

#include <variant>

namespace view_selection::io {

nlohmann::json toJson(const core::Params& params) {
  nlohmann::json out = nlohmann::json::object();
  for (const core::Param& p : params) {
    if (p.group) {
      out[p.name] = toJson(p.children);
      continue;
    }
    std::visit([&](const auto& value) { out[p.name] = value; }, p.value);
  }
  return out;
}

}  // namespace view_selection::io
