// Progress of long work, as COLMAP's own tools report theirs: the stage, the count done of the
// total and an estimate of the time left ("selecting views 1200/5000 frames, about 40 s left").
// On a terminal one line is rewritten in place (\r), at most every 0.25 s; into a log or a pipe
// a plain line at most every 10 s, so that a log of an hour's work stays readable. A stage that
// ends before anything was shown shows nothing: short work stays silent. The Python tools follow
// the same rules (src/view_selection/progress.py).
//
// The estimate is the stage's mean rate so far: elapsed / done x (total - done). The clock is
// injected (seconds on a monotonic clock), so the rules are tested without sleeping.
#pragma once

#include <cstddef>
#include <functional>
#include <optional>
#include <ostream>
#include <string>

namespace view_selection::io {

/// Seconds on the steady clock: the clock a Progress reads unless it is given another.
double steadySeconds();

/// "40 s", "12 min", "2.5 h": as precise as an estimate deserves.
std::string durationText(double seconds);

class Progress {
 public:
  static constexpr double kLogInterval = 10.0;      ///< [s] between two plain lines
  static constexpr double kTerminalInterval = 0.25;  ///< [s] between two redraws in place

  /// Reports to `out`: rewritten in place when `terminal`, else plain lines every `interval` s.
  Progress(std::ostream& out, bool terminal, std::function<double()> clock = steadySeconds,
           double interval = kLogInterval, double redraw = kTerminalInterval);
  /// Ends a line drawn in place (an error thrown through the work then starts on its own line).
  ~Progress() { clear(); }
  Progress(const Progress&) = default;
  Progress& operator=(const Progress&) = default;

  /// Reports to stderr, in place when stderr is a terminal (isatty); `enabled` false: silent.
  static Progress toStderr(bool enabled = true, double interval = kLogInterval);
  /// A reporter that shows nothing.
  static Progress silent();

  /// The work so far. A new `stage`, or a count that went back (the same work run again on
  /// another batch), starts a new estimate and ends the stage before. The stage's whole count
  /// shows its last line at once (when anything of it was shown). `detail` follows the count
  /// ("1200/5000 frames (312 keyframes)").
  void report(const std::string& stage, size_t done, size_t total, const std::string& unit = "",
              const std::string& detail = "");
  /// The stage's last line, when anything of it was shown (and not its whole count already):
  /// how far it got and the time it took ("1/4 rounds, 43 s": it ended early); then the line
  /// is ended.
  void end();
  /// Ends the line drawn in place, so that what is printed next starts on its own.
  void clear();

  /// What the line says now; seconds left at the stage's mean rate (none before an item is
  /// done, or after the last).
  std::string line() const;
  std::optional<double> estimate() const;
  bool enabled() const { return out_ != nullptr; }

 private:
  bool due(double now) const;
  void show(double now);

  std::ostream* out_;
  bool terminal_;
  std::function<double()> clock_;
  double interval_, redraw_;
  std::string stage_, unit_, detail_;
  bool active_ = false;          ///< a stage is under way
  size_t done_ = 0, total_ = 0;
  double started_ = 0.0;         ///< when the stage started
  std::optional<double> shown_at_;  ///< when a line was last shown (any stage)
  bool stage_shown_ = false;     ///< a line of this stage was shown
  bool shown_complete_ = false;  ///< ... and the last one had the whole count
  bool on_line_ = false;         ///< a line is drawn in place and not ended
  bool final_ = false;           ///< the line being shown is the stage's last
};

}  // namespace view_selection::io
