// The layers depend downwards only (docs/architecture.md): the core on Eigen alone; the point
// sources and the files on neither each other nor ROS, the saved session above both; the
// built-in sequence and the evaluation on no ROS; nothing ROS-free on the ROS layer. Checked on
// the sources' #include lines and the libraries' links, so a wrong include fails here first;
// and no code outside the point-source factory casts to a concrete point source.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <regex>
#include <set>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

const std::string kRosHeaders =
    R"((ros/|roscpp|rosbag|tf2|tf/|sensor_msgs|geometry_msgs|std_msgs|std_srvs|nav_msgs|)"
    R"(visualization_msgs|diagnostic_|dynamic_reconfigure|cv_bridge|image_transport|message_filters|)"
    R"(nodelet|pluginlib|view_selection/ros/|view_selection/[A-Z]))";

/// Lines of files under `dirs` (but not under `skip`) whose #include matches `forbidden`, as
/// "file:line: text".
std::string offences(const std::vector<std::string>& dirs, const std::string& forbidden, int* files,
                     const std::vector<std::string>& skip = {}) {
  const fs::path root(VIEW_SELECTION_SOURCE_DIR);
  const std::regex include(R"(^\s*#\s*include\s*[<"])" + forbidden);
  std::string out;
  for (const std::string& dir : dirs) {
    if (!fs::exists(root / dir)) continue;
    for (auto it = fs::recursive_directory_iterator(root / dir);
         it != fs::recursive_directory_iterator(); ++it) {
      const fs::directory_entry& entry = *it;
      if (entry.is_directory() &&
          std::find(skip.begin(), skip.end(), entry.path().lexically_relative(root).string()) !=
              skip.end()) {
        it.disable_recursion_pending();
        continue;
      }
      if (!entry.is_regular_file()) continue;
      ++*files;
      std::ifstream in(entry.path());
      std::string line;
      for (int number = 1; std::getline(in, line); ++number)
        if (std::regex_search(line, include))
          out += entry.path().string() + ":" + std::to_string(number) + ": " + line + "\n";
    }
  }
  return out;
}

TEST(CoreIsRosFree, NoRosIncludeInCoreOrTools) {
  // Every tool lives in src/tools; those that write bags or list the node's parameters are in
  // src/tools/ros, the offline ones beside it are ROS-free.
  int files = 0;
  const std::string found = offences({"include/view_selection/core", "src/core", "src/tools"},
                                     kRosHeaders, &files, {"src/tools/ros"});
  EXPECT_GT(files, 10);  // the walk found the sources
  EXPECT_TRUE(found.empty()) << "ROS includes in the ROS-free core:\n" << found;
  // The skipped folder is where the ROS tools are (a walk that skipped nothing would pass too).
  int ros_tools = 0;
  EXPECT_FALSE(offences({"src/tools/ros"}, kRosHeaders, &ros_tools).empty());
  EXPECT_FALSE(fs::exists(fs::path(VIEW_SELECTION_SOURCE_DIR) / "src/ros/tools"))
      << "tools live in one tree, src/tools";
}

/// Each layer -> what its sources must not include (docs/architecture.md, bottom up: core;
/// images; points and io, which know nothing of each other; session above both; sim and eval;
/// ros and the tools).
const std::map<std::string, std::string>& includeRules() {
  static const std::map<std::string, std::string> rules = {
      {"core",
       R"((opencv2|ceres|nlohmann|yaml-cpp|view_selection/(images|points|io|session|sim|eval|refine|odometry|registration|ros)/)|)" +
           kRosHeaders},
      {"images",
       R"((ceres|nlohmann|yaml-cpp|opencv2/(features2d|calib3d|imgcodecs)|)"
       R"(view_selection/(points|io|session|sim|eval|refine|odometry|registration|ros)/)|)" +
           kRosHeaders},
      {"points",
       R"((nlohmann|yaml-cpp|view_selection/(io|session|sim|eval|refine|odometry|registration|ros)/)|)" +
           kRosHeaders},
      // The file formats need neither the point sources nor Ceres: the point sources' state in
      // the state file is session's.
      {"io",
       R"((ceres|opencv2/features2d|view_selection/(points|session|sim|eval|refine|odometry|registration|ros)/)|)" +
           kRosHeaders},
      {"session",
       R"((view_selection/(sim|eval|refine|odometry|registration|ros)/)|)" + kRosHeaders},
      {"sim",
       R"((view_selection/(session|eval|refine|odometry|registration|ros)/)|)" + kRosHeaders},
      {"eval",
       R"((view_selection/(session|sim|refine|odometry|registration|ros)/)|)" + kRosHeaders},
      // refine: a known-pose COLMAP model bundle-adjusted (Ceres) on io's model files, for the
      // tools
      {"refine",
       R"((opencv2|view_selection/(images|points|session|sim|odometry|registration|ros)/)|)" +
           kRosHeaders},
      // odometry: OpenCV's RGB-D odometry as a drifting SLAM stand-in, on the core's types
      {"odometry",
       R"((ceres|nlohmann|yaml-cpp|view_selection/(points|io|session|sim|eval|refine|registration|ros)/)|)" +
           kRosHeaders},
      // registration: a frame registered to an earlier keyframe from the images (ORB, PnP), on
      // the core's interface; the node and select_views give it to the selector
      {"registration",
       R"((ceres|nlohmann|yaml-cpp|view_selection/(points|io|session|sim|eval|refine|odometry|ros)/)|)" +
           kRosHeaders},
  };
  return rules;
}

