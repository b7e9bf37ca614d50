// Decodes a pack's compressed tiles on background threads for a window that must never wait:
// the renderer says each frame which visible cells it lacks, nearest first (want), and takes the
// cells decoded since (takeDecoded) to upload. Cells nobody asked for follow in cell order, so
// the whole pack becomes resident in the end. No GL here.
#pragma once
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "atlas/pack_file.h"
#include "common/error.h"

namespace sa {

class TileStreamer {
 public:
  // `pack` must outlive the streamer. threads: decoding threads (0: one per core). afterDecode,
  // when given, runs on the decoding thread after each cell's tile is decoded and before the
  // cell is handed out (the renderer's mip levels).
  explicit TileStreamer(const PackReader& pack, unsigned threads = 0, std::function<void(uint32_t)> afterDecode = {});
  ~TileStreamer();
  TileStreamer(const TileStreamer&) = delete;
  TileStreamer& operator=(const TileStreamer&) = delete;

  // The cells wanted first, in order; replaces the previous wish.
  void want(std::vector<uint32_t> cells);
  // The cells decoded (or failed) since the last call, at most maxCells of them.
  std::vector<uint32_t> takeDecoded(size_t maxCells = SIZE_MAX);
  // Blocks until every cell is decoded (tests, and renders that must be complete).
  void waitAll();
  // Whether every cell has been decoded and taken.
  bool done() const { return taken_.load() == cellCount_; }
  // The first cell that failed to decode, if any (its tile stays zero, so the cell never draws).
  Status error() const;

 private:
  void work();
  bool nextCell(uint32_t& cell);  // under mu_
  const PackReader& pack_;
  const uint32_t cellCount_;
  std::function<void(uint32_t)> afterDecode_;
  mutable std::mutex mu_;
  std::condition_variable changed_;
  std::vector<uint8_t> claimed_;  // per cell: a thread has taken it
  std::vector<uint32_t> wish_, decoded_;
  size_t wishPos_ = 0;
  uint32_t nextInOrder_ = 0, finished_ = 0;
  std::atomic<uint32_t> taken_{0};
  Status error_ = Status::ok();
  bool stop_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace sa
