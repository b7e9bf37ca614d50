#include "viewer/tile_streamer.h"

#include <algorithm>

namespace sa {

TileStreamer::TileStreamer(const PackReader& pack, unsigned threads, std::function<void(uint32_t)> afterDecode)
    : pack_(pack), cellCount_(uint32_t(pack.cells().size())), afterDecode_(std::move(afterDecode)), claimed_(cellCount_, 0) {
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  for (unsigned t = 0; t < threads; ++t) threads_.emplace_back([this] { work(); });
}

TileStreamer::~TileStreamer() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  changed_.notify_all();
  for (std::thread& t : threads_) t.join();
}

void TileStreamer::want(std::vector<uint32_t> cells) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    wish_ = std::move(cells);
    wishPos_ = 0;
  }
  changed_.notify_all();
}

// The next unclaimed cell: from the wish first, then in cell order.
bool TileStreamer::nextCell(uint32_t& cell) {
  while (wishPos_ < wish_.size()) {
    const uint32_t c = wish_[wishPos_++];
    if (c < cellCount_ && !claimed_[c]) {
      cell = c;
      return true;
    }
  }
  while (nextInOrder_ < cellCount_ && claimed_[nextInOrder_]) ++nextInOrder_;
  if (nextInOrder_ == cellCount_) return false;
  cell = nextInOrder_++;
  return true;
}

void TileStreamer::work() {
  std::unique_lock<std::mutex> lock(mu_);
  for (;;) {
    uint32_t cell = 0;
    if (stop_ || !nextCell(cell)) return;  // every cell claimed: nothing left for this thread
    claimed_[cell] = 1;
    lock.unlock();
    Status s = pack_.decodeCell(cell);
    if (afterDecode_) afterDecode_(cell);
    lock.lock();
    if (!s && error_) error_ = s;
    decoded_.push_back(cell);
    ++finished_;
    changed_.notify_all();
  }
}

std::vector<uint32_t> TileStreamer::takeDecoded(size_t maxCells) {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<uint32_t> out;
  const size_t n = std::min(maxCells, decoded_.size());
  out.assign(decoded_.begin(), decoded_.begin() + n);
  decoded_.erase(decoded_.begin(), decoded_.begin() + n);
  taken_ += uint32_t(n);
  return out;
}

void TileStreamer::waitAll() {
  std::unique_lock<std::mutex> lock(mu_);
  changed_.wait(lock, [&] { return finished_ == cellCount_; });
}

Status TileStreamer::error() const {
  std::lock_guard<std::mutex> lock(mu_);
  return error_;
}

}  // namespace sa
