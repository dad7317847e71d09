// Fixed-capacity FIFO of bytes (no heap: the AVR has 2 KB of RAM and no business allocating).
#pragma once
#include <stddef.h>
#include <stdint.h>

template <uint16_t Capacity>
class ByteQueue {
 public:
  static constexpr uint16_t kCapacity = Capacity;
  uint16_t size() const { return count_; }
  uint16_t space() const { return static_cast<uint16_t>(Capacity - count_); }
  bool empty() const { return count_ == 0; }
  void clear() { head_ = count_ = 0; }

  bool push(uint8_t b) {
    if (count_ == Capacity) return false;
    data_[(head_ + count_) % Capacity] = b;
    ++count_;
    return true;
  }
  // All n bytes or none, so a frame is never queued in part.
  bool push_all(const uint8_t* p, size_t n) {
    if (n > space()) return false;
    for (size_t i = 0; i < n; ++i) push(p[i]);
    return true;
  }
  uint8_t pop() {  // callers check empty() first
    const uint8_t b = data_[head_];
    head_ = static_cast<uint16_t>((head_ + 1) % Capacity);
    --count_;
    return b;
  }

 private:
  uint8_t data_[Capacity] = {};
  uint16_t head_ = 0;
  uint16_t count_ = 0;
};
