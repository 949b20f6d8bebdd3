// selection.json's "params" object from the core's parameter list (core/parameters.h).
#pragma once

#include "view_selection/core/parameters.h"

#include <nlohmann/json.hpp>

namespace view_selection::io {

/// An object with one key per parameter, in order; groups become nested objects.
nlohmann::json toJson(const core::Params& params);

}  // namespace view_selection::io
