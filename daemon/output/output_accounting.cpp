#include "daemon/output/output_accounting.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "daemon/clocks.hpp"
#include "daemon/io/file_output.hpp"

namespace pandarcap {

void OutputAccounting::write_failed(std::string_view reason, std::uint64_t bytes) {
  last_error_size_ = std::min(reason.size(), last_error_.size());
  std::copy_n(reason.data(), last_error_size_, last_error_.data());
  count_and_log(bytes);
}

void OutputAccounting::write_failed(const io::IoError& error, std::uint64_t bytes) {
  last_error_size_ = io::format_io_error(error, last_error_);
  count_and_log(bytes);
}

void OutputAccounting::count_and_log(std::uint64_t bytes) {
  ++write_errors_;
  bytes_not_written_ += bytes;
  const std::int64_t now = monotonic_ns();
  if (last_error_log_ns_ < 0 || now - last_error_log_ns_ >= 10'000'000'000) {
    spdlog::error("write failed: {} ({} write errors so far)", last_error(), write_errors_);
    last_error_log_ns_ = now;
  }
}

void OutputAccounting::put_in_place(const std::string& from, std::string& to) {
  if (place_without_replacing(from, to)) name_collision(from, to);
}

void OutputAccounting::name_collision(std::string_view from, std::string_view used) {
  ++name_collisions_;
  spdlog::warn("{}: a file of that name exists; kept as {} instead of replacing it", from, used);
}

}  // namespace pandarcap
