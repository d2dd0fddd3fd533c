#include "daemon/io/syscalls.hpp"

#include <unistd.h>

namespace pandarcap::io {
namespace {

const FileSyscalls kReal{::write, ::ftruncate, ::close, ::fdatasync};
std::atomic<const FileSyscalls*> current{&kReal};

}  // namespace

FileSyscalls real_file_syscalls() noexcept {
  return kReal;
}

const FileSyscalls& file_syscalls() noexcept {
  return *current.load(std::memory_order_relaxed);
}

ScopedFileSyscalls::ScopedFileSyscalls(const FileSyscalls& calls) noexcept
    : calls_(calls), previous_(current.exchange(&calls_, std::memory_order_relaxed)) {}

ScopedFileSyscalls::~ScopedFileSyscalls() {
  current.store(previous_, std::memory_order_relaxed);
}

}  // namespace pandarcap::io
