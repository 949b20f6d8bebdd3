#include "view_selection/ros/parameter_docs.h"

#include "view_selection/core/parameters.h"
#include "view_selection/ros/node_config.h"

#include <algorithm>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace view_selection::ros_node {

using core::ParameterDoc;

namespace {

std::vector<ParameterDoc> docs() { return core::describeParameters(NodeConfig{}); }

}  // namespace

std::string parametersYaml() {
  std::ostringstream out;
  out << "# view_selection_node parameters (private, ~name). Every value here is the default, as "
         "the\n"
         "# node's structs hold it: this file is written by `rosrun view_selection "
         "view_selection_params\n"
         "# --yaml`, and a test fails when the two differ. select_views takes the same names as "
         "options\n"
         "# (--name-with-dashes); docs/parameters.md has the ranges. Loaded by launch/*.launch.\n";
  std::string section;
  for (const ParameterDoc& d : docs()) {
    if (d.section != section) {
      section = d.section;
      std::string rule = "# --- " + section + " ";
      rule.resize(std::max<size_t>(rule.size(), 99), '-');
      out << "\n" << rule << "\n";
    }
    std::string line = d.name + ": " + d.value;
    line.resize(std::max<size_t>(line.size() + 1, 34), ' ');
    out << line << "# " << d.doc
        << (d.type == "string" && !d.range.empty() ? " (" + d.range + ")" : "") << "\n";
  }
  return out.str();
}

std::string parametersMarkdown() {
  std::ostringstream out;
  out << "# Parameters\n\n"
         "Every parameter of `view_selection_node` (private, `~name`) with its default and range. "
         "`select_views` takes\nthe same names as options, `_` written `-` (`--min-covisible-ratio "
         "0.5`). "
         "Written by\n`rosrun view_selection view_selection_params --markdown` from the structs "
         "that hold "
         "the defaults;\n`config/view_selection.yaml` is written the same way. Live changes: "
         "`cfg/ViewSelection.cfg`.\n";
  std::string section;
  for (const ParameterDoc& d : docs()) {
    if (d.section != section) {
      section = d.section;
      out << "\n## " << section
          << "\n\n| parameter | type | default | range | meaning |\n|---|---|---|---|---|\n";
    }
    std::string doc = d.doc;
    for (size_t at = doc.find('|'); at != std::string::npos; at = doc.find('|', at + 2))
      doc.replace(at, 1, "\\|");
    std::string range = d.range;
    for (size_t at = range.find('|'); at != std::string::npos; at = range.find('|', at + 2))
      range.replace(at, 1, "\\|");
    out << "| `" << d.name << "` | " << d.type << " | `" << d.value << "` | " << range << " | "
        << doc << " |\n";
  }
  return out.str();
}

std::string parametersNodeTable() {
  std::ostringstream out;
  out << kNodeTableBegin << "\n| section | parameters (defaults) |\n|---|---|\n";
  std::string section;
  bool first = true;
  for (const ParameterDoc& d : docs()) {
    if (d.section != section) {
      if (!section.empty()) out << " |\n";
      section = d.section;
      out << "| " << section << " | ";
      first = true;
    }
    out << (first ? "" : ", ") << "`" << d.name << ": " << d.value << "`";
    first = false;
  }
  if (!section.empty()) out << " |\n";
  out << kNodeTableEnd << "\n";
  return out.str();
}

std::string withNodeTable(const std::string& node_md) {
  const size_t begin = node_md.find(kNodeTableBegin);
  const size_t end = node_md.find(kNodeTableEnd);
  if (begin == std::string::npos || end == std::string::npos || end < begin)
    throw std::runtime_error(
        std::string("docs/node.md has no parameter table between the lines '") + kNodeTableBegin +
        "' and '" + kNodeTableEnd + "'");
  size_t after = end + std::string(kNodeTableEnd).size();
  if (after < node_md.size() && node_md[after] == '\n') ++after;
  return node_md.substr(0, begin) + parametersNodeTable() + node_md.substr(after);
}

}  // namespace view_selection::ros_node
