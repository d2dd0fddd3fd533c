// What the page cache holds of a file, for the tests of the pages the daemon drops once its files
// are synced (daemon/io/file_output.hpp: AfterSync::kDropCached).
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

namespace pandarcap::test {

// Which pages of `file` are in the page cache (mincore of a mapping that touches none). A page
// partly written on a file system whose blocks are smaller than a page is not counted: it is
// cached but not up to date as a whole.
std::vector<bool> cached_pages(const std::filesystem::path& file);

// `file` synced and its pages dropped from the page cache (posix_fadvise POSIX_FADV_DONTNEED), as
// a file written long ago and not read since: where the file system lets clean pages go, none
// stays.
void drop_from_page_cache(const std::filesystem::path& file);

// Whether the file system of `dir` lets clean pages go: not where the pages are the file (tmpfs,
// ramfs, an overlay over either), whatever it is called. Found by trying: 16 pages written,
// synced and dropped.
bool drops_clean_pages(const std::filesystem::path& dir);

// What this process has had read from storage (/proc/self/io read_bytes): page-cache misses.
std::uint64_t storage_bytes_read();

}  // namespace pandarcap::test
