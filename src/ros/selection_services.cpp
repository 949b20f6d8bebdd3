#include "view_selection/ros/selection_services.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/atomic_file.h"
#include "view_selection/io/export.h"
#include "view_selection/io/params_json.h"
#include "view_selection/io/selection_plot.h"
#include "view_selection/ros/conversions.h"

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <chrono>
#include <future>
#include <filesystem>

namespace view_selection::ros_node {

namespace fs = std::filesystem;

SelectionServices::SelectionServices(const NodeConfig& config, ros::NodeHandle private_nh,
                                     KeyframeWorker& worker, PoseProvider& poses,
                                     StateKeeper& keeper, PairStream& pairs,
                                     KeyframeImageWriter& image_writer,
                                     std::function<void()> on_reset)
    : config_(config),
      worker_(worker),
      poses_(poses),
      keeper_(keeper),
      pairs_(pairs),
      image_writer_(image_writer),
      on_reset_(std::move(on_reset)),
      spinner_(1, &queue_),
      files_spinner_(1, &files_queue_) {
  ros::NodeHandle nh(private_nh), files(private_nh);
  nh.setCallbackQueue(&queue_);
  files.setCallbackQueue(&files_queue_);
  next_views_ = nh.advertiseService("get_next_views", &SelectionServices::getNextViews, this);
  selection_ = nh.advertiseService("get_selection", &SelectionServices::getSelection, this);
  reset_ = nh.advertiseService("reset", &SelectionServices::reset, this);
  get_pairs_ = nh.advertiseService("get_pairs", &SelectionServices::getPairs, this);
  write_images_ =
      files.advertiseService("write_keyframe_images", &SelectionServices::writeImages, this);
  export_ = files.advertiseService("export", &SelectionServices::exportSelection, this);
  save_state_ = files.advertiseService("save_state", &SelectionServices::saveState, this);
  spinner_.start();
  files_spinner_.start();
}

SelectionServices::~SelectionServices() {
  spinner_.stop();
  files_spinner_.stop();
  for (auto* s : {&next_views_, &selection_, &export_, &reset_, &save_state_, &get_pairs_,
                  &write_images_})
    s->shutdown();
}

bool SelectionServices::getPairs(view_selection::GetPairs::Request& req,
                                 view_selection::GetPairs::Response& res) {
  (void)worker_.servedLatest();  // keyframes accepted so far are shared, so announced too
  pairs_.answer(req.since, res);
  res.keyframe_image_dir = image_writer_.directory();
  res.keyframe_images_lost = image_writer_.lostNames();
  return true;
}

bool SelectionServices::writeImages(view_selection::WriteKeyframeImages::Request& req,
                                    view_selection::WriteKeyframeImages::Response& res) {
  res.success = false;
  // The switch and the keyframes it leaves to this call are one step: the writer queues the
  // keyframes accepted and not shared yet itself; every one below `shared` is served from now on.
  const KeyframeImageWriter::Switch sw = image_writer_.setDirectory(req.directory);
  if (!sw.error.empty()) {
    res.message = sw.error;
    ROS_ERROR_STREAM_THROTTLE(5.0, "view_selection: ~write_keyframe_images: " << sw.error);
    return true;
  }
  if (req.directory.empty()) {
    res.success = true;
    res.message = "keyframe images are no longer written";
    return true;
  }
  const std::shared_ptr<const ServedSelection> served = worker_.served();
  const core::SelectionOutput& s = served->selection;
  const size_t earlier = std::min(sw.shared, s.size());
  for (size_t i = 0; i < earlier; ++i) {
    const std::string name = s.imageName(i);
    std::error_code ec;
    if (fs::exists(fs::path(req.directory) / name, ec))
      ++res.images_written;  // there already (written once: kept)
    else if (served->images && i < served->image_count && served->images->has(i) &&
             image_writer_.queueFromCache(name, served->images, i))
      ++res.images_queued;
    else
      ++res.images_missing;
  }
  res.images_queued += static_cast<int32_t>(sw.queued - sw.dropped);
  res.images_dropped = static_cast<int32_t>(sw.dropped);
  const size_t keyframes = earlier + sw.queued;
  res.success = true;
  res.message = "keyframe images go to '" + req.directory + "' from now on; of the " +
                std::to_string(keyframes) + " keyframes so far, " +
                std::to_string(res.images_written) + " images are there already, " +
                std::to_string(res.images_queued) + " queued for writing" +
                (res.images_dropped > 0 ? ", " + std::to_string(res.images_dropped) +
                                              " dropped (the image writer is too far behind: "
                                              "ask again once it caught up)"
                                        : std::string()) +
                (res.images_missing > 0
                     ? ", " + std::to_string(res.images_missing) +
                           " missing (the node keeps earlier images only with "
                           "~save_keyframe_images, and none of keyframes continued from "
                           "~state_file)"
                     : std::string());
  ROS_INFO_STREAM("view_selection: " << res.message);
  return true;
}

bool SelectionServices::getNextViews(view_selection::GetNextViews::Request& req,
                                     view_selection::GetNextViews::Response& res) {
  const std::shared_ptr<const ServedSelection> served = worker_.servedLatest();
  const core::SelectionOutput& s = served->selection;
  const size_t n = s.size();
  if (req.view < 0 || static_cast<size_t>(req.view) >= n) {
    res.success = false;
    res.message = "view " + std::to_string(req.view) + " is unknown: " +
                  (n == 0 ? std::string("there are no keyframes yet")
                          : "keyframe ids are 0.." + std::to_string(n - 1));
    return true;
  }
  const auto& sets = req.after_completion ? s.selection.final_next_views : s.selection.next_views;
  for (const core::ViewId j : sets[static_cast<size_t>(req.view)]) {
    res.next_views.push_back(j);
    res.error_resistance.push_back(s.table.at(req.view, j));
  }
  res.success = true;
  res.message = std::to_string(res.next_views.size()) + " next views of view " +
                std::to_string(req.view) + (req.after_completion ? " after completion" : "") +
                " (" + std::to_string(n) + " keyframes)";
  return true;
}

bool SelectionServices::getSelection(view_selection::GetSelection::Request&,
                                     view_selection::GetSelection::Response& res) {
  const std::shared_ptr<const ServedSelection> served = worker_.servedLatest();
  res.selection = selectionToMsg(served->selection, config_.world_frame);
  res.success = true;
  res.message = std::to_string(res.selection.keyframes.size()) + " keyframes, " +
                std::to_string(res.selection.pairs.size()) + " pairs" +
                (res.selection.keyframes.empty() ? " (no keyframes yet)" : "");
  return true;
}

int writeKeyframeImages(const std::string& directory, const ServedSelection& served) {
  const std::vector<std::string> names = served.selection.imageNames();
  int written = 0;
  for (size_t i = 0; served.images && i < served.image_count && i < names.size(); ++i) {
    // Null: a keyframe continued from ~state_file (no image kept), or one the cache lost.
    const sensor_msgs::ImageConstPtr image = served.images->get(i);  // may read it back
    if (!image) continue;
    const fs::path path = fs::path(directory) / names[i];
    std::error_code ec;
    fs::create_directories(path.parent_path(), ec);
    if (ec)
      throw core::IoError("cannot create folder '" + path.parent_path().string() +
                          "': " + ec.message());
    cv::Mat bgr;
    try {
      bgr = imageForCore(image);
    } catch (const core::InvalidInput& e) {
      throw core::IoError("keyframe " + std::to_string(i) + " image: " + e.what());
    }
    io::writeAtomically(path.string(), [&](const std::string& tmp) { io::writePng(tmp, bgr); });
    ++written;
  }
  return written;
}

bool SelectionServices::exportSelection(view_selection::Export::Request& req,
                                        view_selection::Export::Response& res) {
  res.success = false;
  if (req.directory.empty()) {
    res.message = "directory is empty: give the folder to write selection.json and pairs.txt into";
    return true;
  }
  const std::shared_ptr<const ServedSelection> served = worker_.servedLatest();
  const core::SelectionOutput& s = served->selection;
  try {
    nlohmann::json params = io::toJson(*s.params);
    params["source"] = "view_selection_node";
    params["world_frame"] = config_.world_frame;
    params["image_path"] = config_.save_keyframe_images ? "." : "";
    io::ExportOptions options;
    options.title = "view_selection_node, k = " + std::to_string(s.config.k) +
                    ", completion: " + core::toString(s.config.completion);
    const io::ExportResult written = io::exportSelection(req.directory, s, params, options);
    res.selection_json = written.selection_json;
    res.pairs_txt = written.pairs_txt;
    res.images_written = writeKeyframeImages(req.directory, *served);
    size_t lost = 0;
    std::string lost_reason;
    if (served->images) {
      const KeyframeImageCache::Stats cache = served->images->stats();
      lost = cache.lost;
      lost_reason = cache.last_error;
    }
    const size_t missing = s.size() - std::min(s.size(), static_cast<size_t>(res.images_written));
    res.success = true;
    res.message =
        "wrote " + std::to_string(s.size()) + " keyframes, " +
        std::to_string(s.selection.pairs.size()) + " pairs" +
        (config_.save_keyframe_images ? ", " + std::to_string(res.images_written) + " images"
                                      : " (no images: ~save_keyframe_images is false)") +
        (config_.save_keyframe_images && missing > lost
             ? " (" + std::to_string(missing - lost) +
                   " keyframes continued from ~state_file have no image)"
             : std::string()) +
        (lost > 0 ? " (" + std::to_string(lost) +
                        " images lost: beyond ~image_cache_mb and not written to ~image_dir: " +
                        lost_reason + ")"
                  : std::string()) +
        " to " + req.directory;
  } catch (const std::exception& e) {
    res.success = false;
    res.message = std::string("export failed: ") + e.what();
  }
  return true;
}

bool SelectionServices::reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  const size_t forgotten = worker_.reset();  // and the statistics, in the same step
  poses_.reset();
  if (on_reset_) on_reset_();
  res.success = true;
  res.message = "forgot " + std::to_string(forgotten) + " keyframes and the input statistics";
  return true;
}

bool SelectionServices::saveState(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  if (!keeper_.enabled()) {
    res.success = false;
    res.message = "~state_file is empty: saving is off";
    return true;
  }
  // The worker's thread captures the session before its next frame and the keeper's writes it;
  // this thread only waits for the answer, at most kSaveAnswerWait.
  auto done = std::make_shared<std::promise<SaveResult>>();
  std::future<SaveResult> answer = done->get_future();
  worker_.requestSave([done](const SaveResult& r) { done->set_value(r); });
  if (answer.wait_for(std::chrono::duration<double>(kSaveAnswerWait)) !=
      std::future_status::ready) {
    res.success = true;
    res.message = "the save is under way (not written within " +
                  core::formatNumber(kSaveAnswerWait) +
                  " s: a large session, or the worker is busy); ~statistics' "
                  "state_saved_keyframes says when it is on disk";
    return true;
  }
  try {
    const SaveResult saved = answer.get();
    res.success = saved.ok;
    res.message = saved.message;
  } catch (const std::future_error&) {
    res.success = false;
    res.message = "the node stopped before the session was saved";
  }
  return true;
}

}  // namespace view_selection::ros_node
