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

// Every record of `file` from after its leading magic up to and including DataEnd. Each must
// parse and DataEnd must be there (REQUIRE): the files walked are whole.
inline std::vector<DataRecord> data_records(std::span<const std::uint8_t> file) {
  std::vector<DataRecord> records;
  for (std::size_t at = mcap::kMagic.size(); at < file.size();) {
    INFO("record at " << at);
    const auto record = mcap::record_at(file.subspan(at));
    REQUIRE(record.has_value());
    records.push_back({record->op, at, record->content});
    if (record->op == mcap::Op::kDataEnd) return records;
    at = records.back().end();
  }
  FAIL("no DataEnd record");
  return records;
}

inline std::vector<DataRecord> data_records(const std::string& file) {
  return data_records(std::span(reinterpret_cast<const std::uint8_t*>(file.data()), file.size()));
}

}  // namespace pandarcap::test
