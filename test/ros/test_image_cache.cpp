// The keyframe image cache (~image_cache_mb, ~image_dir): at most the budget in RAM, the rest on
// disk and read back equal, folders made and removed as documented, and a folder that cannot be
// written loses images (counted, with the reason) without throwing. The keyframe image writer
// (~write_keyframe_images): a full queue drops images and says which, and a folder switch loses
// no accepted keyframe. No master needed.
#include "view_selection/core/exceptions.h"
#include "view_selection/ros/image_cache.h"
#include "view_selection/ros/keyframe_image_writer.h"

#include <boost/make_shared.hpp>
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <set>
#include <memory>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using view_selection::ros_node::ImageFolder;
using view_selection::ros_node::KeyframeImageCache;
using view_selection::ros_node::KeyframeImageWriter;

namespace {

sensor_msgs::ImageConstPtr makeImage(int seed, uint32_t width = 40, uint32_t height = 30) {
  auto m = boost::make_shared<sensor_msgs::Image>();
  m->header.stamp = ros::Time(100.0 + seed, 12345u);
  m->header.frame_id = "cam_" + std::to_string(seed);
  m->width = width;
  m->height = height;
  m->encoding = "rgb8";
  m->step = width * 3 + 2;  // padded rows
  m->data.resize(static_cast<size_t>(m->step) * height);
  for (size_t i = 0; i < m->data.size(); ++i)
    m->data[i] = static_cast<uint8_t>((i * 7 + static_cast<size_t>(seed) * 31) & 0xff);
  return m;
}

void expectSameImage(const sensor_msgs::Image& a, const sensor_msgs::Image& b, size_t id) {
  EXPECT_EQ(a.header.stamp, b.header.stamp) << id;
  EXPECT_EQ(a.header.frame_id, b.header.frame_id) << id;
  EXPECT_EQ(a.width, b.width) << id;
  EXPECT_EQ(a.height, b.height) << id;
  EXPECT_EQ(a.encoding, b.encoding) << id;
  EXPECT_EQ(a.is_bigendian, b.is_bigendian) << id;
  EXPECT_EQ(a.step, b.step) << id;
  EXPECT_TRUE(a.data == b.data) << "pixels of image " << id << " differ after the read-back";
}

fs::path scratch(const std::string& name) {
  return fs::temp_directory_path() /
         ("view_selection_test_image_cache_" + std::to_string(::getpid()) + "_" + name);
}

size_t filesIn(const fs::path& dir) {
  size_t n = 0;
  for (const auto& e : fs::directory_iterator(dir)) n += e.is_regular_file() ? 1 : 0;
  return n;
}

TEST(ImageCache, KeepsTheBudgetInMemoryAndReadsTheRestBackEqual) {
  const size_t one = makeImage(0)->data.size();
  auto folder = std::make_shared<ImageFolder>("");
  ASSERT_TRUE(folder->error().empty()) << folder->error();
  ASSERT_TRUE(fs::is_directory(folder->path()));
  KeyframeImageCache cache(2 * one + one / 2, folder);  // two and a half images
  std::vector<sensor_msgs::ImageConstPtr> pushed;
  for (int i = 0; i < 6; ++i) {
    pushed.push_back(i == 3 ? nullptr : makeImage(i));  // keyframe 3 has no image
    cache.push(pushed.back());
    ASSERT_TRUE(cache.waitSpilled(30.0));  // spills are written on the cache's own thread
    EXPECT_LE(cache.stats().memory_bytes, 2 * one + one / 2) << "over budget after " << i;
  }
  const KeyframeImageCache::Stats s = cache.stats();
  EXPECT_EQ(s.images, 6u);
  EXPECT_EQ(s.in_memory, 2u);  // the newest two: 4 and 5
  EXPECT_EQ(s.on_disk, 3u);    // 0, 1, 2
  EXPECT_EQ(s.lost, 0u);
  EXPECT_TRUE(s.last_error.empty()) << s.last_error;
  ASSERT_FALSE(cache.folder().empty());
  EXPECT_EQ(fs::path(cache.folder()).parent_path(), fs::path(folder->path()));
  EXPECT_EQ(filesIn(cache.folder()), 3u);
  for (size_t i = 0; i < pushed.size(); ++i) {
    const sensor_msgs::ImageConstPtr back = cache.get(i);
    if (!pushed[i]) {
      EXPECT_FALSE(back) << "keyframe " << i << " has no image";
      continue;
    }
    ASSERT_TRUE(back) << "image " << i << " is gone";
    expectSameImage(*pushed[i], *back, i);
    if (i >= 4) {
      EXPECT_EQ(back.get(), pushed[i].get()) << "image " << i << " should be in RAM";
    }
  }
  EXPECT_FALSE(cache.get(6));  // unknown id
}

TEST(ImageCache, ZeroBudgetPutsEveryImageOnDisk) {
  auto folder = std::make_shared<ImageFolder>("");
  KeyframeImageCache cache(0, folder);
  for (int i = 0; i < 3; ++i) cache.push(makeImage(i, 17, 5));
  ASSERT_TRUE(cache.waitSpilled(30.0));
  EXPECT_EQ(cache.stats().in_memory, 0u);
  EXPECT_EQ(cache.stats().memory_bytes, 0u);
  EXPECT_EQ(cache.stats().on_disk, 3u);
  for (int i = 0; i < 3; ++i) expectSameImage(*makeImage(i, 17, 5), *cache.get(size_t(i)), size_t(i));
}

TEST(ImageCache, FoldersItMadeAreRemovedAndAGivenOneIsKept) {
  std::string temp, session;
  {
    auto folder = std::make_shared<ImageFolder>("");
    temp = folder->path();
    EXPECT_TRUE(folder->created());
    KeyframeImageCache cache(0, folder);
    cache.push(makeImage(1));
    ASSERT_TRUE(cache.waitSpilled(30.0));
    session = cache.folder();
    EXPECT_TRUE(fs::exists(session));
  }
  EXPECT_FALSE(fs::exists(session)) << session << " outlived its cache";
  EXPECT_FALSE(fs::exists(temp)) << "the temporary folder " << temp << " was not removed";

  // A given folder that exists: only the cache's own subfolder goes.
  const fs::path given = scratch("given");
  fs::create_directories(given);
  {
    auto folder = std::make_shared<ImageFolder>(given.string());
    EXPECT_FALSE(folder->created());
    KeyframeImageCache cache(0, folder);
    cache.push(makeImage(2));
    ASSERT_TRUE(cache.waitSpilled(30.0));
    session = cache.folder();
    EXPECT_EQ(fs::path(session).parent_path(), given);
  }
  EXPECT_FALSE(fs::exists(session));
  EXPECT_TRUE(fs::is_directory(given)) << "a folder the user gave must stay";
  fs::remove_all(given);

  // A given folder that does not exist: made, and removed at the end.
  const fs::path made = scratch("made") / "deeper";
  {
    auto folder = std::make_shared<ImageFolder>(made.string());
    EXPECT_TRUE(folder->error().empty()) << folder->error();
    EXPECT_TRUE(folder->created());
    KeyframeImageCache cache(0, folder);
    cache.push(makeImage(3));
    ASSERT_TRUE(cache.waitSpilled(30.0));
    EXPECT_EQ(cache.stats().on_disk, 1u);
  }
  EXPECT_FALSE(fs::exists(made));
  fs::remove_all(made.parent_path());
}

TEST(ImageCache, AFolderLeftByAKilledNodeIsRemovedWhenTheNextIsMade) {
  // A node killed (SIGKILL: no destructor runs) left its temporary folder with its spilled
  // images; the next folder made removes it, and leaves a living owner's and an unmarked one.
  auto alive = std::make_shared<ImageFolder>("");
  ASSERT_TRUE(alive->created()) << alive->error();
  int fds[2];
  ASSERT_EQ(0, ::pipe(fds));
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {  // the node that is killed: its folder made, one image spilled, then gone
    auto* folder = new ImageFolder("");
    auto* cache = new KeyframeImageCache(0, std::shared_ptr<ImageFolder>(folder, [](ImageFolder*) {}));
    cache->push(makeImage(1));
    const bool spilled = cache->waitSpilled(30.0);
    const std::string path = spilled ? folder->path() : "";
    if (::write(fds[1], path.data(), path.size()) < 0) ::_exit(2);
    ::_exit(0);
  }
  ::close(fds[1]);
  std::string killed;
  char buffer[512];
  for (ssize_t n; (n = ::read(fds[0], buffer, sizeof buffer)) > 0;) killed.append(buffer, static_cast<size_t>(n));
  ::close(fds[0]);
  int status = 0;
  ASSERT_EQ(child, ::waitpid(child, &status, 0));
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  ASSERT_FALSE(killed.empty()) << "the child spilled nothing";
  ASSERT_TRUE(fs::is_directory(killed));
  const fs::path unmarked = fs::temp_directory_path() / ("view_selection_images_unmarked_" + std::to_string(::getpid()));
  fs::create_directories(unmarked);

  auto next = std::make_shared<ImageFolder>("");
  EXPECT_TRUE(next->created()) << next->error();
  EXPECT_FALSE(fs::exists(killed)) << killed << " (its owner killed) was not removed";
  EXPECT_TRUE(fs::is_directory(alive->path())) << "a living owner's folder was removed";
  EXPECT_TRUE(fs::is_directory(unmarked)) << "a folder without .owner was removed";
  fs::remove_all(unmarked);
}

TEST(ImageCache, AnUnwritableFolderLosesImagesWithTheReasonAndNeverThrows) {
  // A regular file where the folder should be, and a folder below a regular file: neither can
  // hold images (permissions would not do: the tests may run as root).
  const fs::path file = scratch("a_file");
  { std::ofstream(file) << "not a folder"; }
  for (const fs::path& dir : {file, file / "below"}) {
    auto folder = std::make_shared<ImageFolder>(dir.string());
    EXPECT_FALSE(folder->error().empty()) << dir << " should be unusable";
    EXPECT_NE(folder->error().find(file.string()), std::string::npos) << folder->error();
    const size_t one = makeImage(0)->data.size();
    KeyframeImageCache cache(one, folder);  // one image fits
    std::vector<sensor_msgs::ImageConstPtr> pushed;
    for (int i = 0; i < 4; ++i) {
      pushed.push_back(makeImage(i));
      EXPECT_NO_THROW(cache.push(pushed.back()));
    }
    ASSERT_TRUE(cache.waitSpilled(30.0));
    const KeyframeImageCache::Stats s = cache.stats();
    EXPECT_EQ(s.lost, 3u);
    EXPECT_EQ(s.on_disk, 0u);
    EXPECT_EQ(s.in_memory, 1u);
    EXPECT_LE(s.memory_bytes, one) << "lost images must not stay in RAM";
    EXPECT_EQ(s.last_error, folder->error());
    for (size_t i = 0; i < 3; ++i) EXPECT_FALSE(cache.get(i)) << "image " << i << " was lost";
    ASSERT_TRUE(cache.get(3));
    expectSameImage(*pushed[3], *cache.get(3), 3);
  }
  EXPECT_TRUE(fs::is_regular_file(file)) << "the cache must not remove what it did not make";
  fs::remove(file);
}

TEST(ImageCache, ADamagedFileIsAnIoErrorNamingIt) {
  auto folder = std::make_shared<ImageFolder>("");
  KeyframeImageCache cache(0, folder);
  cache.push(makeImage(5));
  ASSERT_TRUE(cache.waitSpilled(30.0));
  const fs::path spilled = fs::path(cache.folder()) / "0.image";
  ASSERT_TRUE(fs::exists(spilled));
  fs::resize_file(spilled, 10);
  try {
    cache.get(0);
    ADD_FAILURE() << "a truncated file read back without an error";
  } catch (const view_selection::core::IoError& e) {
    EXPECT_NE(std::string(e.what()).find(spilled.string()), std::string::npos) << e.what();
  }
  fs::remove(spilled);
  EXPECT_THROW(cache.get(0), view_selection::core::IoError);
}

// ---------------------------------------------------------------------------------------------
// The keyframe image writer

std::string nameOf(size_t id) { return "rgb/" + std::to_string(id) + ".png"; }

/// PNG files below `dir`, by name relative to it.
std::set<std::string> pngsIn(const fs::path& dir) {
  std::set<std::string> names;
  if (!fs::exists(dir)) return names;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file() && e.path().extension() == ".png")
      names.insert(fs::relative(e.path(), dir).string());
  return names;
}

