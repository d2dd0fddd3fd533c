// The baseline the rings are measured against: a bounded queue guarded by one std::mutex with two
// condition variables, one item per lock, a notify on every push and pop. This is how vendor SDKs
// hand packets from their receive thread to their decoder.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <mutex>
#include <vector>

namespace pandarcap::bench {

template <typename T>
class MutexQueue {
 public:
  explicit MutexQueue(std::size_t capacity) : items_(capacity) {}

  void push(const T& value) {
    std::unique_lock lock(mutex_);
    not_full_.wait(lock, [&] { return size_ < items_.size(); });
    items_[(head_ + size_) % items_.size()] = value;
    ++size_;
    lock.unlock();
    not_empty_.notify_one();
  }

  T pop() {
    std::unique_lock lock(mutex_);
    not_empty_.wait(lock, [&] { return size_ > 0; });
    T value = items_[head_];
    head_ = (head_ + 1) % items_.size();
    --size_;
    lock.unlock();
    not_full_.notify_one();
    return value;
  }

 private:
  std::mutex mutex_;
  std::condition_variable not_empty_;
  std::condition_variable not_full_;
  std::vector<T> items_;
  std::size_t head_ = 0;
  std::size_t size_ = 0;
};

}  // namespace pandarcap::bench