TEST(Layers, EachLayerIncludesOnlyTheLayersBelowIt) {
  for (const auto& [layer, forbidden] : includeRules()) {
    int files = 0;
    const std::string found = offences({"include/view_selection/" + layer, "src/" + layer},
                                       "(" + forbidden + ")", &files);
    EXPECT_GE(files, 2) << layer << ": no sources found";
    EXPECT_TRUE(found.empty()) << "layer " << layer << " includes what it must not:\n" << found;
  }
  // The rules catch what they are there for: io including a point source, or Ceres.
  const std::regex io(R"(^\s*#\s*include\s*[<"]()" + includeRules().at("io") + ")");
  EXPECT_TRUE(std::regex_search("#include \"view_selection/points/map_point_source.h\"", io));
  EXPECT_TRUE(std::regex_search("#include <ceres/ceres.h>", io));
  EXPECT_FALSE(std::regex_search("#include \"view_selection/images/image_conversion.h\"", io));
}

/// The view_selection_* libraries that `target` names in target_link_libraries of `cmake`.
std::set<std::string> linkedLayers(const std::string& cmake, const std::string& target) {
  std::ifstream in(fs::path(VIEW_SELECTION_SOURCE_DIR) / cmake);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::set<std::string> out;
  const std::regex call(R"(target_link_libraries\(\s*)" + target + R"(\b([^)]*)\))");
  const std::regex library(R"(view_selection_(\w+))");
  for (std::sregex_iterator c(text.begin(), text.end(), call), end; c != end; ++c) {
    const std::string args = (*c)[1];
    for (std::sregex_iterator l(args.begin(), args.end(), library); l != end; ++l)
      out.insert((*l)[1]);
  }
  return out;
}

TEST(Layers, EachLibraryLinksOnlyTheLayersBelowIt) {
  // layer -> the layers its library may link
  const std::map<std::string, std::set<std::string>> allowed = {
      {"core", {}},
      {"images", {"core"}},
      {"points", {"core", "images"}},
      {"io", {"core", "images"}},
      {"session", {"core", "images", "points", "io"}},
      {"sim", {"core", "images", "io"}},
      {"eval", {"core"}},
      {"registration", {"core", "images"}},
  };
  for (const auto& [layer, may] : allowed) {
    const std::set<std::string> links =
        linkedLayers("src/" + layer + "/CMakeLists.txt", "view_selection_" + layer);
    for (const std::string& l : links)
      EXPECT_TRUE(may.count(l)) << "view_selection_" << layer << " links view_selection_" << l;
  }
  EXPECT_TRUE(linkedLayers("src/session/CMakeLists.txt", "view_selection_session").count("points"))
      << "the parser finds what a library links";
}

TEST(Layers, NoDynamicCastToAConcreteSourceOutsideTheFactory) {
  // The sources' optional parts (the map input, the feature tracks) are reached through
  // points::mapSourceOf and points::featureSourceOf; the factory is the one place that knows
  // which source is which.
  const fs::path root(VIEW_SELECTION_SOURCE_DIR);
  const std::regex cast(R"(dynamic_cast\s*<[^>]*PointSource\b)");
  const fs::path factory = root / "src/points/point_source_factory.cpp";
  std::string found;
  int files = 0, in_factory = 0;
  for (const std::string dir : {"src", "include"})
    for (const auto& entry : fs::recursive_directory_iterator(root / dir)) {
      if (!entry.is_regular_file()) continue;
      ++files;
      std::ifstream in(entry.path());
      std::string line;
      for (int number = 1; std::getline(in, line); ++number) {
        if (!std::regex_search(line, cast)) continue;
        if (entry.path() == factory)
          ++in_factory;
        else
          found += entry.path().string() + ":" + std::to_string(number) + ": " + line + "\n";
      }
    }
  EXPECT_GT(files, 100);
  EXPECT_GT(in_factory, 0) << "the factory's own casts are found (the pattern works)";
  EXPECT_TRUE(found.empty()) << "dynamic_cast to a concrete point source outside the factory:\n"
                             << found;
}

}  // namespace
