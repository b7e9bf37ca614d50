#include "viewer/tile_streamer.h"

#include <algorithm>

namespace sa {

TileStreamer::TileStreamer(const PackReader& pack, unsigned threads, std::function<Status(uint32_t)> afterDecode, Order order)
    : pack_(pack),
      cellCount_(uint32_t(pack.cells().size())),
      afterDecode_(std::move(afterDecode)),
      order_(order),
      claimed_(cellCount_, 0) {
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

void TileStreamer::release(uint32_t cell) {
  std::lock_guard<std::mutex> lock(mu_);
  if (cell < cellCount_) claimed_[cell] = 0;
}

// The next unclaimed cell: from the wish first, then (a whole pack) in cell order.
bool TileStreamer::nextCell(uint32_t& cell) {
  while (wishPos_ < wish_.size()) {
    const uint32_t c = wish_[wishPos_++];
    if (c < cellCount_ && !claimed_[c]) {
      cell = c;
      return true;
    }
  }
  if (order_ == Order::kOnRequest) return false;
  while (nextInOrder_ < cellCount_ && claimed_[nextInOrder_]) ++nextInOrder_;
  if (nextInOrder_ == cellCount_) return false;
  cell = nextInOrder_++;
  return true;
}

bool TileStreamer::idle() const {
  if (busy_) return false;
  for (size_t k = wishPos_; k < wish_.size(); ++k)
    if (wish_[k] < cellCount_ && !claimed_[wish_[k]]) return false;
  return true;
}

void TileStreamer::work() {
  std::unique_lock<std::mutex> lock(mu_);
  for (;;) {
    uint32_t cell = 0;
    while (!stop_ && !nextCell(cell)) {
      if (order_ == Order::kWholePack) return;  // every cell claimed: nothing left for this thread
      changed_.wait(lock);
    }
    if (stop_) return;
    claimed_[cell] = 1;
    ++busy_;
    lock.unlock();
    Status s = pack_.decodeCell(cell);
    if (afterDecode_) {
      Status t = afterDecode_(cell);
      if (s) s = t;
    }
    lock.lock();
    --busy_;
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
  if (order_ == Order::kWholePack) changed_.wait(lock, [&] { return finished_ == cellCount_; });
  else changed_.wait(lock, [&] { return idle(); });
}

Status TileStreamer::error() const {
  std::lock_guard<std::mutex> lock(mu_);
  return error_;
}

}  // namespace sa
