#include "daemon/pcap/recording_calibration.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <filesystem>
#include <vector>

#include "core/mcap/mcap_parse.hpp"
#include "core/mcap/mcap_records.hpp"
#include "daemon/io/calibration_file.hpp"
#include "daemon/io/unique_fd.hpp"
#include "daemon/pcap/recording_sidecars.hpp"

namespace pandarcap {
namespace {

constexpr std::string_view kAttachmentName = "calibration.csv";
// An attachment larger than this is not a calibration table (40 lines of ~30 bytes).
constexpr std::uint64_t kMaxCalibrationBytes = 1 << 20;

bool read_fully_at(int fd, std::uint64_t offset, std::uint8_t* out, std::size_t n) {
  std::size_t done = 0;
  while (done < n) {
    const ssize_t got = ::pread(fd, out + done, n - done, static_cast<off_t>(offset + done));
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) return false;
    done += static_cast<std::size_t>(got);
  }
  return true;
}

// The calibration.csv attachment of an MCAP file: its top-level records are walked by their
// lengths (chunks are not read) to the first attachment of that name, before the data end.
std::optional<Calibration> mcap_attachment(int fd, std::uint64_t size, const std::string& path,
                                           std::string& looked_for,
                                           std::optional<SensorModelId> model) {
  looked_for = path + " (attachment " + std::string(kAttachmentName) + ")";
  std::uint64_t at = mcap::kMagic.size();
  std::vector<std::uint8_t> record;
  while (size - at >= mcap::kRecordPrefixBytes) {
    std::uint8_t prefix[mcap::kRecordPrefixBytes];
    if (!read_fully_at(fd, at, prefix, sizeof prefix)) break;
    mcap::ByteReader r(std::span<const std::uint8_t>(prefix, sizeof prefix));
    const auto op = static_cast<mcap::Op>(r.u8());
    const std::uint64_t length = r.u64();
    if (op == mcap::Op::kDataEnd || op == mcap::Op::kFooter || length > size - at - sizeof prefix) {
      break;  // the data section's end, or damage: no attachment found before it
    }
    if (op == mcap::Op::kAttachment && length <= kMaxCalibrationBytes + 4096) {
      record.resize(length);
      if (!read_fully_at(fd, at + sizeof prefix, record.data(), record.size())) break;
      mcap::ByteReader a(record);
      a.u64();  // log time
      a.u64();  // create time
      const std::string_view name = a.string();
      if (!a.failed() && name == kAttachmentName) {
        const std::string where = path + " (attachment " + std::string(kAttachmentName) + ")";
        if (!mcap::parse_attachment(record)) {
          throw CalibrationError(where + ": damaged (it fails its CRC or does not parse)");
        }
        a.string();  // media type
        const std::uint64_t data_size = a.u64();
        const auto data = a.bytes(data_size);
        return Calibration::parse_for(
            std::string_view(reinterpret_cast<const char*>(data.data()), data.size()), where,
            model);
      }
    }
    at += sizeof prefix + length;
  }
  return std::nullopt;
}

}  // namespace

std::optional<Calibration> recording_calibration(const std::string& recording_path,
                                                 std::string& looked_for,
                                                 std::optional<SensorModelId> model) {
  const io::UniqueFd fd(::open(recording_path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC));
  struct stat info {};
  std::uint8_t magic[mcap::kMagic.size()] = {};
  if (fd && ::fstat(fd.get(), &info) == 0 && S_ISREG(info.st_mode) &&
      read_fully_at(fd.get(), 0, magic, sizeof magic) &&
      std::equal(mcap::kMagic.begin(), mcap::kMagic.end(), magic)) {
    return mcap_attachment(fd.get(), static_cast<std::uint64_t>(info.st_size), recording_path,
                           looked_for, model);
  }
  const std::optional<RecordingSidecars> sidecars = recording_sidecars(recording_path);
  if (!sidecars) {
    looked_for = "a NAME.calibration.csv beside it (" + recording_path +
                 " is not named NAME.pcap or NAME.pcap.zst)";
    return std::nullopt;
  }
  looked_for = sidecars->calibration_csv;
  std::error_code ec;
  if (std::filesystem::exists(sidecars->calibration_csv, ec)) {
    return load_calibration(sidecars->calibration_csv, model);
  }
  // A recording still open (a killed run's NAME.pcap.part) has no sidecars yet: its run's table
  // is the directory's calibration.csv, which the next start gives it as its sidecar.
  if (recording_path.ends_with(".part")) {
    const std::filesystem::path beside =
        std::filesystem::path(recording_path).parent_path() / "calibration.csv";
    looked_for += " or " + beside.string();
    if (std::filesystem::exists(beside, ec)) return load_calibration(beside.string(), model);
  }
  return std::nullopt;
}

}  // namespace pandarcap
