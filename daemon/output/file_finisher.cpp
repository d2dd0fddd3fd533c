#include "daemon/output/file_finisher.hpp"

#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <exception>
#include <system_error>

#include "daemon/clocks.hpp"
#include "daemon/io/file_output.hpp"

namespace pandarcap {
namespace {

// Idle, the thread wakes this often to look again (a notify is never missed; this only bounds
// the cost of a bug to a delay).
constexpr auto kFinisherIdleWait = std::chrono::seconds(1);

void note_error(FinishJob& job, const std::exception& exception) noexcept {
  const auto* system = dynamic_cast<const std::system_error*>(&exception);
  job.error_code = system != nullptr ? system->code().value() : EIO;
  const char* text = exception.what();
  job.failed = true;
  const std::size_t n = std::min(std::strlen(text), job.error.size() - 1);
  std::memcpy(job.error.data(), text, n);
  job.error[n] = '\0';
}

bool needs_directory_sync(const FinishJob& job) noexcept {
  switch (job.kind) {
    case FinishJob::Kind::kPlace:
      return job.placed;
    case FinishJob::Kind::kSync:
      return job.sync_directory && !job.failed;
    case FinishJob::Kind::kReplace:
      // Health's .prom, every second: its data is synced, so whichever of the old and the new
      // file the directory keeps after a power cut is whole. Not worth a journal commit a second.
      return false;
  }
  return false;
}

const std::string& named_file(const FinishJob& job) noexcept {
  return job.kind == FinishJob::Kind::kSync ? job.from : job.to;
}

}  // namespace

FileFinisher::FileFinisher(FinishReceiver& receiver, std::size_t jobs)
    : receiver_(receiver),
      // Room for every job and the stop marker.
      to_finish_(std::bit_ceil(jobs + 1)),
      done_(std::bit_ceil(jobs + 1)) {
  jobs_.reserve(jobs);
  free_.reserve(jobs);
  batch_.reserve(kMaxBatch);
  batch_directories_.resize(jobs + 1);
  for (std::string& directory : batch_directories_)
    directory.reserve(kReservedPath);
  directory_.reserve(kReservedPath);
  for (std::size_t i = 0; i < jobs; ++i) {
    auto job = std::make_unique<FinishJob>();
    job->from.reserve(kReservedPath);
    job->to.reserve(kReservedPath);
    free_.push_back(job.get());
    jobs_.push_back(std::move(job));
  }
  // Every signal blocked while the thread is made, so it starts with them all blocked.
  sigset_t all, before;
  sigfillset(&all);
  pthread_sigmask(SIG_SETMASK, &all, &before);
  try {
    thread_ = std::thread([this] {
      pthread_setname_np(pthread_self(), "pc-finish");
      run();
    });
  } catch (...) {
    pthread_sigmask(SIG_SETMASK, &before, nullptr);
    throw;
  }
  pthread_sigmask(SIG_SETMASK, &before, nullptr);
}

FileFinisher::~FileFinisher() {
  to_finish_.try_push(nullptr);  // never full: it has room for every job and the marker
  to_finish_.notify();
  thread_.join();
  // What finished after the last collect() is not reported: the writer drains before it goes.
}

FinishJob& FileFinisher::take() noexcept {
  while (free_.empty()) {
    if (collect() == 0) done_.wait_for_data(kFinisherIdleWait);
  }
  FinishJob& job = *free_.back();
  free_.pop_back();
  job.kind = FinishJob::Kind::kSync;
  job.from.clear();
  job.to.clear();
  job.sync_directory = false;
  job.remove_on_failure = false;
  job.bytes = job.items = 0;
  job.stamp_ns = job.done_realtime_ns = 0;
  job.placed = job.name_taken = job.failed = false;
  job.error_code = 0;
  job.error[0] = '\0';
  return job;
}

void FileFinisher::submit(FinishJob& job) noexcept {
  to_finish_.try_push(&job);  // never full: at most every job is queued
  ++in_flight_;
  to_finish_.notify();
}

void FileFinisher::place(FinishOwner owner, std::string_view from, std::string_view to,
                         const Placing& placing) noexcept {
  FinishJob& job = take();
  job.kind = FinishJob::Kind::kPlace;
  job.owner = owner;
  job.from.assign(from);  // within the reserved length: no allocation
  job.to.assign(to);
  job.bytes = placing.bytes;
  job.items = placing.items;
  job.stamp_ns = placing.stamp_ns;
  job.remove_on_failure = placing.remove_on_failure;
  submit(job);
}

void FileFinisher::sync(FinishOwner owner, std::string_view path, bool& directory_synced) noexcept {
  FinishJob& job = take();
  job.kind = FinishJob::Kind::kSync;
  job.owner = owner;
  job.from.assign(path);
  job.sync_directory = !directory_synced;
  directory_synced = true;
  submit(job);
}

std::size_t FileFinisher::collect() noexcept {
  std::size_t n = 0;
  FinishJob* job = nullptr;
  while (in_flight_ != 0 && done_.try_pop(job)) {
    --in_flight_;
    receiver_.finished(*job);
    free_.push_back(job);  // within the reserved capacity: one place per job
    ++n;
  }
  return n;
}

void FileFinisher::drain() noexcept {
  while (in_flight_ != 0) {
    if (collect() == 0) done_.wait_for_data(kFinisherIdleWait);
  }
}

void FileFinisher::run() noexcept {
  bool stopping = false;
  while (!stopping) {
    FinishJob* job = nullptr;
    if (!to_finish_.try_pop(job)) {
      to_finish_.wait_for_data(kFinisherIdleWait);
      continue;
    }
    // The jobs queued now make one batch (up to kMaxBatch): their writeback started together,
    // each synced, renamed in order, and one directory sync each for all of them.
    while (true) {
      if (job == nullptr) {
        stopping = true;  // the destructor's marker: after everything queued before it
        break;
      }
      start(*job);
      batch_.push_back(job);
      if (batch_.size() == kMaxBatch || !to_finish_.try_pop(job)) break;
    }
    for (FinishJob* queued : batch_)
      process(*queued);
    end_batch();
  }
}

void FileFinisher::start(FinishJob& job) noexcept {
  start_writeback(job.from);
}

void FileFinisher::process(FinishJob& job) noexcept {
  try {
    // The health files are read by monitoring every scrape: they keep their pages.
    sync_file(job.from,
              job.owner == FinishOwner::kHealth ? AfterSync::kKeepCached : AfterSync::kDropCached);
  } catch (const std::exception& error) {
    note_error(job, error);
  }
  if (job.failed) {
    if (job.kind != FinishJob::Kind::kSync && job.remove_on_failure) ::unlink(job.from.c_str());
    return;
  }
  try {
    switch (job.kind) {
      case FinishJob::Kind::kPlace:
        job.name_taken = place_without_replacing(job.from, job.to);
        job.placed = true;
        break;
      case FinishJob::Kind::kReplace:
        rename_replacing(job.from, job.to);
        job.placed = true;
        break;
      case FinishJob::Kind::kSync:
        break;
    }
  } catch (const std::exception& error) {
    note_error(job, error);
    if (job.remove_on_failure) ::unlink(job.from.c_str());
  }
}

void FileFinisher::end_batch() noexcept {
  batch_directory_count_ = 0;
  for (FinishJob* job : batch_) {
    if (!needs_directory_sync(*job)) continue;
    assign_directory_of(directory_, named_file(*job));
    const auto end =
        batch_directories_.begin() + static_cast<std::ptrdiff_t>(batch_directory_count_);
    if (std::find(batch_directories_.begin(), end, directory_) != end) continue;
    batch_directories_[batch_directory_count_++].assign(directory_);
  }
  for (std::size_t i = 0; i < batch_directory_count_; ++i) {
    const std::string& directory = batch_directories_[i];
    try {
      sync_directory(directory);
    } catch (const std::exception& error) {
      // Renamed, but the name may not survive a power cut: each job there says so.
      for (FinishJob* job : batch_) {
        if (!needs_directory_sync(*job)) continue;
        assign_directory_of(directory_, named_file(*job));
        if (directory_ == directory) note_error(*job, error);
      }
    }
  }
  const std::int64_t done_ns = realtime_ns();
  for (FinishJob* job : batch_) {
    job->done_realtime_ns = done_ns;
    done_.try_push(job);  // never full: room for every job
  }
  batch_.clear();
  done_.notify();
}

}  // namespace pandarcap
