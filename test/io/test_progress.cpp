// The progress reporter's rules with an injected clock (no sleeps): plain lines at most every
// 10 s into a log, one line rewritten in place on a terminal, short work silent, the estimate at
// the stage's mean rate. The same cases as test/python/test_progress.py.
#include "view_selection/io/progress.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <sstream>
#include <string>
#include <vector>

namespace view_selection::io {
namespace {

std::vector<std::string> lines(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

struct Fixture {
  double now = 100.0;
  std::ostringstream out;
  Progress progress(bool terminal) {
    return Progress(out, terminal, [this] { return now; });
  }
};

TEST(Progress, ALogGetsAPlainLineAtMostEveryTenSeconds) {
  Fixture f;
  Progress p = f.progress(false);
  size_t shown = 0;
  for (size_t done = 0; done <= 2885; done += 4) {  // 2885 pairs at 64 a second: 45 s (exact in binary)
    f.now = 100.0 + static_cast<double>(done) / 64.0;
    p.report("matching", done, 2885, "pairs");
    shown = lines(f.out.str()).size();
  }
  p.report("matching", 2885, 2885, "pairs");
  p.end();
  EXPECT_EQ(f.out.str().find('\r'), std::string::npos);
  // Lines at 10, 20, 30 and 40 s, then the stage's last one.
  EXPECT_EQ(lines(f.out.str()),
            (std::vector<std::string>{"matching 640/2885 pairs, about 35 s left",
                                      "matching 1280/2885 pairs, about 25 s left",
                                      "matching 1920/2885 pairs, about 15 s left",
                                      "matching 2560/2885 pairs, about 5 s left", "matching 2885/2885 pairs, 45 s"}));
  EXPECT_EQ(shown, 4u);
}

TEST(Progress, TheEstimateIsTheStagesMeanRate) {
  Fixture f;
  Progress p = f.progress(false);
  p.report("matching", 0, 2885, "pairs");
  EXPECT_FALSE(p.estimate());  // nothing done yet: no rate
  f.now += 30.0;
  p.report("matching", 1200, 2885, "pairs");
  ASSERT_TRUE(p.estimate());
  EXPECT_NEAR(*p.estimate(), 30.0 / 1200 * 1685, 1e-9);
  EXPECT_EQ(p.line(), "matching 1200/2885 pairs, about 42 s left");
  f.now += 3570.0;  // a stall slows the rate: the estimate grows with it
  EXPECT_EQ(p.line(), "matching 1200/2885 pairs, about 84 min left");
  p.report("matching", 1201, 2885, "pairs", "3 fell back");
  EXPECT_EQ(p.line(), "matching 1201/2885 pairs (3 fell back), about 84 min left");
  EXPECT_EQ(durationText(0.2), "1 s");
  EXPECT_EQ(durationText(89), "89 s");
  EXPECT_EQ(durationText(150), "3 min");  // half up, as progress.py
  EXPECT_EQ(durationText(5400), "1.5 h");
}

TEST(Progress, ShortWorkPrintsNothing) {
  for (const bool terminal : {false, true}) {
    Fixture f;
    Progress p = f.progress(terminal);
    for (size_t done = 0; done <= 10; ++done) {
      p.report("extracting features", done, 10, "images");
      f.now += 0.0625;
    }
    p.end();
    EXPECT_EQ(f.out.str(), "") << terminal;
  }
  std::ostringstream none;
  Progress silent = Progress::silent();  // --quiet
  silent.report("x", 0, 1);
  silent.end();
  EXPECT_FALSE(silent.enabled());
}

TEST(Progress, ATerminalGetsOneLineRewrittenInPlace) {
  Fixture f;
  Progress p = f.progress(true);
  for (size_t done = 0; done <= 100; ++done) {  // 100 images, 1/16 s each
    f.now = 100.0 + static_cast<double>(done) / 16.0;
    p.report("extracting features", done, 100, "images");
  }
  p.end();
  const std::string text = f.out.str();
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 1);
  EXPECT_EQ(text.back(), '\n');
  std::vector<std::string> draws;
  for (size_t at = text.find('\r'); at != std::string::npos;) {
    const size_t next = text.find('\r', at + 1);
    draws.push_back(text.substr(at + 1, next == std::string::npos ? std::string::npos : next - at - 1));
    at = next;
  }
  // Shown after the first second, then every 0.25 s (each 4th image) to the last, once.
  ASSERT_EQ(draws.size(), 22u);
  for (size_t q = 0; q < draws.size(); ++q)
    EXPECT_EQ(draws[q].rfind("extracting features " + std::to_string(16 + 4 * q) + "/100 images", 0), 0u) << draws[q];
  EXPECT_EQ(draws.front(), "extracting features 16/100 images, about 5 s left\033[K");
  EXPECT_EQ(draws.back(), "extracting features 100/100 images, 6 s\033[K\n");  // then the line is ended
}

TEST(Progress, ANewStageStartsANewEstimate) {
  Fixture f;
  Progress p = f.progress(false);
  for (size_t done = 0; done <= 20; ++done) {
    p.report("extracting features", done, 20, "images");
    f.now += 1.0;
  }
  p.report("matching", 0, 10, "pairs");
  f.now += 11.0;
  p.report("matching", 1, 10, "pairs");
  EXPECT_EQ(p.line(), "matching 1/10 pairs, about 2 min left");  // 11 s a pair, not the extraction's 1 s
  p.end();
  EXPECT_EQ(lines(f.out.str()),
            (std::vector<std::string>{"extracting features 10/20 images, about 10 s left",
                                      "extracting features 20/20 images, 20 s", "matching 1/10 pairs, about 2 min left",
                                      "matching 1/10 pairs, 11 s"}));  // ended early: how far it got
}

TEST(Progress, TheWholeCountShowsAtOnceAndACountThatGoesBackStartsAgain) {
  Fixture f;
  Progress p = f.progress(false);
  for (size_t done = 0; done <= 12; ++done) {  // 12 images, 1 s each: a line at 10 s, and the last at once
    p.report("extracting features", done, 12, "images");
    f.now += 1.0;
  }
  EXPECT_EQ(lines(f.out.str()), (std::vector<std::string>{"extracting features 10/12 images, about 2 s left",
                                                          "extracting features 12/12 images, 12 s"}));
  for (size_t done = 0; done <= 4; ++done) {  // the same stage again on another batch: a new estimate from 0
    p.report("extracting features", done, 4, "images");
    f.now += 4.0;
  }
  p.end();
  EXPECT_EQ(lines(f.out.str()),
            (std::vector<std::string>{"extracting features 10/12 images, about 2 s left",
                                      "extracting features 12/12 images, 12 s", "extracting features 3/4 images, about 4 s left",
                                      "extracting features 4/4 images, 16 s"}));
}

TEST(Progress, ClearEndsTheDrawnLineBeforeOtherOutput) {
  Fixture f;
  Progress p = f.progress(true);
  p.report("matching", 0, 10, "pairs");
  f.now += 2.0;
  p.report("matching", 4, 10, "pairs");
  p.clear();
  f.out << "a log line\n";
  f.now += 1.0;
  p.report("matching", 5, 10, "pairs");
  EXPECT_EQ(f.out.str(),
            "\rmatching 4/10 pairs, about 3 s left\033[K\na log line\n\rmatching 5/10 pairs, about 3 s left\033[K");
}

}  // namespace
}  // namespace view_selection::io
