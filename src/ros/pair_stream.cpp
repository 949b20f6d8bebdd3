#include "view_selection/ros/pair_stream.h"

#include "view_selection/ros/conversions.h"

#include <set>

namespace view_selection::ros_node {

PairStream::PairStream(const NodeConfig& config, ros::NodeHandle private_nh)
    : config_(config), announcer_(config.pair_stable_keyframes) {
  publisher_ = private_nh.advertise<view_selection::PairChanges>("pairs", 100);
  if (config_.pair_flush_idle > 0.0)
    timer_ = private_nh.createWallTimer(ros::WallDuration(std::min(0.1, config_.pair_flush_idle)),
                                       &PairStream::onTimer, this);
}

void PairStream::update(const core::PairChanges& changes, const core::SelectionOutput& output) {
  std::lock_guard<std::mutex> lock(mutex_);
  output_ = output;
  const core::Announcement announced = announcer_.update(changes, output.size());
  if (announced.empty() && keyframes_listed_ >= output.size()) return;
  emitLocked(announced, false, false);
}

void PairStream::reset(const core::SelectionOutput& output) {
  std::lock_guard<std::mutex> lock(mutex_);
  announcer_.clear();
  output_ = output;
  keyframes_listed_ = 0;
  session_start_ = sequence_ + 1;
  emitLocked({}, true, false);
}

void PairStream::restore(uint64_t sequence, const core::SelectionOutput& output) {
  std::lock_guard<std::mutex> lock(mutex_);
  output_ = output;
  announcer_.announceAll(output.selection.pairs.toVector());
  sequence_ = std::max(sequence_, sequence);
  first_kept_ = session_start_ = sequence_ + 1;
  history_.clear();
  keyframes_listed_ = 0;
  emitLocked({{announcer_.announced().begin(), announcer_.announced().end()}, {}}, true, false);
}

void PairStream::flush() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (announcer_.pending() == 0) return;
  emitLocked(announcer_.flush(), false, true);
}

void PairStream::onTimer(const ros::WallTimerEvent&) {
  const uint64_t last = last_frame_ns_.load();
  if (last == 0) return;
  if (ros::WallTime::now().toNSec() - last < static_cast<uint64_t>(config_.pair_flush_idle * 1e9))
    return;
  std::lock_guard<std::mutex> lock(mutex_);
  // Pending pairs go out at once; with none, the pause alone is news once (a consumer finishes).
  if (announcer_.pending() > 0 || (!pause_told_.load() && output_.size() > 0))
    emitLocked(announcer_.flush(), false, true);
  pause_told_ = true;
}

uint64_t PairStream::sequence() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return sequence_;
}

void PairStream::emitLocked(const core::Announcement& announced, bool full, bool flushed) {
  auto msg = boost::make_shared<view_selection::PairChanges>();
  msg->header.frame_id = config_.world_frame;
  const std::size_t n = output_.size();
  if (n > 0) msg->header.stamp = ros::Time(output_.keyframes[n - 1].stamp);
  msg->sequence = ++sequence_;
  msg->full = full;
  msg->flushed = flushed;
  std::set<core::ViewId> named;  // the keyframes the pairs name
  const auto add = [&named](const std::vector<core::Pair>& pairs,
                            std::vector<view_selection::ViewPair>& out) {
    for (const core::Pair& p : pairs) {
      out.push_back(pairToMsg(p.first, p.second));
      named.insert(p.first);
      named.insert(p.second);
    }
  };
  add(announced.added, msg->added);
  add(announced.removed, msg->removed);
  for (std::size_t i = std::min(keyframes_listed_, n); i < n; ++i)
    named.insert(static_cast<core::ViewId>(i));
  keyframes_listed_ = std::max(keyframes_listed_, n);
  for (const core::ViewId id : named)
    if (id >= 0 && static_cast<std::size_t>(id) < n) msg->keyframes.push_back(keyframeToMsg(output_, id));
  msg->total_keyframes = static_cast<uint32_t>(n);
  msg->pending_pairs = static_cast<uint32_t>(announcer_.pending());
  history_.push_back(msg);
  while (history_.size() > static_cast<std::size_t>(std::max(1, config_.pair_history))) {
    history_.pop_front();
    ++first_kept_;
  }
  publisher_.publish(msg);
}

view_selection::PairChanges PairStream::fullMessageLocked() const {
  view_selection::PairChanges msg;
  msg.header.frame_id = config_.world_frame;
  const std::size_t n = output_.size();
  if (n > 0) msg.header.stamp = ros::Time(output_.keyframes[n - 1].stamp);
  msg.sequence = sequence_;
  msg.full = true;
  msg.flushed = pause_told_.load() && announcer_.pending() == 0;  // the frames stopped and all is announced
  for (const core::Pair& p : announcer_.announced()) msg.added.push_back(pairToMsg(p.first, p.second));
  for (std::size_t i = 0; i < n; ++i) msg.keyframes.push_back(keyframeToMsg(output_, static_cast<core::ViewId>(i)));
  msg.total_keyframes = static_cast<uint32_t>(n);
  msg.pending_pairs = static_cast<uint32_t>(announcer_.pending());
  return msg;
}

void PairStream::answer(uint64_t since, view_selection::GetPairs::Response& res) const {
  std::lock_guard<std::mutex> lock(mutex_);
  res.sequence = sequence_;
  res.success = true;
  // The messages after `since` when the node still has them all and they are of this session;
  // otherwise the whole announced set.
  if (since > 0 && since <= sequence_ && since + 1 >= first_kept_ && since + 1 >= session_start_) {
    for (const MessagePtr& m : history_)
      if (m->sequence > since) res.changes.push_back(*m);
    res.message = std::to_string(res.changes.size()) + " messages after " + std::to_string(since);
    return;
  }
  res.changes.push_back(fullMessageLocked());
  res.message = "the whole announced set (" + std::to_string(res.changes.back().added.size()) +
                " pairs, sequence " + std::to_string(sequence_) + ")" +
                (since == 0 ? std::string()
                 : since > sequence_ ? ": " + std::to_string(since) +
                                           " is ahead of this node (restarted without ~state_file?)"
                                     : ": " + std::to_string(since) + " is older than the node keeps or of an earlier session");
}

}  // namespace view_selection::ros_node
