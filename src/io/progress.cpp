#include "view_selection/io/progress.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>

namespace view_selection::io {

double steadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

std::string durationText(double seconds) {
  char text[32];
  if (seconds < 90.0)
    std::snprintf(text, sizeof text, "%d s", std::max(1, static_cast<int>(std::lround(seconds))));
  else if (seconds < 90.0 * 60.0)
    std::snprintf(text, sizeof text, "%d min", static_cast<int>(std::lround(seconds / 60.0)));
  else
    std::snprintf(text, sizeof text, "%.1f h", seconds / 3600.0);
  return text;
}

Progress::Progress(std::ostream& out, bool terminal, std::function<double()> clock, double interval, double redraw)
    : out_(&out), terminal_(terminal), clock_(std::move(clock)), interval_(interval), redraw_(redraw) {}

Progress Progress::toStderr(bool enabled, double interval) {
  if (!enabled) return silent();
  return Progress(std::cerr, isatty(fileno(stderr)) == 1, steadySeconds, interval);
}

Progress Progress::silent() {
  Progress p(std::cerr, false);
  p.out_ = nullptr;
  return p;
}

void Progress::report(const std::string& stage, size_t done, size_t total, const std::string& unit,
                      const std::string& detail) {
  if (!out_) return;
  const double now = clock_();
  if (!active_ || stage != stage_ || done < done_) {  // a count that went back: the work run again
    end();
    stage_ = stage;
    unit_ = unit;
    started_ = now;
    active_ = true;
    stage_shown_ = shown_complete_ = false;
  }
  done_ = done;
  total_ = std::max(total, done);
  detail_ = detail;
  const bool complete = done_ >= total_;
  if (due(now) || (complete && stage_shown_ && !shown_complete_)) {  // the whole count shows at once
    show(now);
    shown_complete_ = complete;
  }
}

void Progress::end() {
  if (!out_) return;
  if (active_ && stage_shown_ && !shown_complete_) {  // how far it got ("1/4 rounds": it ended early)
    detail_.clear();
    final_ = true;
    show(clock_());
    final_ = false;
  }
  clear();
  active_ = stage_shown_ = shown_complete_ = false;
}

void Progress::clear() {
  if (!out_ || !on_line_) return;
  *out_ << '\n' << std::flush;
  on_line_ = false;
}

std::optional<double> Progress::estimate() const {
  if (!active_ || done_ == 0 || done_ >= total_) return std::nullopt;
  return (clock_() - started_) / static_cast<double>(done_) * static_cast<double>(total_ - done_);
}

std::string Progress::line() const {
  std::string text = stage_ + " " + std::to_string(done_) + "/" + std::to_string(total_);
  if (!unit_.empty()) text += " " + unit_;
  if (!detail_.empty()) text += " (" + detail_ + ")";
  if (final_ || done_ >= total_)
    text += ", " + durationText(clock_() - started_);
  else if (const auto left = estimate())
    text += ", about " + durationText(*left) + " left";
  return text;
}

bool Progress::due(double now) const {
  // A stage shows itself once it has run a second on a terminal, `interval` in a log: short
  // work prints nothing. Then at most every `redraw`, or every `interval`, seconds.
  const double since_start = now - started_;
  if (terminal_) return since_start >= 1.0 && (!shown_at_ || now - *shown_at_ >= redraw_);
  return since_start >= interval_ && (!shown_at_ || now - *shown_at_ >= interval_);
}

void Progress::show(double now) {
  if (terminal_) {
    *out_ << '\r' << line() << "\033[K" << std::flush;
    on_line_ = true;
  } else {
    *out_ << line() << '\n' << std::flush;
  }
  shown_at_ = now;
  stage_shown_ = true;
}

}  // namespace view_selection::io
