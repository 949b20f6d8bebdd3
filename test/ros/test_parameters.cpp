// One source for every default: config/view_selection.yaml, docs/parameters.md and the
// dynamic_reconfigure defaults and ranges must be what the structs say. No ROS master needed.
#include "view_selection/core/parameters.h"
#include "view_selection/ros/live_reconfigure.h"
#include "view_selection/ros/node_config.h"
#include "view_selection/ros/parameter_docs.h"

#include <gtest/gtest.h>
#include <view_selection/ViewSelectionConfig.h>
#include <yaml-cpp/yaml.h>
#include <boost/any.hpp>

#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>

namespace {

using namespace view_selection;
using core::ParameterDoc;
namespace fs = std::filesystem;

std::string readFile(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

const fs::path kRoot(VIEW_SELECTION_SOURCE_DIR);

TEST(Parameters, TheYamlFileHoldsEveryParameterWithTheStructsDefault) {
  const YAML::Node yaml = YAML::LoadFile((kRoot / "config" / "view_selection.yaml").string());
  ASSERT_TRUE(yaml.IsMap());
  std::set<std::string> known;
  for (const ParameterDoc& d : core::describeParameters(ros_node::NodeConfig{})) {
    known.insert(d.name);
    ASSERT_TRUE(yaml[d.name]) << d.name << " is missing from config/view_selection.yaml";
    const std::string value = yaml[d.name].as<std::string>();
    if (d.type == "double") {
      EXPECT_DOUBLE_EQ(yaml[d.name].as<double>(), std::stod(d.value)) << d.name;
    } else if (d.type == "string") {
      EXPECT_EQ(value, d.value == "\"\"" ? "" : d.value) << d.name;
    } else {
      EXPECT_EQ(value, d.value) << d.name;
    }
  }
  for (const auto& entry : yaml)
    EXPECT_TRUE(known.count(entry.first.as<std::string>()))
        << entry.first.as<std::string>()
        << " in config/view_selection.yaml is no parameter of the node";
  EXPECT_TRUE(readFile(kRoot / "config" / "view_selection.yaml") == ros_node::parametersYaml())
      << "config/view_selection.yaml is not what the structs say; regenerate it: "
         "view_selection_params --yaml > config/view_selection.yaml";
}

TEST(Parameters, TheDocsAreWrittenFromTheStructs) {
  EXPECT_TRUE(readFile(kRoot / "docs" / "parameters.md") == ros_node::parametersMarkdown())
      << "docs/parameters.md is not what the structs say; regenerate it: "
         "view_selection_params --markdown > docs/parameters.md";
}

TEST(Parameters, TheNodeDocsTableIsWrittenFromTheStructs) {
  const std::string node_md = readFile(kRoot / "docs" / "node.md");
  ASSERT_NE(node_md.find(ros_node::kNodeTableBegin), std::string::npos)
      << "docs/node.md lost the line " << ros_node::kNodeTableBegin;
  EXPECT_TRUE(node_md == ros_node::withNodeTable(node_md))
      << "docs/node.md's parameter table is not what the structs say; regenerate it: "
         "view_selection_params --write-docs .";
  // The table names every parameter with its default (a stale default, such as completion
  // paper or min_covisible_ratio 0.1 once, fails here).
  for (const ParameterDoc& d : core::describeParameters(ros_node::NodeConfig{}))
    EXPECT_NE(ros_node::parametersNodeTable().find("`" + d.name + ": " + d.value + "`"),
              std::string::npos)
        << d.name;
  // Splicing keeps the hand-written text around the table and only that.
  const std::string spliced =
      ros_node::withNodeTable(std::string("before\n") + ros_node::kNodeTableBegin + "\nold\n" +
                              ros_node::kNodeTableEnd + "\nafter\n");
  EXPECT_EQ(spliced, "before\n" + ros_node::parametersNodeTable() + "after\n");
  EXPECT_THROW(ros_node::withNodeTable("no markers\n"), std::runtime_error);
}

/// Each parameter's range, by name.
std::map<std::string, std::pair<double, double>> ranges() {
  struct Ranges : core::ParameterVisitor {
    std::map<std::string, std::pair<double, double>> out;
    void visit(const core::ParameterInfo& i, int&) override { out[i.name] = {i.min, i.max}; }
    void visit(const core::ParameterInfo& i, double&) override { out[i.name] = {i.min, i.max}; }
    void visit(const core::ParameterInfo&, bool&) override {}
    void visit(const core::ParameterInfo&, std::string&) override {}
  } r;
  ros_node::NodeConfig().visitParameters(r);
  return r.out;
}

double number(const boost::any& value) {
  if (value.type() == typeid(int)) return boost::any_cast<int>(value);
  return boost::any_cast<double>(value);
}

TEST(Parameters, ReconfigureDefaultsAndRangesAreTheStructs) {
  using Config = view_selection::ViewSelectionConfig;
  // Defaults: the .cfg's, read into a NodeConfig, equal the struct's.
  ros_node::NodeConfig from_cfg;
  ros_node::fromReconfigure(Config::__getDefault__(), from_cfg);
  EXPECT_EQ(core::paramsOf(from_cfg), core::paramsOf(ros_node::NodeConfig{}));
  // And every value the node can hold survives the round trip.
  ros_node::NodeConfig changed;
  changed.selector.selection.k = 7;
  changed.selector.selection.completion = core::CompletionMode::kReachable;
  changed.selector.keyframes.mode = core::KeyframeMode::kEveryNth;
  changed.publish_period = 2.5;
  changed.selector.matrix.gate = core::Gate::kPaper;
  changed.selector.matrix.max_parallax_deg = 25.0;
  ros_node::NodeConfig back;
  ros_node::fromReconfigure(ros_node::toReconfigure(changed), back);
  EXPECT_EQ(core::paramsOf(back), core::paramsOf(changed));
  // Ranges of the numbers, names of the choices.
  const auto range = ranges();
  const std::map<std::string, std::string> choices = {
      {"completion", "paper reachable"},
      {"keyframe_policy", "every_frame every_nth motion"},
      {"gate", "paper matchable"}};
  for (const auto& description : Config::__getParamDescriptions__()) {
    const std::string& name = description->name;
    if (description->type == "str") {
      EXPECT_TRUE(choices.count(name)) << name;
      continue;
    }
    ASSERT_TRUE(range.count(name))
        << name << " in cfg/ViewSelection.cfg is no parameter of the node";
    boost::any lo, hi;
    description->getValue(Config::__getMin__(), lo);
    description->getValue(Config::__getMax__(), hi);
    EXPECT_DOUBLE_EQ(number(lo), range.at(name).first) << name;
    EXPECT_DOUBLE_EQ(number(hi), range.at(name).second) << name;
  }
}

}  // namespace
