#pragma once
// Row parallelism of the simulator: a persistent pool of workers per camera (internal to
// tofcam::sim).

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <vector>

namespace tofcam::sim::internal {

// Persistent workers for the row-parallel loops of one camera (threads - 1 of them; the calling
// thread works too). Rows are handed out in chunks from an atomic counter, so a busy core does not
// hold the frame back; results never depend on which thread ran a row, because every row has its
// own random stream and its own Embree packets (only scratch buffers are per thread). Spawning
// threads per loop, as before, cost tens of microseconds per loop and frame.
class RowPool {
 public:
  explicit RowPool(int threads) {
    for (int t = 1; t < threads; ++t) workers_.emplace_back([this, t] { Work(t); });
  }
  RowPool(const RowPool&) = delete;
  RowPool& operator=(const RowPool&) = delete;
  ~RowPool() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    for (auto& w : workers_) w.join();
  }

  // Runs body(row_begin, row_end, thread_index) over [0, rows); in parallel only when there are
  // at least min_rows_per_thread rows per thread. Chunks start at multiples of `granularity`
  // rows (the sensor loop draws the noise of eight rows at once).
  template <typename F>
  void Run(int rows, const F& body, int min_rows_per_thread = 2, int granularity = 1) {
    const int threads = static_cast<int>(workers_.size()) + 1;
    if (threads == 1 || rows < min_rows_per_thread * threads) {
      body(0, rows, 0);
      return;
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      body_ = &body;
      call_ = [](const void* b, int r0, int r1, int t) { (*static_cast<const F*>(b))(r0, r1, t); };
      rows_ = rows;
      const int chunk = std::max(1, rows / (8 * threads));
      chunk_ = (chunk + granularity - 1) / granularity * granularity;
      next_.store(0, std::memory_order_relaxed);
      open_ = true;
      ++generation_;
    }
    wake_.notify_all();
    Drain(0);
    // Workers that have not joined yet (their core is busy elsewhere) are not waited for: the job
    // closes, and only those already inside it must finish.
    std::unique_lock<std::mutex> lock(mutex_);
    open_ = false;
    done_.wait(lock, [this] { return active_ == 0; });
  }

 private:
  void Drain(int thread) {
    for (;;) {
      const int r0 = next_.fetch_add(chunk_, std::memory_order_relaxed);
      if (r0 >= rows_) return;
      call_(body_, r0, std::min(r0 + chunk_, rows_), thread);
    }
  }
  void Work(int thread) {
    std::uint64_t seen = 0;
    for (;;) {
      {
        std::unique_lock<std::mutex> lock(mutex_);
        wake_.wait(lock, [&] { return stop_ || (open_ && generation_ != seen); });
        if (stop_) return;
        seen = generation_;
        ++active_;
      }
      Drain(thread);
      std::lock_guard<std::mutex> lock(mutex_);
      if (--active_ == 0) done_.notify_one();
    }
  }

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_, done_;
  bool stop_ = false, open_ = false;
  std::uint64_t generation_ = 0;
  int active_ = 0;
  const void* body_ = nullptr;
  void (*call_)(const void*, int, int, int) = nullptr;
  int rows_ = 0, chunk_ = 1;
  std::atomic<int> next_{0};
};

// Runs body(row_begin, row_end) over [0, rows) on `pool`'s threads, or on the calling thread
// when `pool` is null; for row loops whose results do not depend on the thread.
template <typename F>
void RunRows(RowPool* pool, int rows, const F& body) {
  if (pool == nullptr) {
    body(0, rows);
    return;
  }
  pool->Run(rows, [&body](int r0, int r1, int /*thread*/) { body(r0, r1); });
}

// Runs body(row_begin, row_end, thread_index) over [0, rows) on `threads` threads (the caller's
// included), spawning them per call. Grab() shadows it with the camera's persistent RowPool; this
// version stays for row loops elsewhere (e.g. if the sensor retune adds one to Bloom).
template <typename F>
void ParallelRows(int rows, int threads, const F& body) {
  if (threads <= 1 || rows < 2 * threads) {
    body(0, rows, 0);
    return;
  }
  std::vector<std::thread> pool;
  pool.reserve(static_cast<std::size_t>(threads - 1));
  for (int t = 1; t < threads; ++t) {
    pool.emplace_back([&, t] { body(rows * t / threads, rows * (t + 1) / threads, t); });
  }
  body(0, rows / threads, 0);
  for (auto& th : pool) th.join();
}

}  // namespace tofcam::sim::internal
