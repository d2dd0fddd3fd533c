// The records of an MCAP file's data section as the tests walk them (their opcode, where each
// starts, its content), for the tests that look at how pandarcapd laid a file out: its chunks,
// their checksums, the padding after them.
#pragma once

#include <catch2/catch.hpp>
#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "core/mcap/mcap_parse.hpp"

namespace pandarcap::test {

struct DataRecord {
  mcap::Op op{};
  std::size_t at = 0;  // the record's first byte, from the file's start
  std::span<const std::uint8_t> content;
  std::size_t end() const noexcept { return at + mcap::kRecordPrefixBytes + content.size(); }
};

// What a walk expects at the end: a finished file's DataEnd, or (an unfinished .part) the file's
// last byte, where its last record must end.
enum class WalkTo { kDataEnd, kFileEnd };

// Every record of `file` from after its leading magic up to and including DataEnd (or up to the
// file's end). Each must parse, and DataEnd must be there (REQUIRE): the files walked are whole.
inline std::vector<DataRecord> data_records(std::span<const std::uint8_t> file,
                                            WalkTo to = WalkTo::kDataEnd) {
  std::vector<DataRecord> records;
  std::size_t at = mcap::kMagic.size();
  while (at < file.size()) {
    INFO("record at " << at);
    const auto record = mcap::record_at(file.subspan(at));
    REQUIRE(record.has_value());
    records.push_back({record->op, at, record->content});
    if (record->op == mcap::Op::kDataEnd) return records;
    at = records.back().end();
  }
  if (to == WalkTo::kDataEnd) FAIL("no DataEnd record");
  CHECK(at == file.size());
  return records;
}

inline std::vector<DataRecord> data_records(const std::string& file, WalkTo to = WalkTo::kDataEnd) {
  return data_records(std::span(reinterpret_cast<const std::uint8_t*>(file.data()), file.size()),
                      to);
}

}  // namespace pandarcap::test
