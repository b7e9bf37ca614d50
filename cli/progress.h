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
  // unit: what is counted ("pts" shown in millions, anything else as is).
  explicit Progress(bool enabled, const char* command = "pack", const char* unit = "pts")
      : enabled_(enabled), tty_(isatty(2)), command_(command), unit_(unit), start_(Clock::now()) {}
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
    const bool millions = std::string(unit_) == "pts";
    const double scale = millions ? 1e6 : 1;
    const double rate = secs > 0 ? double(done) / secs / scale : 0;
    char eta[64] = "";
    if (done > 0 && done < total && secs > 1) std::snprintf(eta, sizeof(eta), ", ~%.0fs left", secs * double(total - done) / double(done));
    std::fprintf(stderr, "\r%-10s [%s] %5.1f%%  %.*f%s/%.*f%s %s  %.2f %s%s/s  %.1fs%s   ", phase, bar.c_str(), 100 * frac,
                 millions ? 2 : 0, done / scale, millions ? "M" : "", millions ? 2 : 0, total / scale, millions ? "M" : "",
                 unit_, rate, millions ? "M" : "", unit_, secs, eta);
    std::fflush(stderr);
  }
  void finish() {
    if (enabled_ && tty_ && !phase_.empty()) std::fputc('\n', stderr);
  }

 private:
  using Clock = std::chrono::steady_clock;
  bool enabled_, tty_;
  const char* command_;
  const char* unit_;
  std::string phase_;
  Clock::time_point start_, phaseStart_, last_;
};

}  // namespace sa