TEST(KeyframeImageWriter, AFullQueueDropsImagesAndNamesEachOne) {
  ros::Time::init();  // the throttled error log reads ROS time (wall time here: no master)
  const fs::path dir = scratch("writer_full");
  fs::remove_all(dir);
  std::vector<std::string> lost;
  KeyframeImageWriter::Stats stats;
  constexpr size_t kImages = 60;
  {
    // Room for 2 images: a burst of 60 VGA keyframes (PNG encoding takes milliseconds each,
    // pushing them microseconds) overflows it.
    KeyframeImageWriter writer(2);
    ASSERT_TRUE(writer.setDirectory(dir.string()).error.empty());
    for (size_t i = 0; i < kImages; ++i) writer.accepted(i, nameOf(i), makeImage(int(i), 640, 480));
    ASSERT_TRUE(writer.waitIdle(120.0));
    stats = writer.stats();
    lost = writer.lostNames();
  }
  EXPECT_GT(stats.dropped, 0u) << "the queue of 2 never overflowed";
  EXPECT_EQ(stats.written + stats.dropped, kImages) << "every image is written or dropped";
  EXPECT_EQ(stats.failed, 0u) << stats.last_error;
  EXPECT_NE(stats.last_error.find("behind"), std::string::npos) << stats.last_error;
  // The names of the dropped ones are exactly the images missing from the folder.
  const std::set<std::string> on_disk = pngsIn(dir);
  EXPECT_EQ(on_disk.size(), stats.written);
  ASSERT_EQ(lost.size(), stats.dropped);
  for (size_t i = 0; i < kImages; ++i) {
    const bool dropped = std::find(lost.begin(), lost.end(), nameOf(i)) != lost.end();
    EXPECT_NE(dropped, on_disk.count(nameOf(i)) == 1) << nameOf(i);
  }
  fs::remove_all(dir);
}

