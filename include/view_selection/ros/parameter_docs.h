// The parameter documentation written from the structs (core/parameters.h): the commented YAML
// that the launch files load and the Markdown table in docs/parameters.md. Tests compare both
// files with these, so a default is written in its struct and nowhere else.
#pragma once

#include <string>

namespace view_selection::ros_node {

/// config/view_selection.yaml: every parameter with its default, by section, commented.
std::string parametersYaml();
/// docs/parameters.md: a table per section (parameter, type, default, range, meaning).
std::string parametersMarkdown();

}  // namespace view_selection::ros_node
