// Progress on stderr for long commands: a bar on a terminal, one line per phase otherwise.
#pragma once
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>

namespace sa {

class Progress {
 public:
  explicit Progress(bool enabled, const char* command = "pack")
      : enabled_(enabled), tty_(isatty(2)), command_(command), start_(Clock::now()) {}
  void operator()(const char* phase, uint64_t done, uint64_t total) {
    if (!enabled_) return;
    const auto now = Clock::now();
    const bool phaseChanged = phase != phase_;
    if (phaseChanged && !phase_.empty() && tty_) std::fputc('\n', stderr);
    if (phaseChanged) {
      phase_ = phase;
      phaseStart_ = now;
      if (!tty_) std::fprintf(stderr, "%s: %s...\n", command_, phase);
    }
    if (!tty_) return;
    if (!phaseChanged && done < total && now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    const double secs = std::chrono::duration<double>(now - phaseStart_).count();
    const double frac = total ? double(done) / double(total) : 1.0;
    const int width = 30, filled = static_cast<int>(frac * width);
    std::string bar(size_t(filled), '#');
    bar.resize(width, '.');
    const double rate = secs > 0 ? double(done) / secs / 1e6 : 0;
    std::fprintf(stderr, "\r%-10s [%s] %5.1f%%  %.2fM/%.2fM pts  %.2f Mpts/s  %.1fs ", phase, bar.c_str(),
                 100 * frac, done / 1e6, total / 1e6, rate, secs);
    std::fflush(stderr);
  }
  void finish() {
    if (enabled_ && tty_ && !phase_.empty()) std::fputc('\n', stderr);
  }

 private:
  using Clock = std::chrono::steady_clock;
  bool enabled_, tty_;
  const char* command_;
  std::string phase_;
  Clock::time_point start_, phaseStart_, last_;
};

}  // namespace sa