TEST(KeyframeImageWriter, AFolderSwitchLosesNoAcceptedKeyframe) {
  const fs::path a = scratch("writer_switch_a"), b = scratch("writer_switch_b");
  fs::remove_all(a);
  fs::remove_all(b);
  auto cache = std::make_shared<KeyframeImageCache>(size_t(1) << 30,
                                                   std::make_shared<ImageFolder>(""));
  KeyframeImageWriter writer;
  // Keyframes 0-4 accepted without a folder; a selection with 0-2 was shared, 3 and 4 not yet.
  for (size_t i = 0; i < 5; ++i) {
    const sensor_msgs::ImageConstPtr image = makeImage(int(i));
    cache->push(image);
    writer.accepted(i, nameOf(i), image);
  }
  writer.shared(3);
  KeyframeImageWriter::Switch sw = writer.setDirectory(a.string());
  ASSERT_TRUE(sw.error.empty()) << sw.error;
  EXPECT_EQ(sw.shared, 3u) << "the caller writes keyframes 0-2 from the served selection";
  EXPECT_EQ(sw.queued, 2u) << "keyframes 3 and 4 are not served yet: the switch queues them";
  EXPECT_EQ(sw.dropped, 0u);
  for (size_t i = 0; i < sw.shared; ++i) EXPECT_TRUE(writer.queueFromCache(nameOf(i), cache, i));
  // Later keyframes go to the folder as they are accepted.
  const sensor_msgs::ImageConstPtr later = makeImage(5);
  cache->push(later);
  writer.accepted(5, nameOf(5), later);
  ASSERT_TRUE(writer.waitIdle(60.0));
  EXPECT_EQ(pngsIn(a), (std::set<std::string>{nameOf(0), nameOf(1), nameOf(2), nameOf(3),
                                               nameOf(4), nameOf(5)}));
  EXPECT_EQ(writer.stats().written, 6u);
  EXPECT_TRUE(writer.lostNames().empty());

  // Shared up to 5; a switch to b leaves every keyframe but the unshared 5 to the caller.
  writer.shared(5);
  sw = writer.setDirectory(b.string());
  EXPECT_EQ(sw.shared, 5u);
  EXPECT_EQ(sw.queued, 1u);
  ASSERT_TRUE(writer.waitIdle(60.0));
  EXPECT_EQ(pngsIn(b), std::set<std::string>{nameOf(5)});
  // A file already there is kept, not written again.
  EXPECT_TRUE(writer.queueFromCache(nameOf(5), cache, 5));
  ASSERT_TRUE(writer.waitIdle(60.0));
  EXPECT_EQ(writer.stats().kept, 1u);
  // A new session starts its ids over: nothing of the old one is held.
  writer.newSession();
  EXPECT_EQ(writer.setDirectory(a.string()).queued, 0u);
  fs::remove_all(a);
  fs::remove_all(b);
}

}  // namespace
