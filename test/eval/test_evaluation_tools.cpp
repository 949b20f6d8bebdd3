// The evaluation tools end to end on a generated TUM folder: evaluate_trajectory recovers a
// known similarity from a COLMAP images.txt, and select_views --strategy nearest writes the
// nearest-centre pairs by image name. Real executables, real files.
#include "support/test_support.h"

#include "view_selection/io/tum_dataset.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <Eigen/Geometry>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include "support/layers.h"

namespace fs = std::filesystem;

namespace view_selection {
namespace {

std::string readAll(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

class EvaluationTools : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("view_selection_eval_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "rgb");
    // Six cameras on an arc looking at the origin; stamps 1.0, 2.0, ...
    std::ofstream rgb(dir_ / "rgb.txt"), gt(dir_ / "groundtruth.txt");
    gt.precision(17);
    for (int i = 0; i < 6; ++i) {
      const double a =
          0.25 * i + 0.02 * i * i;  // growing steps: each view's nearest is the one before
      TumPoseEntry p;
      p.stamp = 1.0 + i;
      p.pose = test::lookAt(Eigen::Vector3d(3.0 * std::sin(a), 0.2 * i, -3.0 * std::cos(a)),
                            Eigen::Vector3d::Zero());
      poses_.push_back(p);
      char name[64];
      std::snprintf(name, sizeof(name), "%.6f.png", p.stamp);
      names_.push_back(name);
      rgb << std::string(name).substr(0, std::string(name).size() - 4) << " rgb/" << name << "\n";
      const Eigen::Vector3d& t = p.pose.position;
      const Eigen::Quaterniond& q = p.pose.orientation;
      gt << p.stamp << ' ' << t.x() << ' ' << t.y() << ' ' << t.z() << ' ' << q.x() << ' ' << q.y()
         << ' ' << q.z() << ' ' << q.w() << "\n";
      std::ofstream(dir_ / "rgb" / name) << "not an image; the tools here read names only";
    }
    std::ofstream(dir_ / "camera.yaml")
        << "fx: 525\nfy: 525\ncx: 319.5\ncy: 239.5\nwidth: 640\nheight: 480\n";
  }
  void TearDown() override { fs::remove_all(dir_); }

  static std::string tool(const std::string& name) {
    return std::string(VIEW_SELECTION_TOOLS_DIR) + "/" + name;
  }
  int runTool(const std::string& command, std::string* output) {
    const fs::path out = dir_ / "stdout.txt";
    const int status = std::system((command + " > " + out.string() + " 2>&1").c_str());
    *output = readAll(out);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }

  fs::path dir_;
  std::vector<TumPoseEntry> poses_;
  std::vector<std::string> names_;
};

TEST_F(EvaluationTools, EvaluateTrajectoryRecoversAKnownSimilarity) {
  // The "reconstruction" is the ground truth seen through an arbitrary similarity (COLMAP's own
  // frame and scale), one camera left out (not registered) and one unknown image added.
  const double scale = 0.37;
  const Eigen::Matrix3d rot =
      Eigen::AngleAxisd(1.1, Eigen::Vector3d(1, 2, -1).normalized()).toRotationMatrix();
  const Eigen::Vector3d shift(0.5, -2.0, 7.0);
  std::ofstream f(dir_ / "images.txt");
  f << "# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n";
  for (int i = 0; i < 6; ++i) {
    if (i == 3) continue;
    const Eigen::Vector3d c =
        scale * (rot * poses_[i].pose.position) + shift;           // centre in model frame
    const Eigen::Matrix3d r_wc = rot * poses_[i].pose.rotation();  // camera-to-model
    const Eigen::Matrix3d r_cw = r_wc.transpose();
    const Eigen::Vector3d t = -r_cw * c;
    const Eigen::Quaterniond q(r_cw);
    f.precision(17);
    f << i + 1 << ' ' << q.w() << ' ' << q.x() << ' ' << q.y() << ' ' << q.z() << ' ' << t.x()
      << ' ' << t.y() << ' ' << t.z() << " 1 " << names_[i] << "\n1.0 2.0 -1\n";
  }
  f << "9 1 0 0 0 0 0 0 1 unknown.png\n\n";
  f.close();

  std::string out;
  ASSERT_EQ(runTool(tool("evaluate_trajectory") + " --model " + dir_.string() + " --dataset " +
                        dir_.string() + " --json " + (dir_ / "ate.json").string(),
                    &out),
            0)
      << out;
  EXPECT_NE(out.find("1 registered image(s) without ground truth"), std::string::npos) << out;
  const nlohmann::json j = nlohmann::json::parse(readAll(dir_ / "ate.json"));
  EXPECT_EQ(j["matched"].get<int>(), 5);
  EXPECT_NEAR(j["alignment"]["scale"].get<double>(), 1.0 / scale, 1e-6);
  EXPECT_LT(j["ate"]["rmse"].get<double>(), 1e-6);

  // The stamp-named alternative gives the same alignment.
  ASSERT_EQ(runTool(tool("evaluate_trajectory") + " --model " + (dir_ / "images.txt").string() +
                        " --groundtruth " + (dir_ / "groundtruth.txt").string(),
                    &out),
            0)
      << out;
  EXPECT_NE(out.find("ate_rmse"), std::string::npos) << out;

  // Bad input: a clear message and a non-zero exit, no crash.
  EXPECT_EQ(runTool(tool("evaluate_trajectory") + " --model " + (dir_ / "missing").string() +
                        " --dataset " + dir_.string(),
                    &out),
            1);
  EXPECT_NE(out.find("cannot read COLMAP images file"), std::string::npos) << out;
  EXPECT_EQ(runTool(tool("evaluate_trajectory") + " --model " + dir_.string(), &out), 2);
}

TEST_F(EvaluationTools, SelectViewsNearestWritesPairsByName) {
  std::string out;
  const fs::path result = dir_ / "nearest";
  ASSERT_EQ(
      runTool(tool("select_views") + " --dataset " + dir_.string() +
                  " --every 1 --strategy nearest --nearest-k 1 --nearest-max-angle 90 --out " +
                  result.string(),
              &out),
      0)
      << out;
  // Each camera's nearest is the one before it (view 0: view 1): a chain of 5 pairs.
  std::string expected;
  for (int i = 0; i + 1 < 6; ++i) expected += names_[i] + " " + names_[i + 1] + "\n";
  EXPECT_EQ(readAll(result / "pairs.txt"), expected);
  EXPECT_EQ(runTool(tool("select_views") + " --dataset " + dir_.string() + " --nearest-k 2", &out),
            2);
  EXPECT_NE(out.find("need --strategy nearest"), std::string::npos) << out;
}

// Photo collections keep every photo (issue 30): the rendered box seen from views 3 degrees
// apart on an arc, stamped 1 s apart as photos converted to the TUM layout are. By default every
// image is a keyframe and the summary says why; as a video stream the scale-free policy thins
// them (parallax under 5 degrees) and the summary names each one it dropped.
TEST_F(EvaluationTools, SelectViewsKeepsEveryPhotoOfACollection) {
  std::string out;
  auto generate = [&](const std::string& name, int frames, bool depth) {
    const fs::path folder = dir_ / name;
    EXPECT_EQ(runTool(tool("generate_sequence") + " --out " + folder.string() + " --frames " +
                          std::to_string(frames) + " --ring-step 3 --fps 1 --width 320 " +
                          "--height 240 --quiet" + (depth ? "" : " --no-depth"),
                      &out),
              0)
        << out;
    return folder;
  };
  auto keyframes = [&](const fs::path& selection) {
    const nlohmann::json j = nlohmann::json::parse(readAll(selection / "selection.json"));
    return j["keyframes"].size();
  };
  // Two RGB-D photos 3 degrees apart: depth gives the first its points, so a video stream's
  // policy would take the second for the same view.
  const fs::path two = generate("two_photos", 2, true);
  ASSERT_EQ(runTool(tool("select_views") + " --dataset " + two.string() + " --out " +
                        (dir_ / "two_default").string() + " --quiet --print-sets 0",
                    &out),
            0)
      << out;
  EXPECT_EQ(keyframes(dir_ / "two_default"), 2u) << out;
  EXPECT_NE(out.find("a photo collection (--input auto: images 1.000 s apart"), std::string::npos)
      << out;
  EXPECT_NE(out.find("dropped     none"), std::string::npos) << out;
  ASSERT_EQ(runTool(tool("select_views") + " --dataset " + two.string() + " --out " +
                        (dir_ / "two_stream").string() + " --quiet --print-sets 0 --input stream",
                    &out),
            0)
      << out;
  EXPECT_EQ(keyframes(dir_ / "two_stream"), 1u) << "as a stream the second view is thinned: " << out;
  EXPECT_NE(out.find("dropped     1 of 2 images"), std::string::npos) << out;
  EXPECT_NE(out.find("rgb/1001.000000.png"), std::string::npos) << "the dropped photo by name: " << out;

  // Ten photos without depth (features, as DTU and castle): every one kept by default.
  const fs::path ten = generate("ten_photos", 10, false);
  ASSERT_EQ(runTool(tool("select_views") + " --dataset " + ten.string() + " --out " +
                        (dir_ / "ten_default").string() + " --quiet --print-sets 0",
                    &out),
            0)
      << out;
  EXPECT_EQ(keyframes(dir_ / "ten_default"), 10u) << out;
  // An explicit keyframe option applies to a collection too, and its drops are named.
  ASSERT_EQ(runTool(tool("select_views") + " --dataset " + ten.string() + " --out " +
                        (dir_ / "ten_policy").string() +
                        " --quiet --print-sets 0 --keyframe-policy scale_free",
                    &out),
            0)
      << out;
  const size_t kept = keyframes(dir_ / "ten_policy");
  EXPECT_LT(kept, 10u) << out;
  EXPECT_NE(out.find("dropped     " + std::to_string(10 - kept) + " of 10 images"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("thinned by the keyframe options given"), std::string::npos) << out;
}

}  // namespace
}  // namespace view_selection
