// Decodes a pack's compressed tiles on background threads for a window that must never wait:
// the renderer says each frame which visible cells it lacks, nearest first (want), and takes the
// cells decoded since (takeDecoded) to upload. For a whole pack, cells nobody asked for follow in
// cell order, so the whole pack becomes resident in the end; on request (--gpu-budget), only the
// cells asked for are decoded, and a cell released can be asked for again. No GL here.
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
  enum class Order { kWholePack, kOnRequest };
  // `pack` must outlive the streamer. threads: decoding threads (0: one per core). afterDecode,
  // when given, runs on the decoding thread after PackReader::decodeCell and before the cell is
  // handed out (the renderer's levels); an error it returns is kept like a decoding error.
  explicit TileStreamer(const PackReader& pack, unsigned threads = 0, std::function<Status(uint32_t)> afterDecode = {},
                        Order order = Order::kWholePack);
  ~TileStreamer();
  TileStreamer(const TileStreamer&) = delete;
  TileStreamer& operator=(const TileStreamer&) = delete;

  // The cells wanted first, in order; replaces the previous wish.
  void want(std::vector<uint32_t> cells);
  // The cells decoded (or failed) since the last call, at most maxCells of them.
  std::vector<uint32_t> takeDecoded(size_t maxCells = SIZE_MAX);
  // kOnRequest: a cell taken may be asked for again (its data was dropped).
  void release(uint32_t cell);
  // Blocks until every cell is decoded (kWholePack) or every cell asked for is (kOnRequest).
  void waitAll();
  // Whether every cell has been decoded and taken (never, on request).
  bool done() const { return order_ == Order::kWholePack && taken_.load() == cellCount_; }
  // The first cell that failed to decode, if any (its tile stays zero, so the cell never draws).
  Status error() const;

 private:
  void work();
  bool nextCell(uint32_t& cell);  // under mu_
  bool idle() const;               // under mu_: nothing asked for is left or being decoded
  const PackReader& pack_;
  const uint32_t cellCount_;
  std::function<Status(uint32_t)> afterDecode_;
  const Order order_;
  mutable std::mutex mu_;
  std::condition_variable changed_;
  std::vector<uint8_t> claimed_;  // per cell: a thread has taken it
  std::vector<uint32_t> wish_, decoded_;
  size_t wishPos_ = 0;
  uint32_t nextInOrder_ = 0, finished_ = 0, busy_ = 0;
  std::atomic<uint32_t> taken_{0};
  Status error_ = Status::ok();
  bool stop_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace sa
