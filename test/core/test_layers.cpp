// The layers depend downwards only (docs/architecture.md): the core on Eigen alone; the point
// sources, files, the built-in sequence and the evaluation on no ROS; nothing ROS-free on the
// ROS layer. Checked on the sources' #include lines, so a wrong include fails here first.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
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
std::string offences(const std::vector<std::string>& dirs, const std::string& forbidden,
                     int* files, const std::vector<std::string>& skip = {}) {
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

TEST(Layers, EachLayerIncludesOnlyTheLayersBelowIt) {
  // layer -> what its sources must not include
  const std::map<std::string, std::string> rules = {
      {"core", R"((opencv2|ceres|nlohmann|yaml-cpp|view_selection/(points|io|sim|eval|refine|odometry|ros)/)|)" +
                   kRosHeaders},
      {"points", R"((nlohmann|yaml-cpp|view_selection/(io|sim|eval|refine|odometry|ros)/)|)" + kRosHeaders},
      {"io", R"((ceres|view_selection/(sim|eval|refine|odometry|ros)/)|)" + kRosHeaders},
      {"sim", R"((view_selection/(eval|refine|odometry|ros)/)|)" + kRosHeaders},
      {"eval", R"((view_selection/(sim|refine|odometry|ros)/)|)" + kRosHeaders},
      // refine: a known-pose COLMAP model bundle-adjusted (Ceres), for the tools
      {"refine", R"((opencv2|view_selection/(sim|odometry|ros)/)|)" + kRosHeaders},
      // odometry: OpenCV's RGB-D odometry as a drifting SLAM stand-in, on the core's types
      {"odometry", R"((ceres|nlohmann|yaml-cpp|view_selection/(points|io|sim|eval|refine|ros)/)|)" + kRosHeaders},
  };
  for (const auto& [layer, forbidden] : rules) {
    int files = 0;
    const std::string found = offences({"include/view_selection/" + layer, "src/" + layer},
                                       "(" + forbidden + ")", &files);
    EXPECT_GE(files, 2) << layer << ": no sources found";
    EXPECT_TRUE(found.empty()) << "layer " << layer << " includes what it must not:\n" << found;
  }
}

}  // namespace
