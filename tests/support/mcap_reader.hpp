// The MCAP project's own reader (@mcap/core, with Foxglove's ROS 2 CDR deserialiser), run by
// Node.js over a file: tests/mcap_reader/read_mcap.mjs, installed by .ci/install-deps
// (`npm ci` in tests/mcap_reader). It shares no code with pandarcap's writer.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

namespace pandarcap::test {

// What the reader made of `file`: its JSON description (header, statistics, schemas, channels,
// attachments, metadata, and per topic every message decoded), or, when the reader refused the
// file, nothing, with its message in `error`. When the reader is not installed: under CI=true
// the test FAILs; elsewhere it WARNs and the caller gets nothing with `error` empty.
struct IndependentRead {
  std::optional<nlohmann::json> file;
  std::string error;
  bool reader_missing = false;
};
IndependentRead read_mcap_independently(const std::filesystem::path& file);

}  // namespace pandarcap::test
