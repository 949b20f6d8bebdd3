// The core (and the offline tools) compile and run without ROS: no ROS header may appear in them.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <string>

namespace {

namespace fs = std::filesystem;

TEST(CoreIsRosFree, NoRosIncludeInCoreOrTools) {
  const fs::path root(VIEW_SELECTION_SOURCE_DIR);
  const std::regex ros_include(
      R"(^\s*#\s*include\s*[<"](ros/|roscpp|rosbag|tf2|tf/|sensor_msgs|geometry_msgs|std_msgs|)"
      R"(std_srvs|nav_msgs|visualization_msgs|cv_bridge|image_transport|message_filters|nodelet|)"
      R"(pluginlib|view_selection/ros/|view_selection/[A-Z]))");
  int files = 0;
  std::string offences;
  for (const char* dir : {"include/view_selection/core", "src/core", "src/tools"}) {
    if (!fs::exists(root / dir)) continue;
    for (const auto& entry : fs::recursive_directory_iterator(root / dir)) {
      if (!entry.is_regular_file()) continue;
      ++files;
      std::ifstream in(entry.path());
      std::string line;
      for (int number = 1; std::getline(in, line); ++number)
        if (std::regex_search(line, ros_include))
          offences += entry.path().string() + ":" + std::to_string(number) + ": " + line + "\n";
    }
  }
  EXPECT_GT(files, 10);  // the walk found the sources
  EXPECT_TRUE(offences.empty()) << "ROS includes in the ROS-free core:\n" << offences;
}

}  // namespace
