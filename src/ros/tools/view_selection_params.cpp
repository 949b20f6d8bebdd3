// view_selection_params: every parameter of view_selection_node (and, under the same names, of
// select_views) with its default, written from the structs that hold the defaults. It writes
// config/view_selection.yaml and docs/parameters.md; a test fails when those files differ from
// what it writes, so the defaults live in one place.
#include "../../tools/command_line.h"

#include "view_selection/ros/parameter_docs.h"

#include <iostream>

using view_selection::tools::CommandLine;
using view_selection::tools::UsageError;

namespace {

const char* kUsage = R"(usage: view_selection_params --yaml | --markdown

Prints every parameter of view_selection_node with its default:
  --yaml       as config/view_selection.yaml (commented; the launch files load it)
  --markdown   as docs/parameters.md (a table per section)
)";

int run(int argc, char** argv) {
  const CommandLine cli(argc, argv, {}, {"yaml", "markdown", "help"});
  if (cli.flag("help")) {
    std::cout << kUsage;
    return 0;
  }
  if (cli.flag("yaml") == cli.flag("markdown"))
    throw UsageError("give exactly one of --yaml and --markdown (see --help)");
  std::cout << (cli.flag("yaml") ? view_selection::ros_node::parametersYaml()
                                 : view_selection::ros_node::parametersMarkdown());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return view_selection::tools::runTool("view_selection_params", [&] { return run(argc, argv); });
}
