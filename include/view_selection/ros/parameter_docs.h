// The parameter documentation written from the structs (core/parameters.h): the commented YAML
// that the launch files load, the Markdown tables in docs/parameters.md and the overview table in
// docs/node.md. Tests compare the files with these, so a default is written in its struct and
// nowhere else.
#pragma once

#include <string>

namespace view_selection::ros_node {

/// config/view_selection.yaml: every parameter with its default, by section, commented.
std::string parametersYaml();
/// docs/parameters.md: a table per section (parameter, type, default, range, meaning).
std::string parametersMarkdown();

/// docs/node.md's parameter overview: a row per section with its parameters and their defaults,
/// from the line kNodeTableBegin to the line kNodeTableEnd (both included).
std::string parametersNodeTable();
inline constexpr const char* kNodeTableBegin =
    "<!-- parameters: written by `view_selection_params --write-docs .`; test_parameters checks "
    "it -->";
inline constexpr const char* kNodeTableEnd = "<!-- end of the parameters -->";
/// `node_md` (docs/node.md) with its overview replaced by parametersNodeTable(); throws
/// std::runtime_error when it has no kNodeTableBegin ... kNodeTableEnd lines.
std::string withNodeTable(const std::string& node_md);

}  // namespace view_selection::ros_node
