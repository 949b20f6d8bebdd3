// view_selection_params: every parameter of view_selection_node (and, under the same names, of
// select_views) with its default, written from the structs that hold the defaults. It writes
// config/view_selection.yaml, docs/parameters.md and the parameter overview in docs/node.md; a
// test fails when those files differ from what it writes, so the defaults live in one place.
#include "../command_line.h"

#include "view_selection/ros/parameter_docs.h"

#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

using view_selection::tools::CommandLine;
using view_selection::tools::UsageError;

namespace {

const char* kUsage = R"(usage: view_selection_params --yaml | --markdown | --node-table
       view_selection_params --write-docs PACKAGE_DIR

Prints every parameter of view_selection_node with its default:
  --yaml         as config/view_selection.yaml (commented; the launch files load it)
  --markdown     as docs/parameters.md (a table per section)
  --node-table   as the overview in docs/node.md (a row per section)
Or writes all three into the package's source folder:
  --write-docs PACKAGE_DIR   config/view_selection.yaml, docs/parameters.md, and the overview
                             between its marker lines in docs/node.md (the rest is kept)
)";

namespace fs = std::filesystem;

std::string readFile(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw UsageError("cannot read " + path.string() + " (is it the package folder?)");
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

void writeFile(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::trunc);
  out << text;
  if (!out.flush()) throw UsageError("cannot write " + path.string());
  std::cout << "wrote " << path.string() << "\n";
}

int run(int argc, char** argv) {
  using namespace view_selection::ros_node;
  const CommandLine cli(argc, argv, {"write-docs"}, {"yaml", "markdown", "node-table", "help"});
  if (cli.flag("help")) {
    std::cout << kUsage;
    return 0;
  }
  const int given =
      cli.flag("yaml") + cli.flag("markdown") + cli.flag("node-table") + cli.has("write-docs");
  if (given != 1)
    throw UsageError(
        "give exactly one of --yaml, --markdown, --node-table and --write-docs (see --help)");
  if (cli.has("write-docs")) {
    const fs::path dir = cli.text("write-docs", "");
    const std::string node_md = withNodeTable(readFile(dir / "docs" / "node.md"));
    readFile(dir / "config" / "view_selection.yaml");  // the right folder, before writing any
    writeFile(dir / "config" / "view_selection.yaml", parametersYaml());
    writeFile(dir / "docs" / "parameters.md", parametersMarkdown());
    writeFile(dir / "docs" / "node.md", node_md);
    return 0;
  }
  std::cout << (cli.flag("yaml")       ? parametersYaml()
                : cli.flag("markdown") ? parametersMarkdown()
                                       : parametersNodeTable());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return view_selection::tools::runTool("view_selection_params", [&] { return run(argc, argv); });
}
